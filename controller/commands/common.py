"""Options and helpers shared by the workflow commands."""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

from controller import simulated
from controller.config import cell_part, load_config, with_part, with_recipe
from controller.loop.iteration_log import IterationLog
from controller.recipe import load_recipe
from controller.systems.registry import SYSTEMS
from controller.teach.state_folder import StateFolder
from drivers.core import parts
from drivers.core.errors import ConfigError

ALL_PARTS = "all"


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 and below 1e6 (limits, frame rates)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}") from None
    if not (0.0 < value < 1e6):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def positive_int(text: str) -> int:
    """argparse type: a whole number >= 1 (counts of trials, repeats, workers)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") \
            from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def loop_budget(text: str) -> float:
    """argparse type: a loop budget, a finite number >= 0.5 (one half loop)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of loops, got {text!r}") from None
    if not (value >= 0.5 and value < 1e6):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0.5, got {text}")
    return value


def add_config_file_option(parser: argparse.ArgumentParser) -> None:
    """``--config FILE``: the root config (default: the simulated cell, all defaults)."""
    parser.add_argument("--config", metavar="FILE",
                        help="finepos YAML config (default: the simulated cell, all defaults)")


def add_recipe_option(parser: argparse.ArgumentParser) -> None:
    """``--recipe FILE``: the perception and loop settings the command trains with."""
    parser.add_argument("--recipe", metavar="FILE",
                        help="train with this recipe (YAML: perception and loop sections, "
                             "docs/configuration.md#recipe; default: the defaults)")


