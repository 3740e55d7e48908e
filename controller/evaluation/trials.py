"""Evaluation on the simulated cell: train on the default scene, test on random placements.

Unless given a model, the system is taught (auto), acquires its grids and trains on the
default scene. Each trial then places the part at random on the evaluation scene, starts the
arm at the part's grasp pose displaced uniformly by +/-25 mm and +/-180/kappa deg, runs the
positioning loop with the ground truth recorded after every move, and (optionally) grasps.

With ``hil`` (``finepos evaluate --hil``) the same simulated cell is served in this process over
its device emulators (the VAL II monitor and the ATI F/T controller on ptys, the hand camera as
an MJPEG stream on 127.0.0.1), and teach-in, acquisition, the loop and the grasp use the real
drivers on them (``controller.evaluation.hil``); only the part's placement and the ground
truth are taken from the cell directly, as no real cell offers them.
"""

from __future__ import annotations

import dataclasses
import logging
import statistics
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from controller.calibration.rezero import REZERO_SYSTEMS
from controller.devices import open_devices
from controller.evaluation.hil import open_hil_devices
from controller.evaluation.metrics import by_heading, summarise, wilson
from controller.fine_positioner import FinePositioner
from controller.systems.base import TrainedModel
from controller.systems.registry import SYSTEMS
from drivers.core.errors import FineposError
from drivers.core.pose import ToolStep

logger = logging.getLogger(__name__)

OFFSET_MM = 25.0
PLACEMENT_MM = 30.0
EVAL_BUDGET = 6.5


def with_lighting(config, preset: str | None):
    """The config with the scene's lighting preset replaced (None: unchanged)."""
    if preset is None:
        return config
    scene = config.scene
    lighting = dataclasses.replace(scene.lighting, preset=preset)
    return dataclasses.replace(config, scene=dataclasses.replace(scene, lighting=lighting))


def default_scene_config(config):
    """The config with every scene setting at its default (where training happens), except
    the part (``scene.object.kind``: the default scene with that part on it), the camera (it
    belongs to the cell: ``scene.camera``, at its ``mount``) and the timing."""
    scene = config.scene
    obj = type(scene.object)(kind=scene.object.kind)
    return dataclasses.replace(config, scene=type(scene)(object=obj, camera=scene.camera,
                                                         timing=scene.timing))


def with_test_camera(config):
    """The config with the camera as the cell is tested with it (``scene.camera.test_mount``,
    if set, as its mount: the camera knocked after training)."""
    scene = config.scene
    return dataclasses.replace(config, scene=dataclasses.replace(
        scene, camera=scene.camera.at_test()))


def train_on_default_scene(system: str, config, work_dir: Path, seed: int,
                           progress: bool = True, hil: bool = False,
                           lighting: str | None = None) -> tuple[TrainedModel, dict]:
    """Teach (auto), acquire the NN1 and NN2 grids and train, on the default scene
    (``lighting``: under that lighting preset instead of the default scene's)."""
    models, acquisition = train_systems_on_default_scene((system,), config, work_dir, seed,
                                                         progress, hil, lighting)
    return models[system], acquisition


def train_systems_on_default_scene(systems: Sequence[str], config, work_dir: Path, seed: int,
                                   progress: bool = True, hil: bool = False,
                                   lighting: str | None = None
                                   ) -> tuple[dict[str, TrainedModel], dict]:
    """Teach (auto) and acquire the NN1 and NN2 grids once, then train every system on them.

    Returns the trained models by system name, and what the shared acquisition cost
    (``acquire_seconds``, ``images``) and its light (``lighting``, the preset). ``hil``:
    through the real drivers (module docstring); ``lighting``: the default scene under this
    lighting preset (a cell taught in the light it works in; None: the default scene's).
    """
    return train_systems_on_cell(systems, with_lighting(default_scene_config(config), lighting),
                                 work_dir, seed, progress, hil)


