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
from collections.abc import Iterator

from drivers.core.errors import (
    DeviceFaultError,
    DeviceTimeoutError,
    MotionRejectedError,
    ProtocolError,
)
from drivers.core.pose import Pose
from drivers.interfaces import Arm
from drivers.safety import SafetyLimits
from drivers.val.config import ValConfig
from drivers.val.link import ExchangeInterrupted, ValLink
from drivers.val.replies import Reply, ReplyKind
from drivers.val.where import WhereReading, parse_where

logger = logging.getLogger(__name__)

# Questions answered in one start-up before giving up (the controller keeps asking).
_MAX_BOOT_QUESTIONS = 8


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
        except BaseException:
            self.link.close()
            raise

    def _close(self) -> None:
        self.link.close()

    def _handshake(self) -> None:
        timeout_s = self.config.exchange_timeout_s
        reply = self.link.exchange("", timeout_s, echo=False)
        for _ in range(_MAX_BOOT_QUESTIONS):
            if reply.kind is not ReplyKind.QUESTION:
                self._check(reply, "<wake>")
                logger.info("VAL monitor ready on %s", self.config.port)
                return
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
