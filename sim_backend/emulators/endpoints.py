"""Where a serial-device emulator listens: a raw pseudo-terminal or a TCP port on 127.0.0.1.

Both give a ``url`` a client passes to ``serial.serial_for_url`` (the pty's ``/dev/pts/N``, or
``socket://127.0.0.1:PORT``), register their descriptors on the serving thread's selector with a
callable that returns the bytes received, and can ``hang_up``: on a pty that is a pulled cable
(nothing to close, the line just goes quiet); on TCP it closes the client's connection.
"""

from __future__ import annotations

import functools
import logging
import os
import selectors
import socket
import tty

logger = logging.getLogger(__name__)

_READ_CHUNK_BYTES = 4096
# How long a write may wait for a client that does not read before the bytes are dropped.
_WRITE_TIMEOUT_S = 1.0


class PtyEndpoint:
    """A raw pty pair. The emulator keeps the slave open too, so the line survives clients
    closing and reopening it, and bytes written while no client is attached wait for one."""

    def __init__(self) -> None:
        self._master_fd, self._slave_fd = os.openpty()
        tty.setraw(self._slave_fd)
        os.set_blocking(self._master_fd, False)
        self.url = os.ttyname(self._slave_fd)

    def register(self, selector: selectors.BaseSelector) -> None:
        selector.register(self._master_fd, selectors.EVENT_READ, self._read)

    def _read(self) -> bytes:
        try:
            return os.read(self._master_fd, _READ_CHUNK_BYTES)
        except BlockingIOError:
            return b""

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        with selectors.DefaultSelector() as selector:
            selector.register(self._master_fd, selectors.EVENT_WRITE)
            while view:
                try:
                    view = view[os.write(self._master_fd, view):]
                except BlockingIOError:
                    if not selector.select(_WRITE_TIMEOUT_S):
                        logger.debug("pty %s full, dropped %d bytes", self.url, len(view))
                        return

    def hang_up(self) -> None:
        """A pulled serial cable: nothing to close, the emulator just stops answering."""

    def close(self) -> None:
        for fd in (self._master_fd, self._slave_fd):
            os.close(fd)


class TcpEndpoint:
    """A TCP server on 127.0.0.1 for one client at a time (a new client replaces the old)."""

    def __init__(self, port: int = 0) -> None:
        self._listener = socket.create_server(("127.0.0.1", port))
        self._listener.setblocking(False)
        self.url = f"socket://127.0.0.1:{self._listener.getsockname()[1]}"
        self._selector: selectors.BaseSelector | None = None
        self._client: socket.socket | None = None

    def register(self, selector: selectors.BaseSelector) -> None:
        self._selector = selector
        selector.register(self._listener, selectors.EVENT_READ, self._accept)

    def _accept(self) -> bytes:
        try:
            client, _ = self._listener.accept()
        except BlockingIOError:
            return b""
        self.hang_up()
        client.settimeout(_WRITE_TIMEOUT_S)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = client
        assert self._selector is not None
        self._selector.register(client, selectors.EVENT_READ, functools.partial(self._recv, client))
        return b""

    def _recv(self, client: socket.socket) -> bytes:
        if client is not self._client:
            return b""  # replaced or hung up in the same round of events
        try:
            data = client.recv(_READ_CHUNK_BYTES)
        except OSError:
            data = b""
        if not data:
            self.hang_up()
        return data

    def write(self, data: bytes) -> None:
        if self._client is None:
            return
        try:
            self._client.sendall(data)
        except OSError as exc:
            logger.debug("TCP client gone: %s", exc)
            self.hang_up()

    def hang_up(self) -> None:
        client, self._client = self._client, None
        if client is None:
            return
        if self._selector is not None:
            self._selector.unregister(client)
        client.close()

    def close(self) -> None:
        self.hang_up()
        self._listener.close()
