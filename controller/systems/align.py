"""An image-alignment servo: the part's soft silhouette registered to the taught pose's
(a rotation scan, then ECC) and least squares from the image shift and turn to the tool step.
Not the paper's: the comparison a cell owner would make against an OpenCV-built servo. Its
one pass over the frame yields the whole step, so the rotation step only reads the percept.

The vision lives in ``calibration_free.baselines.align``; settings come from the
``perception.align`` recipe section.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration_free.baselines.align.model import AlignModel, AlignPercept
from calibration_free.baselines.align.rezero import rezero_align
from calibration_free.baselines.align.train import train_align
from calibration_free.dataset import Dataset
from controller.systems.base import ModelEstimator, Rezeroed, TrainedModel, VisionSystem
from controller.systems.estimator import RotationEstimate, TranslationEstimate, percept_of
from drivers.core.cell_state import CellState


class AlignEstimator(ModelEstimator):
    """Registration of the silhouette -> (du, dv, turn) -> least squares -> tool step."""

    name = "align"

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """The whole registration; see ``Estimator.estimate_translation``."""
        p = self.model.perceive(image)
        loc = p.localisation
        if p.step is None:
            return TranslationEstimate(loc.status, reason=loc.reason,
                                       record={"area_px": loc.area_px}, percept=p)
        reg = p.registration
        share = self.model.front.seen_share(loc.area_px)
        return TranslationEstimate("ok", p.step[0], p.step[1], loc.u_px, loc.v_px, record={
            "area_px": loc.area_px, "seen_share": share, "registered_px": [reg.u_px, reg.v_px],
            "turn_deg": reg.angle_deg, "correlation": reg.correlation, "refined": reg.refined,
            "scan_deg": reg.scan_deg}, percept=p, seen_share=share)

    def estimate_rotation(self, translation: TranslationEstimate) -> RotationEstimate:
        """The registration's turn through the fit; see ``Estimator.estimate_rotation``."""
        p = percept_of(translation, AlignPercept)
        return RotationEstimate(p.step[2], record={"turn_deg": p.registration.angle_deg},
                                dx_mm=p.step[0], dy_mm=p.step[1])


class AlignSystem(VisionSystem):
    """``align``: model file ``model-align.align``."""

    name = "align"
    suffix = ".align"
    model_cls = AlignModel
    estimator_cls = AlignEstimator
    rezeroes = True

    @classmethod
    def rezero(cls, model: TrainedModel, images: list[np.ndarray], loop: Any,
               grab: Any) -> Rezeroed:
        """Take the servo's template again (``calibration_free.baselines.align.rezero``)."""
        done = rezero_align(model.model, images)
        return Rezeroed(done.model, done.report(), len(images), 1)

    @classmethod
    def train(cls, nn1: Dataset, nn2: Dataset, state: CellState,
              perception_cfg: Any) -> TrainedModel:
        """Template, registrations and the least-squares fits (``train_align``)."""
        model = train_align(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                            nominal_pose=state.nominal_pose, config=perception_cfg.align,
                            localisation_channel=perception_cfg.localisation_channel)
        return cls.trained(model)
