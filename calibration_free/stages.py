"""Perception's stages: each a named object holding its trained data and its settings.

``Perception`` (``calibration_free.perception``) runs them in order on one frame:

- ``Localiser``: the front end's preprocessing and localisation (``FrontEnd``).
- the occlusion fallbacks, each optional: ``EndsFallback`` (``ends``: a bar with one end
  hidden is centred where the end it shows puts it) and ``OutlineFallback`` (``outline``: a
  part partly hidden is centred on the outline it shows, and its features see it drawn in).
- the rotation readers: ``Nn2Turn`` (ROI -> Gabor features -> NN2) and, optional,
  ``AxisTurn`` (``axis``: an elongated part's turn near the taught pose from its long axis).
- ``TranslationNets``: NN1 (half loops), ``nn1_rot`` and its near correction ``nn1_near``.

A part's recipe names the optional stages it uses (``OPTIONAL_STAGES``, recipe key
``perception.stages``; the model keeps the list in ``training["stages"]``): a stage named
runs, and a model without its trained data is refused in one line (``check_stages``); a
stage left out is skipped. Unnamed (None), every optional stage whose data the model has
runs. Each stage's fit is in ``calibration_free.training`` (``prepare_training``,
``fit_ends_stage``, ``fit_outline_stage``, ``train_nn2``, ``fit_axis_stage``,
``fit_translation_nets``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from calibration_free import angles
from calibration_free.axis import AxisMap
from calibration_free.ends import EndMap, hidden_end_shift
from calibration_free.errors import BundleError
from calibration_free.front_end import FrontEnd
from calibration_free.gabor import GaborBank
from calibration_free.localise import Localisation
from calibration_free.mlp import NumpyMLP
from calibration_free.outline import OutlineFit, completed, fit_outline

StageName = Literal["ends", "outline", "axis"]
# The stages a recipe may name; the localiser, NN2 and the translation nets always run.
OPTIONAL_STAGES: tuple[StageName, ...] = ("ends", "outline", "axis")

# Gate of the outline fallback: a part seen this share smaller than at the taught pose is
# centred on the outline it shows. Well below the loop's hidden-part check
# (``controller.loop.hidden_check_share``), so the share does not straddle the gate from one
# pose to the next (docs/decisions/0009-partly-hidden-parts.md).
OUTLINE_BELOW = 0.03


@dataclass(frozen=True)
class Localiser:
    """Stage ``localiser``: preprocessing (max channel -> normalisation, or saturation, or
    the part's colour) and localisation, as the front end was trained
    (``training.prepare_training``)."""

    front: FrontEnd

    def preprocess(self, image: np.ndarray) -> np.ndarray:
        """``FrontEnd.preprocess``. Raises ImageError on a frame of the wrong kind or size."""
        return self.front.preprocess(image)

    def localise(self, normalised: np.ndarray, image: np.ndarray) -> Localisation:
        """``FrontEnd.localise`` of the preprocessed frame (``image``: the RGB frame)."""
        return self.front.localise(normalised, image)


@dataclass(frozen=True)
class EndsFallback:
    """Stage ``ends``: a bar (kappa 2) with one end hidden is centred where the end it shows
    puts it (``calibration_free.ends``; fitted by ``training.fit_ends_stage``).

    Attributes:
        ends: the end map (the bundle's ``axis.ends``).
        threshold: the part's threshold in the localisation channel.
    """

    ends: EndMap
    threshold: float

    def centre(self, normalised: np.ndarray, loc: Localisation
               ) -> tuple[tuple[float, float], float] | None:
        """The bar's centre (u_px, v_px) and the length hidden (px) where one end is hidden;
        None: the whole bar is seen, or no correction."""
        shift = hidden_end_shift(normalised, loc.part_mask, loc.u_px, loc.v_px, self.ends,
                                 self.threshold)
        if shift is None:
            return None
        du, dv, hidden_px = shift
        return (loc.u_px + du, loc.v_px + dv), hidden_px


@dataclass(frozen=True)
class OutlineFallback:
    """Stage ``outline``: a part seen more than ``OUTLINE_BELOW`` smaller than at the taught
    pose is centred on the outline it shows (``calibration_free.outline``), and its features
    see it with its hidden part drawn in (fitted by ``training.fit_outline_stage``).

    Attributes:
        outlines: the taught outline and the turned ones (``FrontEnd.outlines``).
        threshold: the part's threshold in the localisation channel.
        feature_ceiling: the front end's (``FrontEnd.feature_ceiling``; 0: the features see
            the frame as it is).
    """

    outlines: tuple[tuple[tuple[float, float], ...], ...]
    threshold: float
    feature_ceiling: float

    @staticmethod
    def wanted(share: float | None) -> bool:
        """Whether a part seen at ``share`` of its taught area (None: not known) is read from
        its outline."""
        return share is not None and share < 1.0 - OUTLINE_BELOW

    def fit(self, normalised: np.ndarray, loc: Localisation) -> OutlineFit | None:
        """The outline fitted to what is seen of the part (None: no fit)."""
        return fit_outline(normalised, loc.part_mask, loc.u_px, loc.v_px, self.outlines,
                           self.threshold)

    def completed(self, normalised: np.ndarray, loc: Localisation, fit: OutlineFit
                  ) -> tuple[np.ndarray, Localisation]:
        """The frame and localisation the features see: the part with its hidden part drawn
        in, centred on it (unchanged without a feature ceiling)."""
        if not self.feature_ceiling:
            return normalised, loc
        frame, mask = completed(normalised, loc.part_mask, fit,
                                self.feature_ceiling * self.threshold)
        return frame, dataclasses.replace(loc, u_px=fit.u_px, v_px=fit.v_px, part_mask=mask,
                                          coverage=None)


@dataclass(frozen=True)
class Nn2Turn:
    """Stage ``nn2``: the ROI around the part -> Gabor features -> NN2 -> (sin, cos) of
    kappa dphi (fitted by ``training.train_nn2``).

    Attributes:
        front: the front end the ROI is cut by (``FrontEnd.feature_roi``).
        bank: the Gabor filter bank.
        nn2: the network.
        kappa: the part's rotational symmetry count.
    """

    front: FrontEnd
    bank: GaborBank
    nn2: NumpyMLP
    kappa: int

    def roi(self, frame: np.ndarray, seen: Localisation) -> np.ndarray:
        """The ROI the features are taken of."""
        return self.front.feature_roi(frame, seen, self.bank.config.roi_px)

    def features(self, roi: np.ndarray) -> np.ndarray:
        """The Gabor features of the ROI (float32)."""
        return self.bank.features(roi)

    def turn(self, features: np.ndarray) -> tuple[tuple[float, float], float,
                                                  tuple[float, float]]:
        """NN2's raw (sin, cos), the turn decoded from it (deg) and the unit (sin, cos)."""
        s, c = self.nn2(features)
        nn2_deg = angles.decode(float(s), float(c), self.kappa)
        norm = max(float(np.hypot(s, c)), 1e-9)
        return (float(s), float(c)), nn2_deg, (float(s) / norm, float(c) / norm)


@dataclass(frozen=True)
class AxisTurn:
    """Stage ``axis``: an elongated part's turn near the taught pose read from its long axis,
    which takes over from NN2 where it agrees with it (``calibration_free.axis``; fitted by
    ``training.fit_axis_stage``).

    Attributes:
        axis: the axis map.
        front: the front end whose coverage the axis reads (``FrontEnd.coverage_roi``) where
            the map was fitted on it.
        roi_px: the ROI's side.
    """

    axis: AxisMap
    front: FrontEnd
    roi_px: int

    def reading(self, roi: np.ndarray, seen: Localisation, centre_px: tuple[float, float],
                nn2_deg: float) -> float | None:
        """The turn (deg) the long axis reads, or None (no clear axis, or one that disagrees
        with NN2's ``nn2_deg``)."""
        silhouette = roi
        if self.axis.silhouette == "coverage":
            # where the coverage is not read (a part partly hidden, drawn in) the features'
            # silhouette stands in: the same outline, less exactly placed
            coverage = self.front.coverage_roi(seen, self.roi_px)
            silhouette = roi if coverage is None else coverage
        return self.axis.reading(silhouette, *centre_px, nn2_deg)


@dataclass(frozen=True)
class TranslationNets:
    """Stage ``translation``: NN1 on the part's centre (half loops), ``nn1_rot`` on the centre
    and the turn (every full look), and its correction ``nn1_near`` added where ``nn1_rot``
    reads at most ``near_mm`` (fitted by ``training.fit_translation_nets``)."""

    nn1: NumpyMLP
    nn1_rot: NumpyMLP
    nn1_near: NumpyMLP
    near_mm: float

    def half(self, centre_px: tuple[float, float]) -> tuple[float, float]:
        """NN1's corrective translation (dx_mm, dy_mm)."""
        dx, dy = self.nn1(np.array(centre_px))
        return float(dx), float(dy)

    def full(self, centre_px: tuple[float, float], sc: tuple[float, float]
             ) -> tuple[tuple[float, float], bool, tuple[float, float]]:
        """``nn1_rot``'s reading, whether it is near, and the translation with the near
        correction added there."""
        inputs = np.array((*centre_px, *sc))
        dx_rot, dy_rot = self.nn1_rot(inputs)
        rot_mm = (float(dx_rot), float(dy_rot))
        near = math.hypot(*rot_mm) <= self.near_mm
        full_mm = rot_mm
        if near:
            cx, cy = self.nn1_near(inputs)
            full_mm = (rot_mm[0] + float(cx), rot_mm[1] + float(cy))
        return rot_mm, near, full_mm


def _missing(stage: str, axis: AxisMap | None, front: FrontEnd) -> str | None:
    """Why a model of ``axis`` map and ``front`` end cannot run the optional ``stage`` (None:
    it can)."""
    if stage == "axis":
        return None if axis is not None else \
            "the model has no axis map (a part that is not elongated, or perception.axis false)"
    if stage == "ends":
        return None if axis is not None and axis.ends is not None else \
            "the model has no end map (only a bar, kappa 2, with a long axis has one)"
    if stage == "outline":
        return None if front.outlines else \
            "the model has no taught outline (no training frame at the taught pose)"
    return f"unknown stage (the optional stages: {', '.join(OPTIONAL_STAGES)})"


def check_stages(stages: Sequence[str] | None, axis: AxisMap | None, front: FrontEnd) -> None:
    """Refuse a stage list naming a stage that a model of ``axis`` map and ``front`` end has
    no trained data for (None: nothing named, nothing to refuse).

    Raises:
        BundleError: one line naming the stage and what the model lacks.
    """
    for stage in stages or ():
        reason = _missing(stage, axis, front)
        if reason is not None:
            raise BundleError(f"perception.stages: {stage}: {reason}")


@dataclass(frozen=True)
class OptionalStages:
    """The optional stages a model runs, each None where skipped."""

    ends: EndsFallback | None
    outline: OutlineFallback | None
    axis: AxisTurn | None

    @classmethod
    def of(cls, stages: Sequence[str] | None, axis: AxisMap | None, front: FrontEnd,
           roi_px: int) -> OptionalStages:
        """The optional stages with ``stages`` named (None: every one whose data the model
        has) for a model of ``axis`` map, ``front`` end and ROI side ``roi_px``.

        Raises:
            BundleError: a stage named without its trained data (``check_stages``).
        """
        check_stages(stages, axis, front)
        runs = ({s for s in OPTIONAL_STAGES if _missing(s, axis, front) is None}
                if stages is None else set(stages))
        return cls(
            ends=EndsFallback(axis.ends, front.threshold) if "ends" in runs else None,
            outline=(OutlineFallback(front.outlines, front.threshold, front.feature_ceiling)
                     if "outline" in runs else None),
            axis=AxisTurn(axis, front, roi_px) if "axis" in runs else None)
