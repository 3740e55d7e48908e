"""Fixtures of the teach-in tests: the real spacenavd on the Magellan emulator's pty."""

from __future__ import annotations

import os

import pytest

from sim_backend.emulators.magellan.emulator import MagellanEmulator
from sim_backend.emulators.magellan.spacenavd import Spacenavd, find_spacenavd

READY_TIMEOUT_S = 10.0


@pytest.fixture
def spacenavd_installed() -> None:
    """Skip (with the reason) where spacenavd is absent; fail instead under
    FINEPOS_REQUIRE_SPACENAVD=1 (CI sets it, so CI never skips)."""
    if find_spacenavd() is None:
        message = "spacenavd is not installed (Debian: apt-get install -y spacenavd)"
        if os.environ.get("FINEPOS_REQUIRE_SPACENAVD") == "1":
            pytest.fail(message + " but FINEPOS_REQUIRE_SPACENAVD=1")
        pytest.skip(message)


@pytest.fixture
def mouse_and_daemon(spacenavd_installed, tmp_path):
    """A live Magellan emulator and the real daemon reading it (stopped before the pty)."""
    with MagellanEmulator() as mouse, Spacenavd(mouse.url, tmp_path / "spacenavd") as daemon:
        assert mouse.wait_ready(READY_TIMEOUT_S), daemon.log_tail()
        yield mouse, daemon
