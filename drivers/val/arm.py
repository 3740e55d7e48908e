"""The PUMA 260 arm behind a VAL II controller, driven over its RS-232 monitor terminal.

Start-up: wake the monitor with a bare line ending, answer the boot questions from the config,
wait for the ``.`` prompt. Then ``where`` reads the pose, ``speed`` sets the monitor speed and
``do move trans(...)`` moves to absolute targets (the Arm base class turns relative tool moves
into absolute targets from a fresh ``where``). Moves block until the prompt returns.

Errors, by cause:
- controller error ``*text*`` whose text is listed in ``rejection_errors``: MotionRejectedError
  (nothing moved; the arm stays usable);
- any other controller error, or a program HOLD: DeviceFaultError carrying the message;
- no complete reply within the timeout: DeviceTimeoutError;
- line noise, a missing echo, an unexpected question or output: ProtocolError;
- a broken link: DeviceFaultError;
- a command whose reply was still awaited when ``halt()`` was called: MotionRejectedError (the
  halt interrupts the wait, see ``ValLink.interrupt``; no fault).
A controller error in reply to a reading (``where``) is always a DeviceFaultError, never a
rejection.
After a command, all but the first put the arm into FAULT: it refuses motion until ``reset()``
reconnects. During ``connect()`` they are raised and the arm stays disconnected.
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
from collections.abc import Callable, Iterator

from drivers.core.errors import (
    DeviceFaultError,
    DeviceTimeoutError,
    MotionRejectedError,
    ProtocolError,
)
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Descent
from drivers.safety import SafetyLimits
from drivers.val.config import DESCENT_PROGRAM, GRIP_PROGRAM, ValConfig
from drivers.val.link import ExchangeInterrupted, ValLink
from drivers.val.replies import Reply, ReplyKind
from drivers.val.where import WhereReading, parse_where

logger = logging.getLogger(__name__)

# Questions answered in one start-up before giving up (the controller keeps asking).
_MAX_BOOT_QUESTIONS = 8
# The program editor's prompt for its next line ("  3? "): a link lost while a program was
# being entered leaves the controller in the editor.
_EDITOR_LINE = re.compile(r"^\s*\d+\s*\?\s*$")
# A listed program line: its number, then the instruction.
_LISTED_LINE = re.compile(r"^\s*\d+\s+(?P<text>.*\S)\s*$")
# Where the arm stands after a descent that the input stopped at once (mm, deg): the start.
_NOT_MOVED = 0.01


class ProgramDownloadError(DeviceFaultError):
    """A program VAL refused while it was entered, or that lists back otherwise."""


def _normal(line: str) -> str:
    return " ".join(line.replace(" ,", ",").replace(", ", ",").split()).casefold()


class ValArm(Arm):
    """Arm interface over the VAL II monitor. ``link`` exposes byte counters (benchmarks)."""

    def __init__(self, config: ValConfig, limits: SafetyLimits | None = None) -> None:
        super().__init__(limits)
        self.config = config
        self.link = ValLink(config)
        # VAL reports no finger width: the nominal width of the last gripper command.
        self._gripper_closed = False
        self._halts = 0  # counts halt() calls: a segmented move stops when it changes
        self.reuse_reached_pose = not config.where_before_move

    # -- lifecycle -------------------------------------------------------------------------
    def _open(self) -> None:
        self.link.open()
        try:
            self._handshake()
            self._loaded: dict[str, tuple[str, ...]] = {}
            if self.config.programs:
                self._load_programs(self.config.program_text())
        except BaseException:
            self.link.close()
            raise

    def _close(self) -> None:
        self.link.close()

    def _handshake(self) -> None:
        timeout_s = self.config.exchange_timeout_s
        try:
            reply = self.link.exchange("", timeout_s, echo=False)
        except DeviceTimeoutError:
            if not self.link.last_partial.rstrip().endswith(b"*"):
                raise
            # A program still runs (its prompt is "*"; a lost link or a fault left it): stop
            # it, then wake the monitor again.
            logger.warning("VAL start-up: a program is running; sending %r",
                           self.config.commands.halt)
            with contextlib.suppress(DeviceTimeoutError, ProtocolError):
                self.link.exchange(self.config.commands.halt, timeout_s, echo=self.config.echo)
            reply = self.link.exchange("", timeout_s, echo=False)
        for _ in range(_MAX_BOOT_QUESTIONS):
            if reply.kind is not ReplyKind.QUESTION:
                self._check(reply, "<wake>")
                logger.info("VAL monitor ready on %s", self.config.port)
                return
            if _EDITOR_LINE.match(reply.message):
                # the editor, left by a lost link mid-download: end it; the program's
                # listing then differs and it is entered again
                answer = self.config.commands.edit_end
                logger.warning("VAL start-up: the program editor is open (%r); sending %r",
                               reply.message, answer)
                reply = self.link.exchange(answer, timeout_s, echo=self.config.echo)
                continue
            answer = self._boot_answer(reply.message)
            logger.info("VAL start-up: %r -> %r", reply.message, answer)
            reply = self.link.exchange(answer, timeout_s, echo=False)
        raise ProtocolError(f"VAL start-up: still asking after {_MAX_BOOT_QUESTIONS} answers: "
                            f"{reply.message!r}")

    def _boot_answer(self, question: str) -> str:
        for pattern, answer in self.config.boot_answers.items():
            if pattern.casefold() in question.casefold():
                return answer
        raise ProtocolError(f"VAL start-up: unexpected question {question!r} (add it to "
                            "boot_answers to answer it)")

    # -- programs on the controller ----------------------------------------------------------
    @property
    def runs_programs(self) -> bool:
        return self.config.programs

    def _load_programs(self, programs: dict[str, tuple[str, ...]]) -> None:
        """Make the controller hold ``programs``: each is listed, and entered again where the
        listing differs; then listed once more to check it.

        Raises:
            ProgramDownloadError: VAL refused a line, or a program lists back otherwise (one
                line naming the program and the line).
        """
        for name, lines in programs.items():
            if self._loaded.get(name) == lines:
                continue
            if self._listing(name) != [_normal(line) for line in lines]:
                logger.info("VAL: entering program %s (%d lines)", name, len(lines))
                self._enter(name, lines)
                listed = self._listing(name)
                expected = [_normal(line) for line in lines]
                if listed != expected:
                    bad = next((i for i, (a, b) in enumerate(zip(listed, expected,
                                                                  strict=False), 1) if a != b),
                               min(len(listed), len(expected)) + 1)
                    wanted = lines[bad - 1] if bad <= len(lines) else "(none)"
                    raise ProgramDownloadError(
                        f"VAL program {name}: line {bad} {wanted!r} lists back as "
                        f"{listed[bad - 1] if bad <= len(listed) else '(missing)'!r}")
            self._loaded[name] = lines

    def _listing(self, name: str) -> list[str] | None:
        """The program's lines as VAL lists them (normalised), None when it has none."""
        line = self.config.commands.listing.format(program=name)
        with self._faulting(line):
            reply = self.link.exchange(line, self.config.exchange_timeout_s,
                                       echo=self.config.echo)
        if reply.kind is ReplyKind.ERROR:
            return None
        self._check(reply, line, motion=False)
        listed = []
        for text in reply.lines:
            match = _LISTED_LINE.match(text)
            if match:
                listed.append(_normal(match.group("text")))
        return listed

    def _enter(self, name: str, lines: tuple[str, ...]) -> None:
        cmds = self.config.commands
        timeout_s = self.config.exchange_timeout_s
        reply = self.link.exchange(cmds.edit.format(program=name), timeout_s,
                                   echo=self.config.echo)
        for i, line in enumerate(lines, 1):
            if reply.kind is not ReplyKind.QUESTION:
                self._leave_editor()
                raise ProgramDownloadError(f"VAL program {name}: line {i} {line!r}: the "
                                           f"editor did not ask for it ({reply.kind.value}: "
                                           f"{reply.message!r})")
            reply = self.link.exchange(line, timeout_s, echo=self.config.echo)
            refused = next((t.strip() for t in reply.lines
                            if t.strip().startswith("*") and t.strip().endswith("*")), None)
            if refused is not None:
                self._leave_editor()
                raise ProgramDownloadError(f"VAL program {name}: line {i} {line!r} refused: "
                                           f"{refused}")
        reply = self.link.exchange(cmds.edit_end, timeout_s, echo=self.config.echo)
        self._check(reply, cmds.edit_end, motion=False)

    def _leave_editor(self) -> None:
        with contextlib.suppress(DeviceFaultError, DeviceTimeoutError, ProtocolError):
            self.link.exchange(self.config.commands.edit_end, self.config.exchange_timeout_s,
                               echo=self.config.echo)

    def _guarded_descent(self, via: Pose, target: Pose, guard_speed_percent: float,
                         guard_mm: float, lift_mm: float | None,
                         ready: Callable[[], object]) -> Descent:
        """``do set`` the two locations, ``ready()``, then one ``execute`` of the descent
        program (with ``lift_mm``, and ``fpgrip`` among the programs: of the one that also
        closes and lifts); the reaction subroutine's text says the input stopped it, and a
        ``where`` then reads where. An arm that did not move at all met an input already
        high: refused. A halt before the ``execute`` refuses the descent (nothing sent)."""
        cfg = self.config
        grip = lift_mm is not None and GRIP_PROGRAM in cfg.program_lines
        program = GRIP_PROGRAM if grip else DESCENT_PROGRAM
        with self._faulting("programs"):
            _, rest_mm = self.guard_end(via, target, guard_mm)
            self._load_programs(cfg.program_text(guard_speed_percent, round(rest_mm, 2),
                                                 round(lift_mm, 2) if grip else 10.0,
                                                 run=program))
        halts = self._halts
        start = self._move_start if self._move_start is not None else self._read_pose()
        for name, pose in (("fpa", via), ("fpd", target)):
            self._command_without_output(cfg.commands.set_location.format(name=name,
                                                                          **pose.as_dict()))
        ready()  # not a fault of the arm's: its error ends the descent before the run
        if self._halts != halts:
            raise MotionRejectedError(f"halted before the {program} program")
        self._gripper_closed = False  # the program opens the jaws as it starts
        line = cfg.commands.execute.format(program=program)
        try:
            with self._faulting(line):
                reply = self._command(line, cfg.move_timeout_s)
        except (DeviceTimeoutError, ProtocolError):
            # the program may still be moving the arm: stop it before giving up (best effort;
            # the arm is in fault already)
            with contextlib.suppress(DeviceTimeoutError, ProtocolError, DeviceFaultError):
                self.link.exchange(cfg.commands.halt, cfg.exchange_timeout_s, echo=cfg.echo)
            raise
        if self._halts != halts:
            raise MotionRejectedError(f"halted during the {program} program")
        typed = {text.strip().casefold() for text in reply.lines}
        jammed = grip and cfg.program_jam_text.casefold() in typed
        if jammed:
            self._gripper_closed = True
            return Descent(self._where().pose, True, closed=True)
        if cfg.program_contact_text.casefold() not in typed:
            if grip:
                self._gripper_closed = True
                return Descent(target.moved_in_tool_frame(ToolStep(dz_mm=-lift_mm)), False,
                               closed=True, lifted=True)
            return Descent(target, False)
        pose = self._where().pose
        if all(abs(a - b) <= _NOT_MOVED for a, b in zip(pose.as_dict().values(),
                                                        start.as_dict().values(),
                                                        strict=True)):
            raise MotionRejectedError("the contact input was high before the descent: "
                                      "nothing moved")
        return Descent(pose, True)

    # -- exchanges -------------------------------------------------------------------------
    @contextlib.contextmanager
    def _faulting(self, line: str) -> Iterator[None]:
        """Put the arm into FAULT when the exchange for ``line`` fails (not when refused)."""
        try:
            yield
        except ExchangeInterrupted as exc:  # a halt (or close) cut the wait short: no fault
            raise MotionRejectedError(f"halted while waiting for {line!r}") from exc
        except (DeviceTimeoutError, ProtocolError, DeviceFaultError) as exc:
            self.mark_fault(f"{line!r}: {exc}")
            raise

    def _command(self, line: str, timeout_s: float | None = None, motion: bool = True) -> Reply:
        """Send one command and return its OK reply (``motion``: see ``_check``)."""
        reply = self.link.exchange(line, timeout_s or self.config.exchange_timeout_s,
                                   echo=self.config.echo)
        return self._check(reply, line, motion)

    def _check(self, reply: Reply, line: str, motion: bool = True) -> Reply:
        """Return an OK reply; raise the typed error for every other kind.

        A ``rejection_errors`` text is a refusal (MotionRejectedError) only for a command that
        asks for motion (``motion``); answering a reading such as ``where`` with it is a
        controller fault (DeviceFaultError), never a rejected step.
        """
        if reply.kind is ReplyKind.OK:
            return reply
        if reply.kind is ReplyKind.ERROR:
            message = reply.message.casefold()
            if motion and any(text.casefold() in message for text in self.config.rejection_errors):
                logger.warning("VAL refused %r: %s", line, reply.message)
                raise MotionRejectedError(reply.message)
            raise DeviceFaultError(reply.message)
        if reply.kind is ReplyKind.HOLD:
            raise DeviceFaultError(reply.message)
        raise ProtocolError(f"VAL: unexpected {reply.kind.value} after {line!r}: "
                            f"{reply.message!r}")

    def _command_without_output(self, line: str, timeout_s: float | None = None) -> None:
        with self._faulting(line):
            reply = self._command(line, timeout_s)
            if reply.lines:
                raise ProtocolError(f"VAL: unexpected output after {line!r}: {reply.lines!r}")

    # -- public extras -----------------------------------------------------------------------
    def where(self) -> WhereReading:
        """Pose and, when the controller prints them, joint angles (deg)."""
        self._require_connected()
        return self._where()

    def _where(self) -> WhereReading:
        line = self.config.commands.where
        with self._faulting(line):
            return parse_where(self._command(line, motion=False).lines)

    # -- Arm backend -------------------------------------------------------------------------
    def _read_pose(self) -> Pose:
        return self._where().pose

    def _move_to(self, target: Pose) -> Pose:
        halts = self._halts
        start = self._move_start  # (read or kept just before by move_to / move_tool)
        segments = self._segments(start if start is not None else self._read_pose(), target)
        for i, segment in enumerate(segments):
            if self._halts != halts:
                raise MotionRejectedError(f"halted after {i} of {len(segments)} move segments")
            line = self.config.commands.move.format(**segment.as_dict())
            self._command_without_output(line, self.config.move_timeout_s)
        # The prompt comes when the move is done (confirmed): reading back is optional.
        return self._where().pose if self.config.where_after_move else target

    def _segments(self, start: Pose, target: Pose) -> list[Pose]:
        """``target`` reached in equal steps of at most max_segment_mm / max_segment_deg (the
        angles along their shortest way); the last one is ``target`` itself."""
        return split_move(start, target, self.config.max_segment_mm, self.config.max_segment_deg)

    def _set_speed(self, percent: float) -> None:
        self._command_without_output(self.config.commands.speed.format(percent=percent))

    def _halt(self) -> None:
        self._halts += 1  # a segmented move sends no further segment
        # A move blocks its exchange until the prompt returns (or move_timeout_s on a dead
        # link): cut that wait short so the halt goes out now.
        self.link.interrupt()
        self._command_without_output(self.config.commands.halt)

    def _set_gripper(self, closed: bool) -> float:
        commands = self.config.commands
        self._command_without_output(commands.gripper_close if closed else commands.gripper_open)
        self._gripper_closed = closed
        return self._finger_width_mm()

    def _finger_width_mm(self) -> float:
        cfg = self.config
        return cfg.gripper_closed_width_mm if self._gripper_closed else cfg.gripper_open_width_mm


def split_move(start: Pose, target: Pose, max_mm: float, max_deg: float) -> list[Pose]:
    """The poses of a move from ``start`` to ``target`` split into equal segments of at most
    ``max_mm`` (translation) and ``max_deg`` (each of O, A, T, along the shortest way); the
    last pose is ``target``. 0 for both: one segment."""
    if max_mm <= 0 or max_deg <= 0:
        return [target]
    a, b = start.as_dict(), target.as_dict()
    delta = {k: b[k] - a[k] for k in a}
    for k in ("o_deg", "a_deg", "t_deg"):
        delta[k] = (delta[k] + 180.0) % 360.0 - 180.0
    distance_mm = math.dist((0.0, 0.0, 0.0), (delta["x_mm"], delta["y_mm"], delta["z_mm"]))
    turn_deg = max(abs(delta[k]) for k in ("o_deg", "a_deg", "t_deg"))
    count = max(1, math.ceil(distance_mm / max_mm - 1e-9), math.ceil(turn_deg / max_deg - 1e-9))
    return [Pose(**{k: a[k] + delta[k] * i / count for k in a}) for i in range(1, count)] + \
        [target]
