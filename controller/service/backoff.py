"""Exponential backoff between reconnection attempts (pure; the caller keeps the clock)."""

from __future__ import annotations


class Backoff:
    """Delays ``initial_s, 2*initial_s, 4*initial_s, ...`` capped at ``max_s``."""

    def __init__(self, initial_s: float, max_s: float) -> None:
        if not 0 < initial_s <= max_s:
            raise ValueError(f"need 0 < initial_s <= max_s, got {initial_s} / {max_s}")
        self.initial_s = initial_s
        self.max_s = max_s
        self.attempts = 0

    def next_delay_s(self) -> float:
        """The wait before the next attempt; counts the attempt."""
        delay = min(self.max_s, self.initial_s * 2.0 ** min(self.attempts, 60))
        self.attempts += 1
        return delay
