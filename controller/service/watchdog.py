"""When the control loop pings systemd's watchdog: every half WatchdogSec, unless an arm command
has been running longer than ``service.stall_timeout_s`` (then the pings stop, so systemd
restarts the service; STATUS= says why)."""

from __future__ import annotations

import logging

from controller.service.sd_notify import Notifier

logger = logging.getLogger(__name__)


class WatchdogPinger:
    """Call ``tick`` from every round of the control loop."""

    def __init__(self, notifier: Notifier) -> None:
        self._notifier = notifier
        self.interval_s = notifier.watchdog_interval_s
        self._next_ping_s = 0.0
        self._stalled = False

    def tick(self, now_s: float, busy_s: float, stall_timeout_s: float) -> None:
        """``busy_s``: how long the arm command now running has been running (0: none)."""
        if busy_s > stall_timeout_s:
            if not self._stalled:
                message = f"an arm command has been running for {busy_s:.1f} s; watchdog withheld"
                logger.error("%s (systemd restarts the service)", message)
                self._notifier.status(message)
            self._stalled = True
            return
        self._stalled = False
        if self.interval_s is not None and now_s >= self._next_ping_s:
            self._notifier.watchdog()
            self._next_ping_s = now_s + self.interval_s
