"""Table 1 of the paper on the simulated cell: every system in good and in poor light (the
paper's three, and the image-alignment servo a cell owner would weigh it against).

The NN1 and NN2 grids are acquired once on the default scene in good light and every system is
trained once on those same images; then each (system, lighting) pair runs ``trials`` random
placements with the same seed, so every system meets the same placements and start offsets in
both lightings. The pairs run as parallel jobs. Each pair's report is what
``finepos evaluate --system S --lighting L --trials N --seed SEED`` prints (the same training
images, the same trials); only the wall-time figures depend on how busy the machine was.
"""

from __future__ import annotations

import logging
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from controller.evaluation.comparison.pools import Tick, open_pool
from controller.evaluation.trials import (
    EVAL_BUDGET,
    build_report,
    run_trials,
    train_systems_on_default_scene,
    with_lighting,
)
from controller.loop.positioning import LoopState
from controller.systems.base import TrainedModel
from controller.systems.registry import SYSTEMS
from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

TABLE1_SYSTEMS = ("gabor", "pca", "hough", "align")
LIGHTINGS = ("good", "poor")


@dataclass
class Table1Result:
    """Everything Table 1 is written from.

    Attributes:
        reports: one ``finepos evaluate --json`` report per (system, lighting), system-major,
            without the private ``_trial_states``.
        states: every trial's loop states, keyed by (system, lighting).
        outcomes: every trial's loop outcome (converged, budget, no_object, ...), same keys.
        acquisition: the shared acquisition's cost (``acquire_seconds``, ``images``).
        wall_seconds: the whole run, acquisition and training included.
        workers: parallel jobs the trials ran on.
        budget_loops: the loop budget of every trial.
        channels: per system, the image it localises the part in ("max" or "saturation").
    """

    reports: list[dict]
    states: dict[tuple[str, str], list[list[LoopState]]]
    outcomes: dict[tuple[str, str], list[str]]
    acquisition: dict
    wall_seconds: float
    workers: int
    budget_loops: float
    channels: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class _TrialsJob:
    system: str
    lighting: str
    model: TrainedModel
    config: object
    trials: int
    seed: int
    grasp: bool


def _run_trials_job(job: _TrialsJob, tick: Tick) -> dict:
    with tempfile.TemporaryDirectory(prefix="finepos-table1-") as tmp:
        return run_trials(job.system, job.model, with_lighting(job.config, job.lighting),
                          job.trials, job.seed, work_dir=Path(tmp), grasp=job.grasp,
                          progress=False, on_trial=tick)


def run_table1(config, *, trials: int, seed: int, workers: int,
               systems: tuple[str, ...] = TABLE1_SYSTEMS, lightings: tuple[str, ...] = LIGHTINGS,
               grasp: bool = True, progress: bool = True) -> Table1Result:
    """Acquire once, train each system once, run every (system, lighting) pair's trials.

    Args:
        config: the finepos config; trials run on its scene with the lighting preset replaced.
        trials: random placements per pair.
        seed: seeds the acquisition's simulated cell and every pair's placements.
        workers: parallel jobs (1: all in this process).
        systems: systems to compare (names in ``controller.systems.registry.SYSTEMS``).
        lightings: lighting presets to compare.
        grasp: grasp after each positioning run (gives the grasp success rate).
        progress: show progress bars.

    Raises:
        FineposError: an unknown system, or no trials.
    """
    unknown = [s for s in systems if s not in SYSTEMS]
    if unknown:
        raise FineposError(f"unknown system {unknown[0]!r} (one of {', '.join(SYSTEMS)})")
    if trials < 1:
        raise FineposError(f"--trials must be at least 1, got {trials}")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="finepos-table1-train-") as tmp:
        models, acquisition = train_systems_on_default_scene(systems, config, Path(tmp),
                                                             seed, progress)
    jobs = [_TrialsJob(s, light, models[s], config, trials, seed, grasp)
            for s in systems for light in lightings]
    with open_pool(min(workers, len(jobs))) as pool:
        runs = pool.run(_run_trials_job, jobs, weights=[trials] * len(jobs), desc="table1",
                        unit="trial", progress=progress)
        used_workers = pool.workers
    reports, states, outcomes = [], {}, {}
    for job, run in zip(jobs, runs, strict=True):
        report = build_report(job.system, config, with_lighting(config, job.lighting),
                              trials=trials, seed=seed, model=job.model,
                              acquisition=acquisition, run=run)
        report.pop("_trial_states")
        report["hil"] = False  # as in `finepos evaluate`: the devices were the sim's own
        reports.append(report)
        states[(job.system, job.lighting)] = run["states"]
        outcomes[(job.system, job.lighting)] = run["outcomes"]
    wall = time.perf_counter() - t0
    logger.info("table1: %d systems x %d lightings x %d trials in %.1f s on %d workers",
                len(systems), len(lightings), trials, wall, used_workers)
    channels = {s: localisation_channel(models[s]) for s in systems}
    return Table1Result(reports, states, outcomes, acquisition, wall, used_workers, EVAL_BUDGET,
                        channels)


def localisation_channel(model) -> str:
    """The image a trained system localises the part in (the baselines: max(R,G,B))."""
    return model.model.front.channel
