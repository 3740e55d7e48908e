"""The controller as a library object: teach, acquire, train, position, grasp.

``FinePositioner`` owns nothing but references: the opened devices (``controller.devices``),
the config, and an optional iteration log. The CLI creates one per command; the service keeps
one for its lifetime. Files live under ``controller.paths.state_dir``: ``cell.json`` (teach-in),
``datasets/<set>.npz``, ``model-<system>.<suffix>``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from calibration_free.dataset import Dataset
from controller.loop.grasp import GraspResult, guarded_grasp
from controller.loop.iteration_log import IterationLog
from controller.loop.positioning import PositioningLoop, PositioningResult
from controller.systems.registry import SYSTEMS, TrainedModel
from controller.teach.acquisition import acquire, grid_for, random_set, transfer
from controller.teach.cell_state import CellState
from drivers.core.errors import FineposError
from drivers.core.pose import Pose
from sim_backend.cell.objects import PARTS

logger = logging.getLogger(__name__)

DATASETS = ("nn1", "nn2", "test")


class FinePositioner:
    """Teach-in, acquisition, training, the positioning loop and the grasp hand-off."""

    def __init__(self, devices, config, log: IterationLog | None = None,
                 state_dir: str | Path | None = None) -> None:
        self.devices = devices
        self.config = config
        self.log = log
        self.state_dir = Path(state_dir or config.controller.paths.state_dir)
        self._loop: PositioningLoop | None = None
        self._model: TrainedModel | None = None

    # -- files ----------------------------------------------------------------------------
    @property
    def state_path(self) -> Path:
        return self.state_dir / "cell.json"

    def dataset_path(self, name: str) -> Path:
        return self.state_dir / "datasets" / f"{name}.npz"

    def model_path(self, system: str = "gabor") -> Path:
        return self.state_dir / f"model-{system}{SYSTEMS[system].suffix}"

    def state(self) -> CellState:
        return CellState.load(self.state_path)

    # -- teach-in -------------------------------------------------------------------------
    def teach(self, source: str, grasp_depth_mm: float | None = None,
              object_width_mm: float | None = None) -> CellState:
        """Record the arm's current pose as the nominal pre-grasp pose (``source`` says how
        the arm got there). Part data default to the simulated part's, or must be given."""
        pose = self.devices.arm.pose()
        cell = self.devices.cell
        if cell is not None:
            part = cell.part
            grasp_depth_mm = cell.grasp_depth_mm if grasp_depth_mm is None else grasp_depth_mm
            object_width_mm = part.grasp_width_mm if object_width_mm is None else object_width_mm
            kind, kappa = part.kind, part.kappa
        else:
            kind = self.config.scene.object.kind
            kappa = PARTS[kind].kappa
            if grasp_depth_mm is None or object_width_mm is None:
                raise FineposError("teach on a real cell needs --grasp-depth-mm and "
                                   "--object-width-mm")
        state = CellState(pose, kind, kappa, float(grasp_depth_mm), float(object_width_mm),
                          source, CellState.now())
        state.save(self.state_path)
        logger.info("taught nominal pose %s (%s, kappa %d) from %s into %s", pose.as_dict(),
                    kind, kappa, source, self.state_path)
        return state

    def teach_auto(self) -> CellState:
        """Simulated cell only: place the gripper at the part's true grasp pose and record it."""
        cell = self.devices.cell
        if cell is None:
            raise FineposError("teach --auto needs the simulated cell (arm type sim)")
        self.move_to(cell.nominal_grasp_pose())
        return self.teach("auto")

    def move_to(self, target: Pose) -> None:
        """Move there in steps within the safety limits."""
        limits = self.config.safety
        transfer(self.devices.arm, target, limits.max_step_mm, limits.max_step_deg)

    # -- acquisition and training ----------------------------------------------------------
    def acquire(self, name: str, seed: int = 0, progress: bool = True) -> Dataset:
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
                       progress=progress)
        data.save(self.dataset_path(name))
        return data

    def train(self, system: str = "gabor") -> TrainedModel:
        state = self.state()
        nn1 = Dataset.load(self.dataset_path("nn1"))
        nn2 = Dataset.load(self.dataset_path("nn2"))
        impl = SYSTEMS[system]
        model = impl.train(nn1, nn2, state, self.config.perception)
        impl.save(model, self.model_path(system))
        self._model = model
        logger.info("trained %s on %d images in %.2f s -> %s", system, model.train_images,
                    model.train_seconds, self.model_path(system))
        return model

    def load_model(self, path: str | Path | None = None, system: str = "gabor") -> TrainedModel:
        state = self.state()
        self._model = SYSTEMS[system].load(path or self.model_path(system), state)
        return self._model

    def use_model(self, model: TrainedModel) -> None:
        self._model = model

    # -- positioning and grasp --------------------------------------------------------------
    def position(self, max_loops: float | None = None) -> PositioningResult:
        if self._model is None:
            self.load_model()
        estimator = SYSTEMS[self._model.system].estimator(self._model)
        truth = self.devices.ground_truth if self.devices.cell is not None else None
        self._loop = PositioningLoop(self.devices.arm, self.devices.camera,
                                     self.config.controller.loop, self.log, truth)
        try:
            return self._loop.run(estimator, max_loops)
        finally:
            self._loop = None

    def grasp(self) -> GraspResult:
        state = self.state()
        return guarded_grasp(self.devices.arm, self.devices.wrench, state.grasp_depth_mm,
                             state.object_width_mm, self.config.controller.grasp)

    def abort(self) -> None:
        """Stop a running loop before its next move and halt the arm."""
        if self._loop is not None:
            self._loop.abort()
        self.devices.arm.halt()
