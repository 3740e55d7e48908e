"""Every part of the catalogue in good and in poor light (``finepos evaluate --part all``).

Each part is taught (auto), acquired and trained once on the default scene with that part on
the table, in good light, exactly as ``finepos evaluate --part NAME`` does; then each (part,
lighting) pair runs ``trials`` random placements with the same seed on the scene of the config
with that part on it and the lighting preset replaced. Each pair's report is what
``finepos evaluate --part NAME --lighting L --trials N --seed SEED`` prints (the same training
images, the same trials); the table shows, per pair, the safe rates after 1.5 and 2.5 loops
with their 95% Wilson intervals, the RMS error after 1.5, 2.5 and 3.5 loops and the loops to
a safe grasp.
"""

from __future__ import annotations

import logging
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from controller.config import with_part
from controller.evaluation.comparison.pools import Tick, open_pool
from controller.evaluation.metrics import SAFE_DEG, SAFE_MM
from controller.evaluation.trials import (
    build_report,
    rezeroed_on,
    run_trials,
    train_on_default_scene,
    with_lighting,
    with_test_camera,
)
from controller.systems.base import TrainedModel
from controller.systems.registry import SYSTEMS
from drivers.core import parts
from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

LIGHTINGS = ("good", "poor")
SAFE_BUDGETS = ("1.5", "2.5")  # loops, keys of the report's safe_rate
RMS_BUDGETS = ("1.5", "2.5", "3.5")  # loops, keys of the report's rms


@dataclass(frozen=True)
class _TrialsJob:
    part: str
    lighting: str
    system: str
    model: TrainedModel
    config: object
    trials: int
    seed: int
    grasp: bool
    rezero: bool = False
    rezero_heading_step: float | None = None


def _eval_config(config, lighting: str):
    """The config the trials of one pair run on (the part set already)."""
    return with_test_camera(with_lighting(config, lighting))


def _run_trials_job(job: _TrialsJob, tick: Tick) -> dict:
    config = _eval_config(job.config, job.lighting)
    with tempfile.TemporaryDirectory(prefix="finepos-parts-") as tmp:
        model, rezero = job.model, None
        if job.rezero:
            model, rezero = rezeroed_on(model, config, Path(tmp) / "rezero", job.seed,
                                        heading_step_deg=job.rezero_heading_step)
        run = run_trials(job.system, model, config, job.trials, job.seed,
                         work_dir=Path(tmp) / "eval", grasp=job.grasp, progress=False,
                         on_trial=tick)
    return {**run, "rezero": rezero}


