"""The VAL emulator over the simulated cell: driver contract, joints, the CLI leaves."""

from __future__ import annotations

import argparse
import json
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drivers.contract import check_arm
from drivers.safety import SafetyLimits
from drivers.val import ValArm, ValConfig
from sim_backend.emulators.val import bench
from sim_backend.emulators.val.server import ValEmulator
from sim_backend.emulators.val.sim_arm import SIM_KINEMATICS, simulated_arm

LIMITS = SafetyLimits(max_step_mm=20.0, max_step_deg=30.0)
WAIT_S = 60.0  # bound on the CLI process starting PyBullet; no assertion depends on it
JOINT_TOL_DEG = 0.5  # the simulated arm's repeatability error moves its true joints a little


@pytest.fixture
def sim_arm():
    with simulated_arm() as arm:
        yield arm


@pytest.fixture
def emulator(sim_arm):
    with ValEmulator(sim_arm, kinematics=SIM_KINEMATICS) as emu:
        yield emu


def test_where_and_drive_report_the_simulated_joints(emulator, sim_arm):
    with ValArm(ValConfig(port=emulator.url)) as arm:
        reading = arm.where()
        assert reading.joints_deg == pytest.approx(sim_arm.cell.joint_angles_deg(),
                                                   abs=JOINT_TOL_DEG)
        arm.link.exchange("do drive 1,5,50", arm.config.move_timeout_s, echo=True)
        turned = arm.where().joints_deg
        assert turned[0] == pytest.approx(reading.joints_deg[0] + 5.0, abs=0.01)
        assert turned == pytest.approx(sim_arm.cell.joint_angles_deg(), abs=JOINT_TOL_DEG)


def test_bench_writes_round_trips_and_wire_times(tmp_path):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    out = tmp_path / "bench-val.json"
    assert bench.run(parser.parse_args(["--json", str(out), "--repeats", "20",
                                        "--timed-repeats", "1"])) == 0
    report = json.loads(out.read_text())
    for name in ("where", "speed"):
        numbers = report["commands"][name]
        assert numbers["round_trip_median_ms"] > 0
        wire_ms = (numbers["bytes_sent"] + numbers["bytes_received"]) * 10 / 9600 * 1000
        assert numbers["wire_time_ms_at_9600_baud"] == pytest.approx(wire_ms)
    assert report["commands"]["where"]["bytes_received"] > report["commands"]["speed"][
        "bytes_received"]
    timed = report["timed"]  # the realistic emulator: wall time next to wire and motion time
    assert timed["where"]["wire_ms"] == pytest.approx(272.9, rel=0.01)
    assert timed["where"]["motion_ms"] == 0.0
    assert timed["move_5mm"]["motion_ms"] > 0.0
    assert timed["move_5mm"]["wall_ms"] >= timed["move_5mm"]["wire_ms"] + timed["move_5mm"][
        "motion_ms"] - 5.0


def read_line_starting(process: subprocess.Popen, prefix: str) -> str:
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            if selector.select(deadline - time.monotonic()):
                line = process.stdout.readline()
                assert line, "the emulator exited before printing its port"
                if line.startswith(prefix):
                    return line[len(prefix):].strip()
    raise AssertionError(f"no line starting {prefix!r} within {WAIT_S} s")


@pytest.mark.slow
@pytest.mark.parametrize("transport", [["--pty"], ["--tcp", "0"]], ids=["pty", "tcp"])
def test_cli_serves_until_sigterm(transport):
    command = [sys.executable, "-m", "controller.cli", "sim", "val-emulator", *transport,
               "--boot-questions"]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          text=True) as process:
        try:
            url = read_line_starting(process, "VAL emulator on ")
            check_arm(lambda: ValArm(ValConfig(port=url), LIMITS))
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=WAIT_S) == 0
            assert "stopped by SIGTERM" in process.stdout.read()
        finally:
            if process.poll() is None:
                process.kill()


def test_the_emulated_cell_holds_a_part_its_config_declares(tmp_path):
    example = Path(__file__).resolve().parents[3] / "deploy" / "parts" / "example.yaml"
    config = tmp_path / "cell.yaml"
    config.write_text(example.read_text().replace("mesh: ", f"mesh: {example.parent}/")
                      + "scene:\n  object: {kind: wedge}\n")
    with simulated_arm(str(config)) as arm:
        assert arm.cell.object_kind == "wedge"
        assert arm.cell.part.color == (0.8, 0.3, 0.2)  # the declared default colour
