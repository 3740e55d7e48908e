"""The paper's Hough system (2.3, 4.3): the outline's straight lines validated by a model of
the expected Hough-peak constellation give the rotation; a 3x3x3 PSOM completes (u, v, dphi) to
the translation. It reports ``no_object`` when the peaks do not validate.

The vision lives in ``calibration_free.baselines.hough``; settings come from the
``perception.hough`` recipe section.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration_free.baselines.hough.model import HoughModel, HoughPercept
from calibration_free.baselines.hough.train import train_hough
from calibration_free.dataset import Dataset
from controller.systems.base import ModelEstimator, TrainedModel, VisionSystem
from controller.systems.estimator import RotationEstimate, TranslationEstimate, percept_of
from drivers.core.cell_state import CellState


class HoughEstimator(ModelEstimator):
    """Validated Hough lines of the outline -> rotation; centroid + rotation -> PSOM. Its one
    pass over the frame yields both, so the rotation step only reads the percept."""

    name = "hough"

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """The whole Hough pass; see ``Estimator.estimate_translation``."""
        p = self.model.perceive(image)
        loc = p.localisation
        record: dict[str, Any] = {"area_px": loc.area_px}
        if p.outline is not None:  # the ratio is inf when nothing votes off the peaks: JSON
            record.update(lines=len(p.outline.lines), edge_points=p.outline.points,  # has no inf
                          peak_to_sidelobe=min(p.outline.peak_to_sidelobe, 1e6))
        if p.status != "ok":
            return TranslationEstimate(p.status, reason=p.reason, record=record, percept=p)
        c = p.constellation
        record.update(outline_angle_deg=c.angle_deg, outline_centre_px=list(c.centre_px),
                      widths_px=list(c.widths_px), votes=c.votes,
                      psom_s=p.psom_s.tolist(), dphi_deg=p.dphi_deg)
        share = self.model.front.seen_share(loc.area_px)
        record["seen_share"] = share
        return TranslationEstimate("ok", p.dxdy_mm[0], p.dxdy_mm[1], loc.u_px, loc.v_px,
                                   record=record, percept=p, seen_share=share)

    def estimate_rotation(self, translation: TranslationEstimate) -> RotationEstimate:
        """The validated outline's rotation; see ``Estimator.estimate_rotation``."""
        p = percept_of(translation, HoughPercept)
        return RotationEstimate(p.dphi_deg, record={
            "outline_angle_deg": p.constellation.angle_deg,
            "lines": [[line.theta_deg, line.d_px, line.votes]
                      for line in p.constellation.lines]})


class HoughSystem(VisionSystem):
    """``hough``: model file ``model-hough.hough``."""

    name = "hough"
    suffix = ".hough"
    model_cls = HoughModel
    estimator_cls = HoughEstimator

    @classmethod
    def train(cls, nn1: Dataset, nn2: Dataset, state: CellState,
              perception_cfg: Any) -> TrainedModel:
        """Train the edge settings, constellation model, angle map and PSOM
        (``train_hough``)."""
        model = train_hough(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                            nominal_pose=state.nominal_pose, config=perception_cfg.hough)
        return cls.trained(model)
