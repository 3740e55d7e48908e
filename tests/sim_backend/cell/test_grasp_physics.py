"""The physical grasp: the part as a dynamic body, jaws under position and force control."""

from __future__ import annotations

import dataclasses

import pytest

from drivers.core.parts import PARTS as CATALOGUE
from drivers.core.pose import ToolStep
from sim_backend.cell.objects import MATERIAL_FRICTION, PARTS
from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.scene_config import SceneConfig, SimArmConfig
from sim_backend.cell.sim_cell import SimCell


@pytest.fixture
def cell():
    with SimCell(SceneConfig(), seed=3) as c:
        yield c


def _down_to_grip(cell, step: ToolStep | None = None) -> None:
    cell.open_gripper()
    start = cell.nominal_grasp_pose().moved_in_tool_frame(step or ToolStep())
    cell.move_arm(start)
    cell.move_arm(start.moved_in_tool_frame(ToolStep(dz_mm=cell.grasp_depth_mm)))


def _lift(cell, mm: float = 30.0) -> None:
    cell.move_arm(cell.arm_pose().moved_in_tool_frame(ToolStep(dz_mm=-mm)))


def test_every_part_opens_a_little_wider_than_it_is_and_has_a_known_material():
    for kind, part in CATALOGUE.items():
        assert part.grasp_width_mm < part.jaw_opening_mm <= part.grasp_width_mm + 5.0, kind
        assert part.material in MATERIAL_FRICTION and part.mass_g > 0, kind
    assert CATALOGUE["cube"].jaw_opening_mm == pytest.approx(33.0)


def test_the_part_is_a_dynamic_body_with_the_catalogue_mass(cell):
    info = p.getDynamicsInfo(cell._part.body_id, -1, physicsClientId=cell._client)
    assert info[0] == pytest.approx(PARTS["cube"].mass_g / 1000.0)
    assert info[1] == pytest.approx(PARTS["cube"].friction)


def test_a_centred_grasp_lifts_the_cube_square_in_the_jaws(cell):
    _down_to_grip(cell)
    assert cell.close_gripper() == pytest.approx(30.0, abs=0.2)
    _lift(cell)
    assert cell.holding
    assert cell._part_pose[2, 3] == pytest.approx(30.0, abs=0.5), "the cube went up"
    m = cell.grasp_misalignment()
    assert abs(m["across_mm"]) < 0.3 and abs(m["phi_deg"]) < 1.0 and m["tilt_deg"] < 1.0


def test_an_off_centre_jaw_pushes_the_cube_onto_the_axis(cell):
    _down_to_grip(cell, ToolStep(dy_mm=1.5))
    tool_y = cell.true_tool_pose().y_mm
    cell.close_gripper()
    # The first finger to touch pushed the cube until both gripped it, on the tool's axis.
    assert cell.object_pose()[1] == pytest.approx(tool_y, abs=0.3)
    assert cell.holding


def test_closing_on_a_turned_cube_turns_it_square(cell):
    _down_to_grip(cell, ToolStep(dphi_deg=10.0))
    cell.close_gripper()
    _lift(cell)
    assert cell.holding and abs(cell.grasp_misalignment()["phi_deg"]) < 1.5


def test_a_grip_too_weak_for_the_part_lets_it_slide_out_on_the_lift():
    weak = SimArmConfig(grip_force_n=0.5)
    heavy = dataclasses.replace(PARTS["cube"], mass_g=400.0)
    with SimCell(SceneConfig(), weak, seed=3) as cell:
        cell.part = heavy
        p.changeDynamics(cell._part.body_id, -1, mass=0.4, physicsClientId=cell._client)
        _down_to_grip(cell)
        cell.close_gripper()
        assert cell.holding
        _lift(cell)
        assert not cell.holding and cell.grasp_misalignment() is None
        assert cell._part_pose[2, 3] == pytest.approx(0.0, abs=0.5), "it stayed on the table"


def test_a_released_part_falls_onto_the_table(cell):
    _down_to_grip(cell)
    cell.close_gripper()
    _lift(cell, 20.0)
    x, y, _ = cell.object_pose()
    cell.open_gripper()
    assert not cell.holding
    assert cell._part_pose[2, 3] == pytest.approx(0.0, abs=0.5)
    assert cell.object_pose()[:2] == pytest.approx((x, y), abs=3.0)


def test_closing_on_nothing_meets(cell):
    cell.open_gripper()
    cell.move_arm(cell.nominal_grasp_pose())
    assert cell.close_gripper() == pytest.approx(0.0, abs=0.2)
    assert not cell.holding


def test_a_move_into_the_part_collides_instead_of_being_refused(cell):
    cell.open_gripper()
    start = cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dy_mm=10.0))
    cell.move_arm(start)
    target = start.moved_in_tool_frame(ToolStep(dz_mm=cell.grasp_depth_mm))
    reached = cell.move_arm(target)  # a finger comes down onto the cube's top
    assert reached.z_mm > target.z_mm + 5.0, "it stopped on the cube"
    force = cell.wrench(noisy=False)
    assert force[2] < -0.8 * cell.arm_config.max_penetration_mm * \
        cell.arm_config.contact_stiffness_n_per_mm
