"""Time what recording adds to each look (MCAP, Foxglove schemas), on one core.

Example: finepos bench recording --looks 500 --json out/bench-recording.json

Records ``--looks`` looks of synthetic 192x144 cube frames (``calibration_free.synthetic``)
through ``RunRecorder.look``, as the positioning loop calls it: the overlay from the estimate,
the JPEG (or PNG) frame, the annotations, the iteration record with a full loop's 36 features,
the tool pose after the move, into a zstd-chunked MCAP file; the file is finished (summary,
index) and timed too. Pinned to one core with single-threaded OpenCV. Prints and writes JSON:
median_ms and p99_ms per look, finish_ms, bytes_per_look, target_ms (2.0) and met.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from calibration_free.bench import single_core
from calibration_free.gabor import GaborConfig
from calibration_free.synthetic import SyntheticCell, render
from controller.loop.record import IterationRecord
from controller.recording.channels import IMAGE_FORMATS
from controller.recording.writer import RunRecorder
from controller.systems.estimator import TranslationEstimate
from drivers.core.errors import ConfigError
from drivers.core.files import write_json
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Frame

TARGET_MS = 2.0  # issue 16: recording costs <= 2 ms per look on one core
WARMUP_LOOKS = 10


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``finepos bench recording``."""
    parser.add_argument("--looks", type=int, default=500, metavar="N",
                        help="looks recorded and timed (default 500)")
    parser.add_argument("--format", choices=IMAGE_FORMATS, default="jpeg",
                        help="frame encoding (default jpeg)")
    parser.add_argument("--json", metavar="OUT", help="also write the results here")
    parser.add_argument("--cpu", type=int, default=None,
                        help="core to pin to (default: the last core this process may use)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic frames")


def _looks(n: int, seed: int):
    """``n`` (record, frame, estimate) triples of synthetic frames, as a loop would make."""
    cell = SyntheticCell()
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        label = rng.uniform((-20.0, -20.0, -45.0), (20.0, 20.0, 45.0))
        image = render(cell, label, rng)
        u, v = rng.uniform(60, 130), rng.uniform(40, 100)
        estimate = TranslationEstimate("ok", float(label[0]), float(label[1]), u, v,
                                       record={"area_px": 1500.0, "nn1": list(label[:2])})
        record = IterationRecord(time.time(), "bench", "gabor", i + 1, u, v, "ok",
                                 {"area_px": 1500.0, "nn1": list(label[:2]),
                                  "features": rng.normal(size=36).tolist(),
                                  "nn2": [0.1, 0.9], "perception_us": {"total": 600.0}},
                                 loop_kind="full", loops=1.0 + i,
                                 commanded=ToolStep(*label[:2], 0.0, label[2]),
                                 executed=ToolStep(*label[:2], 0.0, label[2]),
                                 pose_after=Pose(300.0, 0.0, 150.0, -90.0, 90.0, float(i % 90)),
                                 timings_ms={"grab": 5.0, "perceive": 1.0, "move": 40.0},
                                 error=(0.1, -0.2, 0.5))
        out.append((record, Frame(image, 1000.0 + 0.1 * i), estimate))
    return out


def run(args) -> int:
    """Run the benchmark and print the JSON results."""
    if args.looks < 1:
        raise ConfigError(f"--looks: must be >= 1, got {args.looks}")
    looks = _looks(args.looks + WARMUP_LOOKS, args.seed)
    estimator = SimpleNamespace(perception=SimpleNamespace(bundle=SimpleNamespace(
        gabor=GaborConfig(), front=SimpleNamespace(nominal_uv_px=(96.0, 60.0)))))
    cpu = args.cpu if args.cpu is not None else max(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory(prefix="finepos-bench-rec-") as tmp, single_core(cpu):
        path = Path(tmp) / "bench.mcap"
        times = []
        recorder = RunRecorder(path, image_format=args.format)
        for i, (record, frame, estimate) in enumerate(looks):
            t0 = time.perf_counter()
            recorder.look(record, frame, estimate, estimator, (0.3, -0.1, 2.0))
            if i >= WARMUP_LOOKS:
                times.append((time.perf_counter() - t0) * 1e3)
        t0 = time.perf_counter()
        recorder.close()
        finish_ms = (time.perf_counter() - t0) * 1e3
        size = path.stat().st_size
    median = float(np.median(times))
    result = {"looks": args.looks, "format": args.format, "cpu": cpu,
              "median_ms": round(median, 4), "p99_ms": round(float(np.percentile(times, 99)), 4),
              "mean_ms": round(float(np.mean(times)), 4), "finish_ms": round(finish_ms, 3),
              "bytes_per_look": round(size / len(looks)), "target_ms": TARGET_MS,
              "met": median <= TARGET_MS}
    write_json(args.json, result)
    return 0
