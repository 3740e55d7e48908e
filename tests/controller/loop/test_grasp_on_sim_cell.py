"""The guarded grasp on the physical simulated cell: the issue's grasp checks."""

from __future__ import annotations

import numpy as np
import pytest

from controller.loop.grasp import GraspConfig, guarded_grasp
from drivers.core.pose import ToolStep
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.devices import SimArm, SimWrenchSensor


@pytest.fixture
def rig():
    with SimCell(SceneConfig(), seed=5) as cell:
        arm, sensor = SimArm(cell), SimWrenchSensor(cell)
        with arm, sensor:
            yield cell, arm, sensor


def _grasp(rig, step: ToolStep):
    cell, arm, sensor = rig
    arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(step))
    weight_n = cell.part.mass_g * 9.81e-3
    return guarded_grasp(arm, sensor, cell.grasp_depth_mm, cell.part.grasp_width_mm,
                         GraspConfig(), part_weight_n=weight_n)


def test_a_centred_grasp_holds(rig):
    cell = rig[0]
    res = _grasp(rig, ToolStep())
    assert res.success and cell.holding, res.reason
    assert res.held_weight_n == pytest.approx(cell.part.mass_g * 9.81e-3, abs=0.03)
    assert abs(cell.grasp_misalignment()["across_mm"]) < 0.3


def test_a_grasp_5mm_across_the_jaws_trips_the_guard_with_no_part_held(rig):
    cell = rig[0]
    res = _grasp(rig, ToolStep(dy_mm=5.0))
    assert not res.success and res.retreated and "early contact" in res.reason
    assert not cell.holding
    assert cell.object_pose()[2] == pytest.approx(0.0, abs=0.5), "the cube was not knocked"


def test_a_15deg_grasp_does_not_end_with_the_part_seated(rig):
    cell = rig[0]
    res = _grasp(rig, ToolStep(dphi_deg=15.0))
    seated = cell.holding and abs(cell.grasp_misalignment()["phi_deg"]) < 3.0
    assert not res.success and not seated, res.reason


# -- the peak force of a contact, on both paths -----------------------------------------------
OFFSETS = {"5 mm across": ToolStep(dy_mm=5.0), "9 mm across": ToolStep(dy_mm=9.0),
           "-7 mm across": ToolStep(dy_mm=-7.0), "8 mm across": ToolStep(dy_mm=8.0),
           "20 deg": ToolStep(dphi_deg=20.0)}
CASES = [pytest.param(programs, step, id=f"{path}, {name}") for name, step in OFFSETS.items()
         for programs, path in ((True, "program path"), (False, "host path"))]


@pytest.mark.parametrize("programs,step", CASES)
def test_a_finger_driven_onto_the_part_stops_under_the_force_limit(programs, step):
    from drivers.core.timing import TimingConfig
    from sim_backend.cell.scene_config import SimArmConfig
    from sim_backend.cell.timing import cell_timing

    timing = cell_timing("realistic", TimingConfig())
    with SimCell(SceneConfig(), SimArmConfig(programs=programs), seed=5) as cell:
        arm, sensor = SimArm(cell, timing=timing), SimWrenchSensor(cell, timing)
        with arm, sensor:
            assert arm.runs_programs is programs
            _drive_onto_the_part(cell, arm, sensor, step)


def _drive_onto_the_part(cell, arm, sensor, step):
    config = GraspConfig()
    limit_n = max(g.limit for g in config.guards)  # "excessive force"
    peak = []
    move_arm = cell.move_arm

    def watched(target):
        try:
            return move_arm(target)
        finally:
            peak.append(float(np.linalg.norm(cell.wrench(noisy=False)[:3] - rest)))

    arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(step))
    rest = cell.wrench(noisy=False)[:3]  # the gripper's weight
    cell.move_arm = watched
    res = guarded_grasp(arm, sensor, cell.grasp_depth_mm, cell.part.grasp_width_mm, config,
                        part_weight_n=cell.part.mass_g * 9.81e-3)
    del cell.move_arm
    assert not res.success and res.retreated, res.reason
    assert 3.0 < max(peak) < limit_n


def test_on_the_program_path_a_centred_grasp_holds_after_one_run():
    from drivers.core.timing import TimingConfig
    from sim_backend.cell.scene_config import SimArmConfig
    from sim_backend.cell.timing import cell_timing

    timing = cell_timing("realistic", TimingConfig())
    with SimCell(SceneConfig(), SimArmConfig(programs=True), seed=5) as cell:
        arm, sensor = SimArm(cell, timing=timing), SimWrenchSensor(cell, timing)
        with arm, sensor:
            arm.move_to(cell.nominal_grasp_pose())
            closes = []
            arm._set_gripper = lambda closed: closes.append(closed)
            weight_n = cell.part.mass_g * 9.81e-3
            res = guarded_grasp(arm, sensor, cell.grasp_depth_mm, cell.part.grasp_width_mm,
                                GraspConfig(), part_weight_n=weight_n)
            assert res.success and cell.holding, res.reason
            assert closes == []  # closed by the program, not by a host command
            assert res.held_weight_n == pytest.approx(weight_n, abs=0.03)
            assert timing.spent["hand"] == pytest.approx(TimingConfig().arm.hand_time_s)
