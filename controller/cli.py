"""The ``finepos`` command: one entry point, one subcommand module per job.

A module in COMMAND_MODULES is either one subcommand, named after the module, whose docstring
is its help (first line) and description (``Example:`` line first), with ``add_arguments`` and
``run`` (see ``controller.commands.leaves``); or it defines ``register(subparsers)``, which adds
several subcommands or a group. ``run`` takes the parsed args and returns the exit code.

A cell command (``CELL_COMMAND_MODULES``) builds the parser of its own module alone, so running
it on a real cell imports neither the simulator nor the lab (the evaluation, the benchmarks,
the comparisons: tests/test_layout.py and tests/test_product_path.py); ``finepos --help`` and
every other command build the whole parser.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys
import textwrap
import threading

from controller.commands.leaves import add_leaf
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
    "controller.commands.check",
    "controller.commands.compare",
    "controller.commands.fit_timing",
    "controller.commands.grasp_sweep",
    "controller.commands.replay",
)

# How ``finepos --help`` groups the subcommands: what a cell runs first, in this order (any
# command not named in either list follows them), then what measures and compares.
CELL_COMMANDS = ("serve", "ctl", "teach", "acquire", "train", "rezero", "position", "grasp",
                 "check", "fit-timing", "replay", "sim", "demo")
RESEARCH_COMMANDS = ("evaluate", "table1", "filter-search", "compare", "grasp-sweep", "bench",
                     "docs")
# The module behind each command a real cell runs: only it is registered when one of these runs.
CELL_COMMAND_MODULES = {
    "serve": "controller.commands.serve",
    "ctl": "controller.commands.ctl",
    **dict.fromkeys(("teach", "acquire", "train", "rezero", "position", "grasp"),
                    "controller.commands.workflow"),
    "check": "controller.commands.check",
    "fit-timing": "controller.commands.fit_timing",
    "replay": "controller.commands.replay",
}

logger = logging.getLogger("finepos")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``finepos`` argument parser, with every module in COMMAND_MODULES registered; for a
    cell ``command`` (a key of CELL_COMMAND_MODULES) only the module behind it."""
    parser = argparse.ArgumentParser(
        prog="finepos",
        description="Calibration-free visual fine positioning for a camera-in-hand robot arm.",
        epilog="Example: finepos sim snapshot --out hand.png --offset 10,-5,20",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging on stderr")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    names = (CELL_COMMAND_MODULES[command],) if command in CELL_COMMAND_MODULES else \
        COMMAND_MODULES
    for name in names:
        module = importlib.import_module(name)
        if hasattr(module, "register"):  # several subcommands, or a group
            module.register(sub)
        else:  # one subcommand, named after its module (fit_timing: fit-timing)
            add_leaf(sub, name.rpartition(".")[2].replace("_", "-"), module)
    _group_commands(parser, sub)
    return parser


def _group_commands(parser: argparse.ArgumentParser, sub) -> None:
    """List the subcommands in ``--help`` as two groups, the cell's commands first and the
    research commands (``RESEARCH_COMMANDS``) after them, in place of argparse's one list."""
    helps = {action.dest: action.help for action in sub._choices_actions}
    cell = [name for name in CELL_COMMANDS if name in helps]
    cell += [name for name in helps if name not in cell and name not in RESEARCH_COMMANDS]
    research = [name for name in RESEARCH_COMMANDS if name in helps]
    width = max(len(name) for name in helps) + 2
    wrap = 100 - width - 2

    def listing(names: list[str]) -> list[str]:
        lines = []
        for name in names:
            # leaf helps are %-escaped for argparse; the description is printed as it is
            text = textwrap.wrap((helps[name] or "").replace("%%", "%"), wrap) or [""]
            lines.append(f"  {name:<{width}}{text[0]}")
            lines += [" " * (width + 2) + more for more in text[1:]]
        return lines

    parser.description = "\n".join([
        parser.description, "", "cell commands (each: finepos COMMAND --help):",
        *listing(cell), "", "research commands (measure, compare, document):",
        *listing(research)])
    sub.help = argparse.SUPPRESS  # the grouped listing above replaces argparse's own
    parser.usage = "%(prog)s [-h] [-v] COMMAND ..."


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

    Every failure ends in one line on stderr, never a traceback (``-v`` adds it to the log).

    Returns:
        The exit status: the subcommand's (None counts as 0); 2 after a FineposError such as an
        unloadable config (printed as ``finepos: error: ...``; for ``finepos serve`` under
        systemd this status is final: the unit's ``RestartPreventExitStatus=2``); 1 after an
        OS error (a full disk, a missing folder...) or an unexpected error (``finepos: internal
        error: ...``), which systemd restarts after ``RestartSec``; 130 after Ctrl-C, 143 after
        SIGTERM (files being written keep their old contents). Bad
        arguments make argparse exit with 2.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_word(argv))
    args = parser.parse_args(argv)
    args.command_line = ["finepos", *argv]  # reports quote the command that made them
    setup_logging(args.verbose)
    previous = _terminate_on_sigterm()
    try:
        return int(args.func(args) or 0)
    except Terminated:
        print("finepos: terminated (SIGTERM); files being written keep their old contents",
              file=sys.stderr)
        return 143
    except FineposError as exc:
        print(f"finepos: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("finepos: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:
        logger.debug("OS error", exc_info=exc)
        where = f" ({exc.filename})" if getattr(exc, "filename", None) else ""
        print(f"finepos: error: {exc.strerror or _one_line(exc)}{where}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug: one line for the user, the traceback with -v
        logger.debug("internal error", exc_info=exc)
        print(f"finepos: internal error: {type(exc).__name__}: {_one_line(exc)} (run with -v "
              "for the traceback)", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _command_word(argv: list[str]) -> str | None:
    """The subcommand ``argv`` names (its first word that is not an option); None when there is
    none or the top-level help comes first."""
    for arg in argv:
        if arg in ("-h", "--help"):
            return None
        if not arg.startswith("-"):
            return arg
    return None


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM, so an interrupted command (train, acquire) unwinds:
    atomic writes remove their temporary file and the old file stays."""


def _terminate_on_sigterm():
    """Install the SIGTERM handler raising Terminated; returns the previous handler (None when
    not in the main thread). ``finepos serve`` installs its own for its run."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def terminate(_signum, _frame):
        raise Terminated

    return signal.signal(signal.SIGTERM, terminate)


def _one_line(exc: BaseException) -> str:
    """The exception's message on one line, at most 500 characters."""
    text = " ".join(str(exc).split())
    return text if len(text) <= 500 else text[:497] + "..."


if __name__ == "__main__":
    sys.exit(main())
