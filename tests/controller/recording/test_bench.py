"""``finepos bench recording`` runs and reports its numbers (no timing asserted here)."""

import argparse
import json

import pytest

from controller.recording import bench


@pytest.mark.slow
def test_bench_recording_reports_cost_per_look(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    out = tmp_path / "bench.json"
    assert bench.run(parser.parse_args(["--looks", "20", "--json", str(out)])) == 0
    result = json.loads(out.read_text())
    assert result == json.loads(capsys.readouterr().out)
    assert result["looks"] == 20 and result["format"] == "jpeg"
    assert 0 < result["median_ms"] <= result["p99_ms"] and result["bytes_per_look"] > 500
    assert result["target_ms"] == 2.0 and result["met"] == (result["median_ms"] <= 2.0)
