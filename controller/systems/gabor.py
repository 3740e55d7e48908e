"""The paper's system: NN1 on the part's centre, NN2 on 36 Gabor features of the ROI; every
look's translation from the rotation-aware net (the part's centre and NN2's rotation)."""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from calibration_free.bundle import ModelBundle
from calibration_free.dataset import Dataset
from calibration_free.perception import Percept, Perception
from calibration_free.rezero import CLIPPED_WARN_SHARE, rezero
from calibration_free.training import TrainingSettings, train_bundle
from controller.loop.checks import mean_scatter, step_scatter
from controller.loop.positioning import LoopConfig
from controller.systems.base import Rezeroed, TrainedModel, VisionSystem
from controller.systems.estimator import (
    RotationEstimate,
    TranslationEstimate,
    full_step,
    percept_of,
)
from drivers.core.cell_state import CellState

logger = logging.getLogger(__name__)


class GaborEstimator:
    """Runs a trained bundle (``calibration_free.perception``) in the positioning loop."""

    name = "gabor"

    def __init__(self, bundle: ModelBundle) -> None:
        self.perception = Perception(bundle)
        self.heading_zero = bundle.heading_zero

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """Localisation, NN1, and NN2 with the rotation-aware translation (``nn1_rot``); see
        ``Estimator.estimate_translation``.

        The translation is ``nn1_rot``'s, which knows the part's rotation: the silhouette's
        centre moves with the part's turn (for a part without symmetry, a screw, by several
        millimetres), which NN1 on (u, v) alone takes for a translation, so its reading sends a
        half loop millimetres off and misjudges r_fine; near the taught pose (``nn1_rot``
        reading at most the bundle's ``near_mm``) the near net's correction is added
        (``nn1_near``). The 36 features and NN2 cost a few tens of microseconds a frame. The
        record keeps the readings: ``nn1_rot``, ``nn1_near`` (the corrected translation
        returned, when the correction was added) and NN1's own (``nn1``), and the blob's
        area over the part's at the taught pose (``seen_share``; None for a bar read from
        the end it shows).
        """
        p = self.perception.perceive(image)
        loc = p.localisation
        if not p.ok:
            return TranslationEstimate(loc.status, reason=loc.reason,
                                       record={"area_px": loc.area_px}, percept=p)
        # a part centred on the outline it shows is still reported partly hidden
        share = p.seen_share
        return TranslationEstimate("ok", p.full_mm[0], p.full_mm[1], loc.u_px, loc.v_px,
                                   record={"area_px": loc.area_px, "seen_share": share,
                                           "nn1": list(p.nn1_mm),
                                           **_translation_readings(p),
                                           "perception_us": p.timings_us}, percept=p,
                                   seen_share=share)

    def estimate_rotation(self, translation: TranslationEstimate) -> RotationEstimate:
        """ROI, Gabor features, NN2 and the rotation-aware translation (already perceived
        with the translation); see ``Estimator.estimate_rotation``."""
        p = percept_of(translation, Percept)
        if p.dphi_deg is None:
            p = self.perception.rotation(p)
        return RotationEstimate(p.dphi_deg, record={
            "features": p.features.tolist(), "nn2": list(p.nn2_sc), **_translation_readings(p),
            "perception_us": p.timings_us}, dx_mm=p.full_mm[0], dy_mm=p.full_mm[1])


def _translation_readings(p: Percept) -> dict[str, Any]:
    """The rotation-aware nets' readings for the iteration record: ``nn1_rot``'s, the
    translation with the near net's correction when it was added, NN2's rotation reading
    (``nn2_deg``), the long axis' where it read one (``axis_deg``), the length of a bar
    found hidden at one end (``hidden_px``; its centre was moved back), and the share of a
    part hidden whose centre was read from the outline it shows (``hidden_share``)."""
    readings: dict[str, Any] = {"nn1_rot": list(p.rot_mm)}
    if p.hidden_px is not None:
        readings["hidden_px"] = p.hidden_px
    if p.hidden_share is not None:
        readings["hidden_share"] = p.hidden_share
    if p.near:
        readings["nn1_near"] = list(p.full_mm)
    if p.nn2_deg is not None:
        readings["nn2_deg"] = p.nn2_deg
    if p.axis_deg is not None:
        readings["axis_deg"] = p.axis_deg
    return readings


