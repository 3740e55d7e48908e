"""Time the perception path per 192x144 frame on one core, against a cv2.filter2D Gabor bank.

Example: finepos bench perception --json out/bench-perception.json --frames 2000

Trains a bundle on synthetic cube images (3x3x7 grids, a = 25 mm for NN1 and 5 mm for NN2,
kappa 4), then times ``Perception.perceive`` (channel split, normalisation, localisation, ROI,
36 Gabor features, NN1, NN2) on random synthetic frames, and the same path with the features
computed the obvious way (one ``cv2.filter2D`` per orientation over the whole frame, sampled at
the nine centres). Everything runs pinned to one core with single-threaded OpenCV, torch and
BLAS. Prints and writes JSON: median_us, p99_us, opencv_median_us, opencv_p99_us, speedup
(opencv median / median), plus training seconds (cold: they include torch's one-off start-up),
per-stage medians (stage_median_us), RMS error of the corrective steps on the frames
(rms_error), and opencv_feature_rel_diff: the median relative difference between the two
feature vectors (the centre filters agree exactly; the off-centre ones differ because the
ROI window clips their envelopes while full-frame filtering does not). The image-alignment
servo (``--system align``, trained on the same images) is timed on the same frames as the
filter2D path: align_median_us, align_p99_us, align_ratio (its median over the Gabor
path's: what a look costs against it).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import platform
import time
from collections.abc import Callable, Iterator

import cv2
import numpy as np
import torch
from threadpoolctl import threadpool_limits

from calibration_free import angles
from calibration_free.baselines.align.train import train_align
from calibration_free.dataset import grid_offsets, random_offsets
from calibration_free.filter2d_reference import Filter2DFeatures
from calibration_free.localise import DEFAULT_CAMERA_GAMMA
from calibration_free.perception import Percept, Perception
from calibration_free.synthetic import SyntheticCell, render, render_dataset
from calibration_free.training import TrainingSettings, train_bundle
from drivers.core.errors import ConfigError, FineposError
from drivers.core.files import write_json

KAPPA = 4
NN1_A_MM = 25.0
NN2_A_MM = 5.0
WARMUP_FRAMES = 50
NOMINAL_POSE = {"x_mm": 0.0, "y_mm": 400.0, "z_mm": 120.0, "o_deg": -90.0, "a_deg": 90.0,
                "t_deg": 0.0}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", required=True, metavar="OUT", help="write the results here")
    parser.add_argument("--frames", type=int, default=2000, metavar="N",
                        help="frames timed on the fast path (default 2000)")
    parser.add_argument("--opencv-frames", type=int, default=300, metavar="N",
                        help="frames timed on the filter2D path (default 300)")
    parser.add_argument("--cpu", type=int, default=None,
                        help="core to pin to (default: the last core this process may use)")
    parser.add_argument("--seed", type=int, default=0, help="seed of scenes and training")


@contextlib.contextmanager
def single_core(cpu: int) -> Iterator[None]:
    """Pin this thread to ``cpu`` with one OpenCV, torch and BLAS thread; restore afterwards."""
    affinity = os.sched_getaffinity(0)
    cv_threads, torch_threads = cv2.getNumThreads(), torch.get_num_threads()
    os.sched_setaffinity(0, {cpu})
    cv2.setNumThreads(1)
    torch.set_num_threads(1)
    try:
        with threadpool_limits(limits=1):
            yield
    finally:
        torch.set_num_threads(torch_threads)
        cv2.setNumThreads(cv_threads)
        os.sched_setaffinity(0, affinity)


def _time_us(fn: Callable[[np.ndarray], object], frames: np.ndarray) -> np.ndarray:
    """Microseconds of ``fn(frame)`` for each frame, after a short warm-up."""
    for frame in frames[:WARMUP_FRAMES]:
        fn(frame)
    out = np.empty(len(frames))
    clock = time.perf_counter_ns
    for i, frame in enumerate(frames):
        t0 = clock()
        fn(frame)
        out[i] = clock() - t0
    return out / 1e3


def _rms_errors(percepts: list[Percept], labels: np.ndarray) -> dict[str, float]:
    """RMS of (perceived - true) corrective steps over the frames where the object was found."""
    errors = np.array([(p.nn1_mm[0] - label[0], p.nn1_mm[1] - label[1],
                        angles.decode(*angles.encode(p.dphi_deg - label[2], KAPPA), KAPPA))
                       for p, label in zip(percepts, labels, strict=True) if p.ok])
    rms = np.sqrt(np.mean(errors**2, axis=0))
    return {"dx_mm": float(rms[0]), "dy_mm": float(rms[1]), "dphi_deg": float(rms[2])}


def measure(n_frames: int, n_opencv_frames: int, seed: int) -> dict:
    """Train a synthetic bundle and time both perception paths (call inside ``single_core``).

    Raises:
        FineposError: the object was not found in some benchmark frame.
    """
    cell = SyntheticCell()
    rng = np.random.default_rng(seed)
    b_deg = 180.0 / KAPPA
    nn1_data = render_dataset(cell, grid_offsets(NN1_A_MM, b_deg), rng)
    nn2_data = render_dataset(cell, grid_offsets(NN2_A_MM, b_deg), rng)
    start = time.perf_counter()
    bundle = train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                          nominal_pose=NOMINAL_POSE, nn1_extra=nn2_data,
                          settings=TrainingSettings(seed=seed, edge_gamma=DEFAULT_CAMERA_GAMMA))
    training_seconds = time.perf_counter() - start

    labels = random_offsets(rng, n_frames, NN2_A_MM, b_deg)
    frames = np.stack([render(cell, label, rng) for label in labels])
    perception = Perception(bundle)
    # Kept for the error and stage figures, without the frame each percept carries along.
    percepts = [dataclasses.replace(perception.perceive(frame), normalised=None)
                for frame in frames]
    missed = sum(not p.ok for p in percepts)
    if missed:
        raise FineposError(f"the object was not found in {missed} of {n_frames} synthetic "
                           f"frames; the benchmark would time different work per frame")
    fast_us = _time_us(perception.perceive, frames)

    filter2d = Filter2DFeatures(bundle.gabor)

    def opencv_perceive(image: np.ndarray) -> float:
        normalised, loc = perception.locate(image)
        bundle.nn1(np.array((loc.u_px, loc.v_px)))
        s, c = bundle.nn2(filter2d.features(bundle.front.feature_frame(normalised, loc),
                                            loc.u_px, loc.v_px))
        return angles.decode(float(s), float(c), bundle.kappa)

    opencv_us = _time_us(opencv_perceive, frames[:n_opencv_frames])
    feature_diff = [np.linalg.norm(filter2d.features(bundle.front.feature_frame(
                        *perception.locate(frame)), p.u_px, p.v_px) - p.features)
                    / np.linalg.norm(p.features)
                    for frame, p in zip(frames[:n_opencv_frames], percepts, strict=False)]
    align = train_align(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                        nominal_pose=NOMINAL_POSE)
    align_us = _time_us(align.perceive, frames[:n_opencv_frames])
    stages = ("preprocess", "localise", "nn1", "roi", "features", "nn2")
    median, opencv_median = float(np.median(fast_us)), float(np.median(opencv_us))
    return {
        "median_us": median,
        "p99_us": float(np.percentile(fast_us, 99)),
        "opencv_median_us": opencv_median,
        "opencv_p99_us": float(np.percentile(opencv_us, 99)),
        "speedup": opencv_median / median,
        "channel": bundle.front.channel,
        "frames": n_frames,
        "opencv_frames": n_opencv_frames,
        "frame_shape": list(frames.shape[1:]),
        "stage_median_us": {s: float(np.median([p.timings_us[s] for p in percepts]))
                            for s in stages},
        "training_seconds": training_seconds,
        "nn1_training_seconds": bundle.training["nn1"]["seconds"],
        "nn2_training_seconds": bundle.training["nn2"]["seconds"],
        "training_images": {"nn1": len(nn1_data), "nn2": len(nn2_data)},
        "rms_error": _rms_errors(percepts, labels),
        "opencv_feature_rel_diff": float(np.median(feature_diff)),
        "align_median_us": float(np.median(align_us)),
        "align_p99_us": float(np.percentile(align_us, 99)),
        "align_ratio": float(np.median(align_us)) / median,
    }


def run(args: argparse.Namespace) -> int:
    if args.frames < 1 or args.opencv_frames < 1:
        raise ConfigError(f"--frames and --opencv-frames must be >= 1, got {args.frames} and "
                          f"{args.opencv_frames}")
    allowed = sorted(os.sched_getaffinity(0))
    cpu = allowed[-1] if args.cpu is None else args.cpu
    if cpu not in allowed:
        raise ConfigError(f"--cpu: core {cpu} is not available (allowed: {allowed})")
    with single_core(cpu):
        result = measure(args.frames, min(args.opencv_frames, args.frames), args.seed)
    result.update(cpu=cpu, machine=platform.machine(), python=platform.python_version(),
                  numpy=np.__version__, opencv=cv2.__version__, torch=torch.__version__)
    write_json(args.json, result)
    return 0
