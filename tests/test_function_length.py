"""No function of the source is longer than ``MAX_LINES`` lines, decorators and docstring
included (read with ``ast``, nothing imported), except the argparse tables in
``ARGPARSE_TABLES``: a ``register`` that adds subcommands and their options and nothing else
reads best as one table."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("drivers", "calibration_free", "sim_backend", "controller")
MAX_LINES = 80
# (module path, function name): argparse tables, exempt.
ARGPARSE_TABLES = {("controller/commands/workflow.py", "register")}


def _functions():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    start = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                    yield (path.relative_to(ROOT).as_posix(), node.name,
                           node.end_lineno - start + 1)


def test_no_function_over_the_limit():
    long = [f"{path}: {name} ({lines} lines)" for path, name, lines in _functions()
            if lines > MAX_LINES and (path, name) not in ARGPARSE_TABLES]
    assert not long, f"functions over {MAX_LINES} lines: " + "; ".join(long)


def test_the_exempt_tables_exist_and_are_argparse_tables():
    found = {(path, name) for path, name, _ in _functions()}
    assert ARGPARSE_TABLES <= found
    for path, name in ARGPARSE_TABLES:
        tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
        node = next(n for n in ast.walk(tree)
                    if isinstance(n, ast.FunctionDef) and n.name == name)
        calls = {ast.unparse(c.func).rpartition(".")[2] for c in ast.walk(node)
                 if isinstance(c, ast.Call)}
        table = {"add_command", "add_argument", "set_defaults", "add_mutually_exclusive_group",
                 "join", "add_config_option", "add_device_options", "add_part_option",
                 "add_system_option", "add_log_option", "add_record_option"}
        assert calls <= table, f"{path}: {name} does more than build parsers: {calls - table}"
