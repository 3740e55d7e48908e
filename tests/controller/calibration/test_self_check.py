"""The self-check (controller.calibration.self_check) and `finepos check` on the simulated
cell."""

import json

import numpy as np
import pytest

from controller.calibration.self_check import CheckLimits, self_check, similarity
from controller.cli import main
from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
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


# -- what it reads, it reads whole (issue 51, defect 7) ------------------------------------------
def _taught_folder(folder):
    from drivers.core.cell_state import CellState
    from drivers.core.pose import Pose

    CellState(Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0), "cube", 4, 20.0, 30.0, "auto",
              CellState.now()).save(folder / "cell.json")
    (folder / "datasets").mkdir()
    return folder


@pytest.mark.parametrize("damage", ["garbage", "truncated zip", "a FIFO", "a dangling link"])
def test_cli_check_fails_on_an_unreadable_dataset_naming_it(tmp_path, capsys, damage):
    import os
    import zipfile

    state = _taught_folder(tmp_path / "state")
    for name in ("nn1", "nn2"):
        path = state / "datasets" / f"{name}.npz"
        if damage == "garbage":
            path.write_bytes(os.urandom(4096))
        elif damage == "truncated zip":
            with zipfile.ZipFile(path, "w") as archive:
                archive.writestr("labels.npy", b"\x93NUMPY" + b"\0" * 100)
            path.write_bytes(path.read_bytes()[:60])
        elif damage == "a FIFO":
            os.mkfifo(path)
        else:
            path.symlink_to(tmp_path / "gone.npz")
    assert main(["check", "--state-dir", str(state)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("finepos: error: "), err
    assert str(state / "datasets" / "nn1.npz") in err[0] and "internal error" not in err[0]


def test_cli_check_fails_on_a_damaged_model_naming_it(tmp_path, capsys):
    state = _taught_folder(tmp_path / "state")
    (state / "model-gabor.fpm").write_bytes(b"not a model" * 100)
    assert main(["check", "--state-dir", str(state)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(state / "model-gabor.fpm") in err[0], err


class _Stub:
    """What self_check asks of a FinePositioner, failing the test if the arm is moved."""

    def __init__(self, folder) -> None:
        from drivers.core.cell_state import CellState

        self.folder = folder
        self._state = CellState.load(folder / "cell.json")

    def state(self):
        return self._state

    def dataset_path(self, name):
        return self.folder / "datasets" / f"{name}.npz"

    def load_model(self, system="gabor"):
        raise LookupError("the model was asked for")

    def move_to(self, pose):
        raise AssertionError("the arm moved before the files were checked")


def test_every_stored_set_is_read_before_the_arm_moves(tmp_path):
    from calibration_free.dataset import Dataset
    from calibration_free.errors import DatasetError

    state = _taught_folder(tmp_path / "state")
    images = np.zeros((1, 24, 32, 3), np.uint8)
    Dataset(np.zeros((1, 3)), images, None, None, {}).save(state / "datasets" / "nn1.npz")
    with pytest.raises(LookupError):  # a good nn1 alone: on to the model
        self_check(_Stub(state))
    (state / "datasets" / "nn2.npz").write_bytes(b"PK\x03\x04 not a zip")  # nn1 is the reference
    with pytest.raises(DatasetError, match="nn2.npz"):
        self_check(_Stub(state))
