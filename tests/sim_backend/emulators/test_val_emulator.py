"""The VAL II monitor emulator: its dialogue (directly), and the strings public PUMA 260 drivers
send, over a real pty and TCP."""

from __future__ import annotations

import time

import pytest
import serial

from drivers.core.pose import Pose
from drivers.safety import SafetyLimits
from drivers.val.replies import ReplyKind, parse_reply, reply_complete
from drivers.val.where import parse_where
from sim_backend.emulators.val.kinematics import NEST_DEG, READY_DEG, Puma260
from sim_backend.emulators.val.lines import LineAssembler
from sim_backend.emulators.val.monitor import ValMonitor
from sim_backend.emulators.val.server import ValEmulator
from tests.mocks.fakes import HOME, FakeArm

WAIT_S = 5.0  # bound on waiting for the emulator thread; no assertion depends on it
KINEMATICS = Puma260()
WIDE = SafetyLimits(workspace_min_mm=(-900, -900, -900), workspace_max_mm=(900, 900, 900),
                    max_step_mm=1e4, max_step_deg=360)


@pytest.fixture
def backing():
    with FakeArm() as arm:
        yield arm


class Session:
    """Types lines into a ValMonitor and returns the reply text (echo removed)."""

    def __init__(self, monitor: ValMonitor) -> None:
        self.monitor = monitor

    def __call__(self, line: str) -> str:
        response = self.monitor.handle_line(line)
        assert response.echo == line.encode() + b"\r\n"
        return response.reply.decode("ascii")


@pytest.fixture
def session(backing):
    return Session(ValMonitor(backing))


def where(session: Session):
    return parse_where(session("where").splitlines())


def close_to(a: Pose, b: Pose, tol: float = 0.01) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a.as_dict().values(), b.as_dict().values(),
                                                 strict=True))


# -- monitor dialogue ------------------------------------------------------------------------
def test_where_table_with_joint_lines(session, backing):
    text = session("where")
    assert text.endswith("\r\n.")
    reading = parse_where(text.splitlines())
    assert close_to(reading.pose, HOME)
    assert close_to(KINEMATICS.forward(reading.joints_deg), HOME)


def test_where_without_joint_lines_when_no_joint_solution():
    with FakeArm(start=Pose(2000.0, 0.0, 0.0, 0.0, 0.0, 0.0)) as far:
        reading = where(Session(ValMonitor(far)))
        assert reading.pose.x_mm == 2000.0 and reading.joints_deg is None


def test_commands_are_case_insensitive_and_abbreviated(session):
    assert session("WHERE") == session("w")
    assert session("  Speed   30 ") == "."


def test_boot_questions_then_prompt(backing):
    monitor = ValMonitor(backing, boot_questions=True)
    assert monitor.first_output() == b"Load VAL from floppy (Y/N)? "
    talk = Session(monitor)
    assert talk("") == "Load VAL from floppy (Y/N)? "  # asked again
    assert talk("maybe") == "Load VAL from floppy (Y/N)? "
    assert talk("N") == "Initialize (Y/N)? "
    assert talk("n") == "."
    assert parse_reply(b"n\r\n" + talk("").encode(), None).kind is ReplyKind.OK


def test_speed_and_gripper_and_abort(session, backing):
    assert session("speed 40") == "."
    assert backing.speed_percent == 40
    assert session("speed 500") == "*Value out of range*\r\n."
    assert session("do closei") == "." and backing.finger_width_mm() == 0.0
    assert session("do openi") == "." and backing.finger_width_mm() == 40.0
    assert session("abort") == "." and backing.halts == 1


def test_move_trans(session, backing):
    assert session("do move trans(310,5,140,-90,90,15)") == "."
    assert backing.pose() == Pose(310, 5, 140, -90, 90, 15)


