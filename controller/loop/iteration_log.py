"""Per-iteration JSON Lines log: one complete record per line, written as it happens.

Each record goes out in one unbuffered append (then fsync). A write that fails (a full disk)
is cut back to the previous end of the file, and a log found ending in half a record (a kill
during a write) has that half removed when it is opened, so every line is a whole record
across kill -9, a full disk and a restart. The log is never opened through a symlink.
Readers: ``read_log`` is strict (raises on a damaged line); ``scan_log`` skips and counts them.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import os
import stat
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from drivers.core.errors import FineposError
from drivers.core.files import has_room

logger = logging.getLogger(__name__)

_TAIL_BYTES = 1 << 20  # how far back open() looks for the last complete line


class LogWriteError(FineposError):
    """A record could not be written (the file keeps only whole records); ``disk_full`` when
    the cause was a full file system or quota."""

    def __init__(self, message: str, disk_full: bool) -> None:
        super().__init__(message)
        self.disk_full = disk_full


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
    """Append-only JSONL writer; thread-safe; every record is written whole and fsynced.

    Subscribers (callables taking the plain record dict) are told of every record, e.g. the
    service's streaming clients.
    """

    def __init__(self, path: str | Path, fsync: bool = True) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._fd: int | None = os.open(
                self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC,
                0o640)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise LogWriteError(f"iteration log {self.path} is a symlink: refused", False) \
                    from exc
            raise
        if not stat.S_ISREG(os.fstat(self._fd).st_mode):
            os.close(self._fd)
            raise LogWriteError(f"iteration log {self.path} is not a regular file", False)
        self._fsync = fsync
        self._lock = threading.Lock()
        self._subscribers: list[Callable[[dict[str, Any]], None]] = []
        self._repair_tail()

    def _repair_tail(self) -> None:
        """Remove a half-written last record (left by a kill or a crash during a write)."""
        assert self._fd is not None
        size = os.fstat(self._fd).st_size
        if size == 0:
            return
        start = max(0, size - _TAIL_BYTES)
        tail = os.pread(self._fd, size - start, start)
        if tail.endswith(b"\n"):
            return
        end = tail.rfind(b"\n")
        keep = start + end + 1 if end >= 0 else start
        try:
            os.ftruncate(self._fd, keep)
        except OSError as exc:
            logger.warning("iteration log %s: cannot remove its half record: %s", self.path, exc)
            return
        logger.warning("iteration log %s: removed a half-written last record (%d bytes)",
                       self.path, size - keep)

    @property
    def closed(self) -> bool:
        """Whether ``close`` was called."""
        return self._fd is None

    def has_room(self) -> bool:
        """Whether the log's file system has room again (``drivers.core.files.has_room``)."""
        return has_room(self.path.parent)

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
            LogWriteError: the record could not be written (nothing of it stays in the file).
        """
        line = to_json_line(record)
        data = (line + "\n").encode("utf-8")
        with self._lock:
            if self._fd is None:
                raise ValueError(f"iteration log {self.path} is closed")
            self._append(self._fd, data)
            subscribers = list(self._subscribers)
        plain = json.loads(line)
        for callback in subscribers:
            callback(plain)

    def _append(self, fd: int, data: bytes) -> None:
        """Append all of ``data`` or nothing (LogWriteError); call with the lock held."""
        size = os.fstat(fd).st_size
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            if self._fsync:
                os.fsync(fd)
        except OSError as exc:
            try:
                os.ftruncate(fd, size)
            except OSError as cut:
                logger.error("iteration log %s: cannot remove a partial record: %s",
                             self.path, cut)
            full = exc.errno in (errno.ENOSPC, errno.EDQUOT)
            raise LogWriteError(f"{'disk_full: ' if full else ''}cannot write the iteration "
                                f"log {self.path}: {exc.strerror or exc}", full) from exc

    def close(self) -> None:
        """Close the file; safe to call twice. Later writes raise ValueError."""
        with self._lock:
            fd, self._fd = self._fd, None
        if fd is not None:
            try:
                os.close(fd)
            except OSError as exc:
                logger.warning("closing the iteration log %s: %s", self.path, exc)

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


def scan_log(path: str | Path) -> tuple[list[dict[str, Any]], int]:
    """The whole records of a log file and how many damaged lines were skipped (a reader that
    must not fail on a log from an older version or another writer)."""
    records, damaged = [], 0
    with open(path, "rb") as f:
        for line in f:
            try:
                record = json.loads(line.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError):
                damaged += 1
                continue
            if isinstance(record, dict):
                records.append(record)
            else:
                damaged += 1
    if damaged:
        logger.warning("%s: skipped %d damaged line(s)", path, damaged)
    return records, damaged
