"""Frame-drop detection from arrival times alone (a stream does not number its frames).

The nominal frame interval is the median of the recent intervals; an interval longer than
``gap_factor`` times it means frames went missing, ``round(interval / median) - 1`` of them.
"""

from __future__ import annotations

import statistics
from collections import deque

_WINDOW = 31  # recent intervals the median is taken over
_MIN_INTERVALS = 5  # no verdict before this many intervals were seen


class DropCounter:
    """Feed it each frame's arrival time; it counts the frames that should have come between."""

    def __init__(self, gap_factor: float = 2.5) -> None:
        self.gap_factor = gap_factor
        self.dropped = 0
        self._intervals_s: deque[float] = deque(maxlen=_WINDOW)
        self._last_s: float | None = None

    def observe(self, arrival_s: float) -> int:
        """Record one arrival (monotonic seconds); returns how many frames it found missing."""
        missing = 0
        if self._last_s is not None:
            interval_s = arrival_s - self._last_s
            if len(self._intervals_s) >= _MIN_INTERVALS:
                nominal_s = statistics.median(self._intervals_s)
                if nominal_s > 0 and interval_s > self.gap_factor * nominal_s:
                    missing = max(1, round(interval_s / nominal_s) - 1)
            self._intervals_s.append(interval_s)
        self._last_s = arrival_s
        self.dropped += missing
        return missing
