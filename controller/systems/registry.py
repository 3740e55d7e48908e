"""Vision systems the positioning loop can run, in one explicit registry.

A system trains from the acquired datasets into a model file and builds an Estimator
(``controller.systems.estimator``) from it. ``gabor`` is the paper's method (``calibration_free``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration_free.bundle import ModelBundle
from calibration_free.dataset import Dataset
from calibration_free.pipeline import Perception, train_bundle
from controller.systems.baselines import HoughSystem, PcaSystem
from controller.systems.estimator import RotationEstimate, TranslationEstimate
from controller.teach.cell_state import CellState


@dataclass
class TrainedModel:
    """A trained system: its model object, and what training cost."""

    system: str
    model: Any
    train_seconds: float
    train_images: int
    feature_count: int


class GaborEstimator:
    """NN1 on the object centre, NN2 on 36 Gabor features of the ROI (the paper's system)."""

    name = "gabor"

    def __init__(self, bundle: ModelBundle) -> None:
        self.perception = Perception(bundle)

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        p = self.perception.translation(image)
        loc = p.localisation
        if not p.ok:
            return TranslationEstimate(loc.status, reason=loc.reason,
                                       record={"area_px": loc.area_px})
        return TranslationEstimate("ok", p.nn1_mm[0], p.nn1_mm[1], loc.u_px, loc.v_px,
                                   record={"area_px": loc.area_px, "nn1": list(p.nn1_mm),
                                           "perception_us": p.timings_us})

    def estimate_rotation(self, image: np.ndarray,
                          translation: TranslationEstimate) -> RotationEstimate:
        p = self.perception.perceive(image)
        if not p.ok or p.dphi_deg is None:  # same frame as the translation: cannot differ
            raise RuntimeError(f"rotation path lost the object: {p.localisation.reason}")
        return RotationEstimate(p.dphi_deg, record={
            "features": p.features.tolist(), "nn2": list(p.nn2_sc), "nn1_rot": list(p.full_mm),
            "perception_us": p.timings_us}, dx_mm=p.full_mm[0], dy_mm=p.full_mm[1])


class GaborSystem:
    name = "gabor"
    suffix = ".fpm"

    @staticmethod
    def train(nn1: Dataset, nn2: Dataset, state: CellState, perception_cfg) -> TrainedModel:
        t0 = time.perf_counter()
        bundle = train_bundle(
            nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
            nominal_pose=state.nominal_pose, gabor=perception_cfg.gabor,
            nn2_hidden=tuple(perception_cfg.nn2_hidden),
            nn2_weight_decay=perception_cfg.nn2_weight_decay,
            localisation_channel=perception_cfg.localisation_channel, seed=perception_cfg.seed,
            nn1_extra=nn2 if perception_cfg.nn1_uses_nn2_set else None)
        return TrainedModel("gabor", bundle, time.perf_counter() - t0, len(nn1) + len(nn2),
                            bundle.gabor.n_filters)

    @staticmethod
    def save(model: TrainedModel, path: str | Path) -> None:
        model.model.save(path)

    @staticmethod
    def load(path: str | Path, state: CellState | None = None) -> TrainedModel:
        bundle = ModelBundle.load(path, expect_object=state.object_kind if state else None)
        training = bundle.training
        return TrainedModel("gabor", bundle, float(training.get("seconds", 0.0)),
                            int(sum(training.get("samples", {}).values())),
                            bundle.gabor.n_filters)

    @staticmethod
    def estimator(model: TrainedModel) -> GaborEstimator:
        return GaborEstimator(model.model)


SYSTEMS = {
    "gabor": GaborSystem,
    "pca": PcaSystem,
    "hough": HoughSystem,
}