def add_config_option(parser: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--state-dir DIR`` (the workflow commands)."""
    add_config_file_option(parser)
    parser.add_argument("--state-dir", metavar="DIR",
                        help="override controller.paths.state_dir (teach-in, datasets, models)")


def part_name(text: str) -> str:
    """argparse type: a part's name (``drivers.core.parts.PART_NAME``); whether the cell knows
    it is checked once the config, which may declare parts, is loaded (``with_part``)."""
    if text in parts.RESERVED_NAMES:
        raise argparse.ArgumentTypeError(f"{text!r} names every part: only finepos evaluate "
                                          "takes it")
    if not parts.PART_NAME.fullmatch(text):
        raise argparse.ArgumentTypeError(
            f"not a part's name: {text[:40]!r} (built-in parts: {', '.join(parts.PARTS)}; "
            f"{parts.DECLARE_HINT})")
    return text


def part_name_or_all(text: str) -> str:
    """argparse type: a part's name, or ``all`` (every part the cell knows)."""
    return text if text == ALL_PARTS else part_name(text)


PART_HELP = (f"{' | '.join(parts.PARTS)} or a part declared under parts: in the config")


def add_part_option(parser: argparse.ArgumentParser, default_help: str) -> None:
    """``--part NAME``: the part the command works on (built-in or declared in the config);
    on the simulated cell that part is also put on the table. ``default_help`` says what
    applies without it."""
    parser.add_argument("--part", metavar="NAME", type=part_name,
                        help=f"the part: {PART_HELP} (default: {default_help}); on the "
                             "simulated cell it is put on the table")


def add_system_option(parser: argparse.ArgumentParser) -> None:
    """``--system NAME``: the vision system (``controller.systems.registry``), gabor by
    default."""
    parser.add_argument("--system", default="gabor", choices=sorted(SYSTEMS),
                        help="the vision system: gabor (finepos' own, the default), pca or "
                             "hough (the paper's baselines), align (an image-alignment servo, "
                             "for comparison)")


TAUGHT_PART_HELP = "the one part taught, else the cell's: controller.part or the simulated table's"


def state_root(args, config) -> str:
    """The state folder: ``--state-dir``, else ``controller.paths.state_dir``."""
    return getattr(args, "state_dir", None) or config.controller.paths.state_dir


def part_setup(args, config, *, teach: bool = False):
    """The config set up for the command's part, and that part's state folder.

    The part is ``--part``; without it, for ``teach`` the cell's part (the simulated table's, or
    ``controller.part`` on a real cell), otherwise the one part taught (the cell's when none
    is).

    Returns:
        (config with ``controller.part`` and the simulated table's part set, the part's folder
        under ``--state-dir`` or ``controller.paths.state_dir``).

    Raises:
        ConfigError: several parts are taught and none is named.
    """
    default = cell_part(config)
    folder = StateFolder(state_root(args, config), default, config.parts)
    requested = getattr(args, "part", None)
    kind = (requested or default) if teach else folder.resolve(requested, default)
    return with_part(config, kind), folder.part_dir(kind)


def add_log_option(parser: argparse.ArgumentParser) -> None:
    """``--log FILE``: the per-iteration JSON Lines log (default: a new file in log_dir)."""
    parser.add_argument("--log", metavar="FILE",
                        help="per-iteration JSON Lines log (default: a new file in "
                             "controller.paths.log_dir)")


def config_from_args(args):
    """The config of ``--config`` (all defaults without it) running the recipe of ``--recipe``
    where the command has one; raises ConfigError naming the key."""
    config = load_config(getattr(args, "config", None))
    recipe = getattr(args, "recipe", None)
    return config if recipe is None else with_recipe(config, load_recipe(recipe))


@contextlib.contextmanager
def iteration_log(args, config):
    """Context manager: the IterationLog at ``--log``, closed when the block ends.

    Without ``--log`` it is a new ``iterations-YYYYmmdd-HHMMSS.jsonl`` in
    ``controller.paths.log_dir``. The path is printed on stderr.
    """
    path = getattr(args, "log", None)
    if path is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        path = Path(config.controller.paths.log_dir) / f"iterations-{stamp}.jsonl"
    with IterationLog(path) as log:
        print(f"iteration log: {path}", file=sys.stderr)
        yield log


def parse_triple(text: str, what: str) -> tuple[float, float, float]:
    """Parse ``DX,DY,DPHI`` (three finite numbers) or raise ConfigError naming ``what``."""
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3 or not all(abs(v) < 1e6 for v in values):
        raise ConfigError(f"{what}: expected three numbers DX,DY,DPHI (mm, mm, deg), "
                          f"got {text!r}")
    return values  # type: ignore[return-value]


def add_command(subparsers, name: str, *, help: str, description: str) -> argparse.ArgumentParser:
    """Add subcommand ``name``; its ``--help`` shows ``description`` as written, which starts
    with its runnable example (``Example: finepos ...``).

    Raises:
        ValueError: the description does not start with an example.
    """
    if not description.startswith("Example: finepos "):
        raise ValueError(f"finepos {name}: the help must start with 'Example: finepos ...'")
    return subparsers.add_parser(name, help=help, description=description,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def add_record_option(parser: argparse.ArgumentParser) -> None:
    """``--record FILE.mcap``: record the run for Foxglove and ``finepos replay``; and
    ``--live [PORT]``."""
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record every look (frame, overlays, record, tool pose) and the "
                             "grasp's wrench readings as MCAP (Foxglove; finepos replay)")
    add_live_option(parser)


def port_number(text: str) -> int:
    """An argparse type: a TCP port, 0..65535 (0: any free one)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number, got {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port 0..65535, got {value}")
    return value


def add_live_option(parser: argparse.ArgumentParser) -> None:
    """``--live [PORT]``: serve the run live to Foxglove (WebSocket on 127.0.0.1)."""
    from controller.service.config import LIVE_PORT

    parser.add_argument("--live", type=port_number, nargs="?", const=LIVE_PORT, metavar="PORT",
                        help="serve the run live for Foxglove (hand camera, overlays, tool pose, "
                             "wrench, iteration records) as a Foxglove WebSocket on 127.0.0.1 "
                             f"at PORT (default {LIVE_PORT}; 0: any free port)")


@contextlib.contextmanager
def run_recorder(args, max_runs: int | None = None):
    """Context manager: what records the run: the RunRecorder at ``--record`` (its first
    ``max_runs`` runs), the live view of ``--live`` (every run), both, or None; closed at the
    end.

    The path and the live view's address are printed on stderr.
    """
    path = getattr(args, "record", None)
    port = getattr(args, "live", None)
    with contextlib.ExitStack() as stack:
        recorders = []
        if port is not None:
            from controller.recording.live import LiveServer

            live = stack.enter_context(LiveServer(port))
            print(f"live: {live.url} (Foxglove: Open connection, Foxglove WebSocket)",
                  file=sys.stderr)
            recorders.append(live)
        if path is not None:
            from controller.recording.writer import RunRecorder

            recorders.append(stack.enter_context(RunRecorder(path, max_runs=max_runs)))
            print(f"recording: {path}", file=sys.stderr)
        if len(recorders) > 1:
            from controller.recording.live import Tee

            yield Tee(*recorders)
        else:
            yield recorders[0] if recorders else None


def add_timing_option(parser: argparse.ArgumentParser, default: str | None = "realistic") -> None:
    """``--timing realistic|ideal``: the simulated cell's timing (``scene.timing``); realistic
    takes the ``timing:`` section's durations (on a virtual clock in process, really on the
    emulators' wire), ideal makes every action instant. None: the config's."""
    parser.add_argument("--timing", choices=("realistic", "ideal"), default=default,
                        help="the simulated cell's timing (default: "
                             f"{default or 'scene.timing of the config'})")


def run_config_from_args(args):
    """The config of ``--config`` with its ``scene`` read, ``--timing`` and ``--part`` applied
    (``--part all`` leaves the part to the caller): what evaluate, table1 and demo run on, the
    simulated cell whatever devices the file names."""
    config = with_timing(simulated.with_scene_read(config_from_args(args)), args.timing)
    part = getattr(args, "part", None)
    return config if part in (None, ALL_PARTS) else with_part(config, part)


def with_timing(config, mode: str | None):
    """``config`` with ``scene.timing`` replaced by ``mode`` (None: unchanged)."""
    if mode is None:
        return config
    import dataclasses

    return dataclasses.replace(config, scene=dataclasses.replace(config.scene, timing=mode))
