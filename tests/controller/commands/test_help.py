"""Every ``--help`` of the command tree prints: the top level lists each subcommand's help,
which argparse %-formats, so a leaf's docstring with a percent sign must not break it."""

from __future__ import annotations

import argparse
import subprocess
import sys

from controller.cli import build_parser


def _parsers(parser: argparse.ArgumentParser, path: str = "finepos"):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from _parsers(child, f"{path} {name}")


def test_every_parsers_help_formats():
    seen = []
    for path, parser in _parsers(build_parser()):
        text = parser.format_help()
        assert text.startswith("usage:"), path
        seen.append(path)
    assert "finepos compare" in seen and "finepos bench perception" in seen
    assert "finepos ctl status" in seen


def test_top_level_help_lists_compare_with_its_percent_sign():
    done = subprocess.run([sys.executable, "-m", "controller.cli", "--help"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-500:]
    assert "paired 95% intervals" in done.stdout
    assert "Traceback" not in done.stderr
    # a first sentence running over two docstring lines is listed whole
    assert "servo (align), in good and poor light" in " ".join(done.stdout.split())
