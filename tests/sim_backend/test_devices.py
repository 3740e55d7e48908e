"""SimArm, SimCamera, SimWrenchSensor: the shared contract, contact forces, gripping."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.core.errors import DeviceFaultError
from drivers.core.pose import ToolStep
from sim_backend.cell.scene_config import SceneConfig, SimArmConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.devices import SimArm, SimCamera, SimWrenchSensor


@pytest.fixture
def cell():
    with SimCell(SceneConfig()) as c:
        yield c


def test_devices_refuse_a_closed_cell():
    c = SimCell(SceneConfig())
    c.close()
    for device in (SimArm(c), SimCamera(c), SimWrenchSensor(c)):
        with pytest.raises(DeviceFaultError, match="closed"):
            device.connect()


def _descend(arm: SimArm, sensor: SimWrenchSensor, steps: int) -> list[float]:
    """Fz after each 1 mm step down the approach axis."""
    fz = []
    for _ in range(steps):
        arm.move_tool(ToolStep(dz_mm=1.0))
        fz.append(sensor.read().fz_n)
    return fz


def test_pressing_onto_the_table_gives_a_normal_force(cell):
    arm, sensor = SimArm(cell), SimWrenchSensor(cell)
    with arm, sensor:
        # Beside the part, fingertips 65 mm above the table.
        arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dy_mm=50.0)))
        sensor.bias()
        free = _descend(arm, sensor, 65)
        assert max(abs(f) for f in free) < 0.2, "no force before the fingertips touch"
        pressing = _descend(arm, sensor, 3)
        k = cell.arm_config.contact_stiffness_n_per_mm
        # The table pushes back against the approach direction: Fz < 0, growing with depth.
        assert pressing == pytest.approx([-k, -2 * k, -3 * k], abs=0.3)
        w = sensor.read()
        assert abs(w.fx_n) < 0.2 and abs(w.fy_n) < 0.2


def test_a_move_into_the_table_collides_and_stalls(cell):
    arm, sensor = SimArm(cell), SimWrenchSensor(cell)
    with arm, sensor:
        arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dy_mm=50.0)))
        before = arm.pose()
        sensor.bias()
        arm.move_tool(ToolStep(dz_mm=before.z_mm + 10.0))  # 10 mm below the table's top
        reached = arm.pose()
        # Not refused: the fingertips (the TCP) stall pushed max_penetration_mm into the table,
        # which pushes back hard (a force guard would stop the arm there).
        depth = cell.arm_config.max_penetration_mm
        assert reached.z_mm == pytest.approx(-depth, abs=0.3)
        assert reached.x_mm == pytest.approx(before.x_mm, abs=0.2)
        force = sensor.read()
        assert force.fz_n < -0.8 * depth * cell.arm_config.contact_stiffness_n_per_mm


def test_descending_onto_the_part_in_small_steps_does_not_tunnel(cell):
    arm, sensor = SimArm(cell), SimWrenchSensor(cell)
    with arm, sensor:
        # One finger right above the cube's top.
        arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dy_mm=12.0)))
        sensor.bias()
        approach = _descend(arm, sensor, int(cell.approach_height_mm))
        assert max(abs(f) for f in approach) < 0.2
        contact = _descend(arm, sensor, 3)
        assert contact[0] < -0.5 * cell.arm_config.contact_stiffness_n_per_mm
        assert contact[0] > contact[1] > contact[2], "force grows step by step"


def test_the_gripper_holds_and_lifts_the_cube(cell):
    arm, sensor = SimArm(cell), SimWrenchSensor(cell)
    with arm, sensor:
        arm.move_to(cell.nominal_grasp_pose())
        assert arm.open_gripper() == pytest.approx(cell.part.jaw_opening_mm)
        sensor.bias()
        fz = _descend(arm, sensor, round(cell.grasp_depth_mm))
        assert max(abs(f) for f in fz) < 0.2, "the open jaws pass beside the cube"
        assert arm.close_gripper() == pytest.approx(30.0, abs=0.1)
        assert cell.holding
        x, y, _ = cell.object_pose()
        arm.move_tool(ToolStep(dz_mm=-30.0))
        assert arm.finger_width_mm() == pytest.approx(30.0, abs=0.1)
        assert cell._part_pose[2, 3] == pytest.approx(30.0, abs=0.1), "the cube went up"
        assert cell.object_pose()[:2] == pytest.approx((x, y), abs=0.1)
        weight = cell.part.mass_g / 1000.0 * 9.81
        assert sensor.read().fz_n == pytest.approx(weight, abs=0.08), "feels the cube's weight"
        arm.open_gripper()
        # Let go 30 mm up, the cube falls back onto the table.
        assert not cell.holding and cell._part_pose[2, 3] == pytest.approx(0.0, abs=0.5)


def test_closing_centres_an_off_centre_cube_and_closing_on_nothing_meets(cell):
    arm = SimArm(cell)
    with arm:
        arm.move_to(cell.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dy_mm=3.0)))
        arm.move_tool(ToolStep(dz_mm=cell.grasp_depth_mm))
        assert arm.close_gripper() == pytest.approx(30.0, abs=0.1)
        # The first finger to touch pushed the cube onto the tool axis.
        assert cell.object_pose()[1] == pytest.approx(arm.pose().y_mm, abs=0.15)
        arm.open_gripper()
        arm.move_tool(ToolStep(dz_mm=-cell.grasp_depth_mm))
        assert arm.close_gripper() == pytest.approx(0.0, abs=0.1)
        assert not cell.holding


def test_repeatability_is_configurable():
    with SimCell(SceneConfig(), SimArmConfig(repeatability_mm=1.0, repeatability_deg=1.0),
                 seed=1) as c:
        errors = []
        for _ in range(30):
            c.move_arm(c.nominal_grasp_pose())
            errors.append(c.ground_truth_error())
        spread = np.abs(np.array(errors))
        assert spread[:, :2].max() > 0.3 and spread[:, :2].max() <= 1.0 + 1e-9
        assert spread[:, 2].max() > 0.3 and spread[:, 2].max() <= 1.0 + 1e-9


def test_the_guard_setup_takes_its_time_alongside_what_the_caller_does(cell):
    from drivers.core.timing import TimingConfig
    from drivers.interfaces import MonitorCondition
    from sim_backend.cell.timing import cell_timing

    timing = cell_timing("realistic", TimingConfig())
    condition = MonitorCondition("fz_n", "<", -3.0)
    with SimWrenchSensor(cell, timing) as sensor:
        timing.at_rest_s = timing.clock.now()
        setup = sensor.prepare_contact_guard(condition, 16)
        begun = timing.clock.now()
        timing.val_wire(250)  # the arm's line meanwhile: 0.26 s, longer than the set-up
        waited = timing.clock.now()
        assert abs(setup.wait().fz_n) < 0.1  # the mean after the bias
        assert timing.clock.now() == waited
        # alone, the wait is the mean's 16 samples (100 Hz) and the ATI line's exchanges
        timing.at_rest_s = timing.clock.now()
        setup = sensor.prepare_contact_guard(condition, 16)
        assert timing.clock.now() == waited > begun
        setup.wait()
        assert 0.16 <= timing.clock.now() - waited < 0.2
