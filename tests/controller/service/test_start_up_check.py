"""``service.self_check_at_start``: the service looks at the taught pose when it starts and
refuses motion (fault ``self_check``) when the camera no longer sees what it was taught."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from calibration_free.training import TrainingSettings, train_bundle
from controller.service.client import ServiceError
from drivers.core.cell_state import CellState
from tests.mocks.fakes import FakeArm, FakeCamera, FakeWrenchSensor
from tests.synthetic_scene import KAPPA, cell, grids  # noqa: F401  (fixtures)

from .conftest import client_for, cube_view, device_opener, running_service, service_config
from .test_faults import NOMINAL


@pytest.fixture(scope="module")
def taught(grids, tmp_path_factory):  # noqa: F811  (the fixture imported above)
    """A state folder: the synthetic cube taught at NOMINAL and a fully trained model."""
    folder = tmp_path_factory.mktemp("taught")
    nn1, nn2 = grids
    train_bundle(nn1, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL.as_dict(),
                 nn1_extra=nn2, settings=TrainingSettings(seed=0)).save(folder / "model-gabor.fpm")
    CellState(NOMINAL, "cube", KAPPA, 5.0, 30.0, "test", 0.0).save(folder / "cell.json")
    return folder


@pytest.mark.parametrize("knock_mm, state", [(0.0, "idle"), (4.0, "fault")])
def test_start_up_check(tmp_path, short_dir, taught, knock_mm, state):
    config = service_config(tmp_path, short_dir, service={"self_check_at_start": True})
    shutil.copytree(taught, config.controller.paths.state_dir)
    arm = FakeArm()
    camera = FakeCamera(cube_view(arm, knock_mm))  # a knocked camera: the part looks shifted
    with running_service(config, device_opener(arm, camera, FakeWrenchSensor())) \
            as service, client_for(service) as client:
        status = client.call("status")
        assert status["state"] == state, status
        assert arm._pose.tool_step_to(NOMINAL).translation_mm < 1e-6  # it looked from there
        if state == "fault":
            assert status["fault"]["code"] == "self_check"
            assert "new teach-in" in status["fault"]["reason"]
            with pytest.raises(ServiceError, match="motion is refused until a reset"):
                client.call("position", wait=True)


def test_a_damaged_acquired_set_is_a_start_up_fault_naming_it(tmp_path, short_dir, taught):
    config = service_config(tmp_path, short_dir, service={"self_check_at_start": True})
    state = Path(shutil.copytree(taught, config.controller.paths.state_dir))
    (state / "datasets").mkdir()
    (state / "datasets" / "nn1.npz").write_bytes(b"garbage" * 500)
    arm = FakeArm()
    with running_service(config, device_opener(arm, FakeCamera(cube_view(arm)),
                                               FakeWrenchSensor())) \
            as service, client_for(service) as client:
        status = client.call("status")
        assert status["state"] == "fault" and status["fault"]["code"] == "self_check", status
        assert str(state / "datasets" / "nn1.npz") in status["fault"]["reason"]
