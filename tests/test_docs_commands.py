"""Every ``finepos`` command a reader is told to type parses with the real argument parser:
the command lines in the shell blocks of README.md and docs/*.md, and the commands quoted in
their tables (parsed, never run). ``S`` (a seed) and ``P`` (a part) stand for values."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from controller.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PLACEHOLDERS = ((r"--seed S\b", "--seed 1"), (r"--part P\b", "--part cube"))


def _commands(text: str) -> list[str]:
    """Command lines in ``sh`` blocks, and backticked commands in table rows."""
    found, block = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            block = line.strip() == "```sh"
            continue
        if block and line.strip().startswith("finepos "):
            found.append(line.strip().split(" # ")[0].split("  #")[0].rstrip(" &\\"))
        elif not block and line.startswith("|"):
            found += re.findall(r"`(finepos [^`]+)`", line)
    return found


CASES = [(page.relative_to(ROOT).as_posix(), command)
         for page in PAGES for command in _commands(page.read_text(encoding="utf-8"))]


def test_the_pages_quote_commands():
    assert len(CASES) > 50


@pytest.mark.parametrize(("page", "command"), CASES)
def test_command_parses(page, command):
    for pattern, value in PLACEHOLDERS:
        command = re.sub(pattern, value, command)
    words = shlex.split(command)
    if words[1:] == ["--help"]:
        return
    try:
        build_parser().parse_args(words[1:])
    except SystemExit as exc:
        pytest.fail(f"{page}: `{command}` does not parse (exit {exc.code})")
