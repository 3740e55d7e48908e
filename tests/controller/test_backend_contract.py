"""One contract test over every device backend: each entry of the backend registries
(``controller.devices.REGISTRIES``), built through the registry as a config names it, and the
test fakes. The real drivers meet their emulators, which serve one simulated cell."""

from __future__ import annotations

import contextlib

import pytest

from controller.config import load_config
from controller.devices import REGISTRIES, DeviceContext, with_device
from drivers.contract import check_arm, check_camera, check_wrench
from drivers.safety import SafetyLimits
from sim_backend.cell.scene_config import SimArmConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.emulators.cell import CellEmulators
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor

CHECKS = {"arm": check_arm, "camera": check_camera, "wrench": check_wrench}
FAKES = {"arm": lambda: FakeArm(SafetyLimits(max_step_mm=20.0, max_step_deg=30.0)),
         "camera": FakeCamera, "wrench": FakeWrenchSensor}
BACKENDS = [(kind, backend) for kind, registry in REGISTRIES.items() for backend in registry]


@pytest.fixture(scope="module")
def emulators():
    """The simulated cell served over the VAL, ATI and MJPEG emulators."""
    config = load_config(None)
    with SimCell(config.scene, SimArmConfig(), seed=0) as cell, \
            CellEmulators(cell, ati=True, mjpeg_port=0) as served:
        yield served


@pytest.mark.parametrize("kind, backend", BACKENDS, ids=[f"{k}-{b}" for k, b in BACKENDS])
def test_every_registered_backend_meets_the_contract(kind, backend, emulators):
    config = load_config(None)
    if backend != "sim":  # a real driver: pointed at its emulator, as the HIL config does
        options = dict(emulators.device_sections()[kind])
        config = with_device(config, kind, options.pop("type"), **options)
    assert getattr(config, kind).type == backend
    ctx = DeviceContext(config)
    with contextlib.closing(ctx):
        section = getattr(config, kind)
        CHECKS[kind](lambda: REGISTRIES[kind][backend].build(section.options, ctx))


@pytest.mark.parametrize("kind", sorted(FAKES))
def test_the_test_fakes_meet_the_contract(kind):
    CHECKS[kind](FAKES[kind])
