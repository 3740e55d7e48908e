"""Table 1 files from a hand-made result: markdown sections, computed verdict, JSON, plots."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from controller.evaluation.comparison.table1 import Table1Result
from controller.evaluation.comparison.table1_report import (
    _paired,
    failure_rate,
    rms_at,
    table1_markdown,
    verdict,
    why,
    write_table1,
)
from controller.evaluation.metrics import summarise
from controller.loop.positioning import LoopState as S

START = S(0.0, (20.0, -10.0, 30.0))
CONVERGING = [START, S(0.5, (2.0, 1.0, 30.0)), S(1.5, (0.2, 0.1, 1.0)), S(2.5, (0.1, 0.0, 0.5))]
SLOW = [START, S(0.5, (3.0, 1.0, 30.0)), S(1.5, (1.0, 1.0, 6.0)), S(2.5, (0.5, 0.5, 2.0))]
OFF = [START, S(0.5, (3.0, 1.0, 30.0)), S(1.5, (2.5, 0.5, 3.0))]  # converged off target
STUCK = [START]  # no object found at the first look


def report(system: str, lighting: str, trials: list, outcomes: dict) -> dict:
    return {"system": system, "lighting": lighting, "object": "cube", "trials": len(trials),
            "seed": 1, **summarise(trials), "grasp_success_rate": 0.5, "train_images": 126,
            "train_seconds": 1.5, "acquire_seconds": 3.0, "feature_count": 36,
            "seconds_per_loop": 0.02, "outcomes": outcomes, "scene": "<defaults>"}


@pytest.fixture()
def result() -> Table1Result:
    runs = {("gabor", "good"): ([CONVERGING, CONVERGING], {"converged": 2}),
            ("gabor", "poor"): ([CONVERGING, STUCK], {"converged": 1, "no_object": 1}),
            ("hough", "good"): ([SLOW, OFF], {"converged": 2}),
            ("hough", "poor"): ([STUCK, STUCK], {"no_object": 2})}
    per_trial = {("gabor", "good"): ["converged"] * 2,
                 ("gabor", "poor"): ["converged", "no_object"],
                 ("hough", "good"): ["converged"] * 2, ("hough", "poor"): ["no_object"] * 2}
    reports = [report(s, light, trials, outcomes) for (s, light), (trials, outcomes)
               in runs.items()]
    return Table1Result(reports, {k: v[0] for k, v in runs.items()}, per_trial,
                        {"acquire_seconds": 3.0, "images": 126}, 12.0, 2, 6.5)


def test_rms_at_a_budget_uses_the_state_after_the_last_move_within_it():
    assert rms_at([CONVERGING, SLOW], 1.5) == pytest.approx(
        ((0.2**2 / 2 + 1.0**2 / 2) ** 0.5, (0.1**2 / 2 + 1.0**2 / 2) ** 0.5,
         (1.0**2 / 2 + 6.0**2 / 2) ** 0.5))


def test_failure_means_not_safe_at_the_end_whatever_the_outcome(result):
    rates = [failure_rate(result, r["system"], r["lighting"]) for r in result.reports]
    assert rates == [0.0, 0.5, 0.5, 1.0]


def test_verdict_is_computed_per_lighting(result):
    good, poor = verdict(result)
    assert good.startswith("- good light, gabor vs hough:")
    assert "position RMS after 2.5 loops 0.100 vs 1.871 mm (gabor better, within noise)" in good
    assert "median loops to a safe grasp 1.5 vs 2.5 (gabor better)" in good
    assert "failure rate 50% vs 100% (gabor better)" in poor


def test_paired_comparison_says_when_a_difference_is_clear():
    ours, theirs = np.array([0.1, 0.2, 0.1]), np.array([1.0, 1.1, 1.0])
    assert _paired("x", ours, theirs, "deg", "pca").endswith("(gabor better, clear)")
    assert _paired("x", theirs, theirs, "deg", "pca").endswith("(tie)")


def test_markdown_has_every_section_and_row(result):
    md = table1_markdown(result, "<defaults>")
    for heading in ("## Accuracy", "## Outcomes and failures", "## Cost", "## Verdict",
                    "## Why", "## The paper's Table 1"):
        assert heading in md
    assert "| hough | poor | 0 | 0 | 2 | 0 | 0 | 0 | 0 | 0 | 0 | 100% | 100% | 50% |" in md
    assert "| hough | good | 2 | 0 | 0 | 0 | 0 | 0 | 0 | 0 | 1 | 50% | 0% | 50% |" in md
    assert "| gabor | good | 0.20, 0.10, 1.00 | 0.10, 0.00, 0.50 |" in md
    assert "never / never | 2 of 2 |" in md
    assert "| gabor | 36 | 126 | 3.0 | 1.5 | 20 / 20 |" in md


def test_files_are_written(result, tmp_path):
    paths = write_table1(result, tmp_path / "out", "<defaults>")
    data = json.loads(paths["json"].read_text())
    assert [(r["system"], r["lighting"]) for r in data] == [
        ("gabor", "good"), ("gabor", "poor"), ("hough", "good"), ("hough", "poor")]
    assert paths["plot_good"].name == "convergence-good.png"
    for key in ("markdown", "plot_good", "plot_poor"):
        assert paths[key].stat().st_size > 0


def test_why_explains_ties_and_names_the_localisation_channels(result):
    lines = why(result)
    assert not any("Localisation channels" in line for line in lines)  # none recorded
    with_channels = dataclasses.replace(result, channels={"gabor": "saturation",
                                                          "hough": "max"})
    md = table1_markdown(with_channels, "<defaults>")
    assert "Localisation channels (gabor: saturation, hough: max)" in md


def test_why_describes_the_alignment_servo_only_when_it_ran(result):
    assert not any("image-alignment servo" in line for line in why(result))

    def rename(key):
        return ("align", key[1]) if key[0] == "hough" else key

    with_align = dataclasses.replace(
        result, reports=[{**r, "system": rename((r["system"], ""))[0]} for r in result.reports],
        states={rename(k): v for k, v in result.states.items()},
        outcomes={rename(k): v for k, v in result.outcomes.items()})
    assert any("image-alignment servo" in line for line in why(with_align))
    assert "- good light, gabor vs align:" in table1_markdown(with_align, "<defaults>")
