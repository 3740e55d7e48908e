"""Atomic writes and bounded reads: stale temporary files are removed (but never one being
written), and a FIFO or a symlink to /dev/zero is refused at once instead of hanging or filling
the memory."""

from __future__ import annotations

import fcntl
import os
import threading
from pathlib import Path

import pytest

from drivers.core.files import (
    FileReadError,
    atomic_write_bytes,
    read_regular_file,
    remove_stale_temp_files,
)


def test_stale_temp_files_are_removed_but_not_one_being_written(tmp_path):
    atomic_write_bytes(tmp_path / "model.fpm", b"whole")
    stale = tmp_path / ".model.fpm.abc123.tmp"
    stale.write_bytes(b"x" * 4096)  # what a kill during a write leaves
    busy = tmp_path / ".data.npz.def456.tmp"
    busy.write_bytes(b"y")
    fd = os.open(busy, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # as atomic_write_bytes holds it while writing
    try:
        assert remove_stale_temp_files(tmp_path) == 1
    finally:
        os.close(fd)
    assert not stale.exists() and busy.exists()
    assert (tmp_path / "model.fpm").read_bytes() == b"whole"


def test_a_failed_write_leaves_the_old_file_and_no_temp_file(tmp_path, monkeypatch):
    target = tmp_path / "cell.json"
    atomic_write_bytes(target, b"old")

    def failing_replace(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError) as failed:
        atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"old" and not list(tmp_path.glob(".*.tmp"))
    # the error names the file asked for, not the temporary one
    assert failed.value.errno == 28 and failed.value.filename == str(target)


def test_a_folder_that_cannot_hold_the_file_is_named(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        if os.access(folder, os.W_OK):  # root writes anywhere: a missing /proc entry instead
            target = Path("/proc/finepos-report.json")
        else:
            target = folder / "report.json"
        with pytest.raises(OSError) as failed:
            atomic_write_bytes(target, b"x")
        assert failed.value.filename == str(target) and failed.value.strerror
    finally:
        folder.chmod(0o700)


def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "model.fpm"
    os.mkfifo(fifo)
    done = []
    thread = threading.Thread(target=lambda: done.append(_error(fifo)), daemon=True)
    thread.start()
    thread.join(10.0)
    assert done and "FIFO" in done[0]


def test_a_symlink_to_dev_zero_is_refused(tmp_path):
    link = tmp_path / "model.fpm"
    link.symlink_to("/dev/zero")
    assert "character device" in _error(link)


def test_a_file_over_the_limit_is_refused(tmp_path):
    big = tmp_path / "big"
    big.write_bytes(b"0" * 101)
    assert "larger than 100 bytes" in _error(big, 100)
    assert read_regular_file(big, 101) == b"0" * 101


def _error(path, limit: int = 1 << 20) -> str:
    with pytest.raises(FileReadError) as refused:
        read_regular_file(path, limit)
    return str(refused.value)
