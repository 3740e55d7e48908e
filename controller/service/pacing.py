"""Per-connection pacing: a token bucket that spaces one client's responses.

A client may send requests as fast as it likes; its answers come at most ``rate_hz`` per second
after a burst of ``burst`` (``service.request_rate_hz`` / ``service.request_burst``). The
connection's thread sleeps (releasing the GIL) until the next token, so a client polling too
fast slows only itself, never the control loop or the other clients. ``abort`` is never paced.
"""

from __future__ import annotations

import time


class RequestPacer:
    """Token bucket: ``burst`` tokens, refilled at ``rate_hz`` per second (0: no pacing)."""

    def __init__(self, rate_hz: float, burst: int) -> None:
        self.rate_hz = rate_hz
        self.burst = burst
        self._tokens = float(burst)
        self._at_s = time.monotonic()

    def delay_s(self, now_s: float | None = None) -> float:
        """Take one token; how long to wait before answering (0 when one was available)."""
        if self.rate_hz <= 0:
            return 0.0
        now_s = time.monotonic() if now_s is None else now_s
        self._tokens = min(float(self.burst),
                           self._tokens + (now_s - self._at_s) * self.rate_hz)
        self._at_s = now_s
        self._tokens -= 1.0
        return 0.0 if self._tokens >= 0 else -self._tokens / self.rate_hz
