"""The results page: built from evaluate reports, every quoted command parses with the real
``finepos`` argument parser (parsed, never run)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from controller.cli import build_parser
from controller.docs import results_page
from drivers.core.errors import ConfigError

ROOT = Path(__file__).resolve().parents[3]
FIXTURES = Path(__file__).resolve().parent / "fixtures"


def _parses(command: str) -> None:
    words = shlex.split(command)
    assert words[0] == "finepos", command
    build_parser().parse_args(words[1:])  # argparse exits (SystemExit) on a bad command line


def test_fixture_report_becomes_a_row_with_its_command():
    page = results_page.render(results_page.load_reports(FIXTURES))
    row = next(line for line in page.splitlines() if line.startswith("| cube |"))
    cells = [c.strip() for c in row.strip("|").split(" | ")]
    assert cells[:11] == ["cube", "good", "gabor", "2", "1", "100.0", "100.0", "0.017", "0.016",
                          "0.11", "5.95"]
    assert results_page.commands(page) == [
        "finepos evaluate --lighting good --trials 2 --seed 1 --json out/cube-good.json"]


def test_every_command_on_the_fixture_page_parses():
    for command in results_page.commands(results_page.render(
            results_page.load_reports(FIXTURES))):
        _parses(command)


def test_every_command_on_the_committed_page_parses():
    page = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    for command in results_page.commands(page):
        _parses(command)


def test_committed_page_matches_its_reports():
    page = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    assert page == results_page.render(results_page.load_reports(ROOT / "docs" / "results")), (
        f"docs/results.md is out of date with docs/results/: run `{results_page.COMMAND}`")


def test_a_command_that_does_not_parse_is_caught():
    with pytest.raises(SystemExit):
        _parses("finepos evaluate --no-such-option")


def test_reports_in_a_list_or_mapping_are_each_a_row(tmp_path):
    report = json.loads((FIXTURES / "evaluate-report.json").read_text(encoding="utf-8"))
    other = {**report, "lighting": "poor", "command": report["command"] + " --lighting poor"}
    (tmp_path / "parts.json").write_text(json.dumps({"rows": [report, other]}),
                                         encoding="utf-8")
    assert len(results_page.load_reports(tmp_path)) == 2


def test_the_rows_of_a_parts_table_take_its_command(tmp_path):
    report = json.loads((FIXTURES / "evaluate-report.json").read_text(encoding="utf-8"))
    del report["command"]
    table = {"system": "gabor", "rows": [report, {**report, "lighting": "poor"}],
             "command": "finepos evaluate --part all --trials 2 --seed 3 --no-grasp"}
    (tmp_path / "parts.json").write_text(json.dumps(table), encoding="utf-8")
    found = results_page.load_reports(tmp_path)
    assert [r["command"] for _, r in found] == [table["command"]] * 2


def test_a_report_without_its_command_is_refused(tmp_path):
    report = json.loads((FIXTURES / "evaluate-report.json").read_text(encoding="utf-8"))
    del report["command"]
    (tmp_path / "r.json").write_text(json.dumps(report), encoding="utf-8")
    with pytest.raises(ConfigError, match="without its command"):
        results_page.load_reports(tmp_path)


def test_a_randomized_report_becomes_a_row_of_its_own_table(tmp_path):
    wilson = {"rate": 0.9, "low": 0.8, "high": 0.95}
    report = {"randomize": True, "object": "cube", "system": "gabor", "trials": 50, "seed": 2,
              "cells": [{}, {}], "wall_seconds": 120.0,
              "command": "finepos evaluate --randomize --trials 50 --seed 2",
              "visible_0.8": {"trials": 40, "safe_2.5": wilson,
                              "rms_2.5": {"x_mm": 0.04, "y_mm": 0.05, "phi_deg": 0.3}},
              "stops_visible_0.85": {"stops": {"rate": 0.05, "low": 0.01, "high": 0.1}},
              "worst_class": {"factor": "gamma", "class": "1-1.35", "trials": 12,
                              "safe_2.5": wilson},
              "by_factor": {"gamma": [{"class": "1-1.35", "trials": 12, "safe_2.5": wilson,
                                       "rms_2.5": {"x_mm": 0.1, "y_mm": 0.1,
                                                   "phi_deg": 1.0}}]},
              "targets": {"a": True, "b": False}}
    (tmp_path / "random.json").write_text(json.dumps(report), encoding="utf-8")
    page = results_page.render(results_page.load_reports(tmp_path))
    assert "## Randomized cells" in page and "## Default cell" not in page
    row = next(line for line in page.splitlines() if line.startswith("| cube | gabor | 50"))
    cells = [c.strip() for c in row.strip("|").split(" | ")]
    assert cells[:13] == ["cube", "gabor", "50", "2", "2", "90.0 (80.0-95.0)", "0.040",
                          "0.050", "0.30", "5.0 (1.0-10.0)", "gamma 1-1.35: 90.0 (80.0-95.0)",
                          "1 of 2", "2.0"]
    assert "| gamma | 1-1.35 | 12 | 90.0 (80.0-95.0) | 0.100 | 0.100 | 1.00 |" in page
    for command in results_page.commands(page):
        _parses(command)
