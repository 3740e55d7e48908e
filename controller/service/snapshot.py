"""The ``status`` answer as a snapshot: encoded once, served to every poller until it changes.

Connection threads asking ``status`` as fast as they can must not cost the control loop: the
answer is rebuilt (under the state lock, walking the last iteration record) only when one of
its inputs is a different object than at the last build, or after ``max_age_s`` (for the
figures that drift: uptime, the devices' state while in fault). Otherwise a request takes one
comparison and the pre-encoded bytes.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from controller.loop.iteration_log import to_json_line
from controller.service.protocol import EncodedResult


class StatusSnapshot:
    """Caches ``build()``'s result, encoded, while ``key()`` returns the same objects."""

    def __init__(self, build: Callable[[], dict[str, Any]], key: Callable[[], tuple],
                 max_age_s: float = 0.1) -> None:
        self._build = build
        self._key = key
        self.max_age_s = max_age_s
        self._lock = threading.Lock()
        self._cached: tuple[tuple, float, EncodedResult] | None = None
        self.builds = 0

    def get(self) -> EncodedResult:
        """The current answer, rebuilt only when an input changed or it is too old."""
        key, now_s = self._key(), time.monotonic()
        cached = self._cached
        if cached is not None and now_s - cached[1] < self.max_age_s and _same(cached[0], key):
            return cached[2]
        with self._lock:  # one builder at a time; the others take its result
            cached = self._cached
            if cached is not None and now_s - cached[1] < self.max_age_s and \
                    _same(cached[0], key):
                return cached[2]
            key = self._key()
            encoded = EncodedResult(to_json_line(self._build()).encode())
            self._cached = (key, time.monotonic(), encoded)
            self.builds += 1
            return encoded


def _same(old: tuple, new: tuple) -> bool:
    """Element by element: the very same object (mutable inputs), or equal (plain values)."""
    return len(old) == len(new) and all(
        a is b or (type(a) in _PLAIN and type(b) is type(a) and a == b)
        for a, b in zip(old, new, strict=True))


_PLAIN = (int, float, str, bool, tuple)  # tuples of plain values, e.g. the state snapshot
