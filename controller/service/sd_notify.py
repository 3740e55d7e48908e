"""systemd's notification protocol (sd_notify) in a few lines: READY, WATCHDOG, STATUS, STOPPING.

Datagrams go to ``$NOTIFY_SOCKET`` (a path, or ``@name`` in the abstract namespace). Without that
variable every call does nothing, so the service runs the same outside systemd. The watchdog is
on when ``$WATCHDOG_USEC`` is set and ``$WATCHDOG_PID`` is unset or names this process; pings are
due at half the timeout, as sd_watchdog_enabled(3) recommends.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping

logger = logging.getLogger(__name__)


class Notifier:
    """Sends notifications to systemd; thread-safe (one datagram per call)."""

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        address = env.get("NOTIFY_SOCKET", "")
        self._address = "\0" + address[1:] if address.startswith("@") else address
        self._socket: socket.socket | None = None
        if self._address:
            # Non-blocking: a peer that stops reading must never stall the control loop.
            self._socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC
                                         | socket.SOCK_NONBLOCK)
        self.watchdog_interval_s = _watchdog_interval_s(env)

    def notify(self, *fields: str) -> None:
        """Send ``KEY=value`` fields in one datagram; a missing or full receiver drops it."""
        if self._socket is None:
            return
        try:
            self._socket.sendto("\n".join(fields).encode("utf-8"), self._address)
        except OSError as exc:
            logger.debug("sd_notify %s: %s", fields, exc)

    def ready(self, status: str) -> None:
        """Tell systemd that start-up is complete (READY=1), with a status line."""
        self.notify("READY=1", _status(status))

    def status(self, status: str) -> None:
        """Set the status line systemd shows for the service (STATUS=)."""
        self.notify(_status(status))

    def watchdog(self) -> None:
        """Ping the systemd watchdog (WATCHDOG=1)."""
        self.notify("WATCHDOG=1")

    def stopping(self, status: str) -> None:
        """Tell systemd that shutdown has begun (STOPPING=1), with a status line."""
        self.notify("STOPPING=1", _status(status))

    def close(self) -> None:
        """Close the notification socket; later calls send nothing. Safe to call twice."""
        if self._socket is not None:
            self._socket.close()
            self._socket = None


def _status(text: str) -> str:
    """A STATUS= field: one line (a newline would start another field)."""
    return "STATUS=" + " ".join(text.split())


def _watchdog_interval_s(env: Mapping[str, str]) -> float | None:
    """Half of ``$WATCHDOG_USEC`` in seconds, when the watchdog is meant for this process."""
    usec = env.get("WATCHDOG_USEC", "")
    pid = env.get("WATCHDOG_PID", "")
    if not usec.isdigit() or int(usec) == 0:
        return None
    if pid and (not pid.isdigit() or int(pid) != os.getpid()):
        return None
    return int(usec) / 2e6
