"""The state folder's lock: one writer at a time (a service, or a CLI teach, acquire, train,
rezero, position or grasp).

The writer holds an exclusive ``flock`` on ``<state folder>/.lock`` and writes its PID and what
it is there; another writer fails at once with ``StateFolderLocked`` naming that PID. The kernel
drops the lock when the holder's descriptor is closed, however the process ends (SIGKILL
included), so a ``.lock`` file left behind locks nothing. Readers (``finepos status``,
``check``) take no lock.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import logging
import os
import stat
from collections.abc import Iterator
from pathlib import Path

from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

LOCK_NAME = ".lock"
_HOLDER_MAX_BYTES = 256  # what is read back of the holder's line


class StateLockError(FineposError):
    """The state folder's lock file cannot be used (a symlink, a FIFO, a directory...)."""


class StateFolderLocked(StateLockError):
    """Another process holds the state folder's lock.

    Attributes:
        pid: the holder's PID (None when it has not written it yet).
    """

    def __init__(self, message: str, pid: int | None):
        super().__init__(message)
        self.pid = pid


@contextlib.contextmanager
def locked_state_folder(root: str | Path, holder: str, *, create: bool = True) \
        -> Iterator[Path | None]:
    """Hold the lock of state folder ``root`` for the block.

    Args:
        root: the state folder (``controller.paths.state_dir`` or ``--state-dir``).
        holder: what holds it, for the error another writer gets (``finepos teach``).
        create: create ``root`` when missing; otherwise a missing folder is not locked (a
            command that needs its teach-in there then says that nothing is taught, and a
            mistyped path leaves no folder behind).

    Yields:
        The lock file's path (None: no folder, no lock).

    Raises:
        StateFolderLocked: another process holds it (the message names its PID).
        StateLockError: the lock file is a symlink or not a regular file.
    """
    root = Path(root)
    if not create and not root.is_dir():
        yield None
        return
    root.mkdir(parents=True, exist_ok=True)
    path = root / LOCK_NAME
    try:  # never through a planted link, never blocking on a FIFO
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC,
                     0o644)
    except OSError as exc:
        kinds = {errno.ELOOP: "a symlink", errno.EISDIR: "a directory"}
        if exc.errno in kinds:
            raise StateLockError(f"{path}: the state folder's lock file is "
                                 f"{kinds[exc.errno]}; remove it") from exc
        raise
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise StateLockError(f"{path}: the state folder's lock file is not a regular file; "
                                 "remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _locked(root, fd) from None
        _write_holder(fd, path, holder)
        yield path
    finally:
        os.close(fd)  # releases the lock


def _locked(root: Path, fd: int) -> StateFolderLocked:
    """The error for a lock held by another process, read from its line in the lock file."""
    try:
        line = os.pread(fd, _HOLDER_MAX_BYTES, 0).decode("utf-8", "replace")
    except OSError:
        line = ""
    pid_text, _, what = line.strip().partition(" ")
    pid = int(pid_text) if pid_text.isdigit() and len(pid_text) < 10 else None
    what = " ".join(what.split())[:120]
    who = f"PID {pid}" + (f" ({what})" if what else "") if pid is not None \
        else "another process (its PID not written yet)"
    return StateFolderLocked(f"{root}: the state folder is in use by {who}; stop it first or "
                             "use another state folder", pid)


def _write_holder(fd: int, path: Path, holder: str) -> None:
    """Write ``<pid> <holder>`` into the held lock file; on a full disk the lock holds without
    it (another writer's error then names no PID)."""
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()} {holder}\n".encode(), 0)
    except OSError as exc:
        logger.warning("%s: cannot write the holder's PID: %s", path, exc.strerror or exc)
