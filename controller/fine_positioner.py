"""The controller as a library object: teach, acquire, train, position, grasp.

``FinePositioner`` owns nothing but references: the opened devices (``controller.devices``),
the config, and an optional iteration log. The CLI creates one per command; the service keeps
one for its lifetime. Files live in its state folder, the part's folder under
``controller.paths.state_dir`` (``controller.teach.state_folder``): ``cell.json`` (teach-in),
``datasets/<set>.npz``, ``model-<system>.<suffix>``. A model file carries the recipe it was
trained with (``controller.recipe``); the loop runs with that recipe's loop keys.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path

import numpy as np

from calibration_free.dataset import Dataset
from controller.calibration.rezero import REZERO_FRAMES, rezero
from controller.config import recipe_of
from controller.loop.grasp import GraspResult, guarded_grasp
from controller.loop.iteration_log import IterationLog
from controller.loop.positioning import (
    LoopConfig,
    PositioningLoop,
    PositioningResult,
)
from controller.recipe import Recipe, recipe_of_model, with_recipe_stored
from controller.systems.base import TrainedModel
from controller.systems.registry import DEFAULT_SYSTEM, SYSTEMS
from controller.teach.acquisition import acquire, grid_for, random_set, transfer
from controller.teach.symmetry import find_symmetry
from drivers.core.cell_state import CellState
from drivers.core.errors import ConfigError, FineposError
from drivers.core.pose import Pose

logger = logging.getLogger(__name__)

DATASETS = ("nn1", "nn2", "test")


class FinePositioner:
    """Teach-in, acquisition, training, the positioning loop and the grasp hand-off.

    Args:
        devices: the opened devices (``controller.devices.CellDevices``: arm, camera, wrench,
            and the simulated cell or None).
        config: the root config (``controller.config.FineposConfig``).
        log: where each loop iteration is written (None: not logged).
        state_dir: the cell's files (default ``controller.paths.state_dir``).
        recorder: records every look and the grasp's readings (``controller.recording``;
            None: not recorded).
    """

    def __init__(self, devices, config, log: IterationLog | None = None,
                 state_dir: str | Path | None = None, recorder=None) -> None:
        self.devices = devices
        self.config = config
        self.log = log
        self.recorder = recorder
        self.state_dir = Path(state_dir or config.controller.paths.state_dir)
        self._loop: PositioningLoop | None = None
        self._model: TrainedModel | None = None
        # a run whose converged step waits for the grasp, and the pose the loop left the arm at
        self._carried: tuple[PositioningResult, Pose] | None = None

    # -- files ----------------------------------------------------------------------------
    @property
    def state_path(self) -> Path:
        """The teach-in file, ``cell.json``."""
        return self.state_dir / "cell.json"

    def dataset_path(self, name: str) -> Path:
        """Where the acquired set ``name`` (nn1, nn2, test) is stored."""
        return self.state_dir / "datasets" / f"{name}.npz"

    def model_path(self, system: str = DEFAULT_SYSTEM) -> Path:
        """Where ``system``'s trained model is stored."""
        return self.state_dir / f"model-{system}{SYSTEMS[system].suffix}"

    def state(self) -> CellState:
        """What teach-in recorded.

        Raises:
            StateError: nothing taught yet, or the file is damaged.
        """
        return CellState.load(self.state_path)

    # -- teach-in -------------------------------------------------------------------------
    def teach(self, source: str, grasp_depth_mm: float | None = None,
              object_width_mm: float | None = None, kappa: int | None = None) -> CellState:
        """Record the arm's current pose as the nominal pre-grasp pose, with the part's
        symmetry and grasp geometry, into ``cell.json``.

        A part declared without kappa has it found from its own images at this pose
        (``controller.teach.symmetry``): the tool turns a full turn and comes back. The kappa
        found and how sure it is are recorded (``CellState.kappa_found``).

        Args:
            source: how the arm got there (``auto``, ``current``, ``spacenav``), stored.
            grasp_depth_mm: the descent from the pose to grip; default: the part's (the
                simulated part on the simulated cell, else ``controller.part`` from the parts
                catalogue).
            object_width_mm: the finger width holding the part; default as above.
            kappa: the part's symmetry as the operator confirms it (default: the declared
                one, else the one found).

        Returns:
            The stored state.

        Raises:
            FineposError: the kappa found is unsure and none is confirmed (the message gives
                the best guess and how to confirm it), or ``kappa`` disagrees with the
                declared one.
        """
        pose = self.devices.arm.pose()
        cell = self.devices.cell
        if cell is not None:
            part = cell.part
            default_depth = cell.grasp_depth_mm
        else:
            part = self.config.parts.part(self.config.controller.part)
            default_depth = part.grasp_depth_mm
        found = None
        if part.kappa is not None:
            if kappa is not None and kappa != part.kappa:
                raise ConfigError(f"--kappa: {kappa}, but parts.{part.kind}.kappa is declared "
                                  f"{part.kappa}")
            kappa = part.kappa
        elif kappa is None:
            found = find_symmetry(self.devices.arm, self.devices.camera, pose, self.move_to)
            if not found.sure:
                guess = f"best guess {found.kappa}" if found.kappa else "no guess"
                raise FineposError(
                    f"kappa of the {part.kind}: unsure ({guess}, confidence "
                    f"{found.confidence:.2f}: {found.reason}); confirm it with --kappa N or "
                    f"declare parts.{part.kind}.kappa")
            kappa = found.kappa
        grasp_depth_mm = default_depth if grasp_depth_mm is None else grasp_depth_mm
        object_width_mm = part.grasp_width_mm if object_width_mm is None else object_width_mm
        state = CellState(pose, part.kind, kappa, float(grasp_depth_mm),
                          float(object_width_mm), source, CellState.now(),
                          None if found is None else found.as_dict())
        state.save(self.state_path)
        logger.info("taught nominal pose %s (%s, kappa %d%s) from %s into %s", pose.as_dict(),
                    part.kind, kappa, "" if found is None else ", found from images", source,
                    self.state_path)
        return state

    def teach_auto(self, kappa: int | None = None) -> CellState:
        """Simulated cell only: place the gripper at the part's true grasp pose and record it
        (``kappa``: as ``teach``).

        Raises:
            FineposError: not on the simulated cell.
        """
        cell = self.devices.cell
        if cell is None:
            raise FineposError("teach --auto needs the simulated cell (arm type sim)")
        self.move_to(cell.nominal_grasp_pose())
        return self.teach("auto", kappa=kappa)

    def move_to(self, target: Pose) -> None:
        """Move there in steps within the safety limits (``safety.max_step_mm``/``_deg``)."""
        limits = self.config.safety
        transfer(self.devices.arm, target, limits)

    # -- acquisition and training ----------------------------------------------------------
    def acquire(self, name: str, seed: int = 0, progress: bool = True) -> Dataset:
        """Take a set of images around the taught pose and store it.

        Args:
            name: ``nn1`` (the 3x3x7 translation grid), ``nn2`` (the rotation grid) or ``test``
                (random displacements, ``controller.acquisition.test_count``).
            seed: draws the test set's displacements.
            progress: show a progress bar.

        Returns:
            The set: one image and the exact tool-frame step back to the taught pose each.

        Raises:
            FineposError: an unknown set name, or nothing taught yet.
        """
        if name not in DATASETS:
            raise FineposError(f"unknown dataset {name!r} (one of {', '.join(DATASETS)})")
        state = self.state()
        acq = self.config.controller.acquisition
        if name == "test":
            offsets = random_set(np.random.default_rng(seed), acq.test_count, acq.nn1.a_mm,
                                 state.kappa)
        else:
            offsets = grid_for(getattr(acq, name), state.kappa)
        self.move_to(state.nominal_pose)
        data = acquire(self.devices.arm, self.devices.camera, state.nominal_pose, offsets,
                       name=name, limits=self.config.safety,
                       ground_truth=self.devices.ground_truth if self.devices.cell else None,
                       metadata={"object_kind": state.object_kind, "kappa": state.kappa},
                       progress=progress,
                       taught_frames=0 if name == "test" else acq.taught_pose_frames)
        data.save(self.dataset_path(name))
        return data

    def train(self, system: str = DEFAULT_SYSTEM, recipe: Recipe | None = None) -> TrainedModel:
        """Train ``system`` on the stored nn1 and nn2 sets with ``recipe``, store its model
        (the recipe written into it) and use it.

        Args:
            recipe: the perception and loop settings (None: the recipe of ``system``'s current
                model file; where there is none, the one this positioner's config runs).

        Raises:
            DatasetError: a set is missing or damaged.
            TrainingError: the sets cannot train the system.
        """
        state = self.state()
        nn1 = Dataset.load(self.dataset_path("nn1"))
        nn2 = Dataset.load(self.dataset_path("nn2"))
        impl = SYSTEMS[system]
        recipe = recipe if recipe is not None else self._current_recipe(system)
        model = impl.train(nn1, nn2, state, recipe.perception)
        model = dataclasses.replace(model, model=with_recipe_stored(model.model, recipe))
        impl.save(model, self.model_path(system))
        self._model = model
        logger.info("trained %s on %d images in %.2f s -> %s", system, model.train_images,
                    model.train_seconds, self.model_path(system))
        return model

    def _current_recipe(self, system: str) -> Recipe:
        """The recipe of ``system``'s model file where one is stored and readable, else the one
        the config runs."""
        file = self.model_path(system)
        if file.is_file():
            try:
                return recipe_of_model(SYSTEMS[system].load(file).model)
            except FineposError as exc:
                logger.warning("%s: its recipe cannot be read (%s); training with the "
                               "config's", file, exc)
        return recipe_of(self.config)

    def loop_config(self, model: TrainedModel | None = None) -> LoopConfig:
        """The loop's settings for ``model`` (default: the model in use): the cell config's
        ``controller.loop`` with the recipe keys of the model's recipe."""
        model = model if model is not None else self._model
        loop = self.config.controller.loop
        return loop if model is None else recipe_of_model(model.model).apply_loop(loop)

    def load_model(self, path: str | Path | None = None,
                   system: str = DEFAULT_SYSTEM) -> TrainedModel:
        """Load and use a model file (default: ``system``'s stored model), checked to be
        taught on the taught part.

        Raises:
            FineposError: no model file there (the message says which command makes one).
            BundleError: the file is damaged, of another system or another part.
        """
        state = self.state()
        file = Path(path) if path is not None else self.model_path(system)
        if not file.is_file():
            train = "finepos train" + ("" if system == DEFAULT_SYSTEM
                                       else f" --system {system}")
            raise FineposError(f"{file}: no trained {system} model; run `{train}` first")
        self._model = SYSTEMS[system].load(file, state)
        return self._model

    def rezero(self, frames: int = REZERO_FRAMES, system: str = DEFAULT_SYSTEM,
               heading_step_deg: float | None = None,
               heading_range_deg: tuple[float, float] | None = None
               ) -> tuple[TrainedModel, dict]:
        """Re-zero the part's model of ``system`` in the cell's light, and use it
        (``controller.calibration.rezero.rezero``, which says how)."""
        model, report = rezero(self, frames, system, heading_step_deg, heading_range_deg)
        self._model = model
        return model, report

    def use_model(self, model: TrainedModel) -> None:
        """Use an already trained or loaded model for the next positioning runs."""
        self._model = model

    # -- positioning and grasp --------------------------------------------------------------
    def position(self, max_loops: float | None = None,
                 then_grasp: bool = False) -> PositioningResult:
        """Run the positioning loop from wherever the arm is (loading the stored model first
        if none is in use).

        Args:
            max_loops: the loop budget (default ``controller.loop.max_loops``).
            then_grasp: ``grasp`` is called next, from where the loop leaves the arm: the
                converged look's step is left for the grasp's first descent move
                (``controller.grasp.carry_final_step``); the result's ``carried`` holds it
                until then.

        Returns:
            The outcome, loops spent and the state after every move (``PositioningResult``).
        """
        self._carried = None
        if self._model is None:
            self.load_model()
        estimator = SYSTEMS[self._model.system].estimator(self._model)
        truth = self.devices.ground_truth if self.devices.cell is not None else None
        nn1_grid = self.config.controller.acquisition.nn1
        self._loop = PositioningLoop(self.devices.arm, self.devices.camera,
                                     self.loop_config(), self.log, truth,
                                     recorder=self.recorder,
                                     reach_mm=nn1_grid.a_mm * math.sqrt(2.0))
        carry = then_grasp and self.config.controller.grasp.carry_final_step
        try:
            result = self._loop.run(estimator, max_loops, carry_final_step=carry)
        finally:
            self._loop = None
        if result.carried is not None:
            self._carried = (result, self.devices.arm.pose(fresh=False))
        return result

    def grasp(self) -> GraspResult:
        """The force-guarded grasp from the pre-grasp pose (``controller.loop.grasp``): open,
        descend the taught depth under the guards, close, verify, lift.

        Where the last ``position(then_grasp=True)`` left its converged step to the grasp and the
        arm is still where that loop left it, the first descent move makes the step; the run's
        result then gets that full loop and the state after it, as if the loop had made it.

        Returns:
            Whether the part is held, the guard that tripped (if any) and the readings.
        """
        pending, self._carried = self._carried, None
        carried = on_carried = None
        if pending is not None:
            run, left_at = pending
            if _same_pose(self.devices.arm.pose(fresh=False), left_at):
                carried = run.carried
                on_carried = self._carried_step_made(run)
            else:
                logger.warning("the arm moved after positioning run %s: its converged step is "
                               "not carried to the grasp", run.run_id)
                run.carried_dropped()
        state = self.state()
        recorder = self.recorder
        clock = getattr(self.devices, "clock", None)  # cell seconds, for the recording
        sensor = self.devices.wrench if recorder is None else \
            recorder.recording_sensor(self.devices.wrench, clock)
        weight_n = self.config.parts.part(state.object_kind).weight_n  # the taught part's
        result = guarded_grasp(self.devices.arm, sensor, state.grasp_depth_mm,
                               state.object_width_mm, self.config.controller.grasp, weight_n,
                               carried, on_carried)
        if recorder is not None:
            recorder.grasp_event(result, clock() if clock is not None else None)
        return result

    def _carried_step_made(self, run: PositioningResult):
        """What the grasp calls once its first move has made ``run``'s converged step: the
        run counts it as the full loop the loop would have made, with the state after it."""
        truth = self.devices.ground_truth if self.devices.cell is not None else None

        def made() -> None:
            run.carried_made(tuple(truth()) if truth else None)
        return made

    def abort(self) -> None:
        """Stop a running loop before its next move and halt the arm."""
        if self._loop is not None:
            self._loop.abort()
        self.devices.arm.halt()


def _same_pose(a: Pose, b: Pose, tol: float = 0.005) -> bool:
    """Whether two reported poses are the same: within ``tol`` (mm and degrees), under the
    0.01 mm and 0.01 deg to which VAL reports a pose."""
    return all(abs(getattr(a, f) - getattr(b, f)) <= tol
               for f in ("x_mm", "y_mm", "z_mm", "o_deg", "a_deg", "t_deg"))
