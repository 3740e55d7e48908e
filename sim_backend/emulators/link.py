"""The line a serial-device emulator serves (VAL II monitor, ATI F/T controller, Magellan
mouse), and the threaded server every one of them is.

``EmulatorLink`` wraps an endpoint of ``sim_backend.emulators.endpoints`` (a raw pty whose
slave the emulator keeps open, or a TCP port on 127.0.0.1) for one serving thread: ``read``
waits on a selector with a timeout that other threads can cut short (``wake``: new work for the
serving thread) or end for good (``interrupt``: stop serving), so an emulator reacts at once
and stops deterministically. ``LinkServer`` (a ``ThreadedServer``) owns the link and that thread.

With a ``baud`` rate (``--timing realistic``) the link takes the wire time of a real serial
line in both directions (``bits_per_byte`` bits a byte, 10 for 8N1): bytes the client sent are
handed to the emulator only after their time on the line, and replies leave in small chunks,
each after its own time, so a client sees them arrive at the line's pace.
"""

from __future__ import annotations

import functools
import logging
import os
import selectors
import threading
import time
from abc import abstractmethod
from collections.abc import Callable

from drivers.core.lifecycle import ThreadedServer
from sim_backend.emulators.endpoints import PtyEndpoint, TcpEndpoint

logger = logging.getLogger(__name__)

_WAKE_CHUNK_BYTES = 64
# A paced reply leaves in chunks of about this long on the wire (s).
_PACE_CHUNK_S = 0.01


class EmulatorLink:
    """A pty (default) or TCP endpoint plus a wake-up pipe. ``close()`` is idempotent.

    baud: pace the bytes at this rate both ways (None: as fast as the endpoint goes);
    bits_per_byte: bits on the line per byte (8N1: 10). wire_s: seconds spent pacing so far.
    """

    def __init__(self, endpoint: PtyEndpoint | TcpEndpoint | None = None,
                 baud: float | None = None, bits_per_byte: int = 10) -> None:
        if baud is not None and baud <= 0:
            raise ValueError(f"baud must be > 0, got {baud}")
        self.baud = baud
        self.bits_per_byte = bits_per_byte
        self.wire_s = 0.0
        self._line_free_at = 0.0  # monotonic time the last paced byte leaves
        self._stop = threading.Event()
        self.endpoint = endpoint or PtyEndpoint()
        self.url = self.endpoint.url
        self._wake_r, self._wake_w = os.pipe()
        self._selector = selectors.DefaultSelector()
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        self.endpoint.register(self._selector)
        self._interrupted = False
        self._closed = False

    def read(self, timeout_s: float | None) -> bytes | None:
        """Bytes the client sent; ``b""`` after ``timeout_s``, on ``wake()`` or a new TCP client.

        Returns None once ``interrupt()`` was called: the serving loop should end.
        """
        if self._interrupted:
            return None
        data = b""
        for key, _ in self._selector.select(timeout_s):
            if key.data is None:
                os.read(self._wake_r, _WAKE_CHUNK_BYTES)
            else:
                data += key.data()
        if data:
            self._pace(len(data))
        return None if self._interrupted else data

    def _pace(self, n_bytes: int) -> None:
        """Take the wire time of ``n_bytes`` (when paced; cut short by ``interrupt``)."""
        if self.baud is None or n_bytes <= 0:
            return
        seconds = n_bytes * self.bits_per_byte / self.baud
        self.wire_s += seconds
        self._stop.wait(seconds)

    def write(self, data: bytes) -> None:
        """Send to the client (dropped after a while if nobody reads, as on a real line);
        paced at ``baud`` when set."""
        if self.baud is None:
            self.endpoint.write(data)
            return
        chunk = max(1, int(self.baud * _PACE_CHUNK_S / self.bits_per_byte))
        free_at = max(time.monotonic(), self._line_free_at)
        for i in range(0, len(data), chunk):
            piece = data[i:i + chunk]
            seconds = len(piece) * self.bits_per_byte / self.baud
            self.wire_s += seconds
            free_at += seconds  # deadlines: the work of writing does not slow the line
            self._stop.wait(max(0.0, free_at - time.monotonic()))
            if self._stop.is_set():
                return
            self.endpoint.write(piece)
        self._line_free_at = free_at

    def hang_up(self) -> None:
        """A pulled cable: a pty goes quiet, a TCP client is disconnected."""
        self.endpoint.hang_up()

    def wake(self) -> None:
        """Make a pending ``read`` return now (thread-safe)."""
        os.write(self._wake_w, b"w")

    def interrupt(self) -> None:
        """Make a pending and every later ``read`` return None (thread-safe)."""
        self._interrupted = True
        self._stop.set()
        os.write(self._wake_w, b"x")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.endpoint.close()  # first: it unregisters a connected TCP client from the selector
        self._selector.close()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def __enter__(self) -> EmulatorLink:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


class LinkServer(ThreadedServer):
    """An emulator serving one line from its own thread; use as a context manager.

    ``start()`` opens the line (a pty, or a TCP port on 127.0.0.1 when ``tcp_port`` is given)
    and runs ``_serve`` on a thread until ``close()``, which interrupts any pending read or
    ``_closing`` wait, joins the thread and closes the line. ``baud``: pace the line (see
    ``EmulatorLink``).
    """

    def __init__(self, tcp_port: int | None = None, baud: float | None = None,
                 bits_per_byte: int = 10) -> None:
        super().__init__()
        self._tcp_port = tcp_port
        self._baud = baud
        self._bits_per_byte = bits_per_byte
        self._link: EmulatorLink | None = None

    @property
    def url(self) -> str:
        """The port a client opens (``/dev/pts/N`` or ``socket://127.0.0.1:PORT``)."""
        if self._link is None:
            raise RuntimeError(f"{type(self).__name__} is not started")
        return self._link.url

    def _open(self) -> dict[str, Callable[[], object]]:
        endpoint = PtyEndpoint() if self._tcp_port is None else TcpEndpoint(self._tcp_port)
        self._link = EmulatorLink(endpoint, self._baud, self._bits_per_byte)
        logger.info("%s on %s%s", type(self).__name__, self._link.url,
                    f" at {self._baud:g} baud" if self._baud else "")
        return {"serve": functools.partial(self._serve, self._link)}

    def _interrupt(self) -> None:
        assert self._link is not None
        self._link.interrupt()

    def _release(self) -> None:
        assert self._link is not None
        self._link.close()
        self._link = None

    @abstractmethod
    def _serve(self, link: EmulatorLink) -> None:
        """The serving loop: runs until ``link.read`` returns None."""
