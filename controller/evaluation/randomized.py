"""``finepos evaluate --randomize``: the method on randomized cells, the yardstick.

A real cell brings a camera, a lamp and a table nobody here has seen. Each drawn *cell* is a
camera (its rendition, optics and mount), a table and the part's colour; it is taught,
acquires its grids and trains under a drawn light, as a user would set it up. Each *trial* on
that cell then draws the light afresh (the lamps of a room change; the camera, mount and table
do not), a card over the part and other parts on the table, places the part at random and runs
the loop. Several trials share one trained cell (``trials_per_cell``), so the yardstick costs
one training per cell, not per trial.

Every draw comes from one seed (``numpy.random.SeedSequence``: cell i and trial j of it have
their own spawned streams), is recorded in the report, and the report breaks the results down
by each drawn factor, so a weak spot shows as a row.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from controller.config import with_part
from controller.evaluation.comparison.pools import Tick, open_pool
from controller.evaluation.metrics import is_safe, loops_to_safe, state_at, wilson
from controller.evaluation.mounts import random_camera
from controller.evaluation.trials import rezeroed_on, run_trials, train_systems_on_cell
from controller.loop.checks import STOPPED
from controller.systems.registry import SYSTEMS
from drivers.core.errors import FineposError
from sim_backend.cell.lighting import kelvin_rgb
from sim_backend.cell.scene_config import (
    ClutterConfig,
    ExposureConfig,
    LampConfig,
    LightingConfig,
    OccluderConfig,
    TableConfig,
)
from sim_backend.cell.sim_cell import SimCell

logger = logging.getLogger(__name__)

TRIALS_PER_CELL = 25
# The camera's rendition.
GAMMA_RANGE = (1.0, 2.4)
NOISE_STD_RANGE = (0.5, 4.0)  # read noise, grey levels at unit gain
FULL_WELL_RANGE_E = (3000.0, 20000.0)
MAX_GAIN_RANGE = (4.0, 16.0)
JPEG_QUALITY_RANGE = (60, 100)
# A fixed exposure is set once by the user, under the light the cell is taught in: within this
# factor of what auto-exposure would settle on there.
FIXED_EXPOSURE_RANGE = (0.7, 1.4)
EXPOSURE_SETTLE_FRAMES = 12
# The light: 1-3 lamps; an overall brightness drawn log-uniformly from dim to bright scales
# the ambient and every lamp's diffuse light.
LAMPS_RANGE = (1, 3)
BRIGHTNESS_RANGE = (0.25, 1.4)
AMBIENT_RANGE = (0.1, 0.5)
DIFFUSE_RANGE = (0.3, 0.9)
ELEVATION_RANGE_DEG = (20.0, 90.0)
KELVIN_RANGE = (2700.0, 6500.0)
SHADOW_RANGE = (0.2, 0.95)
# The table and the part.
TABLE_TEXTURES = ("none", "wood", "checker", "noise")
TABLE_VALUE_RANGE = (0.15, 0.85)
TABLE_SATURATION_RANGE = (0.0, 0.6)
PART_VALUE_RANGE = (0.5, 1.0)
PART_SATURATION_RANGE = (0.4, 1.0)
# A part whose colour lies this close to the table's (RGB distance, 0..1 a channel) is one no
# camera tells from it: such a pair is drawn again.
MIN_COLOUR_DISTANCE = 0.25
OCCLUDER_RANGE = (0.0, 0.3)
OCCLUDER_MIN = 0.01  # a card hiding less than this is left off
CLUTTER_RANGE = (0, 3)
# The yardstick's targets (issue: a randomized cell as the yardstick).
VISIBLE_SAFE = 0.8  # trials where at least this share of the part is visible ...
SAFE_TARGET = 0.99  # ... are safe within 2.5 loops at least this often
RMS_TARGET = {"x_mm": 0.05, "y_mm": 0.05, "phi_deg": 0.3}
CLASS_SAFE_TARGET = 0.97
MIN_CLASS_TRIALS = 10  # a factor's class with fewer trials says too little to be the worst
VISIBLE_STOPS = 0.85  # where at least this share is visible ...
STOPS_TARGET = 0.02  # ... at most this share of the trials stops as one of STOP_KINDS
STOP_KINDS = ("occluded", "ambiguous", "no_object")
BUDGET = 2.5  # loops


def _hsv(hue: float, saturation: float, value: float) -> tuple[float, float, float]:
    """RGB (0..1) of a colour given as hue (0..1), saturation and value."""
    i = int(hue * 6.0) % 6
    f = hue * 6.0 - math.floor(hue * 6.0)
    p, q, t = value * (1 - saturation), value * (1 - f * saturation), value * (
        1 - (1 - f) * saturation)
    return [(value, t, p), (q, value, p), (p, value, t), (p, q, value), (t, p, value),
            (value, p, q)][i]


def draw_light(rng: np.random.Generator) -> tuple[LightingConfig, dict]:
    """A room's light: 1-3 lamps at random directions and heights, each with its colour
    temperature and shadow strength, and an ambient share, all scaled by one brightness from
    dim to bright. Returns the config and the draw's factors (for the report)."""
    brightness = float(np.exp(rng.uniform(*np.log(BRIGHTNESS_RANGE))))
    count = int(rng.integers(LAMPS_RANGE[0], LAMPS_RANGE[1] + 1))
    lamps = []
    for _ in range(count):
        azimuth = math.radians(rng.uniform(0.0, 360.0))
        elevation = math.radians(rng.uniform(*ELEVATION_RANGE_DEG))
        direction = (math.cos(elevation) * math.cos(azimuth),
                     math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
        kelvin = float(rng.uniform(*KELVIN_RANGE))
        lamps.append({"direction": tuple(round(c, 6) for c in direction),
                      "elevation_deg": math.degrees(elevation), "kelvin": kelvin,
                      "diffuse": brightness * float(rng.uniform(*DIFFUSE_RANGE)) / math.sqrt(count),
                      "shadow_strength": float(rng.uniform(*SHADOW_RANGE))})
    ambient = brightness * float(rng.uniform(*AMBIENT_RANGE))
    key, *more = lamps
    config = LightingConfig(
        preset="good", ambient=ambient, diffuse=key["diffuse"], specular=0.0,
        direction=key["direction"], shadows=True, shadow_strength=key["shadow_strength"],
        color=kelvin_rgb(key["kelvin"]),
        lamps=tuple(LampConfig(direction=lamp["direction"], diffuse=lamp["diffuse"],
                               color=kelvin_rgb(lamp["kelvin"]),
                               shadow_strength=lamp["shadow_strength"]) for lamp in more))
    factors = {"lamps": count, "brightness": brightness, "ambient": ambient,
               "key_elevation_deg": key["elevation_deg"], "key_kelvin": key["kelvin"],
               "key_shadow": key["shadow_strength"], "lamp_list": lamps}
    return config, factors


@dataclass(frozen=True)
class CellDraw:
    """One drawn cell: the camera (``scene_config.CameraConfig``; a fixed exposure's gain is
    set at training, ``fixed_exposure`` the factor against auto-exposure's), the table, the
    part's colour and the light it is taught in; ``factors``: the draw as the report lists
    it."""

    index: int
    seed: int
    camera: object
    table: TableConfig
    part_color: tuple[float, float, float]
    train_light: LightingConfig
    fixed_exposure: float | None
    factors: dict


@dataclass(frozen=True)
class TrialDraw:
    """One drawn trial on a cell: its light, the card over the part, the clutter, and the
    seed of the placement and the cell's noise."""

    seed: int
    light: LightingConfig
    occluder: float
    clutter: int
    factors: dict


def draw_cell(rng: np.random.Generator, base_camera, index: int, seed: int) -> CellDraw:
    """A random cell around ``base_camera`` (the config's ``scene.camera``)."""
    camera = random_camera(rng, base_camera)  # mount and lens
    auto = bool(rng.random() < 0.5)
    exposure = ExposureConfig(auto=True, target_grey=camera.exposure.target_grey,
                              speed=camera.exposure.speed,
                              max_gain=float(rng.uniform(*MAX_GAIN_RANGE)))
    jpeg = 0 if rng.random() < 0.5 else int(rng.integers(JPEG_QUALITY_RANGE[0],
                                                          JPEG_QUALITY_RANGE[1] + 1))
    camera = dataclasses.replace(
        camera, preset="realistic", exposure=exposure,
        gamma=float(rng.uniform(*GAMMA_RANGE)),
        noise_std=float(rng.uniform(*NOISE_STD_RANGE)),
        full_well_e=float(rng.uniform(*FULL_WELL_RANGE_E)),
        pixel_samples=int(rng.integers(1, 4)), jpeg_quality=jpeg,
        bayer=bool(rng.random() < 0.5))
    fixed = None if auto else float(rng.uniform(*FIXED_EXPOSURE_RANGE))
    texture = TABLE_TEXTURES[int(rng.integers(len(TABLE_TEXTURES)))]
    while True:
        table_rgb = _hsv(rng.random(), rng.uniform(*TABLE_SATURATION_RANGE),
                         rng.uniform(*TABLE_VALUE_RANGE))
        part_rgb = _hsv(rng.random(), rng.uniform(*PART_SATURATION_RANGE),
                        rng.uniform(*PART_VALUE_RANGE))
        distance = float(np.linalg.norm(np.subtract(table_rgb, part_rgb)))
        if distance >= MIN_COLOUR_DISTANCE:
            break
    light, light_factors = draw_light(rng)
    factors = {
        "gamma": camera.gamma, "auto_exposure": auto, "fixed_exposure": fixed,
        "noise_std": camera.noise_std, "full_well_e": camera.full_well_e,
        "pixel_samples": camera.pixel_samples, "jpeg_quality": jpeg, "bayer": camera.bayer,
        "fov_deg": camera.lens.fov_deg, "k1": camera.lens.k1,
        "vignetting": camera.lens.vignetting, "blur_px": camera.lens.blur_px,
        "mount": dataclasses.asdict(camera.mount),
        "table_texture": texture, "table_rgb": list(table_rgb),
        "table_value": max(table_rgb), "part_rgb": list(part_rgb),
        "part_hue": _hue_name(part_rgb), "colour_distance": distance,
        "train_light": light_factors,
    }
    return CellDraw(index, seed, camera, TableConfig(color=table_rgb, texture=texture),
                    part_rgb, light, fixed, factors)


def _hue_name(rgb) -> str:
    r, g, b = rgb
    top, low = max(rgb), min(rgb)
    if top - low < 0.1:
        return "grey"
    if top == r:
        hue = ((g - b) / (top - low)) % 6
    elif top == g:
        hue = (b - r) / (top - low) + 2
    else:
        hue = (r - g) / (top - low) + 4
    return ("red", "yellow", "green", "cyan", "blue", "magenta")[int((hue + 0.5) % 6)]


def draw_trial(rng: np.random.Generator, seed: int, train_brightness: float) -> TrialDraw:
    """A trial's light, card and clutter on a cell taught under a light of
    ``train_brightness`` (the factors' ``light_change``: |log2| of the brightness ratio)."""
    light, factors = draw_light(rng)
    coverage = float(rng.uniform(*OCCLUDER_RANGE))
    clutter = int(rng.integers(CLUTTER_RANGE[0], CLUTTER_RANGE[1] + 1))
    coverage = coverage if coverage >= OCCLUDER_MIN else 0.0
    change = abs(math.log2(factors["brightness"] / train_brightness))
    return TrialDraw(seed, light, coverage, clutter,
                     {**factors, "light_change": change, "occluder": coverage,
                      "clutter": clutter})


def cell_config(config, cell: CellDraw, light: LightingConfig, occluder: float = 0.0,
                clutter: int = 0):
    """``config`` with the drawn cell's scene, under ``light``, with a card hiding
    ``occluder`` of the part and ``clutter`` other parts on the table."""
    scene = config.scene
    scene = dataclasses.replace(
        scene, camera=cell.camera, table=cell.table, lighting=light,
        object=dataclasses.replace(scene.object, color=cell.part_color),
        occluder=OccluderConfig(enabled=occluder > 0.0, coverage=occluder),
        clutter=ClutterConfig(count=clutter))
    return dataclasses.replace(config, scene=scene)


def settled_exposure(config, seed: int) -> float:
    """The exposure x gain auto-exposure settles on at the cell's start pose."""
    camera = config.scene.camera
    auto = dataclasses.replace(camera, exposure=dataclasses.replace(camera.exposure, auto=True))
    scene = dataclasses.replace(config.scene, camera=auto)
    with SimCell(scene, seed=seed, parts=config.parts) as cell:
        for _ in range(EXPOSURE_SETTLE_FRAMES):
            cell.render()
        return cell.exposure_factor


def with_fixed_exposure(config, cell: CellDraw, seed: int):
    """``config`` with the cell's camera at a fixed exposure, set against what auto-exposure
    settles on under the training light (``CellDraw.fixed_exposure``), or unchanged for a
    camera with auto-exposure."""
    if cell.fixed_exposure is None:
        return config, None
    factor = settled_exposure(config, seed) * cell.fixed_exposure
    camera = config.scene.camera
    gain = float(np.clip(factor, 0.05, 32.0))
    camera = dataclasses.replace(camera, exposure=dataclasses.replace(
        camera.exposure, auto=False, gain=gain))
    return dataclasses.replace(config, scene=dataclasses.replace(config.scene, camera=camera)), gain


@dataclass(frozen=True)
class _CellJob:
    system: str
    config: object
    cell: CellDraw
    trials: tuple[TrialDraw, ...]
    grasp: bool
    rezero: bool = False
    rezero_heading_step: float | None = None


def training_config(config, cell: CellDraw):
    """``config`` with the drawn ``cell`` under its training light, and the gain of its fixed
    exposure (None: auto-exposure); the trials run with its ``scene.camera``."""
    return with_fixed_exposure(cell_config(config, cell, cell.train_light), cell, cell.seed)


def train_cell(system: str, train_cfg, cell: CellDraw, work_dir: Path):
    """Teach, acquire and train ``system`` on ``train_cfg`` (``training_config``), the drawn
    ``cell``, with that config's recipe; the trained model.

    Raises:
        FineposError: the cell cannot be taught or trained.
    """
    models, _ = train_systems_on_cell((system,), train_cfg, work_dir, cell.seed, progress=False)
    return models[system]


def run_cell_trial(system: str, model, config, cell: CellDraw, camera, trial: TrialDraw,
                   work_dir: Path, grasp: bool) -> dict:
    """One drawn trial on a trained cell (the trial's light, card and clutter, the cell's
    ``camera``): its report record."""
    trial_cfg = cell_config(config, cell, trial.light, trial.occluder, trial.clutter)
    trial_cfg = dataclasses.replace(trial_cfg, scene=dataclasses.replace(
        trial_cfg.scene, camera=camera))
    run = run_trials(system, model, trial_cfg, 1, trial.seed, work_dir=work_dir, grasp=grasp,
                     progress=False, measure_visible=True)
    return _trial_record(cell, trial, run["states"][0], run)


def _run_cell(job: _CellJob, tick: Tick) -> dict:
    """Train on a drawn cell, then run its trials; one record per trial."""
    cell = job.cell
    records = []
    with tempfile.TemporaryDirectory(prefix="finepos-random-") as tmp:
        train_cfg, gain = training_config(job.config, cell)
        camera = train_cfg.scene.camera
        t0 = time.perf_counter()
        try:
            trained = train_cell(job.system, train_cfg, cell, Path(tmp) / "train")
        except FineposError as exc:  # the cell cannot be taught: every trial on it fails
            logger.warning("randomized cell %d: not trained: %s", cell.index, exc)
            for trial in job.trials:
                records.append(untrained_record(cell, trial, str(exc)))
                tick()
            return {"cell": cell.index, "fixed_gain": gain, "train_seconds": None,
                    "train_error": str(exc), "records": records}
        train_s = time.perf_counter() - t0
        for trial in job.trials:
            model, rezero = trained, None
            if job.rezero:
                model, rezero = _rezeroed(job, trained, camera, trial, Path(tmp) / "rezero")
            record = run_cell_trial(job.system, model, job.config, cell, camera, trial,
                                    Path(tmp) / "eval", job.grasp)
            records.append(record if rezero is None else {**record, "rezero": rezero})
            tick()
    return {"cell": cell.index, "fixed_gain": gain, "train_seconds": train_s,
            "train_error": None, "records": records}


def _rezeroed(job: _CellJob, model, camera, trial: TrialDraw, work_dir: Path
              ) -> tuple[object, dict]:
    """The cell's model re-zeroed at the taught pose in the trial's light, as a user runs
    ``finepos rezero`` after the light changed (the part lying free: no card, no clutter),
    and what it cost and moved (``error``: the re-zero refused; the trial then runs with the
    model as trained)."""
    config = cell_config(job.config, job.cell, trial.light)
    config = dataclasses.replace(config, scene=dataclasses.replace(config.scene, camera=camera))
    try:
        rezeroed, report = rezeroed_on(model, config, work_dir, trial.seed,
                                       heading_step_deg=job.rezero_heading_step)
    except FineposError as exc:
        return model, {"error": str(exc), "cell_seconds": None}
    return rezeroed, {"error": None, "cell_seconds": report.get("cell_seconds")}


def _trial_record(cell: CellDraw, trial: TrialDraw, states, run: dict) -> dict:
    err = state_at(states, BUDGET).error
    lts = loops_to_safe(states)
    return {"cell": cell.index, "seed": trial.seed, "visible": run["visible"][0],
            "outcome": run["outcomes"][0], "error": list(err),
            "safe_1.5": is_safe(state_at(states, 1.5).error), "safe_2.5": is_safe(err),
            "loops_to_safe": lts if math.isfinite(lts) else None,
            "grasped": run["grasps"][0] if run["grasps"] else None,
            "draw": trial.factors}


def untrained_record(cell: CellDraw, trial: TrialDraw, reason: str) -> dict:
    return {"cell": cell.index, "seed": trial.seed, "visible": None, "outcome": "untrained",
            "reason": reason, "error": None, "safe_1.5": False, "safe_2.5": False,
            "loops_to_safe": None, "grasped": False, "draw": trial.factors}


def draw_plan(config, *, trials: int, seed: int, trials_per_cell: int
              ) -> list[tuple[CellDraw, tuple[TrialDraw, ...]]]:
    """The cells and trials of a run: ``ceil(trials / trials_per_cell)`` cells, the trials
    dealt to them in turn, every draw from ``seed``."""
    cells = max(1, math.ceil(trials / trials_per_cell))
    root = np.random.SeedSequence(seed)
    plan = []
    counts = [trials // cells + (1 if i < trials % cells else 0) for i in range(cells)]
    for i, (cell_seq, count) in enumerate(zip(root.spawn(cells), counts, strict=True)):
        cell_part, trials_part = cell_seq.spawn(2)
        cell_rng = np.random.default_rng(cell_part)
        cell_seed = int(cell_rng.integers(2**31))
        cell = draw_cell(cell_rng, config.scene.camera, i, cell_seed)
        draws = []
        for t_seq in trials_part.spawn(count):
            t_rng = np.random.default_rng(t_seq)
            draws.append(draw_trial(t_rng, int(t_rng.integers(2**31)),
                                    cell.factors["train_light"]["brightness"]))
        plan.append((cell, tuple(draws)))
    return plan


def planned(config, *, trials: int, seed: int, trials_per_cell: int):
    """``config`` with its scene's part set up, and its ``draw_plan``.

    Raises:
        FineposError: no trials.
    """
    if trials < 1:
        raise FineposError(f"--trials must be at least 1, got {trials}")
    config = with_part(config, config.scene.object.kind)
    return config, draw_plan(config, trials=trials, seed=seed, trials_per_cell=trials_per_cell)


def evaluate_randomized(system: str, config, *, trials: int, seed: int,
                        trials_per_cell: int = TRIALS_PER_CELL, grasp: bool = True,
                        workers: int = 1, progress: bool = True, rezero: bool = False,
                        rezero_heading_step: float | None = None) -> dict:
    """The ``finepos evaluate --randomize`` report (module docstring): every cell's and
    trial's draw, each trial's result, the yardstick's figures and targets, and the results
    by drawn factor. ``rezero``: before each trial the cell's model is re-zeroed in the
    trial's light (``rezero_heading_step``: also by heading); the report's ``rezero`` says
    how often that was refused and the arm time it took.

    Raises:
        FineposError: an unknown system, or no trials.
    """
    if system not in SYSTEMS:
        raise FineposError(f"unknown system {system!r} (one of {', '.join(SYSTEMS)})")
    t0 = time.perf_counter()
    config, plan = planned(config, trials=trials, seed=seed, trials_per_cell=trials_per_cell)
    jobs = [_CellJob(system, config, cell, draws, grasp, rezero, rezero_heading_step)
            for cell, draws in plan]
    with open_pool(min(workers, len(jobs))) as pool:
        results = pool.run(_run_cell, jobs, weights=[len(j.trials) for j in jobs],
                           desc=f"randomized {system}", unit="trial", progress=progress)
    records = [r for res in results for r in res["records"]]
    cells = []
    for (cell, _), res in zip(plan, results, strict=True):
        cells.append({"index": cell.index, "seed": cell.seed, "fixed_gain": res["fixed_gain"],
                      "train_seconds": res["train_seconds"], "train_error": res["train_error"],
                      **cell.factors})
    return {"system": system, "randomize": True, "object": config.scene.object.kind,
            "trials": trials, "seed": seed, "trials_per_cell": trials_per_cell,
            "grasp": grasp, "wall_seconds": time.perf_counter() - t0,
            "rezero": _rezero_summary(records) if rezero else None,
            "rezero_heading_step": rezero_heading_step,
            **summarise_randomized(records, cells), "cells": cells, "trial_records": records}


def _rezero_summary(records: list[dict]) -> dict:
    """How many re-zeros were refused, and the median arm time of those made (cell s)."""
    made = [r["rezero"] for r in records if r.get("rezero") and r["rezero"]["error"] is None]
    seconds = [m["cell_seconds"] for m in made if m["cell_seconds"] is not None]
    return {"trials": sum(1 for r in records if r.get("rezero")),
            "refused": sum(1 for r in records if r.get("rezero") and r["rezero"]["error"]),
            "cell_seconds_median": float(np.median(seconds)) if seconds else None}


def _rates(records: list[dict]) -> dict:
    n = len(records)
    if n == 0:
        return {"trials": 0}
    safe = sum(r["safe_2.5"] for r in records)
    errs = np.array([r["error"] for r in records if r["error"] is not None],
                    dtype=float).reshape(-1, 3)
    rms = np.sqrt(np.mean(errs ** 2, axis=0)) if len(errs) else np.full(3, math.nan)
    return {"trials": n, "safe_2.5": wilson(safe, n),
            "rms_2.5": {"x_mm": float(rms[0]), "y_mm": float(rms[1]), "phi_deg": float(rms[2])}}


def _visible(record: dict) -> float:
    """The share of the part seen at its pre-grasp pose; a trial on a cell that could not be
    taught never placed its part, and counts as fully visible (its failure is the method's)."""
    return 1.0 if record["visible"] is None else record["visible"]


def summarise_randomized(records: list[dict], cells: list[dict]) -> dict:
    """The yardstick's figures over ``records`` (one per trial), the targets they meet, and
    the results by drawn factor (``by_factor``)."""
    seen = [r for r in records if _visible(r) >= VISIBLE_SAFE]
    mostly = [r for r in records if _visible(r) >= VISIBLE_STOPS]
    stops = sum(r["outcome"] in STOP_KINDS for r in mostly)
    outcomes: dict[str, int] = {}
    for r in records:
        outcomes[r["outcome"]] = outcomes.get(r["outcome"], 0) + 1
    factors = by_factor(records, cells)
    visible = _rates(seen)
    worst = min(({"factor": name, **row} for name, rows in factors.items() for row in rows
                 if row["trials"] >= MIN_CLASS_TRIALS),
                key=lambda row: row["safe_2.5"]["rate"], default=None)
    stop_rate = wilson(stops, len(mostly)) if mostly else None
    targets = {
        "safe_2.5_visible": bool(seen) and visible["safe_2.5"]["rate"] >= SAFE_TARGET,
        "rms_2.5_visible": bool(seen) and all(visible["rms_2.5"][k] <= v
                                              for k, v in RMS_TARGET.items()),
        "class_safe": worst is not None and worst["safe_2.5"]["rate"] >= CLASS_SAFE_TARGET,
        "stops_visible": stop_rate is not None and stop_rate["rate"] <= STOPS_TARGET,
    }
    grasped = [r["grasped"] for r in records if r["grasped"] is not None]
    return {
        "all": _rates(records),
        f"visible_{VISIBLE_SAFE:g}": visible,
        f"stops_visible_{VISIBLE_STOPS:g}": {"kinds": list(STOP_KINDS), "trials": len(mostly),
                                             "stops": stop_rate},
        "outcomes": dict(sorted(outcomes.items())),
        "stopped": sum(r["outcome"] in STOPPED for r in records),
        "grasp_success": wilson(sum(grasped), len(grasped)) if grasped else None,
        "worst_class": worst, "targets": targets, "by_factor": factors,
    }


def _bins(edges: tuple[float, ...]):
    def label(value: float) -> str:
        for lo, hi in zip(edges, edges[1:], strict=False):
            if value < hi:
                return f"{lo:g}-{hi:g}"
        return f">={edges[-1]:g}"
    return label


# Each factor: where its value is read (the trial's own draw or its cell's) and its classes.
_FACTORS = {
    "gamma": ("cell", "gamma", _bins((1.0, 1.35, 1.7, 2.05, 2.4))),
    "auto_exposure": ("cell", "auto_exposure", str),
    "noise_std": ("cell", "noise_std", _bins((0.5, 1.5, 2.5, 3.5, 4.0))),
    "pixel_samples": ("cell", "pixel_samples", str),
    "jpeg_quality": ("cell", "jpeg_quality",
                     lambda q: "none" if q == 0 else _bins((60, 80, 100))(q)),
    "bayer": ("cell", "bayer", str),
    "fov_deg": ("cell", "fov_deg", _bins((40.0, 48.0, 52.0, 56.0, 64.0))),
    "k1": ("cell", "k1", _bins((-0.35, -0.2, -0.05, 0.1))),
    "mount_tilt_deg": ("cell", "mount", lambda m: _bins((0.0, 3.0, 6.0, 8.0))(
        abs(m["tilt_deg"]))),
    "table_texture": ("cell", "table_texture", str),
    "table_value": ("cell", "table_value", _bins((0.15, 0.4, 0.6, 0.85))),
    "part_hue": ("cell", "part_hue", str),
    "colour_distance": ("cell", "colour_distance", _bins((0.25, 0.45, 0.7, 1.0))),
    "train_lamps": ("cell", "train_light", lambda f: str(f["lamps"])),
    "lamps": ("trial", "lamps", str),
    "brightness": ("trial", "brightness", _bins((0.25, 0.45, 0.7, 1.0, 1.4))),
    "light_change": ("trial", "light_change", _bins((0.0, 0.5, 1.0, 2.0))),
    "key_elevation_deg": ("trial", "key_elevation_deg", _bins((20.0, 40.0, 60.0, 90.0))),
    "key_kelvin": ("trial", "key_kelvin", _bins((2700.0, 3500.0, 4500.0, 5500.0, 6500.0))),
    "key_shadow": ("trial", "key_shadow", _bins((0.2, 0.45, 0.7, 0.95))),
    "occluder": ("trial", "occluder", lambda c: "none" if c == 0 else _bins((0.0, 0.1, 0.2,
                                                                            0.3))(c)),
    "visible": ("visible", "visible", _bins((0.0, 0.7, 0.8, 0.9, 0.99))),
    "clutter": ("trial", "clutter", str),
}


def by_factor(records: list[dict], cells: list[dict]) -> dict:
    """For each drawn factor, one row per class: trials, safe within 2.5 loops (Wilson
    interval) and RMS after 2.5 loops."""
    by_cell = {c["index"]: c for c in cells}
    out: dict[str, list[dict]] = {}
    for name, (where, key, classify) in _FACTORS.items():
        groups: dict[str, list[dict]] = {}
        for r in records:
            source = {"cell": by_cell[r["cell"]], "trial": r["draw"],
                      "visible": {"visible": _visible(r)}}[where]
            groups.setdefault(classify(source[key]), []).append(r)
        out[name] = [{"class": k, **_rates(v)} for k, v in sorted(groups.items())]
    return out
