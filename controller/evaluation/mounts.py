"""``finepos evaluate --mounts N``: the method on N random cameras, each set up from scratch.

Every cell mounts its camera a little differently and buys a different lens. For each of N
random cameras (``random_camera``: mount tilt within +/-8 deg, roll and pan within +/-4 deg,
lens offset within +/-5 mm, field of view within +/-15 %, k1 within [-0.35, 0.1], vignetting,
blur and auto-exposure varied) the cell is taught, acquires its grids, trains and is tested, as a
user would do it (``trials.evaluate``). The method is never given any camera parameter: they
only shape the simulated images.
"""

from __future__ import annotations

import dataclasses
import statistics
import tempfile
from pathlib import Path

import numpy as np

from controller.calibration.self_check import self_check
from controller.devices import open_devices
from controller.evaluation.trials import (
    build_report,
    evaluate,
    run_trials,
    train_on_default_scene,
)
from controller.fine_positioner import FinePositioner
from sim_backend.cell import hand_camera
from sim_backend.cell.optics import resolve_camera
from sim_backend.cell.scene_config import ExposureConfig, LensConfig, MountConfig

TILT_DEG = 8.0
ROLL_DEG = 4.0
PAN_DEG = 4.0
OFFSET_MM = 5.0
FOV_FRACTION = 0.15
K1_RANGE = (-0.35, 0.1)
VIGNETTING_RANGE = (0.0, 0.5)
BLUR_RANGE_PX = (0.0, 1.2)
TARGET_GREY_RANGE = (80.0, 140.0)
SPEED_RANGE = (0.3, 0.9)
GAMMA_RANGE = (1.6, 2.4)


def random_camera(rng: np.random.Generator, base):
    """A random camera (``scene_config.CameraConfig``) drawn around ``base`` (its preset,
    noise, Bayer and JPEG kept): mount, lens and exposure as the module docstring says. k2 is
    drawn in [0, 0.05] and raised until the lens does not fold the image (real strong barrel
    lenses have a positive k2)."""
    mount = MountConfig(tilt_deg=float(rng.uniform(-TILT_DEG, TILT_DEG)),
                        roll_deg=float(rng.uniform(-ROLL_DEG, ROLL_DEG)),
                        pan_deg=float(rng.uniform(-PAN_DEG, PAN_DEG)),
                        offset_mm=tuple(float(v) for v in rng.uniform(-OFFSET_MM, OFFSET_MM, 3)))
    fov = hand_camera.VFOV_DEG * (1.0 + rng.uniform(-FOV_FRACTION, FOV_FRACTION))
    k1 = float(rng.uniform(*K1_RANGE))
    k2 = float(rng.uniform(0.0, 0.05))
    p1, p2 = (float(v) for v in rng.uniform(-0.001, 0.001, 2))
    vignetting = float(rng.uniform(*VIGNETTING_RANGE))
    blur = float(rng.uniform(*BLUR_RANGE_PX))
    exposure = ExposureConfig(auto=True, target_grey=float(rng.uniform(*TARGET_GREY_RANGE)),
                              speed=float(rng.uniform(*SPEED_RANGE)))
    gamma = float(rng.uniform(*GAMMA_RANGE))
    while True:
        lens = LensConfig(fov_deg=float(fov), k1=k1, k2=round(k2, 4), p1=p1, p2=p2,
                          vignetting=vignetting, blur_px=blur)
        try:
            return dataclasses.replace(base, lens=lens, mount=mount, test_mount=None,
                                       exposure=exposure, gamma=gamma)
        except ValueError:  # the lens folds the image
            k2 += 0.02


def _with_camera(config, camera):
    return dataclasses.replace(config, scene=dataclasses.replace(config.scene, camera=camera))


def camera_row(camera) -> dict:
    """A camera's parameters as the report lists them: the mount and every resolved optics
    and sensor value."""
    return {"mount": dataclasses.asdict(camera.mount), **resolve_camera(camera).as_dict()}


