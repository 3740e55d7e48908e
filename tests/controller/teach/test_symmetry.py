"""A part's kappa found from its own images: the judging of the shift scores (pure), the
search on the simulated cell, and teach-in with kappa left out, confirmed or unsure."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from controller import cli
from controller.config import load_config, with_part
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.teach import symmetry
from controller.teach.symmetry import judge
from drivers.core.errors import FineposError

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "deploy" / "parts" / "example.yaml"


def _periodic(period: int, same: float, other: float, looks: int = 12) -> list[float]:
    return [same if d % period == 0 else other for d in range(1, looks)]


@pytest.mark.parametrize("scores, kappa", [
    (_periodic(2, 0.02, 0.24), 6),  # the nut in good light: a 30 deg turn differs 0.24 px
    ([0.30, 0.17, 0.35, 0.20, 0.33, 0.18, 0.33, 0.20, 0.35, 0.17, 0.30], 6),  # the nut, poor
    (_periodic(3, 0.22, 1.24), 4),  # the cube in poor light
    (_periodic(6, 0.02, 4.5), 2),  # the ledge
    (_periodic(4, 0.03, 2.0), 3),
    ([3.3, 5.7, 7.3, 6.7, 4.7, 3.5, 4.7, 6.7, 7.3, 5.7, 3.3], 1),  # the screw: no turn repeats
])
def test_a_clear_pattern_gives_its_kappa_surely(scores, kappa):
    found = judge(scores, 0.05)
    assert (found.kappa, found.sure) == (kappa, True), found.reason
    assert 0.25 <= found.confidence <= 1.0


@pytest.mark.parametrize("scores, kappa", [
    (_periodic(6, 0.7, 4.0), 1),  # a half turn almost repeats the view: nearly symmetric
    (_periodic(2, 0.20, 0.25), None),  # repeating and other shifts barely apart: none fits
    ([0.2, 0.3, 0.1, 0.3, 0.2, 0.3, 0.25, 0.3, 0.1, 0.3, 0.2], None),  # round: nothing changes
])
def test_weak_evidence_is_unsure_never_a_guess_taken_as_sure(scores, kappa):
    found = judge(scores, 0.05)
    assert not found.sure and found.kappa == kappa, found.reason


def test_an_outline_is_as_far_from_itself_turned_as_the_shape_is_asymmetric():
    square = np.zeros((60, 60), np.uint8)
    square[20:40, 20:40] = 1
    bar = np.zeros((60, 60), np.uint8)
    bar[25:35, 10:50] = 1
    assert symmetry.outline_distance(square, square) == 0.0
    assert symmetry.outline_distance(square, square.T) == 0.0  # a quarter turn: the same
    assert symmetry.outline_distance(bar, bar.T) > 3.0
    assert symmetry.outline_distance(bar, np.zeros_like(bar)) == float("inf")


def _cross_config(light: str = "good"):
    config = with_part(load_config(EXAMPLE), "cross")
    scene = config.scene
    return dataclasses.replace(config, scene=dataclasses.replace(
        scene, lighting=dataclasses.replace(scene.lighting, preset=light)))


@pytest.mark.slow
def test_the_search_on_the_simulated_cell_finds_the_crosss_four_and_comes_back():
    config = _cross_config()
    with open_devices(config, seed=1) as devices:
        fp = FinePositioner(devices, config, state_dir="unused")
        taught = devices.cell.nominal_grasp_pose()
        fp.move_to(taught)
        found = symmetry.find_symmetry(devices.arm, devices.camera, taught, fp.move_to)
        assert devices.arm.pose().tool_step_to(taught).translation_mm < 0.1
    assert (found.kappa, found.sure) == (4, True), found.reason
    assert len(found.scores_px) == symmetry.LOOKS - 1 and found.repeat_px < 0.1


@pytest.mark.slow
def test_teach_with_kappa_left_out_records_the_kappa_found(tmp_path, capsys):
    assert cli.main(["teach", "--auto", "--config", str(EXAMPLE), "--part", "cross",
                     "--state-dir", str(tmp_path)]) == 0
    taught = json.loads(capsys.readouterr().out)
    assert taught["kappa"] == 4 and taught["kappa_found"]["sure"]
    state = json.loads((tmp_path / "cross" / "cell.json").read_text())
    assert state["kappa"] == 4 and state["kappa_found"]["kappa"] == 4


def test_unsure_evidence_refuses_to_guess_until_kappa_is_confirmed(tmp_path, monkeypatch,
                                                                   capsys):
    unsure = symmetry.SymmetryEvidence(2, False, 0.1, reason="nearly symmetric")
    monkeypatch.setattr("controller.fine_positioner.find_symmetry", lambda *a, **k: unsure)
    common = ["--config", str(EXAMPLE), "--part", "cross", "--state-dir", str(tmp_path)]
    assert cli.main(["teach", "--auto", *common]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "kappa of the cross: unsure (best guess 2, confidence 0.10: nearly symmetric); " \
           "confirm it with --kappa N or declare parts.cross.kappa" in err
    assert not (tmp_path / "cross" / "cell.json").exists()
    assert cli.main(["teach", "--auto", "--kappa", "4", *common]) == 0
    taught = json.loads(capsys.readouterr().out)
    assert taught["kappa"] == 4 and taught["kappa_found"] is None
    with pytest.raises(FineposError, match=r"--kappa: 2, but parts.bracket.kappa is declared 1"):
        config = with_part(load_config(EXAMPLE), "bracket")
        with open_devices(config, seed=1) as devices:
            FinePositioner(devices, config, state_dir=tmp_path / "b").teach_auto(kappa=2)
