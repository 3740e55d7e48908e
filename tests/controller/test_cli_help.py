"""``finepos --help``: the cell's commands first, the research commands as their own group, and
every subcommand listed exactly once."""

from __future__ import annotations

from controller.cli import CELL_COMMANDS, RESEARCH_COMMANDS, build_parser


def _listed(text: str, header: str) -> list[str]:
    """The command names listed under ``header`` in the top-level help."""
    block = text.split(header, 1)[1].split("\n\n", 1)[0]
    return [line.split()[0] for line in block.splitlines()[1:]
            if line.startswith("  ") and not line.startswith("   ")]


def test_cell_commands_come_first_and_research_commands_are_grouped():
    parser = build_parser()
    text = parser.format_help()
    assert text.index("cell commands") < text.index("research commands") < text.index("options:")
    cell = _listed(text, "cell commands")
    research = _listed(text, "research commands")
    assert cell[:len(CELL_COMMANDS)] == list(CELL_COMMANDS)
    assert research == list(RESEARCH_COMMANDS)
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sorted(cell + research) == sorted(sub.choices)


def test_usage_still_names_the_command():
    assert build_parser().format_usage().startswith("usage: finepos [-h] [-v] COMMAND ...")
