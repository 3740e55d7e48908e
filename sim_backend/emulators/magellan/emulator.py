"""An emulated Magellan serial 3D mouse on a pseudo-terminal, for spacenavd to read.

Answers spacenavd 1.1's probe exactly as the hardware notes describe: the Spaceball probe
``\\r@RESET\\r`` gets ``\\r?\\r`` (not ``@1``, so the daemon stops waiting for a Spaceball), the
version query ``vQ\\r`` gets ``version`` (a line starting with ``v``) only after the query
arrived, and the mode set ``m3\\r`` makes the device live (``wait_ready``). Other commands are
ignored.

Once live it plays what it is given (``play``): motions held for a time, repeated every
``report_period_s`` like a real device (spacenavd turns a repeat into no event), and button
changes; after the last step the cap springs back to zero. ``play(..., replace=True)`` drops
what is queued and starts at once (keyboard-driven jogging).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Iterable

from sim_backend.emulators.link import EmulatorLink, LinkServer
from sim_backend.emulators.magellan.protocol import encode_buttons, encode_motion
from sim_backend.emulators.magellan.script import Motion, Step

logger = logging.getLogger(__name__)

DEFAULT_VERSION = "v  MAGELLAN  Version 6.70  3Dconnexion GmbH 05/11/00 "
_REST = (0, 0, 0, 0, 0, 0)


class MagellanEmulator(LinkServer):
    """One emulated Magellan mouse on a pty (``url``: the device path for spacenavd's
    ``serial = ...``); use as a context manager. Stop spacenavd before closing it: the daemon
    spins on a hung-up line."""

    def __init__(self, report_period_s: float = 0.02, version: str = DEFAULT_VERSION) -> None:
        super().__init__()
        self.report_period_s = report_period_s
        self.version = version
        self.probe_log: list[str] = []  # commands received from the daemon, in order
        self._ready = threading.Event()
        self._idle = threading.Condition()
        self._queue: deque[Step] = deque()
        self._axes = _REST
        self._motion_end_s = 0.0
        self._pressed: set[int] = set()

    # -- control (any thread) -------------------------------------------------------------
    def wait_ready(self, timeout_s: float) -> bool:
        """Wait until the daemon finished probing (sent the mode set); False on timeout."""
        return self._ready.wait(timeout_s)

    def play(self, steps: Iterable[Step], replace: bool = False) -> None:
        """Queue ``steps`` (or, with ``replace``, drop the queue and the current motion)."""
        with self._idle:
            if replace:
                self._queue.clear()
                self._motion_end_s = 0.0
            self._queue.extend(steps)
        if self._link is not None:
            self._link.wake()

    def wait_done(self, timeout_s: float) -> bool:
        """Wait until everything queued was played and the cap is at rest; False on timeout."""
        with self._idle:
            return self._idle.wait_for(self._is_idle, timeout_s)

    def _is_idle(self) -> bool:
        return not self._queue and self._axes == _REST and self._motion_end_s == 0.0

    # -- serving thread -------------------------------------------------------------------
    def _serve(self, link: EmulatorLink) -> None:
        pending = b""
        next_report_s = 0.0
        while True:
            timeout_s = None
            if self._ready.is_set() and not self._is_idle():
                timeout_s = max(0.0, next_report_s - time.monotonic())
            data = link.read(timeout_s)
            if data is None:
                return
            pending += data
            while b"\r" in pending:
                line, pending = pending.split(b"\r", 1)
                self._answer(line.decode("ascii", "replace"))
            if self._ready.is_set() and time.monotonic() >= next_report_s:
                self._advance()
                next_report_s = time.monotonic() + self.report_period_s

    def _answer(self, command: str) -> None:
        if not command:
            return
        self.probe_log.append(command)
        if command == "@RESET":
            self._ready.clear()
            self._send(b"\r?\r")
        elif command == "vQ":
            self._send(self.version.encode("ascii") + b"\r")
        elif command.startswith("m"):
            self._ready.set()
            logger.info("Magellan emulator: spacenavd set mode %s, device live", command)
        else:
            logger.debug("Magellan emulator: ignoring %r", command)

    def _advance(self) -> None:
        """One report tick: run due steps, then repeat the held motion (or spring back)."""
        now_s = time.monotonic()
        with self._idle:
            while now_s >= self._motion_end_s and self._queue:
                step = self._queue.popleft()
                if isinstance(step, Motion):
                    self._axes = step.axes
                    self._motion_end_s = now_s + step.duration_s
                else:
                    if step.pressed:
                        self._pressed.add(step.button)
                    else:
                        self._pressed.discard(step.button)
                    self._send(encode_buttons(self._pressed))
            if now_s >= self._motion_end_s and not self._queue:
                self._motion_end_s = 0.0
                if self._axes != _REST:
                    self._axes = _REST
                    self._send(encode_motion(_REST))
                self._idle.notify_all()
                return
        self._send(encode_motion(self._axes))

    def _send(self, packet: bytes) -> None:
        assert self._link is not None
        self._link.write(packet)