def run_parts_table(config, *, system: str = "gabor", trials: int, seed: int,
                    part_names: tuple[str, ...] = tuple(parts.PARTS),
                    lightings: tuple[str, ...] = LIGHTINGS, grasp: bool = True,
                    workers: int = 1, progress: bool = True, rezero: bool = False,
                    teach_lighting: str | None = None,
                    rezero_heading_step: float | None = None) -> dict:
    """Train each part once, run every (part, lighting) pair's trials; the JSON report.

    Args:
        config: the finepos config; each part's trials run on its scene with that part on the
            table and the lighting preset replaced.
        system: the vision system (``controller.systems.registry.SYSTEMS``).
        trials: random placements per pair.
        seed: seeds each part's acquisition and every pair's placements.
        part_names: the parts (catalogue names), in table order.
        lightings: lighting presets, in table order.
        grasp: grasp after each positioning run (gives the grasp success rate).
        workers: parallel processes for the trials (1: all in this process).
        progress: show progress bars.
        rezero: re-zero each part's model in each pair's light before its trials
            (``trials.rezeroed_on``; each row's ``rezero`` says what moved).
        rezero_heading_step: with ``rezero``, also its zero by heading in steps of at most
            this (deg; ``controller.calibration.heading_zero``).
        teach_lighting: teach each part, acquire and train under this lighting preset
            instead of the default scene's (each row's ``teach_lighting``).

    Returns:
        ``{"system", "trials", "seed", "scene", "teach_lighting", "wall_seconds", "rows":
        [...]}``: one ``finepos evaluate`` report per (part, lighting), part-major, each with
        ``part`` and ``lighting``.

    Raises:
        FineposError: an unknown system or part, or no trials.
    """
    if system not in SYSTEMS:
        raise FineposError(f"unknown system {system!r} (one of {', '.join(SYSTEMS)})")
    if trials < 1:
        raise FineposError(f"--trials must be at least 1, got {trials}")
    t0 = time.perf_counter()
    configs = {kind: with_part(config, kind) for kind in part_names}
    models, acquisitions = {}, {}
    with tempfile.TemporaryDirectory(prefix="finepos-parts-train-") as tmp:
        for kind in part_names:
            logger.info("parts table: teach-in, acquisition and training on the %s", kind)
            models[kind], acquisitions[kind] = train_on_default_scene(
                system, configs[kind], Path(tmp) / kind, seed, progress,
                lighting=teach_lighting)
    jobs = [_TrialsJob(kind, light, system, models[kind], configs[kind], trials, seed, grasp,
                       rezero, rezero_heading_step)
            for kind in part_names for light in lightings]
    with open_pool(min(workers, len(jobs))) as pool:
        runs = pool.run(_run_trials_job, jobs, weights=[trials] * len(jobs), desc="parts",
                        unit="trial", progress=progress)
    rows = []
    for job, run in zip(jobs, runs, strict=True):
        report = build_report(system, job.config, _eval_config(job.config, job.lighting),
                              trials=trials, seed=seed, model=job.model,
                              acquisition=acquisitions[job.part], run=run)
        report.pop("_trial_states")
        report["hil"] = False
        rows.append({"part": job.part, "kappa": run["kappa"], **report})
    wall = time.perf_counter() - t0
    logger.info("parts table: %d parts x %d lightings x %d trials in %.1f s", len(part_names),
                len(lightings), trials, wall)
    return {"system": system, "trials": trials, "seed": seed, "scene": config.source,
            "teach_lighting": teach_lighting, "wall_seconds": wall, "rows": rows}


def _rate(row: dict, budget: str) -> str:
    ci = row["safe_rate_ci"][budget]
    return f"{_percent(ci['rate'])}% ({ci['low'] * 100:.0f}-{ci['high'] * 100:.0f})"


def _percent(rate: float) -> str:
    """A rate in percent to 0.1, without a trailing .0: 199 of 200 is 99.5, not 100."""
    return f"{rate * 100:.1f}".removesuffix(".0")


def _rms(row: dict, budget: str) -> str:
    r = row["rms"][budget]
    return f"{r['x_mm']:.2f} / {r['y_mm']:.2f} / {r['phi_deg']:.2f}"


def _loops(row: dict) -> str:
    lts = row["loops_to_safe"]

    def text(value) -> str:
        return "never" if value is None else f"{value:g}"

    never = f", {lts['never_safe']} never" if lts["never_safe"] else ""
    return f"{text(lts['median'])} / {text(lts['p95'])}{never}"


def parts_markdown(report: dict) -> str:
    """The parts table as Markdown: per part and lighting the safe rates (95% Wilson interval),
    RMS x / y / phi (mm, mm, deg) after 1.5, 2.5 and 3.5 loops and the loops to a safe grasp
    (median / p95)."""
    head = (["part", "kappa", "light"] + [f"safe <= {b} loops" for b in SAFE_BUDGETS]
            + [f"RMS after {b} loops (x mm / y mm / phi deg)" for b in RMS_BUDGETS]
            + ["loops to safe (median / p95)"])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in report["rows"]:
        cells = ([row["part"], str(row["kappa"]), row["lighting"]]
                 + [_rate(row, b) for b in SAFE_BUDGETS] + [_rms(row, b) for b in RMS_BUDGETS]
                 + [_loops(row)])
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    taught = report.get("teach_lighting")
    taught = f", taught in {taught} light" if taught else ""
    lines.append(f"{report['system']}, {report['trials']} trials per row, seed {report['seed']}, "
                 f"scene {report['scene']}{taught}; safe: within {SAFE_MM:g} mm and "
                 f"{SAFE_DEG:g} deg of the grasp pose; {report['wall_seconds']:.0f} s in all.")
    return "\n".join(lines) + "\n"