@pytest.mark.parametrize("line, message", [
    ("do move trans(1,2,3)", "Syntax error"),
    ("do move trans(1,2,3,4,5,x)", "Syntax error"),
    ("do move", "Syntax error"),
    ("do fly", "Syntax error"),
    ("speed", "Syntax error"),
    ("where now", "Syntax error"),
    ("fly away", "Unknown command"),
    ("do move nowhere", "Undefined location"),
    ("do move #nowhere", "Undefined location"),
    ("do drive 7,10,50", "Syntax error"),
    ("do drive 1,10,0", "Value out of range"),
    ("do drive 2,300,50", "Position out of range"),
])
def test_errors(session, backing, line, message):
    assert session(line) == f"*{message}*\r\n."
    assert backing.moves == []


def test_unreachable_pose_from_the_arm():
    with FakeArm(SafetyLimits(workspace_min_mm=(-450, -450, 100), max_step_mm=1e4,
                              max_step_deg=360)) as arm:
        talk = Session(ValMonitor(arm))
        assert talk("do move trans(300,0,50,-90,90,0)") == "*Position out of range*\r\n."
        assert arm.moves == []


def test_drive_turns_one_joint(session):
    before = where(session).joints_deg
    assert session("do drive 1,10,100") == "."
    after = where(session).joints_deg
    assert after[0] == pytest.approx(before[0] + 10.0, abs=0.01)
    assert after[1:] == pytest.approx(before[1:], abs=0.01)


def test_ready_and_nest():
    with FakeArm(WIDE) as arm:
        talk = Session(ValMonitor(arm))
        assert talk("do ready") == "."
        assert close_to(arm.pose(), KINEMATICS.forward(READY_DEG))
        assert talk("do nest") == "."
        assert where(talk).joints_deg == pytest.approx(NEST_DEG, abs=0.01)


def test_calibration_asks_first(session):
    assert session("cal") == "Are you sure (Y/N)? "
    assert session("y") == "."


def test_transformation_dialogue(session, backing):
    shown = session("poi pick")
    assert shown.endswith("Change? ") and "X" in shown
    changed = session("310,5,140,-90,90,15")
    assert parse_where(changed.splitlines()[:-1]).pose == Pose(310, 5, 140, -90, 90, 15)
    assert session(",,145") .endswith("Change? ")  # empty fields keep their values
    assert session("") == "."
    assert session("") == "."  # the public driver's second empty line: just a prompt
    assert session("do move pick") == "."
    assert backing.pose() == Pose(310, 5, 145, -90, 90, 15)


def test_precision_point_dialogue(session, backing):
    joints = (-20.0, 25.0, -170.0, 0.0, -25.0, 60.0)
    assert session("point #x").endswith("Change? ")
    assert session(", ".join(f"{q:g}" for q in joints)).endswith("Change? ")
    assert session("") == "."
    assert session("do move #x") == "."
    assert close_to(backing.pose(), KINEMATICS.forward(joints))
    assert where(session).joints_deg == pytest.approx(joints, abs=0.01)


def test_bad_change_input_asks_again(session):
    session("poi a")
    assert session("1,2,x").startswith("*Syntax error*\r\n")


# -- kinematics and input lines ------------------------------------------------------------------
@pytest.mark.parametrize("joints", [NEST_DEG, (30, 60, -150, 10, 40, 200),
                                    (-100, 10, -200, -300, 150, -100)])
def test_inverse_recovers_joints_near_the_seed(joints):
    pose = KINEMATICS.forward(joints)
    solved = KINEMATICS.inverse(pose, [q + 3.0 for q in joints])
    assert solved == pytest.approx(joints, abs=1e-3)


def test_inverse_at_the_stretched_singularity_reaches_the_pose():
    pose = KINEMATICS.forward(READY_DEG)
    solved = KINEMATICS.inverse(pose, [q + 3.0 for q in READY_DEG])
    assert close_to(KINEMATICS.forward(solved), pose, tol=1e-3)


