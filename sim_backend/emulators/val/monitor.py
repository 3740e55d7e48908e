"""The VAL II monitor as a state machine over any ``drivers.interfaces.Arm``: lines in, text out.

No I/O here: the serving thread (``server``) feeds it one input line at a time and writes back the
echo and the reply. What it speaks (confirmed behaviour from the hardware notes, plus the
unconfirmed commands the VAL driver's defaults send):

- prompt ``.`` at the start of a line after every command; questions end in ``? ``;
- optional boot questions ``Load VAL from floppy (Y/N)?`` then ``Initialize (Y/N)?``;
- ``where`` (``X Y Z O A T`` table, then ``JT1..JT6`` when the pose has a joint solution),
  ``speed N`` (0.01..327.67, 100 normal), ``do move trans(x,y,z,o,a,t)``, ``do move name``,
  ``do move #name``,
  ``do drive joint,deg,speed``, ``do ready``, ``do nest``, ``point #name`` / ``point name``
  (``poi``) with their ``Change?`` dialogues, ``cal`` + ``y``; unconfirmed: ``do openi``,
  ``do closei`` (also ``do open`` / ``do close``), ``abort``;
- errors as ``*text*`` lines: unreachable poses (the arm's MotionRejectedError, or joints out of
  range) give ``*Position out of range*``; other arm failures give the arm's message.

Commands are case-insensitive; monitor commands may be abbreviated (``poi``, ``cal``, ``sp``).
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass

from drivers.core.errors import FineposError, MotionRejectedError
from drivers.core.pose import Pose
from drivers.core.timing import VAL_SPEED_MAX, VAL_SPEED_MIN
from drivers.interfaces import Arm
from sim_backend.emulators.val.kinematics import (
    NEST_DEG,
    READY_DEG,
    TOOL_DOWN_DEG,
    Joints,
    Puma260,
    within_ranges,
)
from sim_backend.emulators.val.programs import (
    PROGRAM_RUNNING,
    UNDEFINED_PROGRAM,
    InstructionError,
    ProgramRun,
    check_instruction,
)

logger = logging.getLogger(__name__)

OUT_OF_RANGE = "Position out of range"
SYNTAX_ERROR = "Syntax error"
UNKNOWN_COMMAND = "Unknown command"
UNDEFINED_LOCATION = "Undefined location"
VALUE_OUT_OF_RANGE = "Value out of range"

BOOT_QUESTIONS = ("Load VAL from floppy (Y/N)? ", "Initialize (Y/N)? ")
CAL_QUESTION = "Are you sure (Y/N)? "
CHANGE_QUESTION = "Change? "
PROMPT = "."

# Monitor commands and the shortest abbreviation accepted for each.
_MONITOR_COMMANDS = {"where": 1, "speed": 2, "point": 3, "calibrate": 3, "abort": 2, "do": 2,
                     "edit": 2, "listp": 4, "execute": 2}
_SET = re.compile(r"set\s+(?P<name>[a-z][a-z0-9_.]*)\s*=\s*(?P<value>.*)", re.IGNORECASE)
PROGRAM_PROMPT = "*"  # the prompt while a program runs
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NAME = re.compile(r"#?[a-z][a-z0-9_.]*")
_TRANS = re.compile(r"trans\s*\((?P<args>[^()]*)\)", re.IGNORECASE)
_CARTESIAN_HEADER = "".join(f"{label:>10}" for label in "XYZOAT")
_JOINT_HEADER = "".join(f"{label:>10}" for label in ("JT1", "JT2", "JT3", "JT4", "JT5", "JT6"))


class _Refusal(Exception):
    """A command the monitor answers with ``*message*``."""


@dataclass(frozen=True)
class Response:
    """What the monitor sends for one input line: the echo, then the reply."""

    echo: bytes
    reply: bytes
    after: Callable[[], None] | None = None  # call once the reply is out (starts a program)


def _text(lines: list[str], tail: str) -> bytes:
    text = "".join(f"{line}\r\n" for line in lines) + tail
    return text.encode("ascii", "replace")


def _numbers(text: str, count: int) -> list[float]:
    fields = [f.strip() for f in text.split(",")]
    if len(fields) != count or not all(_NUMBER.fullmatch(f) for f in fields):
        raise _Refusal(SYNTAX_ERROR)
    return [float(f) for f in fields]


def _refusal_text(exc: Exception) -> str:
    """The controller error text for an arm failure (refused poses: out of range)."""
    if isinstance(exc, MotionRejectedError):
        return OUT_OF_RANGE
    return " ".join(str(exc).replace("*", " ").split()) or type(exc).__name__


def _column(value: float, decimals: int) -> str:
    return f"{round(value, decimals) + 0.0:10.{decimals}f}"  # + 0.0: no "-0.000"


def _pose_lines(pose: Pose) -> list[str]:
    values = [_column(v, 2) for v in (pose.x_mm, pose.y_mm, pose.z_mm)]
    values += [_column(v, 3) for v in (pose.o_deg, pose.a_deg, pose.t_deg)]
    return [_CARTESIAN_HEADER, "".join(values)]


def _joint_lines(joints: Joints) -> list[str]:
    return [_JOINT_HEADER, "".join(_column(q, 3) for q in joints)]


class ValMonitor:
    """One VAL II monitor session driving ``arm`` (connected and active, without safety limits:
    the VAL driver applies those).

    Programs (``sim_backend.emulators.val.programs``): ``EDIT name`` asks for numbered lines
    (``  1? ``; each checked as it is entered, a refused one is asked again after the error
    line) until ``E``; ``LISTP name`` prints ``PROGRAM name``, the numbered lines and
    ``END`` (no line of a reply but the prompt starts with ``.``: a client sees a reply
    complete at a ``.`` that starts a line); ``EXECUTE name`` (``EX``) answers the ``*``
    prompt at once and runs the program on its own thread: ``on_program_end`` receives what
    it prints when it ends (its TYPE lines or error, then the ``.`` prompt). While it runs
    only ``ABORT`` (stops the motion at once, ends the program, then the prompt) and
    ``WHERE`` are taken; any other command gets ``*Program already running*``.
    ``set_input(sig, source)`` wires an input line.
    """

    def __init__(self, arm: Arm, kinematics: Puma260 | None = None,
                 boot_questions: bool = False) -> None:
        self._arm = arm
        self._kinematics = kinematics or Puma260()
        self._pending: Callable[[str], bytes] | None = None  # handles the answer to a question
        self._first_output = _text([], PROMPT)
        if boot_questions:
            self._first_output = _text([], BOOT_QUESTIONS[0])
            self._pending = self._boot_answer(0)
        self._seed: Joints = TOOL_DOWN_DEG
        self._known: tuple[Pose, Joints] | None = None
        self._transformations: dict[str, Pose] = {}
        self._precision_points: dict[str, Joints] = {}
        self._programs: dict[str, list[str]] = {}
        self._inputs: dict[int, Callable[[], bool]] = {}
        self._run: ProgramRun | None = None
        self._thread: threading.Thread | None = None
        self._starting: Callable[[], None] | None = None
        self._active = False  # a program runs (from EXECUTE to its end or ABORT)
        self.on_program_end: Callable[[bytes], None] = lambda _data: None
        self.programs_run = 0

    # -- inputs and programs ---------------------------------------------------------------------
    def set_input(self, signal: int, source: Callable[[], bool] | None) -> None:
        """Wire input line ``signal`` to ``source()`` (None: unwired, always low)."""
        if source is None:
            self._inputs.pop(signal, None)
        else:
            self._inputs[signal] = source

    def input_high(self, signal: int) -> bool:
        source = self._inputs.get(signal)
        return bool(source()) if source is not None else False

    @property
    def program_running(self) -> bool:
        return self._active

    def wait_program(self, timeout_s: float | None = None) -> bool:
        """Wait for a running program to end; False on timeout."""
        thread = self._thread
        if thread is not None and thread.ident is not None:
            thread.join(timeout_s)
            return not thread.is_alive()
        return True

    def stop_program(self) -> None:
        """End a running program at once (closing the emulator), without output."""
        if self._run is not None:
            self._run.abort()
            self._arm_halt()
            self.wait_program()
            self._active = False

    def first_output(self) -> bytes:
        """What the controller prints when it comes up: the first boot question or the prompt."""
        return self._first_output

    def handle_line(self, line: str, forced_error: str | None = None) -> Response:
        """Answer one input line. ``forced_error`` replaces the reply to a command (not to an
        answer) with ``*forced_error*`` and does not run the command."""
        echo = line.encode("latin-1") + b"\r\n"
        if self._pending is not None:
            return Response(echo, self._pending(line))
        if self.program_running:
            return Response(echo, self._while_running(line))
        if forced_error is not None:
            return Response(echo, _text([f"*{forced_error}*"], PROMPT))
        try:
            reply = self._command(line)
            starting, self._starting = self._starting, None
            return Response(echo, reply, starting)
        except _Refusal as refusal:
            return Response(echo, _text([f"*{refusal}*"], PROMPT))

    # -- questions -----------------------------------------------------------------------------
    def _ask(self, lines: list[str], question: str, handler: Callable[[str], bytes]) -> bytes:
        self._pending = handler
        return _text(lines, question)

    def _yes_no(self, question: str, on_answer: Callable[[bool], bytes]) -> Callable[[str], bytes]:
        def handle(answer: str) -> bytes:
            word = answer.strip().lower()
            if word not in ("y", "n", "yes", "no"):
                return _text([], question)  # ask again
            self._pending = None
            return on_answer(word.startswith("y"))
        return handle

    def _boot_answer(self, index: int) -> Callable[[str], bytes]:
        def after(_yes: bool) -> bytes:
            if index + 1 < len(BOOT_QUESTIONS):
                return self._ask([], BOOT_QUESTIONS[index + 1], self._boot_answer(index + 1))
            return _text([], PROMPT)
        return self._yes_no(BOOT_QUESTIONS[index], after)

    # -- commands ------------------------------------------------------------------------------
    def _command(self, line: str) -> bytes:
        words = line.strip().split(None, 1)
        if not words:
            return _text([], PROMPT)
        head, rest = words[0].lower(), (words[1] if len(words) > 1 else "")
        name = next((full for full, shortest in _MONITOR_COMMANDS.items()
                     if len(head) >= shortest and full.startswith(head)), None)
        if name == "where" and not rest.strip():
            return self._where()
        if name == "speed":
            return self._speed(rest)
        if name == "point":
            return self._point(rest.strip().lower())
        if name == "calibrate" and not rest.strip():
            return self._ask([], CAL_QUESTION, self._yes_no(CAL_QUESTION, self._calibrated))
        if name == "abort" and not rest.strip():
            self._arm_call(self._arm.halt)
            return _text([], PROMPT)
        if name == "do":
            return self._do(rest.strip())
        if name == "edit" and _NAME.fullmatch(rest.strip().lower() or "#"):
            return self._edit_program(rest.strip().lower(), [])
        if name == "listp" and rest.strip():
            return self._list_program(rest.strip().lower())
        if name == "execute" and rest.strip():
            return self._execute(rest.strip().lower())
        raise _Refusal(UNKNOWN_COMMAND if name is None else SYNTAX_ERROR)

    # -- programs ------------------------------------------------------------------------------
    def _edit_program(self, name: str, lines: list[str]) -> bytes:
        def answer(text: str) -> bytes:
            if text.strip().lower() == "e":
                self._pending = None
                self._programs[name] = lines
                return _text([], PROMPT)
            try:
                check_instruction(text)
            except InstructionError as refusal:
                return self._ask([f"*{refusal}*"], f"{len(lines) + 1:3d}? ", answer)
            lines.append(text.strip())
            return self._ask([], f"{len(lines) + 1:3d}? ", answer)

        return self._ask([f"PROGRAM {name}"], f"{len(lines) + 1:3d}? ", answer)

    def _list_program(self, name: str) -> bytes:
        if name not in self._programs:
            raise _Refusal(UNDEFINED_PROGRAM)
        body = [f"{i:3d}  {line}" for i, line in enumerate(self._programs[name], 1)]
        return _text([f"PROGRAM {name}", *body, "END"], PROMPT)

    def _execute(self, name: str) -> bytes:
        if name not in self._programs:
            raise _Refusal(UNDEFINED_PROGRAM)
        run = ProgramRun(self._arm, self._programs, self._transformations, self.input_high)
        self._run = run
        self.programs_run += 1

        def body() -> None:
            lines: list[str] = []
            try:
                run.run(name)
            except InstructionError as exc:
                lines = [f"*{exc}*"]
            except _Refusal as exc:
                lines = [f"*{exc}*"]
            except FineposError as exc:
                lines = [f"*{_refusal_text(exc)}*"]
            self._active = False  # the monitor takes commands again before the prompt goes
            if not run.aborted.is_set():
                self.on_program_end(b"\r\n" + _text(run.output + lines, PROMPT))

        self._active = True
        self._thread = threading.Thread(target=body, name=f"VAL program {name}", daemon=True)
        self._starting = self._thread.start
        return _text([], PROGRAM_PROMPT)

    def _while_running(self, line: str) -> bytes:
        words = line.strip().lower().split()
        head = words[0] if words else ""
        if not head:
            return _text([], PROGRAM_PROMPT)
        if head and "abort".startswith(head) and len(head) >= 2 and len(words) == 1:
            self.stop_program()
            return _text([], PROMPT)
        if head and "where".startswith(head) and len(words) == 1:
            try:
                return self._where()
            except _Refusal as refusal:
                return _text([f"*{refusal}*"], PROGRAM_PROMPT)
        return _text([f"*{PROGRAM_RUNNING}*"], PROGRAM_PROMPT)

    def _arm_halt(self) -> None:
        try:
            self._arm.halt()
        except FineposError as exc:
            logger.warning("VAL emulator: halt failed: %s", exc)

    def _calibrated(self, yes: bool) -> bytes:
        logger.info("VAL emulator: calibration %s", "done" if yes else "skipped")
        return _text([], PROMPT)

    def _where(self) -> bytes:
        pose = self._arm_call(self._arm.pose)
        joints = self._joints(pose)
        return _text(_pose_lines(pose) + (_joint_lines(joints) if joints else []), PROMPT)

    def _speed(self, rest: str) -> bytes:
        (percent,) = _numbers(rest, 1)
        if not VAL_SPEED_MIN <= percent <= VAL_SPEED_MAX:
            raise _Refusal(VALUE_OUT_OF_RANGE)
        self._arm_call(self._arm.set_speed, percent)
        return _text([], PROMPT)

    def _do(self, rest: str) -> bytes:
        words = rest.split(None, 1)
        instruction = words[0].lower() if words else ""
        argument = words[1].strip() if len(words) > 1 else ""
        if instruction == "set" and _SET.fullmatch(rest):
            self._set_location(_SET.fullmatch(rest))
        elif instruction == "move" and argument:
            self._move_to_location(argument)
        elif instruction == "drive" and argument:
            self._drive(argument)
        elif instruction in ("ready", "nest") and not argument:
            self._move_joints(READY_DEG if instruction == "ready" else NEST_DEG)
        elif instruction in ("openi", "open") and not argument:
            self._arm_call(self._arm.open_gripper)
        elif instruction in ("closei", "close") and not argument:
            self._arm_call(self._arm.close_gripper)
        else:
            raise _Refusal(SYNTAX_ERROR)
        return _text([], PROMPT)

    def _move_to_location(self, argument: str) -> None:
        trans = _TRANS.fullmatch(argument)
        if trans:
            self._move_pose(Pose(*_numbers(trans.group("args"), 6)))
            return
        name = argument.lower()
        if not _NAME.fullmatch(name):
            raise _Refusal(SYNTAX_ERROR)
        if name.startswith("#"):
            if name not in self._precision_points:
                raise _Refusal(UNDEFINED_LOCATION)
            self._move_joints(self._precision_points[name])
        else:
            if name not in self._transformations:
                raise _Refusal(UNDEFINED_LOCATION)
            self._move_pose(self._transformations[name])

    def _set_location(self, match: re.Match[str]) -> None:
        trans = _TRANS.fullmatch(match.group("value").strip())
        if not trans:
            raise _Refusal(SYNTAX_ERROR)
        self._transformations[match.group("name").lower()] = Pose(
            *_numbers(trans.group("args"), 6))

    def _drive(self, argument: str) -> None:
        joint, delta_deg, speed_percent = _numbers(argument, 3)
        if joint != int(joint) or not 1 <= joint <= 6:
            raise _Refusal(SYNTAX_ERROR)
        if not VAL_SPEED_MIN <= speed_percent <= VAL_SPEED_MAX:
            raise _Refusal(VALUE_OUT_OF_RANGE)
        joints = self._joints(self._arm_call(self._arm.pose))
        if joints is None:
            raise _Refusal(OUT_OF_RANGE)
        target = list(joints)
        target[int(joint) - 1] += delta_deg
        self._move_joints(tuple(target))

    def _move_pose(self, target: Pose) -> None:
        self._arm_call(self._arm.move_to, target)

    def _move_joints(self, joints: Joints) -> None:
        if not within_ranges(joints):
            raise _Refusal(OUT_OF_RANGE)
        self._arm_call(self._arm.move_to, self._kinematics.forward(joints))
        self._seed, self._known = joints, None

    def _joints(self, pose: Pose) -> Joints | None:
        """Joint angles of ``pose`` (cached; solved near the last known joints)."""
        if self._known is not None and self._known[0] == pose:
            return self._known[1]
        joints = self._kinematics.inverse(pose, self._seed)
        if joints is not None:
            self._seed, self._known = joints, (pose, joints)
        return joints

    def _arm_call(self, method, *args):
        try:
            return method(*args)
        except MotionRejectedError as exc:
            logger.info("VAL emulator: arm refused: %s", exc)
            raise _Refusal(OUT_OF_RANGE) from exc
        except FineposError as exc:
            logger.warning("VAL emulator: arm failed: %s", exc)
            raise _Refusal(_refusal_text(exc)) from exc

    # -- point dialogues -----------------------------------------------------------------------
    def _point(self, name: str) -> bytes:
        if not _NAME.fullmatch(name):
            raise _Refusal(SYNTAX_ERROR)
        if name.startswith("#"):
            joints = self._precision_points.get(name)
            if joints is None:
                joints = self._joints(self._arm_call(self._arm.pose))
            if joints is None:
                raise _Refusal(OUT_OF_RANGE)
            return self._edit(name, list(joints))
        pose = self._transformations.get(name) or self._arm_call(self._arm.pose)
        return self._edit(name, list(pose.as_dict().values()))

    def _edit(self, name: str, values: list[float]) -> bytes:
        """Show ``values`` and ask ``Change?``: a line of comma-separated values (empty fields
        keep theirs) changes them, an empty line stores the location and ends the dialogue."""
        precision = name.startswith("#")
        lines = _joint_lines(tuple(values)) if precision else _pose_lines(Pose(*values))

        def answer(text: str) -> bytes:
            if not text.strip():
                self._pending = None
                if precision:
                    self._precision_points[name] = tuple(values)  # type: ignore[assignment]
                else:
                    self._transformations[name] = Pose(*values)
                return _text([], PROMPT)
            fields = [f.strip() for f in text.split(",")]
            if len(fields) > 6 or not all(not f or _NUMBER.fullmatch(f) for f in fields):
                return self._ask([f"*{SYNTAX_ERROR}*"] + lines, CHANGE_QUESTION, answer)
            changed = [float(f) if f else old for f, old in zip(fields, values, strict=False)]
            return self._edit(name, changed + values[len(changed):])

        return self._ask(lines, CHANGE_QUESTION, answer)
