"""Runs the real spacenavd daemon on a serial line (the Magellan emulator's pty).

Debian's spacenavd 1.1 in the foreground (``-d``) binds the *relative* paths
``run/spnav.sock`` and ``run/spnavd.pid`` (no option sets them), so it runs with its working
directory set to a folder of its own holding ``run/``, its config (only
``serial = /dev/pts/N``) and its log. No root, X11 or uinput is needed.

Stop the daemon before closing the pty: on a hung-up line it spins at 100 % CPU. Nesting does
that: ``with MagellanEmulator() as mouse, Spacenavd(mouse.url, folder) as daemon: ...``.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path
from typing import Self

from drivers.core.errors import DeviceNotConnectedError, DeviceTimeoutError
from drivers.core.lifecycle import Lifecycle

logger = logging.getLogger(__name__)

_SEARCH_PATH = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"])
# The stdlib has no "socket file appeared" event (that would need inotify), so readiness is
# polled this often, bounded by start_timeout_s.
_POLL_S = 0.02
_STOP_TIMEOUT_S = 5.0


def find_spacenavd() -> str | None:
    """Path of the spacenavd executable, or None when it is not installed."""
    return shutil.which("spacenavd", path=_SEARCH_PATH)


class Spacenavd(Lifecycle):
    """One spacenavd process reading ``serial_path``; use as a context manager."""

    def __init__(self, serial_path: str, folder: str | Path, executable: str | None = None,
                 start_timeout_s: float = 10.0) -> None:
        self.serial_path = serial_path
        self.folder = Path(folder)
        self.executable = executable or find_spacenavd()
        self.start_timeout_s = start_timeout_s
        self.socket_path = str(self.folder / "run" / "spnav.sock")
        self.config_path = self.folder / "spnavrc"
        self.log_path = self.folder / "spacenavd.log"
        self._process: subprocess.Popen | None = None

    def start(self) -> Self:
        """Start the daemon and wait until its socket accepts clients."""
        if self.executable is None:
            raise DeviceNotConnectedError("spacenavd is not installed (Debian: apt-get install "
                                          "spacenavd)")
        (self.folder / "run").mkdir(parents=True, exist_ok=True)
        self.config_path.write_text(f"serial = {self.serial_path}\n", encoding="ascii")
        self._process = subprocess.Popen(
            [self.executable, "-d", "-v", "-c", str(self.config_path), "-l", str(self.log_path)],
            cwd=self.folder, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL)
        try:
            self._wait_for_socket()
        except BaseException:
            self.close()
            raise
        logger.info("spacenavd (pid %d) serving %s on %s", self._process.pid,
                    self.serial_path, self.socket_path)
        return self

    def close(self) -> None:
        """Terminate the daemon and reap it (idempotent)."""
        if self._process is None:
            return
        process, self._process = self._process, None
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(_STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                logger.warning("spacenavd ignored SIGTERM; killing it")
                process.kill()
                process.wait()

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except FileNotFoundError:
            return "(no log)"

    def _wait_for_socket(self) -> None:
        assert self._process is not None
        deadline_s = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline_s:
            if self._process.poll() is not None:
                raise DeviceNotConnectedError(
                    f"spacenavd exited with status {self._process.returncode}:\n"
                    f"{self.log_tail()}")
            with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
                try:
                    probe.connect(self.socket_path)
                    return
                except (FileNotFoundError, ConnectionRefusedError):
                    pass
            time.sleep(_POLL_S)
        raise DeviceTimeoutError(f"spacenavd socket {self.socket_path} did not appear within "
                                 f"{self.start_timeout_s} s:\n{self.log_tail()}")
