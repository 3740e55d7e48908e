"""The line a serial-device emulator serves (ATI F/T controller, Magellan mouse), and the
threaded server both emulators are.

``EmulatorLink`` wraps an endpoint of ``sim_backend.emulators.endpoints`` (a raw pty whose
slave the emulator keeps open, or a TCP port on 127.0.0.1) for one serving thread: ``read``
waits on a selector with a timeout that other threads can cut short (``wake``: new work for the
serving thread) or end for good (``interrupt``: stop serving), so an emulator reacts at once
and stops deterministically. ``LinkServer`` owns the link and that thread.
"""

from __future__ import annotations

import logging
import os
import selectors
import threading
from abc import ABC, abstractmethod
from typing import Self

from sim_backend.emulators.endpoints import PtyEndpoint, TcpEndpoint

logger = logging.getLogger(__name__)

_WAKE_CHUNK_BYTES = 64


class EmulatorLink:
    """A pty (default) or TCP endpoint plus a wake-up pipe. ``close()`` is idempotent."""

    def __init__(self, endpoint: PtyEndpoint | TcpEndpoint | None = None) -> None:
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
        return None if self._interrupted else data

    def write(self, data: bytes) -> None:
        """Send to the client (dropped after a while if nobody reads, as on a real line)."""
        self.endpoint.write(data)

    def hang_up(self) -> None:
        """A pulled cable: a pty goes quiet, a TCP client is disconnected."""
        self.endpoint.hang_up()

    def wake(self) -> None:
        """Make a pending ``read`` return now (thread-safe)."""
        os.write(self._wake_w, b"w")

    def interrupt(self) -> None:
        """Make a pending and every later ``read`` return None (thread-safe)."""
        self._interrupted = True
        os.write(self._wake_w, b"x")

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._selector.close()
        self.endpoint.close()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def __enter__(self) -> EmulatorLink:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


class LinkServer(ABC):
    """An emulator serving one line from its own thread; use as a context manager.

    ``start()`` opens the line (a pty, or a TCP port on 127.0.0.1 when ``tcp_port`` is given)
    and runs ``_serve`` on a thread until ``close()``, which interrupts any pending read or
    ``_stop`` wait, joins the thread and closes the line.
    """

    def __init__(self, tcp_port: int | None = None) -> None:
        self._tcp_port = tcp_port
        self._stop = threading.Event()
        self._link: EmulatorLink | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """The port a client opens (``/dev/pts/N`` or ``socket://127.0.0.1:PORT``)."""
        if self._link is None:
            raise RuntimeError(f"{type(self).__name__} is not started")
        return self._link.url

    def start(self) -> Self:
        endpoint = PtyEndpoint() if self._tcp_port is None else TcpEndpoint(self._tcp_port)
        self._link = EmulatorLink(endpoint)
        self._thread = threading.Thread(target=self._serve, args=(self._link,),
                                        name=type(self).__name__, daemon=True)
        self._thread.start()
        logger.info("%s on %s", type(self).__name__, self._link.url)
        return self

    def close(self) -> None:
        """Stop serving and close the line (idempotent)."""
        if self._link is None:
            return
        self._stop.set()
        self._link.interrupt()
        assert self._thread is not None
        self._thread.join()
        self._link.close()
        self._link = None
        self._thread = None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.close()

    @abstractmethod
    def _serve(self, link: EmulatorLink) -> None:
        """The serving loop: runs until ``link.read`` returns None."""
