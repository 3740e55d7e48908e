"""Filter-search statistics and files from hand-made runs: ranking, spread, paired difference."""

from __future__ import annotations

import json

import pytest

from controller.evaluation.comparison.filter_report import (
    search_markdown,
    summarise_search,
    write_search,
)
from controller.evaluation.comparison.filter_search import SearchResult, SetRun
from controller.evaluation.comparison.filter_sets import FILTER_SETS, PAPER_SET

OTHER = "2x2x4-l30-s12.5-even"


def run(name: str, repeat: int, phi_deg: float) -> SetRun:
    return SetRun(name, repeat, 1 + repeat, FILTER_SETS[name].n_filters, 0.4, 2 * phi_deg,
                  (0.3, 0.4, phi_deg), 1.0, 0)


@pytest.fixture()
def result() -> SearchResult:
    runs = [run(PAPER_SET, r, phi) for r, phi in enumerate((0.30, 0.40, 0.50))]
    runs += [run(OTHER, r, phi) for r, phi in enumerate((0.20, 0.30, 0.40))]
    sets = {PAPER_SET: FILTER_SETS[PAPER_SET], OTHER: FILTER_SETS[OTHER]}
    return SearchResult(sets, runs, 3, 20, 1, 50, 2, 10.0, "<defaults>")


def test_ranks_by_mean_closed_loop_angle_rms_with_spread(result):
    summary = summarise_search(result)
    assert summary["winner"] == OTHER
    best, paper = summary["sets"]
    assert (best["name"], best["rank"], paper["rank"]) == (OTHER, 1, 2)
    assert paper["closed_phi_rms_deg"] == pytest.approx(
        {"mean": 0.4, "std": 0.1, "min": 0.3, "max": 0.5})
    assert paper["closed_position_rms_mm"]["mean"] == pytest.approx(0.5)
    assert paper["open_loop_phi_rms_deg"]["mean"] == pytest.approx(0.8)
    assert [r["seed"] for r in paper["repeats"]] == [1, 2, 3]


def test_paper_set_is_compared_pairwise_with_the_winner(result):
    paper = summarise_search(result)["paper_set"]
    assert paper["rank"] == 2
    assert paper["paired_difference_deg"] == pytest.approx(0.1)
    assert paper["paired_difference_se_deg"] == pytest.approx(0.0, abs=1e-9)
    md = search_markdown(summarise_search(result))
    assert f"**Winner: {OTHER}.**" in md and "a real if small loss" in md
    assert f"| 2 | {PAPER_SET} | 36 | 0.40 ± 0.10 |" in md


def test_files_are_written(result, tmp_path):
    summary, paths = write_search(result, tmp_path / "fig5")
    assert json.loads(paths["json"].read_text()) == json.loads(json.dumps(summary))
    assert paths["markdown"].read_text() == search_markdown(summary)
    assert paths["plot"].stat().st_size > 10_000
