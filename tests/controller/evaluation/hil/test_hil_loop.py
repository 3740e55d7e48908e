"""Hardware in the loop: the positioning loop and the guarded grasp through the real drivers.

``finepos evaluate --hil`` serves its simulated cell over the VAL, ATI and MJPEG emulators in
process; ``finepos position`` runs against ``finepos sim val-emulator --ati --mjpeg 0`` in
another process, configured by the file that command writes. The model is trained once, on
the simulated devices directly, so the device path is the only difference.
"""

from __future__ import annotations

import json
import selectors
import signal
import subprocess
import sys
import time

import pytest

from controller.cli import main
from controller.config import load_config
from controller.evaluation.metrics import is_safe
from controller.evaluation.trials import train_on_default_scene

pytestmark = pytest.mark.slow

START_TIMEOUT_S = 60.0  # bound on the emulator process starting PyBullet


@pytest.fixture(scope="module")
def state_dir(tmp_path_factory):
    """A state folder with the taught pose (default scene) and a gabor model trained there."""
    folder = tmp_path_factory.mktemp("state")
    train_on_default_scene("gabor", load_config(None), folder, seed=0, progress=False)
    return folder


def test_evaluate_hil_converges_to_the_safe_tolerance(state_dir, tmp_path, capsys):
    (model_path,) = state_dir.glob("model-gabor*")
    states_path = tmp_path / "states.json"
    capsys.readouterr()
    assert main(["evaluate", "--hil", "--model", str(model_path), "--trials", "3",
                 "--seed", "2", "--quiet", "--states", str(states_path),
                 "--timing", "ideal"]) == 0  # realistic HIL runs in real time
    report = json.loads(capsys.readouterr().out)
    finals = [trace[-1] for trace in json.loads(states_path.read_text())]
    assert report["hil"] is True
    assert report["outcomes"].get("converged", 0) + report["outcomes"].get("budget", 0) == 3
    assert all(is_safe(error) for _loops, error in finals), finals
    assert report["grasp_success_rate"] == 1.0


def read_lines_until(process: subprocess.Popen, last_prefix: str) -> dict[str, str]:
    """The emulator's stdout lines, by their text before the value, up to ``last_prefix``."""
    lines: dict[str, str] = {}
    deadline_s = time.monotonic() + START_TIMEOUT_S
    with selectors.DefaultSelector() as selector:
        selector.register(process.stdout, selectors.EVENT_READ)
        while time.monotonic() < deadline_s:
            if not selector.select(deadline_s - time.monotonic()):
                continue
            line = process.stdout.readline()
            assert line, f"the emulator exited early after {lines}"
            for prefix in ("VAL emulator on ", "ATI F/T emulator on ", "camera stream on ",
                           "device options: ", "config written to "):
                if line.startswith(prefix):
                    lines[prefix.strip()] = line[len(prefix):].strip()
            if line.startswith(last_prefix):
                return lines
    raise AssertionError(f"no line starting {last_prefix!r} within {START_TIMEOUT_S} s")


def test_position_and_grasp_against_the_emulator_process(state_dir, tmp_path, capsys):
    config_path = tmp_path / "hil.yaml"
    command = [sys.executable, "-m", "controller.cli", "sim", "val-emulator", "--ati",
               "--mjpeg", "0", "--write-config", str(config_path)]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                          text=True) as process:
        try:
            lines = read_lines_until(process, "config written to ")
            capsys.readouterr()
            exit_code = main(["position", "--config", str(config_path), "--state-dir",
                              str(state_dir), "--offset", "12,-8,20", "--grasp",
                              "--log", str(tmp_path / "iterations.jsonl")])
            report = json.loads(capsys.readouterr().out)
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=START_TIMEOUT_S) == 0
        finally:
            if process.poll() is None:
                process.kill()
    assert lines["VAL emulator on"].startswith("/dev/pts/")
    assert lines["ATI F/T emulator on"].startswith("/dev/pts/")
    assert lines["camera stream on"].startswith("http://127.0.0.1:")
    assert lines["camera stream on"] in lines["device options:"]
    assert exit_code == 0, report
    assert report["outcome"] in ("converged", "budget")
    assert report["grasp"]["success"] is True, report["grasp"]
