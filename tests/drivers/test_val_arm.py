"""The VAL II arm driver against the VAL emulator over a real pty (and TCP): contract, start-up,
port URLs, controller errors, and every fault knob: typed error, no further motion, recovery."""

from __future__ import annotations

import os

import pytest

from drivers.contract import check_arm
from drivers.core.errors import (
    DeviceFaultError,
    DeviceTimeoutError,
    MotionRejectedError,
    ProtocolError,
)
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Lifecycle
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from drivers.val.arm import split_move
from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from tests.mocks.fakes import FakeArm

LIMITS = SafetyLimits(max_step_mm=20.0, max_step_deg=30.0)
# Short enough that the timeout faults below take a fraction of a second each.
FAULT_TIMEOUT_S = 0.5
STEP = ToolStep(2.0, -1.0, 0.5, 3.0)


def make_arm(url: str, **overrides) -> ValArm:
    return ValArm(ValConfig(port=url, **overrides), LIMITS)


@pytest.mark.skipif("FINEPOS_VAL_PORT" not in os.environ,
                    reason="real-hardware test: set FINEPOS_VAL_PORT to the controller's port URL "
                           "(the arm moves a few mm and works the gripper)")
def test_contract_on_the_real_controller():
    check_arm(lambda: make_arm(os.environ["FINEPOS_VAL_PORT"]))


def test_contract_over_socket_url(backing):
    with ValEmulator(backing, tcp_port=0) as emu:
        assert emu.url.startswith("socket://127.0.0.1:")
        check_arm(lambda: make_arm(emu.url))


def test_contract_with_newline_cr_endings_and_boot_questions(backing):
    with ValEmulator(backing, boot_questions=True) as emu:
        check_arm(lambda: make_arm(emu.url, line_ending="\n\r"))


def test_startup_answers_the_boot_questions(backing):
    with ValEmulator(backing, boot_questions=True) as emu, make_arm(emu.url) as arm:
        assert emu.lines_handled == 3  # the wake-up line and two answers
        assert arm.pose() == backing.pose()


def test_startup_refuses_an_unexpected_question(backing):
    with ValEmulator(backing, boot_questions=True) as emu:
        arm = make_arm(emu.url, boot_answers={"Load VAL from floppy": "n"})
        with pytest.raises(ProtocolError, match="Initialize"):
            arm.connect()
        assert not arm.is_connected


def test_spy_url_logs_the_traffic(emulator, tmp_path):
    log = tmp_path / "spy.txt"
    with make_arm(f"spy://{emulator.url}?file={log}") as arm:
        arm.pose()
    assert "where" in log.read_text()


def test_loop_url_opens_but_never_sees_a_prompt():
    arm = make_arm("loop://", exchange_timeout_s=0.2)
    with pytest.raises(DeviceTimeoutError, match="no complete reply"):
        arm.connect()
    assert arm.state is Lifecycle.DISCONNECTED


def test_commands_reach_the_controller(emulator, backing):
    with make_arm(emulator.url) as arm:
        arm.set_speed(25)
        assert backing.speed_percent == 25
        assert arm.close_gripper() == 0.0 and backing.finger_width_mm() == 0.0
        assert arm.open_gripper() == 40.0 and backing.finger_width_mm() == 40.0
        arm.halt()
        assert backing.halts == 1
        reading = arm.where()
        assert reading.pose == backing.pose() and reading.joints_deg is not None


def test_unreachable_pose_is_refused_without_fault():
    workspace = SafetyLimits(workspace_min_mm=(-450, -450, 100), max_step_mm=1e4,
                             max_step_deg=360)
    with FakeArm(workspace) as controller_arm, ValEmulator(controller_arm) as emu, \
            ValArm(ValConfig(port=emu.url)) as arm:  # no driver limits: the controller refuses
        start = arm.pose()
        below = Pose(start.x_mm, start.y_mm, 90.0, start.o_deg, start.a_deg, start.t_deg)
        with pytest.raises(MotionRejectedError, match="Position out of range"):
            arm.move_to(below)
        assert arm.state is Lifecycle.ACTIVE and controller_arm.moves == []
        arm.move_tool(STEP)
        assert len(controller_arm.moves) == 1


def test_forced_position_error_is_a_rejection(emulator, backing):
    with make_arm(emulator.url) as arm:
        emulator.set_faults(ValFaults(forced_error="Position out of range"))
        with pytest.raises(MotionRejectedError):
            arm.set_speed(10)
        assert arm.state is Lifecycle.ACTIVE


FAULTS = {
    "reply delay": (ValFaults(reply_delay_s=30.0), DeviceTimeoutError),
    "link dropped before the move": (ValFaults(drop_link_after_lines=1), DeviceTimeoutError),
    "line noise": (ValFaults(garbage=DEFAULT_GARBAGE), ProtocolError),
    "unexpected output": (ValFaults(garbage=b"NOISE\r\n"), ProtocolError),
    "controller error": (ValFaults(forced_error="Arm power off"), DeviceFaultError),
}


