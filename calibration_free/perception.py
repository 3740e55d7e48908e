"""Perception of one hand-camera frame with a trained model bundle (the paper's Fig. 3).

The bundle's front end (max channel -> normalisation, or saturation -> localisation) -> NN1
(centre -> dx, dy): the half-loop path, ``Perception.translation``. ``Perception.rotation``
goes on from that percept: 50x50 ROI -> 36 Gabor features -> NN2 (features -> sin/cos of kappa
dphi) -> dphi (for an elongated part read from its long axis where the bundle has an axis map,
``calibration_free.axis``), and the full loop's translation. ``perceive`` is both in one pass.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from calibration_free import angles
from calibration_free.bundle import ModelBundle
from calibration_free.ends import hidden_end_shift
from calibration_free.gabor import GaborBank
from calibration_free.localise import Localisation
from calibration_free.outline import OutlineFit, completed, fit_outline

# A part seen this share smaller than at the taught pose is centred on the outline it shows
# where something lies against it (``calibration_free.outline``). Well below the loop's
# hidden-part check (``controller.loop.hidden_check_share``): a bar's centre moves by
# millimetres for a few per cent hidden, and a gate the hidden share straddles from one pose
# to the next made the loop step back and forth between the two.
OUTLINE_BELOW = 0.03


@dataclass(frozen=True)
class Percept:
    """What perception saw in one frame.

    Attributes:
        localisation: where the object is, or why it was not found.
        nn1_mm: NN1's corrective translation (dx_mm, dy_mm); None unless localisation is ok.
        features: the Gabor features (float32); None unless ok and rotation was asked for.
        nn2_sc: NN2's raw (sin, cos) of kappa dphi; None like ``features``.
        dphi_deg: the corrective rotation decoded from nn2_sc; None like ``features``.
        timings_us: microseconds per stage (preprocess, localise, ends (a bar's hidden end),
            roi, features, nn1, nn2, total); stages not run are absent.
        full_mm: the translation from (u, v) and NN2's rotation: ``nn1_rot``'s reading, with
            the bundle's ``nn1_near`` correction added where it reads at most the bundle's
            ``near_mm``; None like ``features``.
        normalised: the preprocessed frame the ROI is cut from (kept for ``rotation``).
        rot_mm: ``nn1_rot``'s reading (without the near correction); None like
            ``features``.
        near: ``full_mm`` has the near correction.
        nn2_deg: NN2's own reading (decoded from nn2_sc); None like ``features``.
        axis_deg: the long axis' reading (``bundle.axis``: an elongated part), or None
            (no axis map, no clear axis, or one that disagrees with NN2); ``dphi_deg`` is
            this one where there is one, else NN2's, and ``nn1_rot`` sees the one taken.
        hidden_px: for a bar (kappa 2) with one end hidden, the length hidden (px)
            (``calibration_free.ends``); None: the whole bar is seen, or no correction.
        centre_px: the part's centre the translation nets read: the localisation's, or for
            a bar with one end hidden where the end seen puts it, or for a part partly
            hidden where the outline it shows puts it (the features still look at the ROI
            around the blob seen).
        hidden_share: for a part partly hidden whose centre was read from the outline it
            shows (``calibration_free.outline``), the share of its taught area not seen;
            None: seen whole, or no correction.
        outline_fit: that fit (the features then see the part with its hidden part drawn
            in, ``outline.completed``).
        seen_share: the blob's area over the part's at the taught pose
            (``FrontEnd.seen_share``): below 1 where something hides part of it; None where
            that area is not known, or for a bar read from the end it shows (its hidden part
            accounted for).
    """

    localisation: Localisation
    nn1_mm: tuple[float, float] | None
    features: np.ndarray | None
    nn2_sc: tuple[float, float] | None
    dphi_deg: float | None
    timings_us: dict[str, float]
    full_mm: tuple[float, float] | None = None
    normalised: np.ndarray | None = field(default=None, repr=False, compare=False)
    rot_mm: tuple[float, float] | None = None
    near: bool = False
    nn2_deg: float | None = None
    axis_deg: float | None = None
    hidden_px: float | None = None
    centre_px: tuple[float, float] | None = None
    hidden_share: float | None = None
    outline_fit: OutlineFit | None = field(default=None, repr=False, compare=False)
    seen_share: float | None = None

    @property
    def ok(self) -> bool:
        return self.localisation.status == "ok"

    @property
    def u_px(self) -> float | None:
        return self.localisation.u_px

    @property
    def v_px(self) -> float | None:
        return self.localisation.v_px


class Perception:
    """Runs a trained bundle on hand-camera frames (HxWx3 uint8 RGB).

    Args:
        bundle: the trained model; its ``front`` preprocesses and localises, its networks
            map the result to the corrective step.
    """

    def __init__(self, bundle: ModelBundle):
        self.bundle = bundle
        self._front = bundle.front
        self._bank = GaborBank(bundle.gabor)
        self._roi_px = bundle.gabor.roi_px
        # a bar (both ends alike): where one end is hidden, the other says where its centre is
        self._ends = bundle.axis.ends if bundle.axis is not None else None

    def locate(self, image: np.ndarray) -> tuple[np.ndarray, Localisation]:
        """The preprocessed image (``FrontEnd.preprocess``) and the object's localisation in it.

        Args:
            image: an HxWx3 uint8 RGB frame.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self._front.locate(image)

    def translation(self, image: np.ndarray) -> Percept:
        """NN1 only: the corrective translation (the half-loop fast path). The percept keeps
        the preprocessed frame, so ``rotation`` can go on from it without a second pass.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        clock = time.perf_counter_ns
        t0 = clock()
        normalised = self._front.preprocess(image)
        t1 = clock()
        loc = self._front.localise(normalised, image)
        t2 = clock()
        timings = {"preprocess": (t1 - t0) / 1e3, "localise": (t2 - t1) / 1e3}
        if loc.status != "ok":
            timings["total"] = (t2 - t0) / 1e3
            return Percept(loc, None, None, None, None, timings)
        hidden_px, centre = None, (loc.u_px, loc.v_px)
        if self._ends is not None:
            shift = hidden_end_shift(normalised, loc.part_mask, loc.u_px, loc.v_px,
                                     self._ends, self._front.threshold)
            if shift is not None:
                du, dv, hidden_px = shift
                centre = (loc.u_px + du, loc.v_px + dv)
            t_ends = clock()
            timings["ends"] = (t_ends - t2) / 1e3
            t2 = t_ends
        hidden_share, fit = None, None
        share = self._front.seen_share(loc.area_px)
        if hidden_px is None and share is not None and share < 1.0 - OUTLINE_BELOW \
                and self._front.outlines:
            fit = fit_outline(normalised, loc.part_mask, loc.u_px, loc.v_px,
                              self._front.outlines, self._front.threshold)
            if fit is not None:
                centre, hidden_share = (fit.u_px, fit.v_px), 1.0 - share
            t_outline = clock()
            timings["outline"] = (t_outline - t2) / 1e3
            t2 = t_outline
        dx, dy = self.bundle.nn1(np.array(centre))
        t3 = clock()
        timings.update(nn1=(t3 - t2) / 1e3, total=(t3 - t0) / 1e3)
        return Percept(loc, (float(dx), float(dy)), None, None, None, timings,
                       normalised=normalised, hidden_px=hidden_px, centre_px=centre,
                       hidden_share=hidden_share, outline_fit=fit,
                       seen_share=None if hidden_px is not None else share)

    def rotation(self, percept: Percept) -> Percept:
        """Go on from a ``translation`` percept of the same frame: ROI -> Gabor features ->
        NN2 -> dphi, and the full loop's translation (``nn1_rot``). A percept whose object was
        not found is returned as it is.

        Raises:
            ValueError: the percept is not one of ``translation``'s (no frame kept).
        """
        if not percept.ok:
            return percept
        if percept.normalised is None:
            raise ValueError("rotation: needs the percept that translation() returned")
        clock = time.perf_counter_ns
        t3 = clock()
        loc = percept.localisation
        frame, seen = percept.normalised, loc
        fit = percept.outline_fit
        if fit is not None and self._front.feature_ceiling:
            # the features see the part with its hidden part drawn in, centred on it
            frame, mask = completed(frame, loc.part_mask, fit,
                                    self._front.feature_ceiling * self._front.threshold)
            seen = dataclasses.replace(loc, u_px=fit.u_px, v_px=fit.v_px, part_mask=mask,
                                       coverage=None)
        roi = self._front.feature_roi(frame, seen, self._roi_px)
        t4 = clock()
        features = self._bank.features(roi)
        t5 = clock()
        s, c = self.bundle.nn2(features)
        dphi = nn2_deg = angles.decode(float(s), float(c), self.bundle.kappa)
        norm = max(float(np.hypot(s, c)), 1e-9)
        sc = (float(s) / norm, float(c) / norm)
        axis_deg = None
        if self.bundle.axis is not None:
            silhouette = roi
            if self.bundle.axis.silhouette == "coverage":
                # where the coverage is not read (a part partly hidden, drawn in) the
                # features' silhouette stands in: the same outline, less exactly placed
                coverage = self._front.coverage_roi(seen, self._roi_px)
                silhouette = roi if coverage is None else coverage
            axis_deg = self.bundle.axis.reading(silhouette, *percept.centre_px, nn2_deg)
            if axis_deg is not None:
                dphi = axis_deg
                sc = tuple(float(v) for v in angles.encode(dphi, self.bundle.kappa))
        inputs = np.array((*percept.centre_px, *sc))
        dx_rot, dy_rot = self.bundle.nn1_rot(inputs)
        rot_mm = (float(dx_rot), float(dy_rot))
        near = math.hypot(*rot_mm) <= self.bundle.near_mm
        full_mm = rot_mm
        if near:
            cx, cy = self.bundle.nn1_near(inputs)
            full_mm = (rot_mm[0] + float(cx), rot_mm[1] + float(cy))
        t6 = clock()
        timings = dict(percept.timings_us)
        timings.update(roi=(t4 - t3) / 1e3, features=(t5 - t4) / 1e3, nn2=(t6 - t5) / 1e3,
                       total=timings["total"] + (t6 - t3) / 1e3)
        return Percept(loc, percept.nn1_mm, features, (float(s), float(c)), dphi, timings,
                       full_mm, percept.normalised, rot_mm, near, nn2_deg, axis_deg,
                       percept.hidden_px, percept.centre_px, percept.hidden_share,
                       fit, percept.seen_share)

    def perceive(self, image: np.ndarray) -> Percept:
        """The whole path in one pass: corrective translation (NN1) and rotation (NN2).

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self.rotation(self.translation(image))
