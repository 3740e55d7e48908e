"""The simulated devices on the realistic cell's virtual clock (``sim_backend.cell.timing``)."""

from __future__ import annotations

import threading

import pytest

from drivers.core.pose import ToolStep
from drivers.core.timing import ArmTiming, TimingConfig, wire_time_s
from sim_backend.cell import timing as cell_timing
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.devices import SimArm, SimCamera, SimWrenchSensor

CONFIG = TimingConfig(arm=ArmTiming(t0_s=0.1, joint_speed_deg_s=40.0, joint_accel_deg_s2=150.0,
                                    settle_s=0.05, hand_time_s=0.5))


@pytest.fixture(scope="module")
def cell():
    with SimCell(SceneConfig(timing="realistic"), seed=3) as c:
        yield c


@pytest.fixture
def devices(cell):
    timing = cell_timing.cell_timing("realistic", CONFIG)
    with SimArm(cell, None, timing) as arm, SimCamera(cell, timing) as camera, \
            SimWrenchSensor(cell, timing) as wrench:
        arm.move_to(cell.nominal_grasp_pose())
        yield arm, camera, wrench, timing


def _elapsed(timing, action) -> float:
    start = timing.clock.now()
    action()
    return timing.clock.now() - start


def test_where_takes_its_wire_time_at_9600_baud(devices):
    arm, _, _, timing = devices
    assert cell_timing.where_bytes() == 262
    assert _elapsed(timing, arm.pose) == pytest.approx(wire_time_s(262, 9600))


def test_a_longer_move_takes_longer_and_a_lower_speed_slows_it(devices):
    arm, _, _, timing = devices
    short = _elapsed(timing, lambda: arm.move_tool(ToolStep(1.0, 0.0, 0.0, 0.0)))
    long = _elapsed(timing, lambda: arm.move_tool(ToolStep(20.0, 0.0, 0.0, 0.0)))
    arm.set_speed(20)
    slow = _elapsed(timing, lambda: arm.move_tool(ToolStep(-20.0, 0.0, 0.0, 0.0)))
    arm.set_speed(100)
    assert short < long < slow
    # a move costs at least t0 + settle on top of the command's wire time (it starts from the
    # pose the last one reached: no where)
    assert short > CONFIG.arm.t0_s + CONFIG.arm.settle_s + wire_time_s(100, 9600)
    arm.halt()  # forgets the kept pose: the next move reads it first
    after_halt = _elapsed(timing, lambda: arm.move_tool(ToolStep(1.0, 0.0, 0.0, 0.0)))
    assert after_halt == pytest.approx(short + wire_time_s(262, 9600), abs=0.01)


def test_the_hand_takes_its_hand_time(devices):
    arm, _, _, timing = devices
    assert _elapsed(timing, arm.close_gripper) >= CONFIG.arm.hand_time_s
    assert _elapsed(timing, arm.open_gripper) >= CONFIG.arm.hand_time_s


def test_a_frame_waits_for_the_next_exposure_and_its_latency(devices):
    _, camera, _, timing = devices
    cam = CONFIG.camera
    period = 1.0 / cam.frame_rate_hz
    waited = _elapsed(timing, camera.grab)
    assert cam.exposure_s + period <= waited <= cam.exposure_s + 2 * period + 1e-9
    frame = camera.grab()
    assert frame.timestamp_s == pytest.approx(timing.clock.now())


def test_a_wrench_reading_waits_for_the_next_sample_and_the_ati_line(devices):
    _, _, wrench, timing = devices
    wire = wire_time_s(cell_timing.ATI_QR_BYTES, 38400)
    waited = _elapsed(timing, wrench.read)
    assert wire <= waited <= wire + 1.0 / CONFIG.wrench_rate_hz


def test_ideal_devices_take_no_cell_time(cell):
    assert cell_timing.cell_timing("ideal", CONFIG) is None
    with SimArm(cell, None, None) as arm:
        before = arm.pose()
        arm.move_tool(ToolStep(1.0, 0.0, 0.0, 0.0))
        assert arm.pose() != before


def test_the_virtual_clock_never_sleeps_and_the_wall_clock_does():
    virtual = cell_timing.VirtualClock()
    virtual.advance(100.0)
    assert virtual.now() == 100.0
    wall = cell_timing.WallClock()
    start = wall.now()
    wall.advance(0.02)
    assert wall.now() - start >= 0.02
    wall.interrupt()
    start = wall.now()
    wall.advance(10.0)  # interrupted: returns at once
    assert wall.now() - start < 1.0


@pytest.mark.slow
def test_a_frame_exposed_during_a_move_is_blurred_and_one_frame_late(cell):
    from sim_backend.emulators.cell import SerialisedCell

    shared = SerialisedCell(cell)
    timing = cell_timing.cell_timing("realistic", CONFIG, wall=True)
    with SimArm(shared, None, timing) as arm, SimCamera(shared, timing) as camera:
        arm.move_to(cell.nominal_grasp_pose())
        still = [camera.grab() for _ in range(3)]
        assert camera.blurred_frames == 0  # the arm stood still
        assert still[1].timestamp_s == still[0].timestamp_s  # delivered one grab late
        mover = threading.Thread(target=arm.move_tool, args=(ToolStep(20.0, 0.0, 0.0, 10.0),))
        mover.start()
        while mover.is_alive():
            camera.grab()
        mover.join()
        assert camera.blurred_frames > 0
        assert timing.motion_s > CONFIG.arm.t0_s + CONFIG.arm.settle_s


def test_the_budget_splits_every_cell_second_by_kind(devices):
    arm, camera, sensor, timing = devices
    start = timing.clock.now()
    before = dict(timing.spent)
    arm.move_tool(ToolStep(5.0, 0.0, 0.0, 0.0))
    arm.close_gripper()
    sensor.read()
    camera.grab()
    spent = {k: timing.spent[k] - before[k] for k in cell_timing.BUDGET}
    assert spent["setup"] == pytest.approx(CONFIG.arm.t0_s)
    assert spent["hand"] == pytest.approx(CONFIG.arm.hand_time_s)
    assert spent["motion"] > CONFIG.arm.settle_s
    assert spent["wire"] > 0 and spent["camera"] > 0 and spent["sensor"] >= 0
    assert sum(spent.values()) == pytest.approx(timing.clock.now() - start)
