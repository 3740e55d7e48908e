"""VAL programs in the emulated controller: the instructions it knows, and one program run.

A program is a list of instruction lines entered with ``EDIT`` (``sim_backend.emulators.val.
monitor``). ``check_instruction`` accepts only what ``ProgramRun`` interprets; any other line
gets the controller's ``*Unknown instruction*`` (or ``*Syntax error*``) at entry, so nothing is
ever silently skipped when it runs. The instructions (case-insensitive):

- ``SPEED n``: program speed, percent of the monitor speed (0.01..327.67), for later motions;
- ``OPEN`` / ``CLOSE``: the jaws open / close as the next motion starts (no wait of their own);
  ``OPENI`` / ``CLOSEI``: at once, after the motion, then the hand time;
- ``MOVE loc`` / ``MOVES loc``: to a location set with ``DO SET`` or ``POINT`` (joint and
  straight-line motion are timed alike); ``APPRO loc, d`` / ``APPROS loc, d``: to ``d`` mm
  before ``loc`` along its approach axis; ``DEPART d`` / ``DEPARTS d``: back ``d`` mm along
  the tool's approach axis from where it stands; ``DRAW dx,dy,dz``: by that much in the base
  frame;
- ``REACTI sig[, prog]``: from now on a motion stops at once when input ``sig`` is high, then
  ``prog`` runs as a subroutine (none: the program stops); an input already high when armed
  reacts at once. ``IGNORE sig``: disarms it;
- ``TYPE text``: prints ``text`` on the terminal; ``STOP``: ends the program.

Signal numbers, the instruction spellings and the error texts are VAL II's as the hardware notes
give them: unconfirmed, and the driver keeps every program line configurable.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.core.pose import Pose, ToolStep
from drivers.core.timing import VAL_SPEED_MAX, VAL_SPEED_MIN
from drivers.interfaces import Arm

UNKNOWN_INSTRUCTION = "Unknown instruction"
SYNTAX_ERROR = "Syntax error"
UNDEFINED_PROGRAM = "Undefined program"
PROGRAM_RUNNING = "Program already running"

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)"
_NAME = r"[a-z][a-z0-9_.]*"
_FORMS: dict[str, re.Pattern[str]] = {
    "speed": re.compile(rf"({_NUMBER})"),
    "open": re.compile(""), "close": re.compile(""),
    "openi": re.compile(""), "closei": re.compile(""),
    "move": re.compile(rf"(#?{_NAME})"), "moves": re.compile(rf"(#?{_NAME})"),
    "appro": re.compile(rf"({_NAME})\s*,\s*({_NUMBER})"),
    "appros": re.compile(rf"({_NAME})\s*,\s*({_NUMBER})"),
    "depart": re.compile(rf"({_NUMBER})"), "departs": re.compile(rf"({_NUMBER})"),
    "draw": re.compile(rf"({_NUMBER})\s*,\s*({_NUMBER})\s*,\s*({_NUMBER})"),
    "reacti": re.compile(rf"(\d+)(?:\s*,\s*({_NAME}))?"),
    "ignore": re.compile(r"(\d+)"),
    "type": re.compile(r"(.*)"),
    "stop": re.compile(""),
}


class InstructionError(Exception):
    """A program line the controller refuses (the message is VAL's error text)."""


def parse_instruction(line: str) -> tuple[str, tuple[str, ...]]:
    """(instruction, arguments) of one program line; raises InstructionError."""
    words = line.strip().split(None, 1)
    if not words:
        raise InstructionError(SYNTAX_ERROR)
    name = words[0].lower()
    form = _FORMS.get(name)
    if form is None:
        raise InstructionError(UNKNOWN_INSTRUCTION)
    rest = words[1].strip() if len(words) > 1 else ""
    match = form.fullmatch(rest if name == "type" else rest.lower())
    if match is None:
        raise InstructionError(SYNTAX_ERROR)
    if name == "speed" and not VAL_SPEED_MIN <= float(match.group(1)) <= VAL_SPEED_MAX:
        raise InstructionError(SYNTAX_ERROR)
    return name, tuple(g for g in match.groups() if g is not None)


_MOTIONS = frozenset({"move", "moves", "appro", "appros", "depart", "departs", "draw"})
_PASSING = frozenset({"speed", "reacti", "ignore", "open", "close"})  # no stop of their own


def _motion_follows(rest: list[str]) -> bool:
    """Whether the next instruction that acts on the arm is a motion (the path goes on: no
    settling between the two); a hand instruction, TYPE, STOP or the end stop it."""
    for line in rest:
        name = line.strip().split(None, 1)[0].lower() if line.strip() else ""
        if name in _MOTIONS:
            return True
        if name not in _PASSING:
            return False
    return False


def check_instruction(line: str) -> None:
    """Raise InstructionError unless ``line`` is an instruction ``ProgramRun`` interprets."""
    parse_instruction(line)


@dataclass
class ProgramRun:
    """One run of a program on ``arm``, on the caller's thread (the monitor starts a thread).

    programs: every stored program (for subroutines); locations: the named poses;
    input_high(sig): the controller's input lines; output: what TYPE printed.
    ``abort()`` (any thread) stops the motion under way at once and ends the run.
    """

    arm: Arm
    programs: dict[str, list[str]]
    locations: dict[str, Pose]
    input_high: Callable[[int], bool]
    output: list[str] = field(default_factory=list)
    aborted: threading.Event = field(default_factory=threading.Event)
    _speed: float = 100.0
    _armed: dict[int, str | None] = field(default_factory=dict)
    _first_motion: bool = True
    _pending_hand: bool | None = None  # OPEN (False) / CLOSE (True) at the next motion
    _settle: bool = True  # the motion under way ends where the arm stops

    def abort(self) -> None:
        self.aborted.set()

    def run(self, name: str) -> None:
        """Run program ``name`` to its end (or STOP, a reaction without subroutine, abort).
        Raises FineposError from the arm (the monitor answers it as a controller error)."""
        self._run(name, depth=0)

    class _Stop(Exception):
        pass

    def _run(self, name: str, depth: int) -> None:
        if depth > 8:
            raise InstructionError("Too many nested subroutines")
        try:
            lines = self.programs[name]
            for i, line in enumerate(lines):
                if self.aborted.is_set():
                    raise ProgramRun._Stop
                self._settle = not _motion_follows(lines[i + 1:])
                self._step(*parse_instruction(line), depth=depth)
        except ProgramRun._Stop:
            if depth:
                raise

    def _step(self, name: str, args: tuple[str, ...], depth: int) -> None:
        arm = self.arm
        if name == "speed":
            self._speed = float(args[0])
        elif name in ("open", "close"):
            self._pending_hand = name == "close"
        elif name in ("openi", "closei"):
            (arm.close_gripper if name == "closei" else arm.open_gripper)()
        elif name in ("move", "moves"):
            target = self.locations.get(args[0])
            if target is None:
                raise InstructionError("Undefined location")
            self._motion(target, depth)
        elif name in ("appro", "appros"):
            location = self.locations.get(args[0])
            if location is None:
                raise InstructionError("Undefined location")
            self._motion(location.moved_in_tool_frame(ToolStep(dz_mm=-float(args[1]))), depth)
        elif name in ("depart", "departs"):
            here = arm.pose(fresh=False)
            self._motion(here.moved_in_tool_frame(ToolStep(dz_mm=-float(args[0]))), depth)
        elif name == "draw":
            dx, dy, dz = (float(a) for a in args)
            here = arm.pose(fresh=False)
            self._motion(Pose(here.x_mm + dx, here.y_mm + dy, here.z_mm + dz, here.o_deg,
                              here.a_deg, here.t_deg), depth)
        elif name == "reacti":
            signal = int(args[0])
            self._armed[signal] = args[1] if len(args) > 1 else None
            if self.input_high(signal):
                self._react(signal, depth)
        elif name == "ignore":
            self._armed.pop(int(args[0]), None)
        elif name == "type":
            self.output.append(args[0].strip().strip('"'))
        elif name == "stop":
            raise ProgramRun._Stop

    def _tripped(self) -> int | None:
        return next((s for s in self._armed if self.input_high(s)), None)

    def _motion(self, target: Pose, depth: int) -> None:
        hand, self._pending_hand = self._pending_hand, None
        if hand is not None:
            open_now = getattr(self.arm, "set_jaws_during_motion", None)
            if open_now is not None:
                open_now(hand)
            else:
                (self.arm.close_gripper if hand else self.arm.open_gripper)()
        setup, self._first_motion = self._first_motion, False
        _, stopped = self.arm.move_until(
            target, lambda: self.aborted.is_set() or self._tripped() is not None,
            speed_factor=self._speed / 100.0, setup=setup, settle=self._settle)
        if self.aborted.is_set():
            raise ProgramRun._Stop
        if stopped:
            signal = self._tripped()
            if signal is not None:
                self._react(signal, depth)

    def _react(self, signal: int, depth: int) -> None:
        subroutine = self._armed.pop(signal)
        if subroutine is None:
            raise ProgramRun._Stop
        if subroutine not in self.programs:
            raise InstructionError(UNDEFINED_PROGRAM)
        self._run(subroutine, depth + 1)
