"""The self-check (controller.teach.self_check) and ``finepos check`` on the simulated cell."""

import json

import numpy as np
import pytest

from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.teach.self_check import CheckLimits, self_check, similarity
from sim_backend.cell.scene_config import MountConfig


def test_similarity_is_one_for_the_same_view_and_drops_for_another():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 255, (144, 192, 3), dtype=np.uint8)
    assert similarity(image, image) == pytest.approx(1.0)
    assert similarity(image, (image * 0.5).astype(np.uint8)) > 0.99  # brightness: no matter
    assert similarity(image, np.roll(image, 15, axis=1)) < 0.5


@pytest.mark.slow
def test_passes_on_the_trained_cell_and_fires_after_a_5_deg_tilt(trained):
    cfg = load_config(None)
    with open_devices(cfg, seed=5) as devices:
        fp = FinePositioner(devices, cfg, state_dir=trained)
        ok = self_check(fp)
        assert not ok.fired, ok.message
        assert ok.similarity > CheckLimits().min_similarity
        devices.cell.set_camera_mount(MountConfig(tilt_deg=5.0))
        knocked = self_check(fp)
    assert knocked.fired
    assert "new teach-in" in knocked.message
    assert np.hypot(knocked.correction["dx_mm"], knocked.correction["dy_mm"]) > 2.0


@pytest.mark.slow
def test_cli_check_exit_status(trained, tmp_path, capsys):
    assert main(["check", "--state-dir", str(trained), "--seed", "3"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["check"] == "passed" and report["reference"].startswith("nn1")
    knocked = tmp_path / "knocked.yaml"
    knocked.write_text("scene: {camera: {mount: {tilt_deg: 5.0}}}\n")
    assert main(["check", "--state-dir", str(trained), "--config", str(knocked)]) == 1
    assert json.loads(capsys.readouterr().out)["check"] == "fired"
    assert main(["check", "--state-dir", str(trained), "--part", "nut"]) == 1
    assert "taught on the cube" in json.loads(capsys.readouterr().out)["reasons"][0]


def test_cli_check_without_teach_in_is_an_error(tmp_path, capsys):
    assert main(["check", "--state-dir", str(tmp_path)]) == 2
    assert "finepos: error:" in capsys.readouterr().err
