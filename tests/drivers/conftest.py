"""Fixtures shared by the VAL driver's tests: a fake arm behind the VAL emulator."""

from __future__ import annotations

import pytest

from sim_backend.emulators.val.server import ValEmulator
from tests.mocks.fakes import FakeArm


@pytest.fixture
def backing():
    """The fake arm the VAL emulator moves."""
    with FakeArm() as arm:
        yield arm


@pytest.fixture
def emulator(backing):
    """The VAL emulator over ``backing``, on a real pty."""
    with ValEmulator(backing) as emu:
        yield emu
