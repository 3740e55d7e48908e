"""The line a serial-device emulator serves (VAL II monitor, ATI F/T controller, Magellan
mouse), and the threaded server every one of them is.

``EmulatorLink`` wraps an endpoint of ``sim_backend.emulators.endpoints`` (a raw pty whose
slave the emulator keeps open, or a TCP port on 127.0.0.1) for one serving thread: ``read``
waits on a selector with a timeout that other threads can cut short (``wake``: new work for the
serving thread) or end for good (``interrupt``: stop serving), so an emulator reacts at once
and stops deterministically. ``LinkServer`` (a ``ThreadedServer``) owns the link and that thread.
"""

from __future__ import annotations

import functools
import logging
import os
import selectors
from abc import abstractmethod
from collections.abc import Callable

from sim_backend.emulators.endpoints import PtyEndpoint, TcpEndpoint
from sim_backend.emulators.lifecycle import ThreadedServer

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


class LinkServer(ThreadedServer):
    """An emulator serving one line from its own thread; use as a context manager.

    ``start()`` opens the line (a pty, or a TCP port on 127.0.0.1 when ``tcp_port`` is given)
    and runs ``_serve`` on a thread until ``close()``, which interrupts any pending read or
    ``_closing`` wait, joins the thread and closes the line.
    """

    def __init__(self, tcp_port: int | None = None) -> None:
        super().__init__()
        self._tcp_port = tcp_port
        self._link: EmulatorLink | None = None

    @property
    def url(self) -> str:
        """The port a client opens (``/dev/pts/N`` or ``socket://127.0.0.1:PORT``)."""
        if self._link is None:
            raise RuntimeError(f"{type(self).__name__} is not started")
        return self._link.url

    def _open(self) -> dict[str, Callable[[], object]]:
        endpoint = PtyEndpoint() if self._tcp_port is None else TcpEndpoint(self._tcp_port)
        self._link = EmulatorLink(endpoint)
        logger.info("%s on %s", type(self).__name__, self._link.url)
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