def train_systems_on_cell(systems: Sequence[str], train_cfg, work_dir: Path, seed: int,
                          progress: bool = True, hil: bool = False
                          ) -> tuple[dict[str, TrainedModel], dict]:
    """Teach (auto) and acquire the NN1 and NN2 grids once on ``train_cfg``'s cell as it is,
    then train every system on them (``train_systems_on_default_scene`` says what it
    returns)."""
    with device_opener(hil)(train_cfg, seed=seed) as devices:
        fp = FinePositioner(devices, train_cfg, state_dir=work_dir)
        fp.teach_auto()
        t0 = time.perf_counter()
        nn1 = fp.acquire("nn1", progress=progress)
        nn2 = fp.acquire("nn2", progress=progress)
        acquire_seconds = time.perf_counter() - t0
        models = {system: fp.train(system) for system in systems}
    return models, {"acquire_seconds": acquire_seconds, "images": len(nn1) + len(nn2),
                    "lighting": train_cfg.scene.lighting.preset}


def rezeroed_on(model: TrainedModel, config, work_dir: Path, seed: int, hil: bool = False,
                heading_step_deg: float | None = None) -> tuple[TrainedModel, dict]:
    """The model re-zeroed (``FinePositioner.rezero``) on ``config``'s cell, in its light:
    the part where the scene puts it, the arm at its true grasp pose (``teach_auto``).
    The report is ``FinePositioner.rezero``'s and ``cell_seconds``, the arm time the re-zero
    took. ``heading_step_deg``: also its zero by heading, in steps of at most that, over the
    default range, one symmetry period centred on the taught heading: where the trials' tool
    ends (the simulated cell's grasp pose is the one of the part's symmetric turns nearest the
    taught one).

    Raises:
        FineposError: a system that does not re-zero (``REZERO_SYSTEMS``).
        TrainingError: the part is not seen whole there (``calibration_free.rezero``).
    """
    if model.system not in REZERO_SYSTEMS:
        raise FineposError(f"--rezero: the {model.system} system does not re-zero (only "
                           f"{' and '.join(REZERO_SYSTEMS)})")
    with device_opener(hil)(config, seed=seed) as devices:
        fp = FinePositioner(devices, config, state_dir=work_dir)
        fp.teach_auto()
        SYSTEMS[model.system].save(model, fp.model_path(model.system))
        start = devices.clock()
        model, report = fp.rezero(system=model.system, heading_step_deg=heading_step_deg)
        return model, {**report, "cell_seconds": devices.clock() - start}


