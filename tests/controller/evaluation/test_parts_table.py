"""Evaluation per part: ``finepos evaluate --part`` trains on the default scene with that part,
and the parts table (``--part all``) runs and reports every part in good and poor light."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from controller import cli
from controller.config import config_from_mapping
from controller.evaluation.metrics import wilson
from controller.evaluation.parts_table import parts_markdown
from controller.evaluation.trials import default_scene_config
from drivers.core.parts import PARTS

SMALL_GRIDS = {"controller": {"acquisition": {"nn1": {"shape": [3, 3, 3]},
                                              "nn2": {"shape": [3, 3, 3]}}}}


def test_the_default_scene_keeps_the_part_and_resets_the_rest():
    config = config_from_mapping({"scene": {"object": {"kind": "nut", "color": [0.1, 0.2, 0.9],
                                                       "x_mm": 320.0},
                                            "lighting": {"preset": "poor"},
                                            "clutter": {"count": 4}}})
    scene = default_scene_config(config).scene
    assert scene.object.kind == "nut"
    assert scene.object.color == type(scene.object)().color and scene.object.x_mm == 300.0
    assert scene.lighting.preset == "good" and scene.clutter.count == 0


def _row(part: str, lighting: str, safe: int, trials: int) -> dict:
    rms = {"x_mm": 0.05, "y_mm": 0.06, "phi_deg": 0.4}
    return {"part": part, "kappa": PARTS[part].kappa, "lighting": lighting,
            "safe_rate_ci": {"1.5": wilson(safe, trials), "2.5": wilson(trials, trials)},
            "rms": {b: rms for b in ("1.5", "2.5", "3.5")},
            "loops_to_safe": {"median": 1.0, "p95": None, "never_safe": trials - safe}}


def test_the_table_has_a_row_per_part_and_light_with_intervals():
    report = {"system": "gabor", "trials": 20, "seed": 3, "scene": "<defaults>",
              "wall_seconds": 12.0,
              "rows": [_row(p, light, 19, 20) for p in PARTS for light in ("good", "poor")]}
    table = parts_markdown(report)
    lines = table.splitlines()
    assert lines[0].startswith("| part | kappa | light | safe <= 1.5 loops | safe <= 2.5 loops")
    body = [line for line in lines[2:] if line.startswith("| ")]
    assert [line.split(" | ")[0][2:] for line in body] == [p for p in PARTS for _ in (1, 2)]
    ci = wilson(19, 20)
    assert f"95% ({ci['low'] * 100:.0f}-{ci['high'] * 100:.0f})" in body[0]
    assert "0.05 / 0.06 / 0.40" in body[0] and "| 1 / never, 1 never |" in body[0]
    assert "gabor, 20 trials per row, seed 3, scene <defaults>; safe" in table
    assert "scene <defaults>, taught in poor light; safe" in \
        parts_markdown({**report, "teach_lighting": "poor"})


def test_a_rate_short_of_all_is_not_rounded_up_to_100():
    report = {"system": "gabor", "trials": 200, "seed": 3, "scene": "<defaults>",
              "wall_seconds": 12.0, "rows": [_row("nut", "poor", 199, 200)]}
    body = [line for line in parts_markdown(report).splitlines()[2:] if line.startswith("| ")]
    ci = wilson(199, 200)
    assert f"| 99.5% ({ci['low'] * 100:.0f}-100) | 100% (98-100) |" in body[0]


@pytest.mark.slow
def test_every_part_is_trained_on_its_default_scene_and_reported(tmp_path, capsys):
    config, out = tmp_path / "grids.yaml", tmp_path / "parts.json"
    config.write_text(json.dumps(SMALL_GRIDS))
    assert cli.main(["evaluate", "--part", "all", "--config", str(config), "--trials", "2",
                     "--seed", "3", "--no-grasp", "--quiet", "--json", str(out)]) == 0
    table = capsys.readouterr().out
    report = json.loads(out.read_text())
    rows = report["rows"]
    assert [(r["part"], r["lighting"]) for r in rows] == \
        [(p, light) for p in PARTS for light in ("good", "poor")]
    for row in rows:
        assert row["object"] == row["part"] and row["kappa"] == PARTS[row["part"]].kappa
        assert row["trials"] == 2 and sum(row["outcomes"].values()) == 2
        assert row["train_images"] == 2 * (27 + 4)  # the grids and 4 frames at the taught pose
    # Trained on the nut, the nut is found (a cube model would see "no object" every time).
    assert all(r["outcomes"].get("no_object", 0) == 0 for r in rows if r["part"] == "nut")
    assert table == parts_markdown(report)
    assert len([line for line in table.splitlines()
                if line.startswith("| ") and not line.startswith("| part")]) == 8


@pytest.mark.slow
def test_evaluate_part_trains_and_tests_on_that_part(tmp_path, capsys):
    config = tmp_path / "grids.yaml"
    config.write_text(json.dumps(SMALL_GRIDS))
    assert cli.main(["evaluate", "--config", str(config), "--part", "ledge", "--trials", "2",
                     "--no-grasp", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["object"] == "ledge" and report["trials"] == 2
    assert sum(report["outcomes"].values()) == 2 and report["train_images"] == 2 * (27 + 4)
    assert set(report["rms"]) >= {"1.5", "2.5", "3.5"} and "1.5" in report["safe_rate_ci"]
    # the ledge (kappa 2): its turns over half a turn, in twelve bins of 15 deg
    bins = report["by_heading"]["bins"]
    assert len(bins) == 12 and bins[-1]["to_deg"] == 180.0
    assert sum(b["trials"] for b in bins) == 2


@pytest.mark.slow
def test_evaluate_refuses_a_model_of_another_part(trained, capsys):
    model = trained / "model-gabor.fpm"  # taught on the cube
    assert cli.main(["evaluate", "--part", "nut", "--model", str(model), "--trials", "1"]) == 2
    assert "taught on the cube, not the nut" in capsys.readouterr().err


@pytest.mark.slow
def test_evaluate_takes_a_declared_part_with_its_kappa_found(tmp_path, capsys):
    example = Path(__file__).resolve().parents[3] / "deploy" / "parts" / "example.yaml"
    config = tmp_path / "cell.yaml"
    config.write_text(json.dumps({**SMALL_GRIDS, "parts": {"cross": {
        "mesh": str(example.parent / "cross.ply"), "grasp_width_mm": 30.0,
        "grip_below_top_mm": 4.0, "mass_g": 7.0}}}))
    assert cli.main(["evaluate", "--config", str(config), "--part", "cross", "--trials", "2",
                     "--no-grasp", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["object"] == "cross" and report["trials"] == 2
    bins = report["by_heading"]["bins"]
    assert bins[-1]["to_deg"] == 90.0  # kappa 4, found at teach-in: a quarter turn's range
