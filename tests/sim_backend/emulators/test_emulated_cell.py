"""One simulated cell behind the VAL, ATI and MJPEG emulators, read through the real drivers."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from drivers.ati import AtiWrenchSensor
from drivers.ati.config import AtiConfig
from drivers.camera import OpenCvCamera, OpenCvCameraConfig
from drivers.core.pose import ToolStep
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.cell import DEFAULT_FPS, STREAM_MARGIN_S, CellEmulators, SerialisedCell


class Recorder:
    """Stands in for a SimCell: records whether its lock was held during each call."""

    kappa = 4

    def __init__(self) -> None:
        self.lock: threading.RLock | None = None
        self.held: list[bool] = []

    def render(self, noisy: bool = True) -> str:
        assert self.lock is not None
        self.held.append(self.lock._is_owned())
        return f"frame noisy={noisy}"

    def fail(self) -> None:
        raise ValueError("broken")


def test_serialised_cell_holds_its_lock_during_every_call():
    recorder = Recorder()
    cell = SerialisedCell(recorder)
    recorder.lock = cell.lock
    assert cell.render(noisy=False) == "frame noisy=False"
    assert cell.kappa == 4
    assert recorder.held == [True]
    assert not cell.lock._is_owned()
    with pytest.raises(ValueError, match="broken"):
        cell.fail()
    assert not cell.lock._is_owned()


@pytest.mark.slow
def test_real_drivers_see_one_cell():
    from sim_backend.cell.scene_config import SceneConfig
    from sim_backend.cell.sim_cell import SimCell

    with SimCell(SceneConfig(), seed=0) as sim, \
            CellEmulators(sim, ati=True, mjpeg_port=0) as emulators:
        cell = emulators.cell
        sections = emulators.device_sections()
        assert sections["arm"]["port"] == emulators.val_url
        assert "gripper_closed_width_mm" not in sections["arm"]  # the driver's own, as on VAL
        # a frame asked for after a move: one rendered once the move had ended
        assert sections["camera"]["settle_s"] >= 1.0 / DEFAULT_FPS + STREAM_MARGIN_S - 1e-3
        with ValArm(ValConfig(port=emulators.val_url), SafetyLimits()) as arm, \
                AtiWrenchSensor(AtiConfig(port=emulators.ati_url)) as sensor, \
                OpenCvCamera(OpenCvCameraConfig(source=emulators.stream_url,
                                                settle_s=sections["camera"]["settle_s"])) as camera:
            arm.move_tool(ToolStep(6.0, -4.0, 0.0, 10.0))
            target = cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(6.0, -4.0, 0.0, 10.0))
            reached = cell.arm_pose()
            assert np.allclose(reached.position_mm, target.position_mm, atol=0.02)
            frame = camera.grab()  # waits the stream's settle_s: rendered after the move
            difference = np.abs(frame.image.astype(float) - cell.render(noisy=False)).mean()
            assert difference < 4.0  # JPEG and pixel noise only
            expected_fz_n = cell.wrench(noisy=False)[2]  # the gripper's weight, unbiased
            assert sensor.read().fz_n == pytest.approx(expected_fz_n, abs=0.1)
    emulators.close()  # idempotent
