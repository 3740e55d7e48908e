"""Shared plumbing for command groups whose leaves live in other packages.

A group (``finepos sim ...``, ``finepos bench ...``) maps each leaf name to a module that
defines ``add_arguments(parser)``, ``run(args) -> int`` and a module docstring whose first
line is the help text and which has an ``Example: finepos ...`` line (shown first in
--help). Modules are imported when the parser is built; none has import-time side effects.
"""

from __future__ import annotations

import argparse
import importlib


def register_group(subparsers, name: str, help_text: str, leaves: dict[str, str]) -> None:
    """Add command group ``name`` with one leaf per ``leaves`` entry (leaf name -> module name).

    Each leaf gets its module's ``add_arguments`` options and ``run`` as ``func``; its help is the
    module docstring's first line, its description the docstring with the ``Example:`` line first.
    """
    group = subparsers.add_parser(name, help=help_text, description=help_text)
    sub = group.add_subparsers(dest=f"{name}_command", metavar="COMMAND", required=True)
    for leaf, module_name in leaves.items():
        add_leaf(sub, leaf, importlib.import_module(module_name))


def add_leaf(subparsers, name: str, module) -> argparse.ArgumentParser:
    """Add subcommand ``name`` from a leaf module: help from its docstring's first sentence, the
    docstring (``Example:`` line first) as description, its ``add_arguments`` and ``run``."""
    doc = (module.__doc__ or "").strip()
    # the help is the docstring's first paragraph (a sentence may run over two lines)
    first = " ".join(doc.split("\n\n")[0].split()).rstrip(".") if doc else name
    if first[:1].isupper() and not first[1:2].isupper():  # a sentence; --help lists phrases
        first = first[0].lower() + first[1:]
    # argparse %-formats a help string (for %(prog)s): a literal percent sign must be doubled
    parser = subparsers.add_parser(name, help=first.replace("%", "%%"),
                                   description=example_first(doc),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    module.add_arguments(parser)
    parser.set_defaults(func=module.run)
    return parser


def example_first(doc: str) -> str:
    """The docstring with its ``Example:`` line moved to the top (help starts with it)."""
    lines = doc.splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith("Example"):
            rest = lines[:i] + lines[i + 1:]
            return line.strip() + "\n\n" + "\n".join(rest).strip()
    return doc
