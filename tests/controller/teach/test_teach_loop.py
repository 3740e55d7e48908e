"""The 3D-mouse teach-in loop on scripted events and a fake arm: record, abort, refusals."""

from __future__ import annotations

import logging
from collections import deque

import pytest

from controller.cli import main
from controller.config import config_from_mapping
from controller.devices import CellDevices
from controller.fine_positioner import FinePositioner
from controller.teach.spacenav import TeachAborted, jog_and_record, teach_with_spacenav
from drivers.core.errors import ConfigError, FineposError
from drivers.core.parts import PARTS
from drivers.core.pose import ToolStep
from drivers.safety import SafetyLimits
from drivers.spacenav import ButtonEvent, MotionEvent
from tests.mocks.fakes import HOME, FakeArm

FULL = 350  # counts: full deflection with the default jog config
TEACH = {"jog": {"max_period_ms": 1000.0}}  # events alone carry the timing here


def motion(x=0, y=0, z=0, ry=0, period_ms=0) -> MotionEvent:
    return MotionEvent(x, y, z, 0, ry, 0, period_ms)


class ScriptedClient:
    """Hands out the given events, then nothing (each ``next_event`` returns at once)."""

    def __init__(self, events) -> None:
        self.events = deque(events)

    def next_event(self, timeout_s: float):
        return self.events.popleft() if self.events else None


@pytest.fixture
def arm():
    with FakeArm(SafetyLimits()) as fake:
        yield fake


@pytest.fixture
def fp(arm, tmp_path):
    config = config_from_mapping({"controller": {"teach": TEACH}})
    devices = CellDevices(arm=arm, camera=None, wrench=None, cell=None)
    return FinePositioner(devices, config, state_dir=tmp_path)


def run(fp, events, timeout_s=5.0):
    return jog_and_record(fp, ScriptedClient(events), fp.config.controller.teach,
                          grasp_depth_mm=50.0, object_width_mm=25.0, timeout_s=timeout_s)


def assert_pose_close(actual, expected, tol=1e-3):
    for name, value in expected.as_dict().items():
        assert getattr(actual, name) == pytest.approx(value, abs=tol), name


def test_record_button_stores_the_jogged_pose(fp, arm):
    # full x deflection held 0.5 s at 10 mm/s, a twist held 0.3 s at 10 deg/s, then record
    state = run(fp, [motion(x=FULL), motion(ry=-FULL, period_ms=500), motion(period_ms=300),
                     ButtonEvent(0, True), ButtonEvent(0, False)])
    expected = HOME.moved_in_tool_frame(ToolStep(5.0, 0.0, 0.0, 0.0)).moved_in_tool_frame(
        ToolStep(dphi_deg=3.0))
    assert state.source == "spacenav"
    assert_pose_close(state.nominal_pose, expected)
    assert_pose_close(fp.state().nominal_pose, expected)  # and it is in the state file
    assert arm.moves  # every jog went through move_tool, hence the safety layer


def test_axis_mapping_and_deadband(fp, arm):
    # -z drives dy (cap pulled towards the user), -y drives dz; 10 counts are in the deadband
    state = run(fp, [motion(x=10, y=-FULL, z=-FULL), motion(period_ms=200),
                     ButtonEvent(0, True)])
    assert_pose_close(state.nominal_pose, HOME.moved_in_tool_frame(ToolStep(0.0, 2.0, 2.0)))


def test_abort_button_writes_nothing(fp, arm):
    with pytest.raises(TeachAborted, match="aborted"):
        run(fp, [motion(x=FULL), motion(period_ms=300), ButtonEvent(1, True)])
    assert not fp.state_path.exists()


def test_abort_leaves_an_earlier_state_file_untouched(fp, arm):
    fp.teach("current", 50.0, 25.0)
    before = fp.state_path.read_bytes()
    with pytest.raises(TeachAborted):
        run(fp, [motion(x=FULL), motion(period_ms=300), ButtonEvent(1, True)])
    assert fp.state_path.read_bytes() == before


def test_timeout_without_record_writes_nothing(fp):
    with pytest.raises(TeachAborted, match="no record button within 0.2 s"):
        run(fp, [motion(x=FULL), motion(period_ms=100)], timeout_s=0.2)
    assert not fp.state_path.exists()


def test_releases_and_other_buttons_do_nothing(fp, arm):
    state = run(fp, [ButtonEvent(0, False), ButtonEvent(1, False), ButtonEvent(5, True),
                     ButtonEvent(0, True)])
    assert_pose_close(state.nominal_pose, HOME)
    assert not arm.moves


def test_refused_jog_step_stops_the_jog_and_is_not_executed(tmp_path, caplog):
    # HOME's tool x axis is world +y, and the workspace ends 1 mm beyond HOME in y: the 5 mm
    # jog along tool x is refused and the arm stays
    assert HOME.rotation()[1, 0] == pytest.approx(1.0)
    limits = SafetyLimits(workspace_max_mm=(450.0, HOME.y_mm + 1.0, 700.0))
    with FakeArm(limits, start=HOME) as arm:
        config = config_from_mapping({"controller": {"teach": TEACH}})
        fp = FinePositioner(CellDevices(arm, None, None, None), config, state_dir=tmp_path)
        with caplog.at_level(logging.WARNING, logger="controller.teach.spacenav"):
            state = run(fp, [motion(x=FULL), motion(period_ms=500), ButtonEvent(0, True)])
    assert_pose_close(state.nominal_pose, HOME)
    assert "refused" in caplog.text


def test_teach_section_is_strict():
    config = config_from_mapping({"controller": {"teach": {
        "record_button": 3, "abort_button": 4, "socket_path": "/tmp/s",
        "jog": {"deadband": 5, "dphi_deg": "rz"}}}})
    teach = config.controller.teach
    assert (teach.record_button, teach.abort_button, teach.jog.dphi_deg) == (3, 4, "rz")
    with pytest.raises(ConfigError, match="controller.teach: record_button and abort_button"):
        config_from_mapping({"controller": {"teach": {"record_button": 1}}})
    with pytest.raises(ConfigError, match="controller.teach.jog"):
        config_from_mapping({"controller": {"teach": {"jog": {"dx_mm": "w"}}}})
    with pytest.raises(ConfigError, match="controller.teach.buttons: unknown key"):
        config_from_mapping({"controller": {"teach": {"buttons": 2}}})


def test_real_cell_takes_the_grasp_geometry_from_the_parts_catalogue(fp):
    state = fp.teach("current")
    cube = PARTS["cube"]
    assert (state.object_kind, state.kappa) == ("cube", 4)
    assert state.grasp_depth_mm == cube.grasp_depth_mm == 50.0
    assert state.object_width_mm == cube.grasp_width_mm
    given = fp.teach("current", grasp_depth_mm=42.0, object_width_mm=29.0)
    assert (given.grasp_depth_mm, given.object_width_mm) == (42.0, 29.0)
    with pytest.raises(FineposError, match="--start-offset places the simulated arm"):
        teach_with_spacenav(fp, start_offset=(1.0, 2.0, 3.0), grasp_depth_mm=50.0,
                            object_width_mm=25.0)


def test_spacenav_options_need_the_spacenav_device(capsys):
    assert main(["teach", "--auto", "--start-offset", "1,2,3"]) == 2
    assert "--start-offset: only with --device spacenav" in capsys.readouterr().err
