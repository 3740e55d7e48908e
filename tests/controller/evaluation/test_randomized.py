"""``finepos evaluate --randomize``: the drawn cells and trials, and the yardstick's report."""

import json
from pathlib import Path

import numpy as np
import pytest

from controller.cli import main
from controller.config import load_config, with_part
from controller.evaluation import randomized as rz
from sim_backend.cell.optics import resolve_camera

ROOT = Path(__file__).resolve().parents[3]


def _plan(seed, trials=12, per_cell=4):
    return rz.draw_plan(load_config(None), trials=trials, seed=seed, trials_per_cell=per_cell)


def test_a_seed_reproduces_every_draw_and_another_seed_changes_them():
    a, b, c = _plan(7), _plan(7), _plan(8)
    assert [cell.factors for cell, _ in a] == [cell.factors for cell, _ in b]
    assert [[t.factors for t in ts] for _, ts in a] == [[t.factors for t in ts] for _, ts in b]
    assert [cell.factors for cell, _ in a] != [cell.factors for cell, _ in c]


def test_trials_are_dealt_to_cells_and_draws_stay_in_their_ranges():
    plan = _plan(3, trials=50, per_cell=25)
    assert [len(trials) for _, trials in plan] == [25, 25]
    plan = _plan(3, trials=7, per_cell=3)
    assert [len(trials) for _, trials in plan] == [3, 2, 2]
    for seed in range(6):
        for cell, trials in _plan(seed):
            f = cell.factors
            model = resolve_camera(cell.camera)  # a lens that folds the image raises
            assert rz.GAMMA_RANGE[0] <= model.gamma <= rz.GAMMA_RANGE[1]
            assert model.pixel_samples in (1, 2, 3)
            assert model.jpeg_quality == 0 or 60 <= model.jpeg_quality <= 100
            assert (cell.fixed_exposure is None) == f["auto_exposure"]
            assert f["colour_distance"] >= rz.MIN_COLOUR_DISTANCE
            for trial in trials:
                lamps = trial.factors["lamp_list"]
                assert 1 <= len(lamps) == 1 + len(trial.light.lamps) <= 3
                assert all(20.0 <= lamp["elevation_deg"] <= 90.0 for lamp in lamps)
                assert all(2700.0 <= lamp["kelvin"] <= 6500.0 for lamp in lamps)
                assert 0.0 <= trial.occluder <= 0.3 and 0 <= trial.clutter <= 3
                assert trial.light.direction[2] > 0
                train = f["train_light"]["brightness"]
                assert trial.factors["light_change"] == pytest.approx(
                    abs(np.log2(trial.factors["brightness"] / train)))


def _record(cell, visible, outcome, error, lamps=1, brightness=0.5):
    safe = error is not None and np.hypot(error[0], error[1]) <= 2.0 and abs(error[2]) <= 5.0
    return {"cell": cell, "visible": visible, "outcome": outcome, "error": error,
            "safe_2.5": bool(safe), "grasped": None,
            "draw": {"lamps": lamps, "brightness": brightness, "light_change": 0.0,
                     "key_elevation_deg": 50.0,
                     "key_kelvin": 4000.0, "key_shadow": 0.5, "occluder": 0.0, "clutter": 0}}


def _cell(index, auto=True):
    cell, _ = _plan(index, trials=1, per_cell=1)[0]
    return {"index": index, **cell.factors, "auto_exposure": auto,
            "train_light": {**cell.factors["train_light"], "brightness": 0.5}}


def test_the_summary_counts_targets_on_the_visible_trials_and_names_the_weak_class():
    cells = [_cell(0, auto=True), _cell(1, auto=False)]
    good = [_record(0, 1.0, "converged", [0.01, -0.02, 0.1]) for _ in range(20)]
    bad = [_record(1, 1.0, "no_object", [9.0, 3.0, 20.0]) for _ in range(12)]
    hidden = [_record(1, 0.5, "occluded", [4.0, 0.0, 1.0]) for _ in range(5)]
    out = rz.summarise_randomized(good + bad + hidden, cells)
    assert out["all"]["trials"] == 37
    assert out["visible_0.8"]["trials"] == 32
    assert out["visible_0.8"]["safe_2.5"]["rate"] == pytest.approx(20 / 32)
    assert out["stops_visible_0.85"]["stops"]["rate"] == pytest.approx(12 / 32)
    assert out["targets"] == {"safe_2.5_visible": False, "rms_2.5_visible": False,
                              "class_safe": False, "stops_visible": False}
    rows = {row["class"]: row for row in out["by_factor"]["auto_exposure"]}
    assert rows["True"]["safe_2.5"]["rate"] == 1.0 and rows["False"]["trials"] == 17
    assert out["worst_class"]["safe_2.5"]["rate"] == 0.0
    assert out["worst_class"]["factor"] in out["by_factor"]
    assert out["outcomes"] == {"converged": 20, "no_object": 12, "occluded": 5}
    met = rz.summarise_randomized(good, cells)
    assert all(met["targets"].values())


