"""The VAL emulator: a ValMonitor served over a pty or TCP from a background thread, with fault
knobs.

``with ValEmulator(arm) as emulator:`` starts serving and prints nothing; ``emulator.url`` is what
a client (the VAL driver's ``port``) opens. Leaving the block (or ``close()``) stops the thread
deterministically (``LinkServer``: the link's wake-up pipe interrupts the read, and any reply
delay ends) and closes the line. The arm is the caller's: connect and activate it before,
disconnect it after.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

from drivers.interfaces import Arm
from sim_backend.emulators.link import EmulatorLink, LinkServer
from sim_backend.emulators.val.kinematics import Puma260
from sim_backend.emulators.val.lines import LineAssembler
from sim_backend.emulators.val.monitor import ValMonitor

logger = logging.getLogger(__name__)

# Line noise as a wrong baud rate produces it.
DEFAULT_GARBAGE = b"\xfe\x80\x13\xff\x00#\xe0"

# What a listener hears (``ValEmulator.add_listener``): ("command", line) as a line is about to
# run, ("done", line) once it has run (a move: the arm is at rest), ("fault", what) when a knob
# acts: "link_drop", "garbage", "reply_delay" or "forced_error".
ValListener = Callable[[str, str], None]


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


class ValEmulator(LinkServer):
    """Serves the VAL II monitor for ``arm`` on a new pty, or on ``tcp_port`` (0: any free port).

    lines_handled: input lines answered since start (logged at close). baud: pace the line at
    this rate (``--timing realistic``: ``timing.val_baud``; None: unpaced). How long a motion
    takes is the arm's business: a SimArm with a wall-clock ``CellTiming`` returns from a move
    only after its motion time, so ``do move`` answers its prompt then; ``on_line`` is called
    as each line arrives, before it is run (``CellTiming.begin_command``). Listeners
    (``add_listener``) hear every line run and every fault a knob causes, from the serving
    thread, so a test can see what the arm really received.
    """

    def __init__(self, arm: Arm, *, tcp_port: int | None = None, boot_questions: bool = False,
                 kinematics: Puma260 | None = None, faults: ValFaults | None = None,
                 baud: float | None = None, on_line: Callable[[], None] | None = None) -> None:
        super().__init__(tcp_port, baud)
        self._on_line = on_line
        self._monitor = ValMonitor(arm, kinematics, boot_questions)
        self._faults = faults or ValFaults()
        self._lines_since_faults = 0
        self._link_down = False
        self._assembler = LineAssembler()
        self._changed = threading.Condition()
        self._listeners: list[ValListener] = []
        self._write_lock = threading.Lock()  # the serving and the program threads both write
        self._monitor.on_program_end = self._program_ended
        self.lines_handled = 0

    @property
    def monitor(self) -> ValMonitor:
        """The monitor served (``set_input`` wires its input lines)."""
        return self._monitor

    def _program_ended(self, data: bytes) -> None:
        link = self._link
        if link is None or self._link_down:
            return
        self._tell("done", "program")
        with self._write_lock:
            link.write(self._faults.garbage + data)

    def add_listener(self, listener: ValListener) -> None:
        """Call ``listener(event, text)`` for every line run and every fault (see ValListener);
        it runs on the serving thread and must be quick."""
        self._listeners.append(listener)

    def _tell(self, event: str, text: str) -> None:
        for listener in self._listeners:
            listener(event, text)

    def set_faults(self, faults: ValFaults) -> None:
        """Replace the fault knobs; restores a dropped link and ends a pending reply delay."""
        with self._changed:
            self._faults = faults
            self._lines_since_faults = 0
            self._link_down = False
            self._changed.notify_all()
        logger.info("VAL emulator faults: %s", faults)

    def _open(self) -> dict[str, Callable[[], object]]:
        """Open the line and print what the controller prints at power-up (a pty keeps it for
        the first client) before the serving thread starts."""
        bodies = super()._open()
        assert self._link is not None
        self._link.write(self._monitor.first_output())
        return bodies

    def _interrupt(self) -> None:
        with self._changed:  # ends a pending reply delay
            self._changed.notify_all()
        super()._interrupt()
        self._monitor.stop_program()

    def _release(self) -> None:
        super()._release()
        logger.info("VAL emulator closed after %d lines", self.lines_handled)

    # -- serving thread ----------------------------------------------------------------------
    def _serve(self, link: EmulatorLink) -> None:
        while (data := link.read(None)) is not None:
            if data:
                self._handle(link, data)

    def _handle(self, link: EmulatorLink, data: bytes) -> None:
        if self._link_down:
            link.hang_up()
            return
        for line in self._assembler.feed(data):
            with self._changed:
                faults = self._faults
                limit = faults.drop_link_after_lines
                if limit is not None and self._lines_since_faults >= limit:
                    self._link_down = True
            if self._link_down:
                logger.info("VAL emulator: link dropped after %d lines", self._lines_since_faults)
                self._tell("fault", "link_drop")
                self._assembler = LineAssembler()
                link.hang_up()
                return
            if self._on_line is not None:
                self._on_line()
            if faults.forced_error is not None:
                self._tell("fault", "forced_error")
            else:
                self._tell("command", line)
            response = self._monitor.handle_line(line, faults.forced_error)
            if faults.forced_error is None:
                self._tell("done", line)
            with self._write_lock:
                link.write(response.echo)
            if faults.reply_delay_s > 0:
                self._tell("fault", "reply_delay")
                with self._changed:
                    self._changed.wait_for(
                        lambda f=faults: self._closing.is_set() or self._faults is not f,
                        timeout=faults.reply_delay_s)
            with self._changed:  # counted before the reply leaves, so a client sees it
                self._lines_since_faults += 1
                self.lines_handled += 1
            if faults.garbage:
                self._tell("fault", "garbage")
            with self._write_lock:
                link.write(faults.garbage + response.reply)
            if response.after is not None:
                response.after()
