"""Per-iteration JSON Lines log: one complete record per line, flushed as it is written.

Readers (the service's record stream, evaluation, plots) see only whole lines; a crash loses
at most the record being written, never one already written.
"""

from __future__ import annotations

import json
import math
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if hasattr(value, "as_dict"):
        return _plain(value.as_dict())
    return value


def to_json_line(record: dict[str, Any]) -> str:
    """One record as a single JSON line (numpy values converted, NaN/inf become null)."""
    return json.dumps(_plain(record), separators=(",", ":"), allow_nan=False)


class IterationLog:
    """Append-only JSONL writer; thread-safe; every record is flushed and fsynced.

    Subscribers (callables taking the plain record dict) are told of every record, e.g. the
    service's streaming clients.
    """

    def __init__(self, path: str | Path, fsync: bool = True) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._fsync = fsync
        self._lock = threading.Lock()
        self._subscribers: list[Callable[[dict[str, Any]], None]] = []

    def subscribe(self, callback: Callable[[dict[str, Any]], None]) -> Callable[[], None]:
        """Register a callback for every new record; returns a function that unsubscribes."""
        with self._lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    def write(self, record: dict[str, Any]) -> None:
        """Append ``record`` as one line (flushed, fsynced unless disabled), then tell subscribers.

        Subscribers get the record as read back from JSON, in the writing thread.

        Raises:
            ValueError: the log is closed.
        """
        line = to_json_line(record)
        with self._lock:
            if self._file.closed:
                raise ValueError(f"iteration log {self.path} is closed")
            self._file.write(line + "\n")
            self._file.flush()
            if self._fsync:
                os.fsync(self._file.fileno())
            subscribers = list(self._subscribers)
        plain = json.loads(line)
        for callback in subscribers:
            callback(plain)

    def close(self) -> None:
        """Close the file; safe to call twice. Later writes raise ValueError."""
        with self._lock:
            if not self._file.closed:
                self._file.close()

    def __enter__(self) -> IterationLog:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def read_log(path: str | Path) -> list[dict[str, Any]]:
    """All records of a log file (raises ValueError naming the first bad line)."""
    records = []
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, 1):
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError as exc:
                raise ValueError(f"{path}:{number}: not a JSON record: {exc}") from exc
    return records