def test_an_untrained_cell_counts_against_every_figure_but_the_rms():
    cells = [_cell(0)]
    plan = _plan(0, trials=1, per_cell=1)
    cell, (trial,) = plan[0]
    untrained = rz.untrained_record(cell, trial, "the object was found in none")
    out = rz.summarise_randomized([untrained, _record(0, 1.0, "converged", [0, 0, 0])], cells)
    assert out["visible_0.8"]["safe_2.5"]["rate"] == 0.5
    assert out["visible_0.8"]["rms_2.5"]["x_mm"] == 0.0


@pytest.mark.parametrize("args, message", [
    (["--randomize", "--lighting", "poor"], "--lighting: not with --randomize"),
    (["--randomize", "--hil"], "--hil: not with --randomize"),
    (["--trials-per-cell", "3"], "--trials-per-cell: only with --randomize"),
    (["--workers", "2"], "--workers: only with --part all or --randomize"),
])
def test_options_that_do_not_fit_randomized_cells_are_refused(args, message, capsys):
    assert main(["evaluate", *args, "--trials", "1"]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_a_small_seeded_randomized_run_reports_its_draws_and_figures(tmp_path, capsys):
    out = tmp_path / "random.json"
    argv = ["evaluate", "--randomize", "--trials", "2", "--trials-per-cell", "2", "--seed",
            "4", "--no-grasp", "--quiet", "--json", str(out)]
    assert main(argv) == 0
    report = json.loads(out.read_text())
    assert report["command"] == "finepos " + " ".join(argv)
    assert report["randomize"] and report["trials"] == 2 and len(report["cells"]) == 1
    cell = report["cells"][0]
    assert {"gamma", "auto_exposure", "table_texture", "part_rgb", "train_light"} <= set(cell)
    assert len(report["trial_records"]) == 2
    for record in report["trial_records"]:
        assert record["draw"]["lamps"] >= 1 and record["outcome"]
        assert record["outcome"] == "untrained" or 0.0 <= record["visible"] <= 1.0
    assert set(report["by_factor"]) >= {"gamma", "lamps", "occluder", "clutter", "part_hue"}
    assert set(report["targets"]) == {"safe_2.5_visible", "rms_2.5_visible", "class_safe",
                                      "stops_visible"}


@pytest.mark.slow
def test_a_randomized_run_can_rezero_before_each_trial_and_says_what_it_cost(tmp_path):
    out = tmp_path / "random.json"
    argv = ["evaluate", "--randomize", "--rezero", "--trials", "1", "--seed", "4",
            "--no-grasp", "--quiet", "--json", str(out)]
    assert main(argv) == 0
    report = json.loads(out.read_text())
    (record,) = report["trial_records"]
    made = record["rezero"]
    assert report["rezero"]["trials"] == 1
    assert report["rezero"]["refused"] == (made["error"] is not None)
    # a re-zero refused (the part not seen whole in the trial's light) leaves the model as
    # trained, and the trial runs with it
    assert record["outcome"] != "untrained" and 0.0 <= record["visible"] <= 1.0
    if made["error"] is None:
        assert made["cell_seconds"] > 0.0
    else:
        assert made["error"].startswith("rezero: ")


def test_a_part_the_config_declares_is_exposed_for_on_its_drawn_cell():
    config = with_part(load_config(ROOT / "deploy" / "parts" / "example.yaml"), "wedge")
    cell, _ = rz.draw_plan(config, trials=1, seed=5, trials_per_cell=1)[0]
    assert rz.settled_exposure(rz.cell_config(config, cell, cell.train_light), 1) > 0.0
