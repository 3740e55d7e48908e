"""The guarded grasp through the real VAL and ATI drivers on the emulated cell, on both paths:
a finger driven onto the part stops under the force limit; on the program path the emulated
sensor's monitor output stops the emulated controller's program without the host."""

from __future__ import annotations

import numpy as np
import pytest

from controller.loop.grasp import GraspConfig, guarded_grasp
from drivers.ati import AtiWrenchSensor
from drivers.ati.config import AtiConfig
from drivers.core.pose import ToolStep
from drivers.core.timing import TimingConfig
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.cell import CellEmulators

# A finger over the part's edge (tests/controller/loop/test_grasp_on_sim_cell.py drives
# fingers onto its top and rim at several offsets in process).
STEP = ToolStep(dy_mm=8.0)


@pytest.mark.slow
@pytest.mark.parametrize("programs", [False, True], ids=["host path", "program path"])
def test_a_finger_driven_onto_the_emulated_part_stops_under_the_force_limit(programs):
    from sim_backend.cell.scene_config import SceneConfig
    from sim_backend.cell.sim_cell import SimCell

    config = GraspConfig()
    limit_n = max(g.limit for g in config.guards)
    with SimCell(SceneConfig(), seed=5) as sim, \
            CellEmulators(sim, ati=True, timing=TimingConfig()) as emulators:
        cell = emulators.cell
        peak = []
        move_arm = sim.move_arm

        def watched(target):
            try:
                return move_arm(target)
            finally:
                peak.append(float(np.linalg.norm(sim.wrench(noisy=False)[:3] - rest)))

        arm = ValArm(ValConfig(port=emulators.val_url, programs=programs))
        sensor = AtiWrenchSensor(AtiConfig(port=emulators.ati_url, baud=38400))
        with arm, sensor:
            arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(STEP))
            rest = sim.wrench(noisy=False)[:3]
            sim.move_arm = watched
            lines: list[str] = []
            emulators.val.add_listener(lambda event, text: lines.append(text)
                                       if event == "command" else None)
            res = guarded_grasp(arm, sensor, cell.grasp_depth_mm, cell.part.grasp_width_mm,
                                config, part_weight_n=cell.part.mass_g * 9.81e-3)
            del sim.move_arm
    assert not res.success and res.retreated, res.reason
    assert 3.0 < max(peak) < limit_n
    assert any(line.startswith("ex ") for line in lines) is programs
