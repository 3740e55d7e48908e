"""How long the simulated cell takes: the cell clock and what each device action costs on it.

``drivers.core.timing`` holds the model (figures and formulas); this module applies it to the
simulated devices (``sim_backend.devices``). Two clocks, the same seconds:

- ``VirtualClock`` (the in-process simulated cell, ``scene.timing: realistic``): every action
  advances a counter by its modelled duration and nothing sleeps, so a 200-trial evaluation
  stays quick in wall time. The VAL wire time the real driver would spend is charged too (the
  bytes of each exchange as the VAL emulator writes them, at ``timing.val_baud``), and so is
  the ATI line's.
- ``WallClock`` (behind the emulators): an action really takes its duration (``advance``
  sleeps), and the emulator's line paces the bytes at the baud rate itself, so no wire time is
  charged here.

``CellTiming`` is None for ``scene.timing: ideal``: every action is instant and free.
"""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from drivers.core.errors import ConfigError
from drivers.core.timing import TimingConfig, TimingMode, move_time_s
from drivers.core.typed_config import from_mapping, load_yaml_file
from drivers.val.config import ValCommands

# The VAL monitor's `where` reply as the emulator writes it: two header lines and two value
# lines of six 10-character columns, each ending in CR LF, then the prompt.
WHERE_REPLY_BYTES = 4 * (6 * 10 + 2) + 1
_COMMANDS = ValCommands()


def val_exchange_bytes(line: str, reply_bytes: int = 1) -> int:
    """Bytes on the VAL line for one command: the line plus CR, its echo plus CR LF, and the
    reply (default: the bare prompt)."""
    return (len(line) + 1) + (len(line) + 2) + reply_bytes


def where_bytes() -> int:
    """Bytes of one ``where`` exchange (262: 273 ms at 9600 baud)."""
    return val_exchange_bytes(_COMMANDS.where, WHERE_REPLY_BYTES)


def move_bytes(pose_fields: dict[str, float]) -> int:
    """Bytes of one ``do move trans(...)`` exchange to a pose (``Pose.as_dict()``)."""
    return val_exchange_bytes(_COMMANDS.move.format(**pose_fields))


def gripper_bytes(closed: bool) -> int:
    """Bytes of one ``do closei`` / ``do openi`` exchange."""
    return val_exchange_bytes(_COMMANDS.gripper_close if closed else _COMMANDS.gripper_open)


# What the time budget (``CellTiming.spent``, the evaluate report's ``time_split_s``) splits a
# trial's cell seconds into: serial lines, controller set-up (``t0_s`` of a command that
# moves), arm motion (profile and settling), hand, sensor sample waits, camera frame waits.
BUDGET = ("wire", "setup", "motion", "hand", "sensor", "camera")

# ATI: "SA n\r" and its echo, then the prompt (a set-up command of 5 characters).
ATI_SA_BYTES = 5 + 1 + 5 + 2 + 1

# ATI: "QR\r", its echo, then one ASCII record (status, six comma-separated 6-wide values,
# CR LF) and the ">" prompt, as the ATI emulator writes them.
ATI_QR_BYTES = 3 + 4 + (1 + 6 * 7) + 2 + 1


