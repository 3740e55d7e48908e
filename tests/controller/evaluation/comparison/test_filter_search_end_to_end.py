"""``finepos filter-search`` end to end (two sets, two repeats), and NN2 retraining on stored
ROIs matching ``train_bundle``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controller.cli import main
from controller.config import load_config
from controller.evaluation.comparison.filter_search import (
    _RepeatJob,
    acquire_training_grids,
    open_loop_rms_deg,
    prepare_repeat,
    train_nn2,
)
from controller.evaluation.comparison.filter_sets import FILTER_SETS, PAPER_SET

pytestmark = pytest.mark.slow

SETS = (PAPER_SET, "1x1x4-l30-s12.5-even")


def test_cli_writes_json_markdown_and_bar_plot(tmp_path):
    out = tmp_path / "fig5"
    assert main(["filter-search", "--sets", ",".join(SETS), "--repeats", "2", "--trials", "2",
                 "--workers", "2", "--quiet", "--out", str(out)]) == 0
    summary = json.loads((out / "filter_search.json").read_text())
    assert summary["settings"]["repeats"] == 2 and summary["settings"]["trials"] == 2
    assert {s["name"] for s in summary["sets"]} == set(SETS)
    assert [s["rank"] for s in summary["sets"]] == [1, 2]
    assert summary["winner"] == summary["sets"][0]["name"]
    assert summary["paper_set"]["name"] == PAPER_SET
    for s in summary["sets"]:
        assert [r["seed"] for r in s["repeats"]] == [1, 2]
        assert s["closed_phi_rms_deg"]["min"] <= s["closed_phi_rms_deg"]["mean"] \
            <= s["closed_phi_rms_deg"]["max"]
        assert s["gabor"]["centres_px"] == list(FILTER_SETS[s["name"]].centres_px)
    md = (out / "filter_search.md").read_text()
    assert f"**Winner: {summary['winner']}.**" in md and "| 2 | " in md
    assert (out / "filter_search.png").stat().st_size > 10_000


def test_nn2_retrained_on_stored_rois_is_train_bundles(tmp_path: Path):
    config = load_config(None)
    nn1, nn2, state = acquire_training_grids(config, 1, tmp_path, progress=False)
    data = prepare_repeat(_RepeatJob(0, 5, nn1, nn2, state, config), lambda n=1: None)
    acq = config.controller.acquisition
    assert data.train.rois.shape == (63 + acq.taught_pose_frames, 50, 50)
    assert data.train.missed == 0
    assert data.test.rois.shape[0] + data.test.missed == config.controller.acquisition.test_count
    model = train_nn2(data, FILTER_SETS[PAPER_SET], config.perception)
    ours, theirs = model.model.nn2.to_arrays("nn2"), data.base.model.nn2.to_arrays("nn2")
    assert all(np.array_equal(ours[k], theirs[k]) for k in theirs)
    assert open_loop_rms_deg(model, data.test) == open_loop_rms_deg(data.base, data.test) < 5.0
