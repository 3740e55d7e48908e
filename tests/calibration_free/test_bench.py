"""`finepos bench perception`: the JSON it writes, and that it leaves the process as it was."""

from __future__ import annotations

import argparse
import json
import os

import cv2
import pytest
import torch

from calibration_free import bench
from drivers.core.errors import ConfigError


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser)
    return parser.parse_args(argv)


def test_bench_writes_the_numbers_and_restores_threads(tmp_path, capsys):
    affinity, cv_threads = os.sched_getaffinity(0), cv2.getNumThreads()
    torch_threads = torch.get_num_threads()
    out = tmp_path / "bench.json"
    assert bench.run(parse(["--json", str(out), "--frames", "60", "--opencv-frames", "5"])) == 0
    result = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out) == result
    for key in ("median_us", "p99_us", "opencv_median_us", "opencv_p99_us", "speedup",
                "align_median_us", "align_p99_us"):
        assert result[key] > 0, key
    assert result["align_ratio"] == pytest.approx(result["align_median_us"] / result["median_us"])
    assert result["speedup"] == pytest.approx(result["opencv_median_us"] / result["median_us"])
    assert result["frames"] == 60 and result["opencv_frames"] == 5
    assert result["frame_shape"] == [144, 192, 3]
    assert result["rms_error"]["dx_mm"] < 1.0 and result["rms_error"]["dphi_deg"] < 5.0
    assert result["training_images"] == {"nn1": 63, "nn2": 63}
    assert os.sched_getaffinity(0) == affinity
    assert (cv2.getNumThreads(), torch.get_num_threads()) == (cv_threads, torch_threads)


def test_bench_refuses_bad_arguments(tmp_path):
    with pytest.raises(ConfigError, match="--frames"):
        bench.run(parse(["--json", str(tmp_path / "b.json"), "--frames", "0"]))
    with pytest.raises(ConfigError, match="--cpu"):
        bench.run(parse(["--json", str(tmp_path / "b.json"), "--cpu", "4096"]))


def test_docstring_starts_with_a_runnable_example():
    lines = bench.__doc__.strip().splitlines()
    assert "Example: finepos bench perception --json" in "\n".join(lines[:3])
