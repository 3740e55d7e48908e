"""The ``finepos`` command: one entry point, one subcommand module per job.

Each module in COMMAND_MODULES defines ``register(subparsers)``, which adds its subcommand(s)
and sets ``func`` (taking the parsed args, returning an exit code) as the parser default.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys

from drivers.core.errors import FineposError

COMMAND_MODULES = (
    "controller.commands.workflow",
    "controller.commands.evaluate",
    "controller.commands.demo",
    "controller.commands.groups",
    "controller.commands.serve",
    "controller.commands.ctl",
    "controller.commands.table1",
    "controller.commands.filter_search",
)

logger = logging.getLogger("finepos")


def build_parser() -> argparse.ArgumentParser:
    """The ``finepos`` argument parser, with every module in COMMAND_MODULES registered."""
    parser = argparse.ArgumentParser(
        prog="finepos",
        description="Calibration-free visual fine positioning for a camera-in-hand robot arm.",
        epilog="Example: finepos sim snapshot --out hand.png --offset 10,-5,20",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging on stderr")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def setup_logging(verbose: bool) -> None:
    """Human log on stderr; under systemd (stderr is the journal) without our own timestamp,
    since journald adds one."""
    stamp = "" if os.environ.get("JOURNAL_STREAM") else "%(asctime)s "
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format=stamp + "%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (None: ``sys.argv[1:]``), set up logging and run the chosen subcommand.

    Returns:
        The exit status: the subcommand's (None counts as 0), 2 after a FineposError (printed as
        ``finepos: error: ...``), 130 after Ctrl-C. Bad arguments make argparse exit with 2.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    setup_logging(args.verbose)
    try:
        return int(args.func(args) or 0)
    except FineposError as exc:
        print(f"finepos: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("finepos: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