def run_trials(system: str, model: TrainedModel, config, trials: int, seed: int, *,
               work_dir: Path, grasp: bool = True, log=None, progress: bool = True,
               budget: float = EVAL_BUDGET, on_trial: Callable[[], None] | None = None,
               hil: bool = False, recorder=None, measure_visible: bool = False) -> dict:
    """Random placements and start offsets; returns per-trial states and grasp outcomes.

    ``on_trial`` is called after each trial (progress reporting from another process);
    ``hil``: through the real drivers (see the module docstring); ``recorder``: records the
    looks and grasps (``controller.recording.RunRecorder``; its ``max_runs`` picks the first
    trials); ``measure_visible``: the arm first goes to each placement's pre-grasp pose, where
    the share of the part the camera sees is measured (``visible``, one per trial).
    """
    rng = np.random.default_rng(seed)
    states, grasps, per_iteration, outcomes = [], [], [], []
    state_times, grasp_times, splits = [], [], []
    with device_opener(hil)(config, seed=seed) as devices:
        cell = devices.cell
        if cell is None:
            raise FineposError("evaluation needs the simulated cell for its ground truth")
        timed = TimedTruth(devices)
        fp = FinePositioner(timed, config, log=log, state_dir=work_dir, recorder=recorder)
        fp.use_model(model)
        fp.teach_auto()  # the state file records the part's grasp geometry for the grasp
        x0, y0, taught_heading = cell.object_pose()
        kappa = cell.kappa
        period = 360.0 / kappa
        turns = []  # each trial's part turned from its taught heading
        visible = []  # with measure_visible: the share of the part seen at its pre-grasp pose
        for _ in tqdm(range(trials), desc=f"evaluate {system}", unit="trial",
                      disable=None if progress else True, leave=False):
            devices.arm.open_gripper()
            x = x0 + rng.uniform(-PLACEMENT_MM, PLACEMENT_MM)
            y = y0 + rng.uniform(-PLACEMENT_MM, PLACEMENT_MM)
            heading = rng.uniform(0.0, period)
            cell.place_object(x, y, heading)
            turns.append((heading - taught_heading) % period)
            nominal = cell.nominal_grasp_pose()
            if measure_visible:
                fp.move_to(nominal)
                visible.append(cell.visible_fraction())
            dx, dy = rng.uniform(-OFFSET_MM, OFFSET_MM, 2)
            dphi = rng.uniform(-period / 2, period / 2)
            fp.move_to(nominal.moved_in_tool_frame(ToolStep(-dx, -dy, 0.0, -dphi)))
            timed.times.clear()
            start_s = devices.clock()
            split0 = _split(devices.timing)
            # with the grasp, the converged step is made by its first descent move, and the
            # run's states get the state after it (``FinePositioner.grasp``)
            result = fp.position(budget, then_grasp=grasp)
            if grasp:
                g = fp.grasp()
                held = bool(g.success and cell.holding)
                grasps.append(held)
                grasp_times.append(devices.clock() - start_s if held else None)
            states.append(result.states)
            state_times.append([t - start_s for t in timed.times]
                               if len(timed.times) == len(result.states) else None)
            outcomes.append(result.outcome)
            per_iteration.extend(result.seconds_per_iteration)
            if split0 is not None:
                split1 = _split(devices.timing)
                splits.append({"total": devices.clock() - start_s,
                               **{k: split1[k] - split0[k] for k in split0}})
            if on_trial is not None:
                on_trial()
    return {"states": states, "grasps": grasps, "seconds_per_iteration": per_iteration,
            "outcomes": outcomes, "object": cell_kind(config), "kappa": kappa, "turns": turns,
            "state_times": state_times, "grasp_times": grasp_times,
            "timing": config.scene.timing, "time_split": splits,
            "visible": visible if measure_visible else None}


def _split(timing) -> dict[str, float] | None:
    """The seconds the in-process cell's timing has spent so far, by kind (``wire``, ``setup``,
    ``motion``, ``hand``, ``sensor``, ``camera``; None: no timing)."""
    return None if timing is None else dict(timing.spent)


class TimedTruth:
    """The opened devices, with every ground-truth reading's cell time noted in ``times``
    (``devices.clock()``): the loop reads the truth once per state, so ``times`` lines up with
    a positioning run's states (time to safe). Everything else is the devices' own."""

    def __init__(self, devices) -> None:
        self._devices = devices
        self.times: list[float] = []

    def __getattr__(self, name: str):
        return getattr(self._devices, name)

    def ground_truth(self):
        """The devices' ground truth, its cell time noted."""
        self.times.append(self._devices.clock())
        return self._devices.ground_truth()


def _median_split(splits) -> dict | None:
    """The time budget: per trial (positioning and grasp), the median cell seconds in all and
    by kind: on the serial lines (``wire``), the controller's set-up of each command that
    moves (``setup``), arm motion and settling (``motion``), the hand (``hand``), waits for
    sensor samples (``sensor``) and camera frames (``camera``), and the rest (``other``)."""
    if not splits:
        return None
    kinds = [k for k in splits[0] if k != "total"]
    out = {k: float(np.median([s[k] for s in splits])) for k in ("total", *kinds)}
    out["other"] = float(np.median([s["total"] - sum(s[k] for k in kinds) for s in splits]))
    return out


def device_opener(hil: bool):
    """``open_devices``, or with ``hil`` the same cell behind its emulators and the real
    drivers (``controller.evaluation.hil.open_hil_devices``)."""
    return open_hil_devices if hil else open_devices


def cell_kind(config) -> str:
    """The kind of part on ``config``'s scene (``scene.object.kind``)."""
    return config.scene.object.kind