class GaborSystem(VisionSystem):
    """``gabor``: model file ``model-gabor.fpm`` (``calibration_free.bundle``)."""

    name = "gabor"
    suffix = ".fpm"
    model_cls = ModelBundle
    estimator_cls = GaborEstimator
    rezeroes = True
    zero_by_heading = True

    @classmethod
    def rezero(cls, model: TrainedModel, images: list[np.ndarray], loop: LoopConfig,
               grab: Callable[[], np.ndarray]) -> Rezeroed:
        """Shift the translation nets to read zero on ``images`` (``calibration_free.rezero``),
        read on the frames' means as the loop's settling look reads where ``settle_average``
        is ``frames``: as many at a time as it reads where single frames scatter as these do
        (``LoopConfig.settle_count``); where that asks for more frames than given, ``grab``
        takes them (two whole means at least). The zero by heading is dropped (it belongs to
        the old light). The report adds ``frame_scatter`` (standard deviations of single
        frames' steps, mm, mm, deg) and ``heading_zero`` (null)."""
        estimator = cls.estimator(model)
        scatter = step_scatter([step for step in (full_step(estimator, image)
                                                  for image in images) if step is not None])
        images, average = list(images), 1
        if loop.settle_average == "frames":
            average = loop.settle_count(scatter)
            if average > loop.settle_frames:  # the bounds ask for more: at least two
                # means, and whole ones (a short last mean reads differently)
                need = average * max(2, math.ceil(len(images) / average))
                images += [grab() for _ in range(need - len(images))]
        done = rezero(dataclasses.replace(model.model, heading_zero=None), images,
                      average=average)
        report = done.report()
        report["frame_scatter"] = None if scatter is None else [round(v, 4) for v in scatter]
        report["heading_zero"] = None
        warn_if_too_noisy(loop, scatter)
        if done.clipped_share > CLIPPED_WARN_SHARE:
            logger.warning("rezero: the camera clips %.0f%% of the part's pixels at the "
                           "taught pose in this light (a channel at 255): bring its "
                           "exposure down until the part's brightest face is not white "
                           "(docs/decisions/0013-expose-for-the-part.md)",
                           100 * done.clipped_share)
        return Rezeroed(done.bundle, report, len(images), average)

    @classmethod
    def without_heading_zero(cls, model: ModelBundle) -> ModelBundle:
        return dataclasses.replace(model, heading_zero=None)

    @classmethod
    def with_heading_zero(cls, model: ModelBundle, table: Any) -> ModelBundle:
        return dataclasses.replace(model, heading_zero=table)

    @classmethod
    def train(cls, nn1: Dataset, nn2: Dataset, state: CellState,
              perception_cfg: Any) -> TrainedModel:
        """Train NN1, the full loop's translation net and NN2 (``train_bundle``)."""
        t0 = time.perf_counter()
        settings = TrainingSettings(
            gabor=perception_cfg.gabor, nn2_hidden=tuple(perception_cfg.nn2_hidden),
            nn2_weight_decay=perception_cfg.nn2_weight_decay,
            nn2_widen_px=perception_cfg.nn2_widen_px,
            localisation_channel=perception_cfg.localisation_channel, seed=perception_cfg.seed,
            fine_axis=perception_cfg.axis, edge_gamma=perception_cfg.edge_gamma,
            stages=perception_cfg.stages)
        bundle = train_bundle(nn1, nn2, object_kind=state.object_kind, kappa=state.kappa,
                              nominal_pose=state.nominal_pose, settings=settings,
                              nn1_extra=nn2 if perception_cfg.nn1_uses_nn2_set else None)
        return TrainedModel(cls.name, bundle, time.perf_counter() - t0, len(nn1) + len(nn2),
                            bundle.gabor.n_filters)

    @staticmethod
    def training_cost(training: dict[str, Any]) -> tuple[float, int]:
        """(seconds, images): the bundle counts the samples of each set it trained on."""
        return (float(training.get("seconds", 0.0)),
                int(sum(training.get("samples", {}).values())))

    @staticmethod
    def feature_count(model: ModelBundle) -> int:
        """The Gabor bank's filter count."""
        return model.gabor.n_filters


def warn_if_too_noisy(loop: LoopConfig, scatter: tuple[float, float, float] | None) -> None:
    """Warn where single frames at the taught pose scatter so much that a settling look's
    ``settle_max_frames`` still leave its mean step beyond the loop's bounds
    (``LoopConfig.settle_known``): the loop will end with that noise in its step."""
    if scatter is None:
        return
    left = mean_scatter(scatter, loop.settle_max_frames)
    if loop.settle_known(left):
        return
    logger.warning("rezero: single frames at the taught pose scatter by %.3f / %.3f mm and "
                   "%.2f deg in this light; a settling look's %d frames still leave %.3f mm "
                   "and %.2f deg in its mean step, above the recipe's loop.settle_sem_mm / "
                   "settle_sem_deg: lower the camera's gain "
                   "(docs/decisions/0013-expose-for-the-part.md)",
                   *scatter, loop.settle_max_frames, max(left[0], left[1]), left[2])
