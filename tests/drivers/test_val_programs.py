"""The VAL driver's program path against the VAL emulator over a real pty: the programs entered
once and checked by listing, one EXECUTE per descent stopped by the input line, refusals,
abort during a program, and ``arm.programs: false`` keeping one command per move."""

from __future__ import annotations

import threading

import pytest

from drivers.core.errors import DeviceFaultError, DeviceTimeoutError, MotionRejectedError
from drivers.core.pose import ToolStep
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from drivers.val.arm import ProgramDownloadError
from tests.mocks.fakes import HOME

LIMITS = SafetyLimits(max_step_mm=60.0, max_step_deg=30.0)
WAIT_S = 5.0  # bound on waiting for threads; no assertion depends on it


def heard(emulator) -> list[str]:
    lines: list[str] = []
    emulator.add_listener(lambda event, text: lines.append(text) if event == "command" else None)
    return lines


def program_arm(emulator, **overrides) -> ValArm:
    overrides.setdefault("move_timeout_s", WAIT_S)
    return ValArm(ValConfig(port=emulator.url, programs=True, **overrides), LIMITS)


def down(mm: float):
    return HOME.moved_in_tool_frame(ToolStep(dz_mm=mm))


def test_programs_are_entered_once_and_listed_back(emulator):
    lines = heard(emulator)
    with program_arm(emulator):
        pass
    assert "edit fpdesc" in lines and "listp fpdesc" in lines
    entered = len(lines)
    with program_arm(emulator):  # the listings match: nothing is entered again
        pass
    assert not any(line.startswith("edit") for line in lines[entered:])
    assert sum(line.startswith("listp") for line in lines[entered:]) == len(
        ValConfig(port="loop://").program_lines)


def test_one_execute_per_descent_that_reaches_its_target(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)
        arm.guarded_descent(down(10.0), down(20.0), 25.0, 4.0)
        # the guarded part ends 6 mm before the target: the program is entered again once
        assert "edit fpdesc" in lines and "APPROS fpd, 6.00" in lines
        lines.clear()
        descent = arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
    assert not descent.contact and descent.pose == down(30.0)
    assert backing.pose().z_mm == pytest.approx(HOME.z_mm - 30.0)
    assert [line.split()[0] for line in lines] == ["do", "do", "ex"]


def test_the_input_stops_the_descent_and_where_reads_the_stop(emulator, backing):
    emulator.monitor.set_input(1001, lambda: HOME.z_mm - backing.pose().z_mm >= 24.0)
    with program_arm(emulator) as arm:
        descent = arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
    assert descent.contact
    assert HOME.z_mm - descent.pose.z_mm == pytest.approx(24.0, abs=0.51)


def test_an_input_high_before_the_descent_refuses_it(emulator, backing):
    emulator.monitor.set_input(1001, lambda: True)
    with program_arm(emulator) as arm:
        with pytest.raises(MotionRejectedError, match="high before the descent"):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
    assert backing.moves == []


def test_a_refused_program_line_fails_the_connection_naming_program_and_line(emulator):
    bad = {"fpstop": ("TYPE FPCONTACT", "STOP"),
           "fpdesc": ("SPEED 100", "OPEN", "REACTI {input}, fpstop", "WELD 3", "MOVES fpd")}
    arm = program_arm(emulator, program_lines=bad)
    with pytest.raises(ProgramDownloadError,
                       match=r"program fpdesc: line 4 'WELD 3' refused: \*Unknown instruction\*"):
        arm.connect()
    assert not arm.is_connected


def test_a_descent_beyond_the_safety_limits_is_refused_before_the_wire(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)
        with pytest.raises(MotionRejectedError):
            arm.guarded_descent(down(20.0), down(300.0), 25.0, 4.0)
    assert [line for line in lines if line != "where"] == [] and backing.moves == []


def test_abort_stops_the_descent_program_at_once(emulator, backing):
    moving, release = threading.Event(), threading.Event()
    original = backing._move_to

    def slow(target):  # each step of the program's motion takes 10 ms once released
        moving.set()
        release.wait(WAIT_S)
        threading.Event().wait(0.01)
        return original(target)

    backing._move_to = slow
    with program_arm(emulator) as arm:
        errors: list[Exception] = []

        def descend():
            try:
                arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
            except Exception as exc:  # noqa: BLE001 - the test looks at it
                errors.append(exc)

        worker = threading.Thread(target=descend)
        worker.start()
        assert moving.wait(WAIT_S)
        release.set()
        arm.halt()
        worker.join(WAIT_S)
        assert errors and isinstance(errors[0], MotionRejectedError)
        assert backing.halts >= 1
        assert arm.pose().z_mm > HOME.z_mm - 30.0  # stopped short of the target
        arm.move_tool(ToolStep(dz_mm=1.0))  # the arm still works after the abort


def test_ready_is_waited_for_after_the_locations_and_before_the_run(emulator, backing):
    with program_arm(emulator) as arm:
        arm.guarded_descent(down(10.0), down(20.0), 25.0, 4.0)  # programs entered and fitted
        lines = heard(emulator)
        seen: list[list[str]] = []
        arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0,
                            ready=lambda: seen.append(list(lines)))
    assert [[line.split()[0] for line in heard_then] for heard_then in seen] == [["do", "do"]]
    assert [line.split()[0] for line in lines] == ["do", "do", "ex"]