def evaluate(system: str, config, *, trials: int, seed: int, lighting: str | None = None,
             model_path: str | Path | None = None, work_dir: str | Path | None = None,
             grasp: bool = True, log=None, progress: bool = True, hil: bool = False,
             recorder=None, rezero: bool = False, teach_lighting: str | None = None,
             rezero_heading_step: float | None = None) -> dict:
    """The ``finepos evaluate`` report (see the README for its fields); ``hil``: through the
    real drivers and the device emulators (see the module docstring); ``recorder``: records
    the trials' looks (see ``run_trials``); ``rezero``: the model is first re-zeroed in the
    trials' light (``rezeroed_on``; the report's ``rezero`` says what moved), with
    ``rezero_heading_step`` also by heading;
    ``teach_lighting``: teach-in, acquisition and training under this lighting preset instead
    of the default scene's (not with ``model_path``)."""
    if system not in SYSTEMS:
        raise FineposError(f"unknown system {system!r} (one of {', '.join(SYSTEMS)})")
    if teach_lighting is not None and model_path is not None:
        raise FineposError("teach lighting: the model is trained already (not with a model "
                           "file)")
    eval_cfg = with_test_camera(with_lighting(config, lighting))
    with tempfile.TemporaryDirectory(prefix="finepos-eval-") as tmp:
        work = Path(work_dir or tmp)
        if model_path is not None:
            model = SYSTEMS[system].load(model_path)
            taught = getattr(model.model, "object_kind", None)
            if taught is not None and taught != cell_kind(config):
                raise FineposError(f"{model_path}: taught on the {taught}, not the "
                                   f"{cell_kind(config)} (name the part with --part)")
            acquisition = {"acquire_seconds": None, "images": model.train_images,
                           "lighting": None}
        else:
            model, acquisition = train_on_default_scene(system, config, work / "train", seed,
                                                        progress, hil, teach_lighting)
        rezero_report = None
        if rezero:
            model, rezero_report = rezeroed_on(model, eval_cfg, work / "rezero", seed, hil,
                                               rezero_heading_step)
        run = run_trials(system, model, eval_cfg, trials, seed, work_dir=work / "eval",
                         grasp=grasp, log=log, progress=progress, hil=hil, recorder=recorder)
    report = build_report(system, config, eval_cfg, trials=trials, seed=seed, model=model,
                          acquisition=acquisition, run={**run, "rezero": rezero_report})
    report["hil"] = hil
    return report


def build_report(system: str, config, eval_cfg, *, trials: int, seed: int,
                 model: TrainedModel, acquisition: dict, run: dict) -> dict:
    """The ``finepos evaluate`` report of one ``run_trials`` result (``config``: the one the
    model was trained from; ``eval_cfg``: the one the trials ran on; ``run["rezero"]``, if
    any: what re-zeroing the model in the trials' light moved, ``rezeroed_on``)."""
    summary = summarise(run["states"], run.get("state_times"), run.get("grasp_times"))
    report = {
        "system": system,
        "lighting": eval_cfg.scene.lighting.preset,
        "object": run["object"],
        "trials": trials,
        "seed": seed,
        **summary,
        "grasp_success_rate": (float(np.mean(run["grasps"])) if run["grasps"] else None),
        "grasp_success_ci": (wilson(sum(run["grasps"]), len(run["grasps"]))
                             if run["grasps"] else None),
        "timing": run.get("timing"),
        "time_split_s": _median_split(run.get("time_split")),
        "train_images": model.train_images,
        "train_seconds": model.train_seconds,
        "acquire_seconds": acquisition["acquire_seconds"],
        "teach_lighting": acquisition.get("lighting"),
        "feature_count": model.feature_count,
        "seconds_per_loop": (statistics.median(run["seconds_per_iteration"])
                             if run["seconds_per_iteration"] else None),
        "outcomes": {k: run["outcomes"].count(k) for k in sorted(set(run["outcomes"]))},
        "scene": config.source,
        "rezero": run.get("rezero"),
    }
    if run.get("turns") is not None:
        report["by_heading"] = by_heading(run["states"], run["turns"], 360.0 / run["kappa"])
    report["_trial_states"] = [[(s.loops, s.error) for s in t] for t in run["states"]]
    return report
