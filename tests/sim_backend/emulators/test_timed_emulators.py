"""The emulators with realistic timing: paced lines, moves that last, the two clocks agree,
and ``finepos fit-timing`` recovers the emulator's own motion model."""

from __future__ import annotations

import dataclasses
import statistics
import time

import pytest

from controller.commands.fit_timing import fitted_config, time_moves
from controller.config import config_from_mapping
from controller.devices import open_devices
from controller.evaluation.hil import open_hil_devices
from drivers.core.pose import ToolStep
from drivers.core.timing import ArmTiming, TimingConfig, fit_arm_timing, wire_time_s
from drivers.val import ValArm, ValConfig
from sim_backend.cell import timing as cell_timing
from sim_backend.cell.scene_config import SceneConfig
from sim_backend.cell.sim_cell import SimCell
from sim_backend.emulators.cell import CellEmulators

ARM = ArmTiming(t0_s=0.1, joint_speed_deg_s=40.0, joint_accel_deg_s2=150.0, settle_s=0.05,
                hand_time_s=0.3)


@pytest.fixture
def timed_val():
    """A realistic VAL emulator at 9600 baud on a fresh cell, and the driver on it."""
    with SimCell(SceneConfig(), seed=2) as cell, \
            CellEmulators(cell, timing=TimingConfig(arm=ARM)) as emulators, \
            ValArm(ValConfig(port=emulators.val_url)) as arm:
        yield arm, emulators


def _timed(action) -> float:
    start = time.perf_counter()
    action()
    return time.perf_counter() - start


@pytest.mark.slow
def test_where_at_9600_baud_takes_its_wire_time(timed_val):
    arm, emulators = timed_val
    seconds = statistics.median(_timed(arm.where) for _ in range(3))
    assert seconds == pytest.approx(wire_time_s(cell_timing.where_bytes(), 9600), rel=0.10)


@pytest.mark.slow
def test_do_move_answers_after_the_motion(timed_val):
    arm, emulators = timed_val
    where_s = _timed(arm.where)
    short = _timed(lambda: arm.move_tool(ToolStep(1.0, 0.0, 0.0, 0.0)))
    long = _timed(lambda: arm.move_tool(ToolStep(20.0, 0.0, 0.0, 0.0)))
    arm.set_speed(20)
    slow = _timed(lambda: arm.move_tool(ToolStep(-20.0, 0.0, 0.0, 0.0)))
    arm.set_speed(150)  # VAL takes speeds above 100
    assert short > where_s + ARM.t0_s + ARM.settle_s
    assert short < long < slow
    assert emulators.timing.motion_s > 0


@pytest.mark.slow
def test_the_two_clocks_give_the_same_cell_seconds():
    """The same scripted trial on the in-process cell (virtual clock) and through the real
    drivers and the emulators (wall clock) takes the same cell seconds within 10%, the camera's
    frames apart (through the driver a grab waits its ``settle_s``, which for the emulated
    stream also covers rendering and coding on this machine, ``CellEmulators.stream_settle_s``)
    and this machine's own work apart: the emulated cell is never faster than the modelled one,
    and slower by no more than the host's work on the same exchanges."""
    # one render sample a pixel: the emulated cell renders on the wall clock, in the same
    # process as the drivers, and a 2x2 render's 20 ms a frame is the simulation's, not the cell's
    config = config_from_mapping({"scene": {"timing": "realistic",
                                            "camera": {"pixel_samples": 1}},
                                  "timing": {"arm": dataclasses.asdict(ARM)}})
    steps = (ToolStep(20.0, -10.0, 0.0, 15.0), ToolStep(-8.0, 6.0, 0.0, -6.0),
             ToolStep(1.5, 1.5, 0.0, 1.5))  # a grab before each

    def trial(devices) -> tuple[float, float]:
        """The trial's seconds, and those of its camera grabs."""
        # Moves long enough that motion, not the emulated cell's own work per exchange (its
        # rendering shares the process with the drivers), makes most of the seconds.
        start = devices.clock()
        grab_s = 0.0
        devices.arm.open_gripper()
        for step in steps:
            asked = devices.clock()
            devices.camera.grab()
            grab_s += devices.clock() - asked
            devices.arm.move_tool(step)
        devices.wrench.bias()
        for _ in range(3):
            devices.arm.move_tool(ToolStep(0.0, 0.0, 5.0, 0.0))
            devices.wrench.read()
        devices.arm.close_gripper()
        devices.arm.move_tool(ToolStep(0.0, 0.0, -30.0, 0.0))
        return devices.clock() - start, grab_s

    with open_devices(config, seed=4) as devices:
        virtual, virtual_grabs = trial(devices)
    with open_hil_devices(config, seed=4) as devices:
        wall, wall_grabs = trial(devices)
        settle_s = devices.camera.config.settle_s
    # This machine's own work on the same exchanges: the trial through the same drivers and
    # emulators with no line pacing and no motion time. It counts twice on the paced cell, once
    # as work and once as the waits (paced bytes, moves) waking late on a busy machine; on an
    # idle machine the paced trial is 0.2 s over the model, 0.5-0.8 s with CI's load beside it.
    ideal = dataclasses.replace(config, scene=dataclasses.replace(config.scene, timing="ideal"))
    with open_hil_devices(ideal, seed=4) as devices:
        host, host_grabs = trial(devices)
    cell_s, emulated_s = virtual - virtual_grabs, wall - wall_grabs
    assert virtual > 3.0  # the trial takes real cell time, not the ideal cell's zero
    assert emulated_s >= 0.97 * cell_s  # pacing is real: never faster than the model
    assert emulated_s <= 1.10 * cell_s + 2 * (host - host_grabs)
    assert wall_grabs >= len(steps) * settle_s > virtual_grabs


@pytest.mark.slow
def test_fit_timing_recovers_the_emulators_own_parameters():
    baud = 115200  # a faster line keeps the test short; the motion model is what is fitted
    timing = TimingConfig(val_baud=baud, arm=ARM)
    with SimCell(SceneConfig(), seed=5) as cell, \
            CellEmulators(cell, timing=timing) as emulators, \
            ValArm(ValConfig(port=emulators.val_url, baudrate=baud)) as arm:
        moves = time_moves(arm, (1.0, 25.0), (25.0, 100.0), 2, out=None)
    fit = fit_arm_timing(moves)
    assert fit.t0_s == pytest.approx(ARM.t0_s + ARM.settle_s, abs=0.03)
    assert fit.joint_speed_deg_s == pytest.approx(ARM.joint_speed_deg_s, rel=0.15)
    assert fit.joint_accel_deg_s2 == pytest.approx(ARM.joint_accel_deg_s2, rel=0.15)
    written = fitted_config({"scene": {"timing": "realistic"}}, fit)
    assert written["timing"]["arm"]["settle_s"] == 0.0
    assert config_from_mapping(written).timing.arm.joint_speed_deg_s == pytest.approx(
        fit.joint_speed_deg_s, rel=1e-3)
