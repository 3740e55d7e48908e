"""Atomic file writes (a reader sees the old file or the new one, never half of one), the
cleanup of temporary files an interrupted write left behind, and bounded reads that refuse
what is not a regular file (a FIFO would block, ``/dev/zero`` never ends)."""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import secrets
import stat
from pathlib import Path

logger = logging.getLogger(__name__)


class FileReadError(OSError):
    """A file that cannot be read as asked: not a regular file, or larger than allowed."""


def read_regular_file(path: str | Path, max_bytes: int) -> bytes:
    """All bytes of the regular file ``path`` (a symlink to one is followed), without ever
    blocking or reading more than ``max_bytes``.

    Raises:
        FileReadError: ``path`` is a FIFO, device, socket or directory, or over ``max_bytes``.
        OSError: it cannot be opened or read.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    with os.fdopen(fd, "rb") as f:
        mode = os.fstat(f.fileno()).st_mode
        if not stat.S_ISREG(mode):
            raise FileReadError(f"not a regular file ({_kind(mode)})")
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise FileReadError(f"larger than {max_bytes} bytes")
    return data


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISDIR, "a directory")):
        if test(mode):
            return name
    return "not a plain file"


# has_room(): a folder counts as writable again with at least this much free space.
MIN_FREE_BYTES = 64 * 1024


def has_room(folder: str | Path, min_bytes: int = MIN_FREE_BYTES) -> bool:
    """Whether the file system of ``folder`` has ``min_bytes`` free for this user (False when
    it cannot be asked)."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize >= min_bytes


def remove_stale_temp_files(folder: str | Path) -> int:
    """Remove the ``.*.tmp`` files interrupted atomic writes left in ``folder``; returns how many.

    A write in progress (in this or another process) holds a lock on its temporary file, so
    only files nobody is writing are removed.
    """
    removed = 0
    try:
        candidates = list(Path(folder).glob(".*.tmp"))
    except OSError:
        return 0
    for tmp in candidates:
        try:
            fd = os.open(tmp, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError:
            continue
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue  # being written right now
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
                removed += 1
        finally:
            os.close(fd)
    if removed:
        logger.info("removed %d stale temporary file(s) in %s", removed, folder)
    return removed


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same folder, fsync, rename.

    The temporary file (``.<name>.<random>.tmp``) is locked while written and removed when the
    write fails; one left by a killed process is removed by ``remove_stale_temp_files``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # The temporary file's name is chosen before anything is created, so an exception at any
    # point (a SIGTERM/SIGINT handler that raises runs between any two bytecodes, whichever
    # thread the signal was delivered to) finds it for the cleanup below.
    tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0),
                     0o600)
        fcntl.flock(fd, fcntl.LOCK_EX)  # tells remove_stale_temp_files it is being written
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno is not None:
            # the destination is what the caller named, not the temporary file beside it
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    try:
        dir_fd = os.open(path.parent, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dir_fd)
    except OSError:
        pass
    finally:
        os.close(dir_fd)


def atomic_write_text(path: str | Path, text: str) -> None:
    """``atomic_write_bytes`` of ``text`` encoded as UTF-8."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path | None, data: dict) -> None:
    """Print ``data`` as JSON (a report on stdout) and, when a path is given, write it there
    atomically."""
    text = json.dumps(data, indent=2)
    print(text)
    if path:
        atomic_write_text(path, text + "\n")
