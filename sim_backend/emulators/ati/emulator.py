"""An emulated ATI F/T controller on a pseudo-terminal (or TCP), backed by any WrenchSensor.

``AtiEmulator(sensor)`` opens a pty (``tcp_port``: a TCP port on 127.0.0.1 instead) and serves
the controller's ASCII protocol on it from a thread (see ``sim_backend.emulators.ati.protocol``
for the commands); ``url`` is the port a driver opens (``/dev/pts/N`` or ``socket://...``).
The caller owns the backing sensor's lifecycle (connect it first); while the sensor fails,
commands are answered with an ``Error: ...`` line. Fault knobs live in ``faults`` and may be
changed while it runs:

- ``reply_delay_s``: every reply (and every streamed record) comes this much later;
- ``drop_after``: after this many command lines the link goes down until the knob is set back
  to None, as with a pulled cable: a pty goes silent (input is ignored), a TCP client is
  disconnected;
- ``garbage``: each reply is replaced by as many bytes with the high bit set (what a baud-rate
  mismatch looks like) followed by the prompt;
- ``status_word``: the status word sent with every record (nonzero = sensor error).
"""

from __future__ import annotations

import logging
import random
import threading
import time
from dataclasses import dataclass

from drivers.core.errors import FineposError
from drivers.interfaces import WrenchSensor
from sim_backend.emulators.ati.protocol import PROMPT, AtiController
from sim_backend.emulators.link import EmulatorLink, LinkServer

logger = logging.getLogger(__name__)


@dataclass
class AtiFaults:
    """Fault-injection knobs (read by the serving thread at every command)."""

    reply_delay_s: float = 0.0
    drop_after: int | None = None
    garbage: bool = False
    status_word: int = 0


class AtiEmulator(LinkServer):
    """Serves one emulated ATI F/T controller; use as a context manager. ``baud``: pace the
    line at this rate (``--timing realistic``: ``timing.ati_baud``; None: unpaced)."""

    def __init__(self, sensor: WrenchSensor, counts_per_force: float = 20.0,
                 counts_per_torque: float = 333.33, echo: bool = True,
                 stream_period_s: float = 0.05, faults: AtiFaults | None = None,
                 tcp_port: int | None = None, baud: float | None = None) -> None:
        super().__init__(tcp_port, baud)
        self.faults = faults or AtiFaults()
        self.controller = AtiController(sensor, counts_per_force, counts_per_torque, echo,
                                        status_word=lambda: self.faults.status_word)
        self.stream_period_s = stream_period_s
        self.commands_received = 0
        self.replies_sent = 0
        self._replies_changed = threading.Condition()
        self._rng = random.Random(0)

    def wait_replies(self, count: int, timeout_s: float) -> bool:
        """Wait until ``count`` replies were sent in all (e.g. a delayed one); False on timeout."""
        with self._replies_changed:
            return self._replies_changed.wait_for(lambda: self.replies_sent >= count, timeout_s)

    # -- serving thread -------------------------------------------------------------------
    def _serve(self, link: EmulatorLink) -> None:
        pending = b""
        next_record_s = 0.0
        while True:
            timeout_s = max(0.0, next_record_s - time.monotonic()) \
                if self.controller.streaming else None
            data = link.read(timeout_s)
            if data is None:
                return
            if self._link_dropped():
                pending = b""
                self.controller.streaming = False
                link.hang_up()
                continue
            pending += data
            if self.controller.streaming:
                if b"\r" in pending:
                    pending = pending.split(b"\r", 1)[1]
                    self._send(self.controller.stop_stream())
                elif time.monotonic() >= next_record_s:
                    self._send_record()
                    next_record_s = time.monotonic() + self.stream_period_s
            while b"\r" in pending and not self.controller.streaming:
                line, pending = pending.split(b"\r", 1)
                self.commands_received += 1
                if self._link_dropped():
                    pending = b""
                    link.hang_up()
                    break
                text = line.replace(b"\n", b"").decode("ascii", "replace")
                self._send(self.controller.execute(text))
                next_record_s = time.monotonic()

    def _link_dropped(self) -> bool:
        limit = self.faults.drop_after
        return limit is not None and self.commands_received > limit

    def _send_record(self) -> None:
        try:
            self._send(self.controller.record())
        except FineposError as exc:
            self.controller.streaming = False
            self._send(f"Error: {exc}".encode("ascii", "replace") + self.controller.eol + PROMPT)

    def _send(self, reply: bytes) -> None:
        if self.faults.reply_delay_s > 0 and self._closing.wait(self.faults.reply_delay_s):
            return
        if self.faults.garbage:
            reply = bytes(self._rng.randrange(0x80, 0x100) for _ in reply[:-1]) + PROMPT
        assert self._link is not None
        self._link.write(reply)
        with self._replies_changed:
            self.replies_sent += 1
            self._replies_changed.notify_all()