def test_a_failed_ready_ends_the_descent_with_nothing_run(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)

        def sensor_lost():
            raise DeviceFaultError("ATI F/T: serial link lost")

        with pytest.raises(DeviceFaultError, match="ATI"):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0, ready=sensor_lost)
        assert not any(line.startswith("ex ") for line in lines)
        assert backing.moves == [] and arm.fault_reason is None  # not the arm's fault
        arm.move_tool(ToolStep(dz_mm=1.0))


def test_a_halt_while_ready_is_waited_for_refuses_the_run(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)
        with pytest.raises(MotionRejectedError, match="halted before"):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0, ready=arm.halt)
        assert not any(line.startswith("ex ") for line in lines)
        assert backing.moves == []


def test_without_programs_the_arm_runs_no_descent(emulator):
    with ValArm(ValConfig(port=emulator.url), LIMITS) as arm:
        assert not arm.runs_programs
        with pytest.raises(MotionRejectedError, match="runs no guarded descent"):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)


def test_a_lost_link_during_a_program_is_a_fault(emulator, backing):
    from sim_backend.emulators.val.server import ValFaults

    with program_arm(emulator, move_timeout_s=0.5) as arm:
        emulator.set_faults(ValFaults(drop_link_after_lines=2))
        with pytest.raises((DeviceFaultError, DeviceTimeoutError)):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
        with pytest.raises(DeviceFaultError):
            arm.move_tool(ToolStep(dz_mm=1.0))


def test_a_program_outliving_its_wait_is_aborted_and_reset_recovers(emulator, backing):
    release = threading.Event()
    original = backing._move_to

    def stuck(target):  # the arm's motion outlasts the driver's move timeout
        release.wait(WAIT_S)
        return original(target)

    backing._move_to = stuck
    lines = heard(emulator)
    with program_arm(emulator, move_timeout_s=0.3) as arm:
        with pytest.raises(DeviceTimeoutError):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0)
        release.set()
        assert "abort" in lines  # the driver stopped the program before giving up
        backing._move_to = original
        arm.reset()
        arm.activate()
        arm.move_tool(ToolStep(dz_mm=1.0))


def test_connecting_while_a_program_runs_stops_it_first(emulator, backing):
    release = threading.Event()
    original = backing._move_to

    def stuck(target):
        release.wait(WAIT_S)
        return original(target)

    with program_arm(emulator) as arm:
        arm.guarded_descent(down(10.0), down(20.0), 25.0, 4.0)  # programs entered and fitted
    backing._move_to = stuck
    session = emulator.monitor
    response = session.handle_line("ex fpdesc")  # another client left a program running
    response.after()
    assert session.program_running
    release.set()
    backing._move_to = original
    with program_arm(emulator) as arm:
        assert not session.program_running
        arm.move_tool(ToolStep(dz_mm=1.0))


def test_a_connect_that_finds_the_editor_open_ends_it_and_enters_the_program_again(emulator):
    """A link lost while a program was being entered leaves VAL in the editor: the next
    connect ends the editor, and the program, listed back short, is entered again."""
    import serial

    with serial.serial_for_url(emulator.url, timeout=WAIT_S) as raw:
        raw.write(b"\r")
        raw.read_until(b".")
        raw.write(b"edit fpdesc\r")
        raw.read_until(b"? ")
        raw.write(b"SPEED 100\r")
        raw.read_until(b"? ")  # the editor waits for line 2; the link is lost here
    lines = heard(emulator)
    with program_arm(emulator) as arm:
        assert arm.runs_programs
    assert "e" in lines[:3], lines[:5]  # the editor ended at start-up
    assert "edit fpdesc" in lines


def test_one_execute_descends_closes_and_lifts(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)
        descent = arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0, lift_mm=10.0)
        assert "DEPARTS 10.00" in lines  # fpgrip entered again with the lift asked for
        lines.clear()
        again = arm.guarded_descent(down(10.0), down(20.0), 25.0, 4.0, lift_mm=10.0)
    assert descent.closed and descent.lifted and not descent.contact
    assert descent.pose.z_mm == pytest.approx(HOME.z_mm - 20.0)
    assert again.lifted and backing.pose().z_mm == pytest.approx(HOME.z_mm - 10.0)
    assert backing.finger_width_mm() == 0.0
    assert [line.split()[0] for line in lines] == ["do", "do", "ex"]
    assert lines[-1] == "ex fpgrip"


def test_an_input_high_once_the_jaws_closed_stops_before_the_lift(emulator, backing):
    emulator.monitor.set_input(1001, lambda: backing.finger_width_mm() < 40.0)
    with program_arm(emulator) as arm:
        descent = arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0, lift_mm=10.0)
        assert arm.finger_width_mm() == 0.0
    assert descent.contact and descent.closed and not descent.lifted
    assert descent.pose.z_mm == pytest.approx(HOME.z_mm - 30.0)  # where reads it: no lift


def test_a_lift_beyond_the_safety_limits_refuses_the_whole_run(emulator, backing):
    with program_arm(emulator) as arm:
        lines = heard(emulator)
        with pytest.raises(MotionRejectedError):
            arm.guarded_descent(down(20.0), down(30.0), 25.0, 4.0, lift_mm=100.0)
    assert [line for line in lines if line != "where"] == [] and backing.moves == []
