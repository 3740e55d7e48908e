"""A client of spacenavd's UNIX socket: connect, then read typed events with a timeout.

The socket path is, in order: the one configured, ``$SPNAV_SOCKET``, ``/var/run/spnav.sock``.
The client never writes, so the daemon speaks protocol v0 (see ``drivers.spacenav.events``).
"""

from __future__ import annotations

import logging
import os
import selectors
import socket
import time

from drivers.core.errors import DeviceNotConnectedError
from drivers.spacenav.events import EVENT_BYTES, SpnavEvent, decode_event

logger = logging.getLogger(__name__)

DEFAULT_SOCKET_PATH = "/var/run/spnav.sock"
SOCKET_ENV = "SPNAV_SOCKET"


def resolve_socket_path(configured: str | None = None) -> str:
    """The configured path, else ``$SPNAV_SOCKET``, else the daemon's default."""
    return configured or os.environ.get(SOCKET_ENV) or DEFAULT_SOCKET_PATH


class SpacenavClient:
    """One connection to spacenavd. Use as a context manager."""

    def __init__(self, socket_path: str | None = None) -> None:
        self.socket_path = resolve_socket_path(socket_path)
        self._sock: socket.socket | None = None
        self._selector: selectors.BaseSelector | None = None
        self._buffer = b""

    @property
    def is_connected(self) -> bool:
        return self._sock is not None

    def connect(self) -> None:
        """Connect to the daemon (DeviceNotConnectedError when it is not there)."""
        if self._sock is not None:
            return
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.connect(self.socket_path)
        except OSError as exc:
            sock.close()
            raise DeviceNotConnectedError(
                f"spacenavd socket {self.socket_path}: {exc.strerror or exc} (is spacenavd "
                f"running? set ${SOCKET_ENV} or the config's socket_path)") from exc
        sock.setblocking(False)
        self._sock = sock
        self._selector = selectors.DefaultSelector()
        self._selector.register(sock, selectors.EVENT_READ)
        self._buffer = b""
        logger.info("connected to spacenavd at %s", self.socket_path)

    def close(self) -> None:
        """Disconnect (idempotent)."""
        if self._sock is None:
            return
        assert self._selector is not None
        self._selector.close()
        self._sock.close()
        self._sock = None
        self._selector = None

    def __enter__(self) -> SpacenavClient:
        self.connect()
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def next_event(self, timeout_s: float) -> SpnavEvent | None:
        """The next event, or None when none arrived within ``timeout_s``.

        Raises DeviceNotConnectedError when not connected or when the daemon hung up, and
        ProtocolError for a packet that is not a v0 event.
        """
        if self._sock is None or self._selector is None:
            raise DeviceNotConnectedError("spacenav client is not connected")
        deadline_s = time.monotonic() + timeout_s
        while len(self._buffer) < EVENT_BYTES:
            remaining_s = deadline_s - time.monotonic()
            if remaining_s <= 0 or not self._selector.select(remaining_s):
                return None
            try:
                chunk = self._sock.recv(4096)
            except BlockingIOError:
                continue
            except OSError as exc:
                self.close()
                raise DeviceNotConnectedError(f"spacenavd connection lost: {exc}") from exc
            if not chunk:
                self.close()
                raise DeviceNotConnectedError("spacenavd closed the connection")
            self._buffer += chunk
        packet, self._buffer = self._buffer[:EVENT_BYTES], self._buffer[EVENT_BYTES:]
        return decode_event(packet)
