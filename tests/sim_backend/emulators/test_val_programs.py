"""VAL programs in the emulated monitor: line entry, listing, EXECUTE with the ``*`` prompt,
reactions on an input line, ABORT during a program, and refusals of what it does not know."""

from __future__ import annotations

import queue
import threading

import pytest

from drivers.core.pose import Pose
from sim_backend.emulators.val.monitor import ValMonitor
from tests.mocks.fakes import HOME, FakeArm

WAIT_S = 5.0  # bound on waiting for the program thread; no assertion depends on it
DESCENT = ["SPEED 100", "OPEN", "REACTI 1001, fpstop", "MOVES fpa", "SPEED 20", "MOVES fpd",
           "IGNORE 1001"]


class Session:
    """Types lines into a ValMonitor; a program's closing output arrives in ``ended``."""

    def __init__(self, monitor: ValMonitor) -> None:
        self.monitor = monitor
        self.ended: queue.Queue[str] = queue.Queue()
        monitor.on_program_end = lambda data: self.ended.put(data.decode("ascii"))

    def __call__(self, line: str) -> str:
        response = self.monitor.handle_line(line)
        if response.after is not None:
            response.after()
        return response.reply.decode("ascii")

    def enter(self, name: str, lines: list[str]) -> None:
        assert self(f"edit {name}").endswith("  1? ")
        for i, line in enumerate(lines, 2):
            assert self(line).endswith(f"{i:3d}? ")
        assert self("e") == "."


@pytest.fixture
def arm():
    with FakeArm() as arm:
        yield arm


@pytest.fixture
def session(arm):
    return Session(ValMonitor(arm))


def set_location(session: Session, name: str, pose: Pose) -> None:
    values = ",".join(f"{v:.3f}" for v in pose.as_dict().values())
    assert session(f"do set {name}=trans({values})") == "."


def test_program_entered_line_by_line_lists_back(session):
    session.enter("fpdesc", DESCENT)
    listing = session("listp fpdesc").splitlines()
    assert listing[0] == "PROGRAM fpdesc" and listing[-2] == "END" and listing[-1] == "."
    assert [line.split(None, 1)[1] for line in listing[1:-2]] == DESCENT


def test_an_unknown_instruction_gets_the_error_and_the_same_line_again(session):
    session("edit p")
    reply = session("WELD 3")
    assert "*Unknown instruction*" in reply and reply.endswith("  1? ")
    reply = session("SPEED fast")
    assert "*Syntax error*" in reply and reply.endswith("  1? ")
    session("e")
    assert session("listp p").splitlines()[1] == "END"
    assert "*Undefined program*" in session("listp nothing")
    assert "*Undefined program*" in session("ex nothing")


def test_execute_answers_the_star_prompt_and_ends_with_the_dot(session, arm):
    target = Pose(HOME.x_mm, HOME.y_mm, HOME.z_mm - 30.0, HOME.o_deg, HOME.a_deg, HOME.t_deg)
    set_location(session, "fpd", target)
    session.enter("go", ["MOVES fpd", "TYPE FPDONE"])
    assert session("ex go") == "*"
    assert session.ended.get(timeout=WAIT_S) == "\r\nFPDONE\r\n."
    assert arm.pose().z_mm == pytest.approx(target.z_mm)


def test_a_reaction_stops_the_motion_where_the_input_went_high(session, arm):
    start_z = HOME.z_mm
    monitor = session.monitor
    monitor.set_input(1001, lambda: start_z - arm.pose().z_mm >= 10.0)
    via = Pose(HOME.x_mm, HOME.y_mm, HOME.z_mm - 5.0, HOME.o_deg, HOME.a_deg, HOME.t_deg)
    down = Pose(HOME.x_mm, HOME.y_mm, HOME.z_mm - 30.0, HOME.o_deg, HOME.a_deg, HOME.t_deg)
    set_location(session, "fpa", via)
    set_location(session, "fpd", down)
    session.enter("fpstop", ["TYPE FPCONTACT", "STOP"])
    session.enter("fpdesc", DESCENT + ["TYPE FPEND"])
    assert session("ex fpdesc") == "*"
    assert session.ended.get(timeout=WAIT_S) == "\r\nFPCONTACT\r\n."
    assert start_z - arm.pose().z_mm == pytest.approx(10.0, abs=0.51)


def test_an_input_high_when_armed_reacts_before_any_motion(session, arm):
    session.monitor.set_input(1001, lambda: True)
    set_location(session, "fpa", Pose(HOME.x_mm, 0, HOME.z_mm - 5, HOME.o_deg, HOME.a_deg,
                                      HOME.t_deg))
    set_location(session, "fpd", Pose(HOME.x_mm, 0, HOME.z_mm - 9, HOME.o_deg, HOME.a_deg,
                                      HOME.t_deg))
    session.enter("fpstop", ["TYPE FPCONTACT", "STOP"])
    session.enter("fpdesc", DESCENT)
    session("ex fpdesc")
    assert session.ended.get(timeout=WAIT_S) == "\r\nFPCONTACT\r\n."
    assert arm.moves == []


def test_abort_stops_a_running_program_at_once(session, arm):
    release = threading.Event()
    moving = threading.Event()
    original = arm._move_to

    def slow_move(target):
        moving.set()
        release.wait(WAIT_S)
        return original(target)

    arm._move_to = slow_move
    set_location(session, "fpd", Pose(HOME.x_mm, 0, HOME.z_mm - 30, HOME.o_deg, HOME.a_deg,
                                      HOME.t_deg))
    session.enter("go", ["MOVES fpd", "TYPE FPDONE"])
    session("ex go")
    assert moving.wait(WAIT_S)
    assert "*Program already running*" in session("speed 50")
    assert "X" in session("where")
    release.set()
    assert session("abort") == "."
    assert session.ended.empty()  # an aborted program prints nothing more
    assert arm.halts >= 1
    assert HOME.z_mm - arm.pose().z_mm < 30.0
    assert session("where").endswith(".")


def test_departs_backs_off_along_the_approach_axis(session, arm):
    down = Pose(HOME.x_mm, HOME.y_mm, HOME.z_mm - 30.0, HOME.o_deg, HOME.a_deg, HOME.t_deg)
    set_location(session, "fpd", down)
    session.enter("lift", ["MOVES fpd", "CLOSEI", "DEPARTS 10", "TYPE FPUP"])
    session("ex lift")
    assert session.ended.get(timeout=WAIT_S) == "\r\nFPUP\r\n."
    assert arm.pose().z_mm == pytest.approx(HOME.z_mm - 20.0)
    assert arm.finger_width_mm() == 0.0  # closed before the lift
