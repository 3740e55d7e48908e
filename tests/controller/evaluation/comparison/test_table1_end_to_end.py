"""``finepos table1`` end to end on the simulated cell, with two trials per pair."""

from __future__ import annotations

import json

import pytest

from controller.cli import main
from controller.config import load_config
from controller.evaluation.trials import evaluate

pytestmark = pytest.mark.slow

TRIALS, SEED = 2, 3


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    out = tmp_path_factory.mktemp("table1")
    assert main(["table1", "--trials", str(TRIALS), "--seed", str(SEED), "--workers", "2",
                 "--quiet", "--out", str(out)]) == 0
    return out


def test_writes_one_evaluate_report_per_system_and_lighting(out):
    reports = json.loads((out / "table1.json").read_text())
    assert [(r["system"], r["lighting"]) for r in reports] == [
        (s, light) for s in ("gabor", "pca", "hough", "align") for light in ("good", "poor")]
    for r in reports:
        assert r["trials"] == TRIALS and r["seed"] == SEED and r["train_images"] == 134
        assert sum(r["outcomes"].values()) == TRIALS


def test_markdown_and_plots(out):
    md = (out / "table1.md").read_text()
    assert md.startswith("# Table 1 on the simulated cell")
    for system in ("gabor", "pca", "hough", "align"):
        for lighting in ("good", "poor"):
            assert f"| {system} | {lighting} |" in md
    assert "- poor light, gabor vs hough:" in md
    assert "- poor light, gabor vs align:" in md
    for lighting in ("good", "poor"):
        assert (out / f"convergence-{lighting}.png").stat().st_size > 10_000


def test_a_pair_reproduces_finepos_evaluate(out):
    """Same training images and trials: the table's pair is `finepos evaluate`'s report."""
    table = {(r["system"], r["lighting"]): r
             for r in json.loads((out / "table1.json").read_text())}
    alone = evaluate("pca", load_config(None), trials=TRIALS, seed=SEED, lighting="poor",
                     progress=False)
    alone.pop("_trial_states")
    assert set(table[("pca", "poor")]) == set(alone)
    for key in ("rms", "safe_rate", "loops_to_safe", "outcomes", "grasp_success_rate", "hil"):
        assert table[("pca", "poor")][key] == alone[key], key