def test_inverse_keeps_joints_in_range():
    pose = KINEMATICS.forward((30, 60, -150, 10, 40, 200))
    # JT6 = 560 is out of range; of the turns in range (200, -160) the nearest one is taken.
    assert KINEMATICS.inverse(pose, (30, 60, -150, 10, 40, 560)) == pytest.approx(
        (30, 60, -150, 10, 40, 200), abs=1e-3)


def test_inverse_reports_unreachable_poses():
    assert KINEMATICS.inverse(Pose(2000, 0, 0, 0, 0, 0), READY_DEG) is None


def test_base_offset_and_tool_length_shift_the_pose():
    shifted = Puma260(base_mm=(10.0, 20.0, 30.0), tool_length_mm=50.0).forward(READY_DEG)
    plain = KINEMATICS.forward(READY_DEG)
    assert (shifted.x_mm, shifted.y_mm, shifted.z_mm) == pytest.approx(
        (plain.x_mm + 10.0, plain.y_mm + 20.0, plain.z_mm + 80.0))  # READY points up


@pytest.mark.parametrize("chunks, lines", [
    ([b"where\r"], ["where"]),
    ([b"where\n\r"], ["where"]),
    ([b"where\r\n"], ["where"]),
    ([b"a\r\rb\n"], ["a", "", "b"]),
    ([b"point #x\n\r", b"1,2,3,4,5,6\n\r\n\r"], ["point #x", "1,2,3,4,5,6", ""]),
    ([b"where\n", b"\rspeed 5\r"], ["where", "speed 5"]),  # a pair split across reads
])
def test_line_assembler(chunks, lines):
    assembler = LineAssembler()
    assert [line for chunk in chunks for line in assembler.feed(chunk)] == lines


# -- over the wire ---------------------------------------------------------------------------
def read_until(port: serial.SerialBase, done) -> bytes:
    data = b""
    deadline = time.monotonic() + WAIT_S
    while not done(data):
        assert time.monotonic() < deadline, f"reply incomplete: {data!r}"
        data += port.read(max(1, port.in_waiting))
    return data


def read_reply(port: serial.SerialBase, command: str | None) -> bytes:
    return read_until(port, lambda data: reply_complete(data, command))


@pytest.mark.parametrize("tcp", [False, True], ids=["pty", "tcp"])
def test_public_driver_strings_over_the_wire(backing, tcp):
    """The byte strings a public C driver for the PUMA 260 writes (``\\n\\r`` endings, several
    lines in one write, no waiting for prompts between them)."""
    with ValEmulator(backing, tcp_port=0 if tcp else None, boot_questions=True) as emu, \
            serial.serial_for_url(emu.url, baudrate=9600, timeout=0.05) as port:
        port.reset_input_buffer()  # a TCP client never saw the power-up question; wake up
        port.write(b"\n\r")
        assert read_reply(port, None).rstrip().endswith(b"Load VAL from floppy (Y/N)?")
        port.write(b"n\n\r")
        assert read_reply(port, "n").rstrip().endswith(b"Initialize (Y/N)?")
        port.write(b"n\n\r")
        assert read_reply(port, "n").endswith(b"\r\n.")
        port.write(b"speed 50\n\r")
        assert parse_reply(read_reply(port, "speed 50"), "speed 50").kind is ReplyKind.OK
        port.write(b"point #x\n\r-20, 25, -170, 0, -25, 60\n\r\n\r")
        # the answer echoes after "Change? "; the empty line ends the dialogue with a prompt
        read_until(port, lambda data: data.endswith(b"Change? \r\n."))
        port.write(b"do move #x\n\r")
        assert parse_reply(read_reply(port, "do move #x"), "do move #x").kind is ReplyKind.OK
        port.write(b"where\n\r")
        reading = parse_where(parse_reply(read_reply(port, "where"), "where").lines)
        assert reading.joints_deg == pytest.approx((-20, 25, -170, 0, -25, 60), abs=0.01)
        port.write(b"do move trans(300,0,150,-90,90,0)\n\r")
        read_reply(port, "do move trans(300,0,150,-90,90,0)")
        assert backing.pose() == HOME
