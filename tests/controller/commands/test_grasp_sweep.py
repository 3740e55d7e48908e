"""finepos grasp-sweep: tolerances from the points, the report and the map."""

from __future__ import annotations

import json

import pytest

from controller.cli import main
from controller.commands.grasp_sweep import tolerance


def _pt(dx=0.0, dy=0.0, dphi=0.0, ok=True):
    return {"dx_mm": dx, "dy_mm": dy, "dphi_deg": dphi, "success": ok}


def test_the_tolerance_is_the_last_offset_before_the_first_failure():
    points = [_pt(), _pt(dy=1.0), _pt(dy=2.0, ok=False), _pt(dy=3.0),  # 3 is past a failure
              _pt(dphi=4.0), _pt(dphi=8.0), _pt(dx=1.0, ok=False),
              _pt(dy=1.0, dphi=4.0, ok=False)]  # grid points do not count for one axis
    assert tolerance(points, "dy_mm") == 1.0
    assert tolerance(points, "dphi_deg") == 8.0
    assert tolerance(points, "dx_mm") == 0.0
    assert tolerance([_pt(ok=False), _pt(dy=1.0)], "dy_mm") == 0.0


@pytest.mark.slow
def test_a_coarse_sweep_writes_the_report_and_the_map(tmp_path, capsys):
    out = tmp_path / "sweep.json"
    assert main(["grasp-sweep", "--json", str(out), "--out", str(tmp_path), "--max-mm", "5",
                 "--step-mm", "5", "--max-deg", "15", "--step-deg", "15"]) == 0
    report = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out) == report
    by_offset = {(p["dx_mm"], p["dy_mm"], p["dphi_deg"]): p for p in report["points"]}
    assert set(by_offset) == {(0.0, 0.0, 0.0), (0.0, 5.0, 0.0), (5.0, 0.0, 0.0),
                              (0.0, 0.0, 15.0)}
    centred = by_offset[(0.0, 0.0, 0.0)]
    assert centred["success"] and abs(centred["misalignment"]["across_mm"]) < 0.5
    across = by_offset[(0.0, 5.0, 0.0)]  # a finger lands on the cube: the guard trips
    assert not across["success"] and "contact" in across["reason"]
    assert across["misalignment"] is None and across["max_force_n"] > 3.0
    assert not by_offset[(0.0, 0.0, 15.0)]["success"]
    assert report["tolerance"] == {"across_jaws_mm": 0.0, "along_jaws_mm": 5.0, "phi_deg": 0.0}
    assert (tmp_path / "grasp_sweep.png").stat().st_size > 10_000


def test_bad_options_are_refused_with_one_line(tmp_path, capsys):
    assert main(["grasp-sweep", "--json", str(tmp_path / "s.json"), "--step-mm", "0"]) == 2
    assert "--step-mm: must be a positive number" in capsys.readouterr().err
