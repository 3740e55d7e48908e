"""The paper's baseline systems as systems the positioning loop can run (``controller.systems``).

``pca``: eigenimages of the ROI and a B-spline neuro-fuzzy controller for the rotation, NN1 on
the object centre for the translation (paper 2.2, 4.2). ``hough``: the outline's straight lines
validated by a model of the expected Hough-peak constellation for the rotation, a 3x3x3 PSOM
for the translation (paper 2.3, 4.3); it reports ``no_object`` when the peaks do not validate.
The vision itself lives in ``calibration_free.baselines``; this module adapts it to the
Estimator protocol (``controller.systems.estimator``) and the system registry's interface.

Settings come from the ``perception.pca`` and ``perception.hough`` config sections when the
configuration has them, the defaults (the paper's choices) otherwise.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from calibration_free.baselines.hough.model import HoughModel
from calibration_free.baselines.hough.train import train_hough
from calibration_free.baselines.pca.model import PcaModel
from calibration_free.baselines.pca.train import train_pca
from calibration_free.dataset import Dataset
from controller.systems.estimator import RotationEstimate, TranslationEstimate
from controller.teach.cell_state import CellState

if TYPE_CHECKING:
    from controller.systems.registry import TrainedModel


def _trained(system: str, model: Any, seconds: float, images: int,
             features: int) -> TrainedModel:
    # controller.systems.registry imports this module to register the baselines, so its TrainedModel
    # is looked up when a model is made, not when this module is imported.
    from controller.systems.registry import TrainedModel

    return TrainedModel(system, model, seconds, images, features)


def _images(training: dict[str, Any]) -> int:
    """Distinct images the model was trained on (what acquiring them cost in robot moves)."""
    return int(training.get("images", 0))


class _ModelFileSystem:
    """What the baselines share: their model class saves, loads and checks its own file."""

    name: str
    suffix: str
    model_cls: Any
    estimator_cls: Any

    @staticmethod
    def save(model: TrainedModel, path: str | Path) -> None:
        model.model.save(path)

    @classmethod
    def load(cls, path: str | Path, state: CellState | None = None) -> TrainedModel:
        model = cls.model_cls.load(path, expect_object=state.object_kind if state else None)
        return _trained(cls.name, model, float(model.training.get("seconds", 0.0)),
                        _images(model.training), model.feature_count)

    @classmethod
    def estimator(cls, model: TrainedModel):
        return cls.estimator_cls(model.model)


class PcaEstimator:
    """NN1 on the object centre; eigenimage projections of the ROI -> fuzzy controller."""

    name = "pca"

    def __init__(self, model: PcaModel) -> None:
        self.model = model

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        p = self.model.perceive(image, rotation=False)
        loc = p.localisation
        if p.nn1_mm is None:
            return TranslationEstimate(loc.status, reason=loc.reason,
                                       record={"area_px": loc.area_px})
        return TranslationEstimate("ok", p.nn1_mm[0], p.nn1_mm[1], loc.u_px, loc.v_px,
                                   record={"area_px": loc.area_px, "nn1": list(p.nn1_mm)})

    def estimate_rotation(self, image: np.ndarray,
                          translation: TranslationEstimate) -> RotationEstimate:
        p = self.model.perceive(image, rotation=True)
        if p.dphi_deg is None:  # same frame as the translation: cannot differ
            raise RuntimeError(f"rotation path lost the object: {p.localisation.reason}")
        return RotationEstimate(p.dphi_deg, record={"features": p.features.tolist(),
                                                    "fuzzy": list(p.fc_sc)})


class PcaSystem(_ModelFileSystem):
    name = "pca"
    suffix = ".pca"
    model_cls = PcaModel
    estimator_cls = PcaEstimator

    @staticmethod
    def train(nn1: Dataset, nn2: Dataset, state: CellState, perception_cfg) -> TrainedModel:
        model = train_pca(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                          nominal_pose=state.nominal_pose, config=perception_cfg.pca,
                          seed=perception_cfg.seed,
                          nn1_extra=nn2 if perception_cfg.nn1_uses_nn2_set else None)
        return _trained("pca", model, model.training["seconds"], _images(model.training),
                        model.feature_count)


class HoughEstimator:
    """Validated Hough lines of the outline -> rotation; centroid + rotation -> PSOM."""

    name = "hough"

    def __init__(self, model: HoughModel) -> None:
        self.model = model

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        p = self.model.perceive(image)
        loc = p.localisation
        record: dict[str, Any] = {"area_px": loc.area_px}
        if p.outline is not None:  # the ratio is inf when nothing votes off the peaks: JSON
            record.update(lines=len(p.outline.lines), edge_points=p.outline.points,  # has no inf
                          peak_to_sidelobe=min(p.outline.peak_to_sidelobe, 1e6))
        if p.status != "ok":
            return TranslationEstimate(p.status, reason=p.reason, record=record)
        c = p.constellation
        record.update(outline_angle_deg=c.angle_deg, outline_centre_px=list(c.centre_px),
                      widths_px=list(c.widths_px), votes=c.votes,
                      psom_s=p.psom_s.tolist(), dphi_deg=p.dphi_deg)
        return TranslationEstimate("ok", p.dxdy_mm[0], p.dxdy_mm[1], loc.u_px, loc.v_px,
                                   record=record)

    def estimate_rotation(self, image: np.ndarray,
                          translation: TranslationEstimate) -> RotationEstimate:
        p = self.model.perceive(image)
        if p.dphi_deg is None:  # same frame as the translation: cannot differ
            raise RuntimeError(f"rotation path lost the outline: {p.reason}")
        return RotationEstimate(p.dphi_deg, record={
            "outline_angle_deg": p.constellation.angle_deg,
            "lines": [[line.theta_deg, line.d_px, line.votes]
                      for line in p.constellation.lines]})


class HoughSystem(_ModelFileSystem):
    name = "hough"
    suffix = ".hough"
    model_cls = HoughModel
    estimator_cls = HoughEstimator

    @staticmethod
    def train(nn1: Dataset, nn2: Dataset, state: CellState, perception_cfg) -> TrainedModel:
        model = train_hough(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                            nominal_pose=state.nominal_pose, config=perception_cfg.hough)
        return _trained("hough", model, model.training["seconds"], _images(model.training),
                        model.feature_count)