def evaluate_mounts(system: str, config, *, mounts: int, trials: int, seed: int,
                    lighting: str | None = None, grasp: bool = True, progress: bool = True,
                    hil: bool = False) -> dict:
    """The ``finepos evaluate --mounts`` report: one row per random camera (its parameters,
    safe rates, RMS per loop budget, grasp success) and a summary (worst and median camera,
    metric by metric; ``worst_camera``: the index with the lowest safe rate within 2.5 loops,
    then the largest RMS position error after 2.5 loops).

    Camera i is drawn from ``seed`` and is set up and tested with seed ``seed + i``.
    """
    rng = np.random.default_rng(seed)
    rows = []
    for i in range(mounts):
        camera = random_camera(rng, config.scene.camera)
        report = evaluate(system, _with_camera(config, camera), trials=trials, seed=seed + i,
                          lighting=lighting, grasp=grasp, progress=progress, hil=hil)
        rows.append({"camera": camera_row(camera), "seed": seed + i,
                     "safe_rate": report["safe_rate"], "rms": report["rms"],
                     "loops_to_safe": report["loops_to_safe"],
                     "grasp_success_rate": report["grasp_success_rate"],
                     "outcomes": report["outcomes"]})
    return {"system": system, "mounts": mounts, "trials": trials, "seed": seed,
            "lighting": lighting or config.scene.lighting.preset, "scene": config.source,
            "cameras": rows, "summary": summarise_mounts(rows)}


def summarise_mounts(rows: list[dict]) -> dict:
    """Worst and median camera over ``rows``, metric by metric (safe rates: lowest; RMS:
    largest), and the index of the worst camera overall."""
    def metric(pick, key):
        return pick([key(r) for r in rows])

    out: dict = {}
    for name, pick_safe, pick_err in (("worst", min, max),
                                      ("median", statistics.median, statistics.median)):
        out[name] = {
            "safe_rate": {b: metric(pick_safe, lambda r, b=b: r["safe_rate"][b])
                          for b in rows[0]["safe_rate"]},
            "rms": {b: {axis: metric(pick_err, lambda r, b=b, a=axis: r["rms"][b][a])
                        for axis in rows[0]["rms"][b]} for b in rows[0]["rms"]},
        }
        grasps = [r["grasp_success_rate"] for r in rows if r["grasp_success_rate"] is not None]
        out[name]["grasp_success_rate"] = pick_safe(grasps) if grasps else None
    worst = min(range(len(rows)), key=lambda i: (
        rows[i]["safe_rate"]["2.5"], -np.hypot(rows[i]["rms"]["2.5"]["x_mm"],
                                               rows[i]["rms"]["2.5"]["y_mm"])))
    out["worst_camera"] = worst
    return out


def knock_sweep(system: str, config, changes: list[dict], *, trials: int, seed: int,
                check_restarts: int = 1, progress: bool = False) -> list[dict]:
    """The camera knocked after training: train once at ``scene.camera.mount``, then for each
    mount change (``MountConfig`` keys, e.g. ``{"tilt_deg": 2.0}``, added to the trained
    mount) run the self-check (``check_restarts`` times, each a fresh cell seed) and
    ``trials`` positioning trials on the cell with the changed mount.

    Returns one row per change: the change, how often the check fired, the largest
    correction it read, the smallest similarity, and the trials' safe rates and RMS.
    """
    base = config.scene.camera.mount
    rows = []
    with tempfile.TemporaryDirectory(prefix="finepos-knock-") as tmp:
        work = Path(tmp)
        model, acquisition = train_on_default_scene(system, config, work / "train", seed,
                                                    progress)
        for i, change in enumerate(changes):
            values = dataclasses.asdict(base)
            for key, delta in change.items():
                if key == "offset_mm":
                    values[key] = tuple(a + b for a, b in zip(values[key], delta, strict=True))
                else:
                    values[key] = values[key] + delta
            camera = dataclasses.replace(config.scene.camera, mount=MountConfig(**values),
                                         test_mount=None)
            test_cfg = _with_camera(config, camera)
            checks = []
            for restart in range(check_restarts):
                with open_devices(test_cfg, seed=seed + 1000 * (i + 1) + restart) as devices:
                    fp = FinePositioner(devices, test_cfg, state_dir=work / "train")
                    checks.append(self_check(fp, system, model=model))
            run = run_trials(system, model, test_cfg, trials, seed + i, work_dir=work / "eval",
                             grasp=True, progress=progress)
            report = build_report(system, config, test_cfg, trials=trials, seed=seed + i,
                                  model=model, acquisition=acquisition, run=run)
            corrections = [c.correction for c in checks if c.correction is not None]
            rows.append({
                "change": change,
                "check_fired": sum(c.fired for c in checks), "check_runs": len(checks),
                "max_correction_mm": max((float(np.hypot(c["dx_mm"], c["dy_mm"]))
                                          for c in corrections), default=None),
                "max_correction_deg": max((abs(c["dphi_deg"]) for c in corrections),
                                          default=None),
                "min_similarity": min((c.similarity for c in checks
                                       if c.similarity is not None), default=None),
                "safe_rate": report["safe_rate"], "rms_2.5": report["rms"]["2.5"],
                "grasp_success_rate": report["grasp_success_rate"]})
    return rows
