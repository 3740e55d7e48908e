"""The guarded grasp on the physical simulated cell: the issue's grasp checks."""

from __future__ import annotations

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
