"""The VAL emulator: a ValMonitor served over a pty or TCP from a background thread, with fault
knobs.

``with ValEmulator(arm) as emulator:`` starts serving and prints nothing; ``emulator.url`` is what
a client (the VAL driver's ``port``) opens. Leaving the block stops the thread deterministically
(a wake-up pipe interrupts the selector and any reply delay) and closes the endpoint. The arm is
the caller's: connect and activate it before, disconnect it after.
"""

from __future__ import annotations

import logging
import os
import selectors
import threading
from dataclasses import dataclass

from drivers.interfaces import Arm
from sim_backend.emulators.endpoints import PtyEndpoint, TcpEndpoint
from sim_backend.emulators.val.kinematics import Puma260
from sim_backend.emulators.val.lines import LineAssembler
from sim_backend.emulators.val.monitor import ValMonitor

logger = logging.getLogger(__name__)

# Line noise as a wrong baud rate produces it.
DEFAULT_GARBAGE = b"\xfe\x80\x13\xff\x00#\xe0"


@dataclass(frozen=True)
class ValFaults:
    """Fault knobs, applied to every input line while set (``ValEmulator.set_faults``).

    reply_delay_s: pause between the echo of a line and its reply (the command runs first).
    drop_link_after_lines: answer this many more lines, then the link goes down until the knobs
        are set again: on a pty the emulator falls silent (a pulled cable; the driver times
        out), on TCP it closes the connection and every new one (the driver sees a lost link).
    garbage: bytes sent before every reply (the driver sees line noise).
    forced_error: every command is answered ``*forced_error*`` instead of being run.
    """

    reply_delay_s: float = 0.0
    drop_link_after_lines: int | None = None
    garbage: bytes = b""
    forced_error: str | None = None

    def __post_init__(self) -> None:
        if not self.reply_delay_s >= 0.0:
            raise ValueError(f"reply_delay_s must be >= 0, got {self.reply_delay_s!r}")
        if self.drop_link_after_lines is not None and self.drop_link_after_lines < 0:
            raise ValueError("drop_link_after_lines must be >= 0, got "
                             f"{self.drop_link_after_lines}")


class ValEmulator:
    """Serves the VAL II monitor for ``arm`` on a new pty, or on ``tcp_port`` (0: any free port).

    lines_handled: input lines answered since start (logged at stop).
    """

    def __init__(self, arm: Arm, *, tcp_port: int | None = None, boot_questions: bool = False,
                 kinematics: Puma260 | None = None, faults: ValFaults | None = None) -> None:
        self._monitor = ValMonitor(arm, kinematics, boot_questions)
        self._endpoint = PtyEndpoint() if tcp_port is None else TcpEndpoint(tcp_port)
        self._faults = faults or ValFaults()
        self._lines_since_faults = 0
        self._link_down = False
        self._assembler = LineAssembler()
        self._changed = threading.Condition()
        self._stopping = False
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._serve, name="val-emulator", daemon=True)
        self.lines_handled = 0

    @property
    def url(self) -> str:
        """The port URL for ``serial.serial_for_url`` (a pty path or ``socket://...``)."""
        return self._endpoint.url

    def set_faults(self, faults: ValFaults) -> None:
        """Replace the fault knobs; restores a dropped link and ends a pending reply delay."""
        with self._changed:
            self._faults = faults
            self._lines_since_faults = 0
            self._link_down = False
            self._changed.notify_all()
        logger.info("VAL emulator faults: %s", faults)

    def start(self) -> None:
        """Print what the controller prints at power-up (a pty keeps it for the first client),
        then serve from the background thread."""
        self._endpoint.write(self._monitor.first_output())
        self._thread.start()
        logger.info("VAL emulator serving on %s", self.url)

    def stop(self) -> None:
        """Stop serving and close the endpoint; idempotent."""
        with self._changed:
            if self._stopping:
                return
            self._stopping = True
            self._changed.notify_all()
        os.write(self._wake_w, b"x")
        if self._thread.is_alive():
            self._thread.join()
        self._endpoint.close()
        os.close(self._wake_r)
        os.close(self._wake_w)
        logger.info("VAL emulator stopped after %d lines", self.lines_handled)

    def __enter__(self) -> ValEmulator:
        self.start()
        return self

    def __exit__(self, *exc_info) -> None:
        self.stop()

    # -- serving thread ----------------------------------------------------------------------
    def _serve(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self._wake_r, selectors.EVENT_READ, None)
            self._endpoint.register(selector)
            while not self._stopping:
                for key, _ in selector.select():
                    if key.data is None or self._stopping:
                        break
                    data = key.data()
                    if data:
                        self._handle(data)

    def _handle(self, data: bytes) -> None:
        if self._link_down:
            self._endpoint.hang_up()
            return
        for line in self._assembler.feed(data):
            with self._changed:
                faults = self._faults
                limit = faults.drop_link_after_lines
                if limit is not None and self._lines_since_faults >= limit:
                    self._link_down = True
            if self._link_down:
                logger.info("VAL emulator: link dropped after %d lines", self._lines_since_faults)
                self._assembler = LineAssembler()
                self._endpoint.hang_up()
                return
            response = self._monitor.handle_line(line, faults.forced_error)
            self._endpoint.write(response.echo)
            if faults.reply_delay_s > 0:
                with self._changed:
                    self._changed.wait_for(lambda f=faults: self._stopping or self._faults is not f,
                                           timeout=faults.reply_delay_s)
            with self._changed:  # counted before the reply leaves, so a client sees it
                self._lines_since_faults += 1
                self.lines_handled += 1
            self._endpoint.write(faults.garbage + response.reply)