@pytest.mark.parametrize("name", FAULTS)
def test_fault_knob_gives_typed_error_stops_motion_and_recovers(name, emulator, backing):
    faults, error = FAULTS[name]
    with make_arm(emulator.url, exchange_timeout_s=FAULT_TIMEOUT_S,
                  move_timeout_s=FAULT_TIMEOUT_S) as arm:
        emulator.set_faults(faults)
        with pytest.raises(error) as raised:
            arm.move_tool(STEP)
        if error is DeviceFaultError:
            assert raised.value.message == "Arm power off"
        assert arm.state is Lifecycle.FAULT and arm.fault_reason
        moves = len(backing.moves)
        for motion in (lambda: arm.move_tool(STEP), lambda: arm.move_to(backing.pose()),
                       arm.open_gripper, arm.pose):
            with pytest.raises(DeviceFaultError):
                motion()
        assert len(backing.moves) == moves

        emulator.set_faults(ValFaults())
        arm.reset()
        assert arm.state is Lifecycle.INACTIVE
        arm.activate()
        before = arm.pose()
        arm.move_tool(STEP)
        assert len(backing.moves) == moves + 1
        assert before.tool_step_to(arm.pose()).dx_mm == pytest.approx(STEP.dx_mm, abs=0.01)


def test_reset_fails_while_the_link_is_down(emulator):
    with make_arm(emulator.url, exchange_timeout_s=FAULT_TIMEOUT_S) as arm:
        emulator.set_faults(ValFaults(drop_link_after_lines=0))
        with pytest.raises(DeviceTimeoutError):
            arm.pose()
        with pytest.raises(DeviceTimeoutError):
            arm.reset()
        assert not arm.is_connected
        emulator.set_faults(ValFaults())
        arm.reset()
        assert arm.is_connected


def test_small_reply_delay_only_slows_down(emulator):
    with make_arm(emulator.url) as arm:
        emulator.set_faults(ValFaults(reply_delay_s=0.05))
        arm.move_tool(STEP)
        assert arm.state is Lifecycle.ACTIVE


def test_dropped_tcp_link_is_a_lost_link_fault(backing):
    with ValEmulator(backing, tcp_port=0) as emu, \
            make_arm(emu.url, exchange_timeout_s=FAULT_TIMEOUT_S) as arm:
        emu.set_faults(ValFaults(drop_link_after_lines=1))
        with pytest.raises(DeviceFaultError, match="link lost"):
            arm.move_tool(STEP)
        assert arm.state is Lifecycle.FAULT and backing.moves == []
        emu.set_faults(ValFaults())
        arm.reset()
        arm.activate()
        arm.move_tool(STEP)
        assert len(backing.moves) == 1


def test_controller_error_at_startup_leaves_the_arm_disconnected(emulator):
    emulator.set_faults(ValFaults(forced_error="Arm power off"))
    arm = make_arm(emulator.url)
    with pytest.raises(DeviceFaultError, match="Arm power off"):
        arm.connect()
    assert arm.state is Lifecycle.DISCONNECTED
    emulator.set_faults(ValFaults())
    with arm:
        assert arm.pose().is_finite()


def test_an_error_reply_to_where_is_a_device_fault_never_a_rejection(emulator, backing):
    """Issue 15 probe 3: ``*Position out of range*`` answering a pose read is a controller fault
    (the service's idle poll must not take it for a refused step, nor exit on it)."""
    with make_arm(emulator.url) as arm:
        emulator.set_faults(ValFaults(forced_error="Position out of range"))
        with pytest.raises(DeviceFaultError, match="Position out of range") as raised:
            arm.pose()
        assert not isinstance(raised.value, MotionRejectedError)
        assert arm.state is Lifecycle.FAULT
        emulator.set_faults(ValFaults())
        arm.reset()
        arm.activate()
        arm.pose()


def test_halt_interrupts_a_move_waiting_on_a_silent_link(emulator, backing):
    """Issue 15 probe 4: a halt does not wait behind a move whose reply never comes; the move
    ends as refused (no fault from the interruption), the halt gets its own timeout."""
    import threading
    import time

    with make_arm(emulator.url, exchange_timeout_s=0.3, move_timeout_s=30.0) as arm:
        emulator.set_faults(ValFaults(drop_link_after_lines=1))  # the `where` of the move only
        errors = []

        def move() -> None:
            try:
                arm.move_tool(STEP)
            except Exception as exc:  # noqa: BLE001 - checked below
                errors.append(exc)

        thread = threading.Thread(target=move)
        thread.start()
        time.sleep(0.3)  # the move command is waiting for its prompt
        with pytest.raises(DeviceTimeoutError):
            arm.halt()  # the link is still silent: the halt times out (not 30 s later)
        thread.join(5.0)
        assert not thread.is_alive()
        assert errors and isinstance(errors[0], MotionRejectedError), errors
        assert "halted while waiting" in str(errors[0])
        assert arm.state is Lifecycle.FAULT  # from the halt's own timeout
        arm.disconnect()  # closing never raises, also with the link down


