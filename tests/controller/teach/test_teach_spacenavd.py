"""Teach-in end to end with the real spacenavd: Magellan emulator -> daemon -> teach-in loop ->
simulated arm -> state file.

The scripted jog is computed from the known start displacement so that it brings the gripper
to the part's true grasp pose; the stored pose must be within 0.5 mm / 0.5 deg of it. Skipped
with a reason where spacenavd is absent (failing instead with FINEPOS_REQUIRE_SPACENAVD=1).
"""

from __future__ import annotations

import json
import logging
import math
import threading

import numpy as np
import pytest

from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.teach.spacenav import TeachAborted, displaced, jog_and_record
from drivers.core.cell_state import CellState
from drivers.core.pose import Pose
from drivers.spacenav import SpacenavClient
from sim_backend.emulators.magellan.script import Motion, click
from tests.controller.teach.jog_script import REST, jog_script

pytestmark = pytest.mark.slow

POSITION_TOL_MM = 0.5
ANGLE_TOL_DEG = 0.5
START_OFFSET = (4.0, -3.0, 5.0)  # mm, mm, deg
TIMEOUT_S = 60.0  # bound on one teach-in; the jogs take a few seconds


def pose_error(a: Pose, b: Pose) -> tuple[float, float]:
    """(distance in mm, rotation angle in deg) between two poses."""
    distance_mm = float(np.linalg.norm(a.position_mm - b.position_mm))
    cos = (np.trace(a.rotation().T @ b.rotation()) - 1.0) / 2.0
    return distance_mm, math.degrees(math.acos(max(-1.0, min(1.0, cos))))


@pytest.fixture
def sim(tmp_path):
    config = load_config(None)
    with open_devices(config) as devices:
        yield FinePositioner(devices, config, state_dir=tmp_path / "state")


def test_scripted_jog_teaches_the_true_grasp_pose(mouse_and_daemon, sim):
    mouse, daemon = mouse_and_daemon
    truth = sim.devices.cell.nominal_grasp_pose()
    sim.move_to(displaced(truth, START_OFFSET))
    start_error = pose_error(sim.devices.arm.pose(), truth)
    teach = sim.config.controller.teach
    with SpacenavClient(daemon.socket_path) as client:
        needed = sim.devices.arm.pose().tool_step_to(truth)
        mouse.play(jog_script(needed, teach.jog) + click(teach.record_button))
        state = jog_and_record(sim, client, teach, timeout_s=TIMEOUT_S)
    stored = CellState.load(sim.state_path)
    distance_mm, angle_deg = pose_error(stored.nominal_pose, truth)
    assert start_error[0] > 4.0 and start_error[1] > 4.0  # there was something to jog
    assert distance_mm < POSITION_TOL_MM, daemon.log_tail()
    assert angle_deg < ANGLE_TOL_DEG
    assert stored == state and stored.source == "spacenav"


def test_abort_button_writes_nothing(mouse_and_daemon, sim):
    mouse, daemon = mouse_and_daemon
    teach = sim.config.controller.teach
    with SpacenavClient(daemon.socket_path) as client:
        mouse.play([Motion((200, 0, 0, 0, 0, 0), 0.3), Motion(REST, 0.1),
                    *click(teach.abort_button)])
        with pytest.raises(TeachAborted):
            jog_and_record(sim, client, teach, timeout_s=TIMEOUT_S)
    assert not sim.state_path.exists()


class Started(logging.Handler):
    """Sets ``event`` once the teach-in loop says it is listening."""

    def __init__(self) -> None:
        super().__init__()
        self.event = threading.Event()

    def emit(self, record: logging.LogRecord) -> None:
        if record.getMessage().startswith("teach-in: jog with the 3D mouse"):
            self.event.set()


def run_teach_command(argv: list[str], script, mouse) -> int:
    """Run ``finepos teach`` in a thread; play ``script`` once its loop listens."""
    started = Started()
    logger = logging.getLogger("controller.teach.spacenav")
    level = logger.level
    logger.setLevel(logging.INFO)
    logger.addHandler(started)
    exit_codes: list[int] = []
    thread = threading.Thread(target=lambda: exit_codes.append(main(argv)))
    try:
        thread.start()
        assert started.event.wait(TIMEOUT_S), "the teach-in loop did not start"
        mouse.play(script)
        thread.join(TIMEOUT_S)
    finally:
        logger.removeHandler(started)
        logger.setLevel(level)
    assert not thread.is_alive() and exit_codes, "finepos teach did not finish"
    return exit_codes[0]


def test_teach_command_jogs_from_the_start_offset_and_records(tmp_path, mouse_and_daemon,
                                                              capsys):
    mouse, daemon = mouse_and_daemon
    assert main(["teach", "--auto", "--state-dir", str(tmp_path / "truth")]) == 0
    truth = CellState.load(tmp_path / "truth" / "cube" / "cell.json").nominal_pose
    offset = (3.0, 2.0, -4.0)
    needed = displaced(truth, offset).tool_step_to(truth)
    teach = load_config(None).controller.teach
    state_dir = tmp_path / "state"
    argv = ["teach", "--device", "spacenav", "--state-dir", str(state_dir), "--spnav-socket",
            daemon.socket_path, "--start-offset", ",".join(map(str, offset)),
            "--timeout-s", str(TIMEOUT_S)]
    capsys.readouterr()
    assert run_teach_command(argv, jog_script(needed, teach.jog) + click(0), mouse) == 0
    report = json.loads(capsys.readouterr().out)
    stored = CellState.load(state_dir / "cube" / "cell.json")  # the simulated cell's part
    distance_mm, angle_deg = pose_error(stored.nominal_pose, truth)
    assert report["source"] == "spacenav" and report["state_file"] == str(
        state_dir / "cube" / "cell.json")
    assert distance_mm < POSITION_TOL_MM and angle_deg < ANGLE_TOL_DEG


def test_teach_command_abort_exits_1_and_writes_nothing(tmp_path, mouse_and_daemon, capsys):
    mouse, daemon = mouse_and_daemon
    argv = ["teach", "--device", "spacenav", "--state-dir", str(tmp_path), "--spnav-socket",
            daemon.socket_path, "--timeout-s", str(TIMEOUT_S)]
    capsys.readouterr()
    assert run_teach_command(argv, [Motion((0, 0, 150, 0, 0, 0), 0.2), Motion(REST, 0.1),
                                    *click(1)], mouse) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["aborted"] is True
    assert not list(tmp_path.rglob("cell.json"))
