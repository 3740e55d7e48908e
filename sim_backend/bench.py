"""Time the simulated cell on one core: a frame, a relative move, a look-and-move iteration.

Example: finepos bench sim --json out/bench-sim.json

Prints (and with --json writes) medians and 90th percentiles in ms of: rendering one 192x144
frame (``SimCell.render``: shading, cast shadows, noise); one relative move through the arm
interface (``SimArm.move_tool``: pose read, safety check, inverse kinematics, joints set); one
look-and-move iteration as the positioning loop does it, minus the perception
(``SimCamera.grab`` then ``SimArm.move_tool``). The process runs on one CPU meanwhile.
Target: look-and-move under 30 ms median. Then the same look-and-move on the realistic cell
(``timing:`` section of --config; virtual clock): ``realistic_look_and_move`` gives the wall
time next to the cell seconds it stands for, split into wire time (VAL and ATI lines), motion
time (arm and hand) and the camera's wait (``cell_ms``, ``wire_ms``, ``motion_ms``,
``camera_ms``, medians).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from drivers.core.errors import ConfigError
from drivers.core.files import write_json
from drivers.core.pose import ToolStep
from drivers.core.timing import TimingConfig
from drivers.safety import SafetyLimits
from sim_backend.cell.scene_config import SceneConfig, load_scene
from sim_backend.cell.sim_cell import SimCell
from sim_backend.cell.timing import cell_timing, load_timing
from sim_backend.devices import SimArm, SimCamera

logger = logging.getLogger(__name__)

TARGET_LOOK_AND_MOVE_MS = 30.0
_WARMUP = 5


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", type=Path, help="also write the results to this file")
    parser.add_argument("--config", type=Path, help="root config file (its scene: section)")
    parser.add_argument("--repeats", type=int, default=200, help="timed runs of each (>= 10)")


@contextlib.contextmanager
def one_cpu():
    """Run the block on the first CPU this process may use (yields its number); the affinity
    is restored afterwards."""
    allowed = os.sched_getaffinity(0)
    cpu = min(allowed)
    os.sched_setaffinity(0, {cpu})
    try:
        yield cpu
    finally:
        os.sched_setaffinity(0, allowed)


def _timed(fn: Callable[[int], object], repeats: int) -> dict[str, float]:
    for i in range(_WARMUP):
        fn(i)
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        fn(i)
        times.append((time.perf_counter() - start) * 1000.0)
    return {"median": float(np.median(times)), "p90": float(np.percentile(times, 90))}


def _realistic(cell: SimCell, config: TimingConfig, step, repeats: int) -> dict:
    """Look-and-move on the realistic cell: wall ms next to cell, wire, motion, camera ms."""
    timing = cell_timing("realistic", config)
    rows = []
    with SimArm(cell, SafetyLimits(), timing) as arm, SimCamera(cell, timing) as camera:
        for i in range(repeats):
            t0, wire0, motion0 = timing.clock.now(), timing.wire_s, timing.motion_s
            start = time.perf_counter()
            camera.grab().image.mean()
            arm.move_tool(step(i))
            wall = time.perf_counter() - start
            cell_s = timing.clock.now() - t0
            wire, motion = timing.wire_s - wire0, timing.motion_s - motion0
            rows.append((wall, cell_s, wire, motion, cell_s - wire - motion))
    names = ("wall_ms", "cell_ms", "wire_ms", "motion_ms", "camera_ms")
    return {name: float(np.median([r[k] for r in rows])) * 1e3 for k, name in enumerate(names)}


def measure(scene: SceneConfig, repeats: int,
            timing_config: TimingConfig | None = None) -> dict:
    """The benchmark's results (see the module docstring)."""
    timing_config = timing_config or TimingConfig()
    with SimCell(scene) as cell:
        arm, camera = SimArm(cell, SafetyLimits()), SimCamera(cell)
        with arm, camera:
            def step(i: int) -> ToolStep:
                sign = 1.0 if i % 2 == 0 else -1.0
                return ToolStep(sign * 1.5, -sign * 1.0, 0.0, sign * 2.0)

            def look_and_move(i: int) -> None:
                camera.grab().image.mean()  # the mean stands in for the perception
                arm.move_tool(step(i))

            results = {
                "render_ms": _timed(lambda i: cell.render(), repeats),
                "move_ms": _timed(lambda i: arm.move_tool(step(i)), repeats),
                "look_and_move_ms": _timed(look_and_move, repeats),
            }
        results["realistic_look_and_move"] = _realistic(cell, timing_config, step, repeats)
        results["shadows"] = cell.light.casts_shadows
    return results


def run(args: argparse.Namespace) -> int:
    if args.repeats < 10:
        raise ConfigError(f"--repeats must be at least 10, got {args.repeats}")
    scene = load_scene(args.config) if args.config else SceneConfig()
    with one_cpu() as cpu:
        measured = measure(scene, args.repeats, load_timing(args.config))
    results = {"cpu": cpu, "repeats": args.repeats, "lighting": scene.lighting.preset,
               "object": scene.object.kind, **measured}
    median = results["look_and_move_ms"]["median"]
    results["target_look_and_move_ms"] = TARGET_LOOK_AND_MOVE_MS
    results["meets_target"] = median < TARGET_LOOK_AND_MOVE_MS
    write_json(args.json, results)
    if args.json:
        logger.info("wrote %s", args.json)
    return 0