def test_split_move_takes_equal_steps_along_the_shortest_angles():
    start = Pose(300.0, 0.0, 200.0, 170.0, 90.0, 0.0)
    target = Pose(300.0, 50.0, 200.0, -170.0, 90.0, 0.0)  # 50 mm; O turns 20 deg through 180
    segments = split_move(start, target, max_mm=20.0, max_deg=10.0)
    assert len(segments) == 3 and segments[-1] is target
    assert segments[0].y_mm == pytest.approx(50 / 3) and segments[0].o_deg == pytest.approx(
        170 + 20 / 3)
    assert split_move(start, target, 0.0, 0.0) == [target]
    assert split_move(start, start, 20.0, 10.0) == [start]
    assert len(split_move(start, target, 100.0, 5.0)) == 4  # the angle decides


def test_a_long_move_goes_out_in_segments(emulator, backing):
    with make_arm(emulator.url, max_segment_mm=1.0, max_segment_deg=1.0) as arm:
        arm.move_tool(STEP)  # 2.3 mm and 3 deg: three segments
        assert len(backing.moves) == 3
        assert backing.moves[-1] == arm.pose()


def test_segment_config_is_checked():
    from drivers.core.errors import ConfigError
    from drivers.core.typed_config import from_mapping
    with pytest.raises(ConfigError, match="arm.max_segment_mm"):
        from_mapping(ValConfig, {"port": "loop://", "max_segment_mm": -1.0}, "arm")
    with pytest.raises(ConfigError, match="max_segment_mm and max_segment_deg"):
        from_mapping(ValConfig, {"port": "loop://", "max_segment_mm": 5.0}, "arm")


def test_a_halt_during_a_segmented_move_sends_no_further_segment():
    """Abort during a VAL move: the segment under way ends, the next one is never sent."""
    import threading
    import time

    class HaltingArm(FakeArm):
        driver: ValArm | None = None

        def _move_to(self, target: Pose) -> Pose:
            reached = super()._move_to(target)
            if len(self.moves) == 1:  # an operator's abort arrives during the first segment
                threading.Thread(target=self.driver.halt, daemon=True).start()
                time.sleep(0.2)  # (the halt counts itself at once; its command waits its turn)
            return reached

    with HaltingArm() as backing, ValEmulator(backing) as emu, \
            make_arm(emu.url, max_segment_mm=1.0, max_segment_deg=1.0) as arm:
        backing.driver = arm
        with pytest.raises(MotionRejectedError, match="halted"):
            arm.move_tool(STEP)
        assert len(backing.moves) == 1
        deadline = time.monotonic() + 5.0
        while backing.halts == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert backing.halts == 1 and arm.state is Lifecycle.ACTIVE


def _counting_wheres(arm: ValArm) -> list[int]:
    calls = [0]
    where = arm._where

    def counted():
        calls[0] += 1
        return where()
    arm._where = counted
    return calls


def test_moves_start_from_the_last_reached_pose_without_a_where(emulator, backing):
    with make_arm(emulator.url) as arm:
        wheres = _counting_wheres(arm)
        arm.move_tool(STEP)  # nothing kept yet: one where
        arm.move_tool(STEP)
        arm.move_to(arm.pose(fresh=False).moved_in_tool_frame(STEP))
        assert wheres[0] == 1
        kept, read = arm.pose(fresh=False), arm.pose()  # the second one reads
        assert max(abs(a - b) for a, b in zip(kept.as_dict().values(), read.as_dict().values(),
                                              strict=True)) < 0.01  # the line's 2 decimals
        assert wheres[0] == 2
        arm.halt()  # after a halt the next move starts from a fresh reading
        arm.move_tool(STEP)
        assert wheres[0] == 3
        assert arm.open_gripper() == 40.0 and arm.open_gripper() == 40.0  # once on the wire
        arm.close_gripper()
        arm.open_gripper()


def test_jaws_opened_by_the_driver_are_not_opened_again_until_something_happened(emulator,
                                                                                 backing):
    with make_arm(emulator.url) as arm:
        arm.open_gripper()
        backing._width_mm = 0.0  # (the backing's jaws, closed behind the driver's back)
        arm.open_gripper()
        assert backing.finger_width_mm() == 0.0  # kept: not sent again
        arm.halt()
        arm.open_gripper()
        assert backing.finger_width_mm() == 40.0


def test_where_before_move_reads_before_every_move(emulator, backing):
    with make_arm(emulator.url, where_before_move=True) as arm:
        wheres = _counting_wheres(arm)
        arm.move_tool(STEP)
        arm.move_tool(STEP)
        arm.pose(fresh=False)
        assert wheres[0] == 3
        arm.open_gripper()
        backing._width_mm = 0.0
        arm.open_gripper()
        assert backing.finger_width_mm() == 40.0
