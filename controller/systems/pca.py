"""The paper's PCA system (2.2, 4.2): NN1 on the part's centre for the translation; eigenimages
of the ROI and a B-spline neuro-fuzzy controller for the rotation.

The vision lives in ``calibration_free.baselines.pca``; settings come from the
``perception.pca`` recipe section.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration_free.baselines.pca.model import PcaModel, PcaPercept
from calibration_free.baselines.pca.train import train_pca
from calibration_free.dataset import Dataset
from controller.systems.base import ModelEstimator, TrainedModel, VisionSystem
from controller.systems.estimator import RotationEstimate, TranslationEstimate, percept_of
from drivers.core.cell_state import CellState


class PcaEstimator(ModelEstimator):
    """NN1 on the part's centre; eigenimage projections of the ROI -> fuzzy controller."""

    name = "pca"

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """Localisation and NN1; see ``Estimator.estimate_translation``."""
        p = self.model.translation(image)
        loc = p.localisation
        if p.nn1_mm is None:
            return TranslationEstimate(loc.status, reason=loc.reason,
                                       record={"area_px": loc.area_px}, percept=p)
        share = self.model.front.seen_share(loc.area_px)
        return TranslationEstimate("ok", p.nn1_mm[0], p.nn1_mm[1], loc.u_px, loc.v_px,
                                   record={"area_px": loc.area_px, "seen_share": share,
                                           "nn1": list(p.nn1_mm)},
                                   percept=p, seen_share=share)

    def estimate_rotation(self, translation: TranslationEstimate) -> RotationEstimate:
        """Eigenimage projections and the fuzzy controller; see
        ``Estimator.estimate_rotation``."""
        p = self.model.rotation(percept_of(translation, PcaPercept))
        return RotationEstimate(p.dphi_deg, record={"features": p.features.tolist(),
                                                    "fuzzy": list(p.fc_sc)})


class PcaSystem(VisionSystem):
    """``pca``: model file ``model-pca.pca``."""

    name = "pca"
    suffix = ".pca"
    model_cls = PcaModel
    estimator_cls = PcaEstimator

    @classmethod
    def train(cls, nn1: Dataset, nn2: Dataset, state: CellState,
              perception_cfg: Any) -> TrainedModel:
        """Train NN1, the eigenimages and the fuzzy controller (``train_pca``)."""
        model = train_pca(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                          nominal_pose=state.nominal_pose, config=perception_cfg.pca,
                          seed=perception_cfg.seed,
                          nn1_extra=nn2 if perception_cfg.nn1_uses_nn2_set else None)
        return cls.trained(model)