class CellClock:
    """The cell's time in seconds: ``now()``, and ``advance(s)`` to let ``s`` seconds pass."""

    virtual = False

    def now(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def advance(self, seconds: float) -> None:  # pragma: no cover - abstract
        raise NotImplementedError


class VirtualClock(CellClock):
    """A counter: ``advance`` adds to it at once (thread-safe)."""

    virtual = True

    def __init__(self, start_s: float = 0.0) -> None:
        self._t = start_s
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def advance(self, seconds: float) -> None:
        if seconds > 0:
            with self._lock:
                self._t += seconds


class WallClock(CellClock):
    """Real time (``time.monotonic``): ``advance`` sleeps, cut short by ``interrupt()``."""

    def __init__(self) -> None:
        self._stop = threading.Event()

    def now(self) -> float:
        return time.monotonic()

    def advance(self, seconds: float) -> None:
        if seconds > 0:
            self._stop.wait(seconds)

    def interrupt(self) -> None:
        """End every pending and later ``advance`` at once (shutting down)."""
        self._stop.set()


@dataclass
class CellTiming:
    """The realistic cell's timing: the model, the clock, and whether to charge wire time.

    charge_wire: True in process (the virtual clock accounts the VAL and ATI lines' time);
    False behind the emulators, whose lines pace the bytes themselves.
    wire_s / motion_s: seconds charged so far to the lines and to arm and hand motion (set-up,
    profile, settling, hand; ``finepos bench sim`` reports them); spent: the same seconds by
    ``BUDGET`` kind, with the sensor's and the camera's waits; at_rest_s: when the arm and hand
    last came to rest (the simulated devices set it); command_began_s: see
    ``begin_command``.
    """

    config: TimingConfig
    clock: CellClock
    charge_wire: bool = True
    wire_s: float = field(default=0.0)
    motion_s: float = field(default=0.0)
    command_began_s: float | None = None
    spent: dict[str, float] = field(default_factory=lambda: dict.fromkeys(BUDGET, 0.0))
    at_rest_s: float = 0.0  # when the arm and hand last came to rest (cell clock)

    def begin_command(self) -> None:
        """Note that a command line has just arrived (the VAL emulator calls this): on a wall
        clock, a move's or the hand's duration runs from here, so the emulated cell's own work
        before and around it does not lengthen it."""
        self.command_began_s = self.clock.now()

    def take_command_start(self) -> float:
        """When the current command began (``begin_command``; now if not noted), consumed."""
        began, self.command_began_s = self.command_began_s, None
        return began if began is not None else self.clock.now()

    def wire(self, n_bytes: int, baud: int) -> None:
        """Let ``n_bytes`` pass on a line at ``baud`` (when wire time is charged here)."""
        if self.charge_wire:
            seconds = self.config.wire_time_s(n_bytes, baud)
            self.wire_s += seconds
            self.spent["wire"] += seconds
            self.clock.advance(seconds)

    def val_wire(self, n_bytes: int) -> None:
        """A VAL exchange of ``n_bytes`` (both directions)."""
        self.wire(n_bytes, self.config.val_baud)

    def motion(self, seconds: float, kind: str = "motion") -> None:
        """Arm or hand motion taking ``seconds`` (``kind``: motion, setup or hand)."""
        self.note(seconds, kind)
        self.clock.advance(seconds)

    def note(self, seconds: float, kind: str = "motion") -> None:
        """Count ``seconds`` of arm or hand motion that pass on their own (wall clock)."""
        self.motion_s += seconds
        self.spent[kind] += seconds

    def wait(self, seconds: float, kind: str) -> None:
        """Wait ``seconds`` for a device (``kind``: sensor or camera)."""
        if seconds > 0:
            self.spent[kind] += seconds
            self.clock.advance(seconds)

    def move_seconds(self, delta_deg, speed_percent: float) -> float:
        """The model's time of a move with these joint travels (t0 + profile + settle)."""
        return move_time_s(delta_deg, speed_percent, self.config.arm)


def cell_timing(mode: TimingMode, config: TimingConfig, *, wall: bool = False
                ) -> CellTiming | None:
    """The timing for ``mode``: None when ideal; realistic on a virtual clock, or with
    ``wall`` on real time (behind the emulators, which pace their lines themselves)."""
    if mode == "ideal":
        return None
    if wall:
        return CellTiming(config, WallClock(), charge_wire=False)
    return CellTiming(config, VirtualClock(), charge_wire=True)


def load_timing(path: str | Path | None) -> TimingConfig:
    """The ``timing`` section of the root config file ``path`` (defaults where absent or
    without a file). Raises ConfigError naming the file and the key's full path."""
    if path is None:
        return TimingConfig()
    data = load_yaml_file(path)
    try:
        return from_mapping(TimingConfig, data.get("timing"), "timing")
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc


def add_timing_argument(parser: argparse.ArgumentParser) -> None:
    """``--timing realistic|ideal`` for an emulator command (default realistic)."""
    parser.add_argument("--timing", choices=("realistic", "ideal"), default="realistic",
                        help="realistic (default): take the config's timing: section for real "
                             "(lines paced at their baud rate, moves that last their motion "
                             "time, camera frame rate, exposure and latency); ideal: instant")


def timing_from_args(args: argparse.Namespace) -> TimingConfig | None:
    """The emulator's timing from ``--timing`` and ``--config`` (None: ideal)."""
    if args.timing == "ideal":
        return None
    return load_timing(getattr(args, "config", None))
