"""Perception of one hand-camera frame with a trained model bundle (the paper's Fig. 3).

The frame goes through named stages (``calibration_free.stages``): the localiser (the
bundle's front end), the occlusion fallbacks where the model runs them (``ends``: a bar with
one end hidden; ``outline``: a part partly hidden), and the translation nets' NN1 (centre ->
dx, dy): the half-loop path, ``Perception.translation``. ``Perception.rotation`` goes on from
that percept: 50x50 ROI -> 36 Gabor features -> NN2 (features -> sin/cos of kappa dphi) ->
dphi (for an elongated part read from its long axis where the model runs the ``axis``
stage), and the full loop's translation (``nn1_rot``, ``nn1_near``). ``perceive`` is both in
one pass.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration_free import angles
from calibration_free.bundle import ModelBundle
from calibration_free.gabor import GaborBank
from calibration_free.localise import Localisation
from calibration_free.outline import OutlineFit
from calibration_free.stages import (
    Localiser,
    Nn2Turn,
    OptionalStages,
    TranslationNets,
)


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
    """Runs a trained bundle on hand-camera frames (HxWx3 uint8 RGB), stage by stage
    (``calibration_free.stages``).

    Args:
        bundle: the trained model; its ``front`` preprocesses and localises, its networks
            map the result to the corrective step.
        stages: the optional stages to run (``stages.OPTIONAL_STAGES``); None: the ones the
            bundle was trained with (``training["stages"]``), and where it names none every
            one whose trained data it has.

    Attributes:
        localiser, translation, nn2: the stages every model runs.
        optional: the optional stages (``ends``, ``outline``, ``axis``), each None where
            skipped.

    Raises:
        BundleError: a stage named without its trained data (one line naming it).
    """

    def __init__(self, bundle: ModelBundle, stages: Sequence[str] | None = None):
        self.bundle = bundle
        if stages is None:
            stages = bundle.training.get("stages")
        self.localiser = Localiser(bundle.front)
        self.optional = OptionalStages.of(stages, bundle.axis, bundle.front,
                                          bundle.gabor.roi_px)
        self.nn2 = Nn2Turn(bundle.front, GaborBank(bundle.gabor), bundle.nn2, bundle.kappa)
        self.translation_nets = TranslationNets(bundle.nn1, bundle.nn1_rot, bundle.nn1_near,
                                                bundle.near_mm)

    def locate(self, image: np.ndarray) -> tuple[np.ndarray, Localisation]:
        """The preprocessed image (``FrontEnd.preprocess``) and the object's localisation in it.

        Args:
            image: an HxWx3 uint8 RGB frame.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self.bundle.front.locate(image)

    def translation(self, image: np.ndarray) -> Percept:
        """NN1 only: the corrective translation (the half-loop fast path). The percept keeps
        the preprocessed frame, so ``rotation`` can go on from it without a second pass.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        clock = time.perf_counter_ns
        t0 = clock()
        normalised = self.localiser.preprocess(image)
        t1 = clock()
        loc = self.localiser.localise(normalised, image)
        t2 = clock()
        timings = {"preprocess": (t1 - t0) / 1e3, "localise": (t2 - t1) / 1e3}
        if loc.status != "ok":
            timings["total"] = (t2 - t0) / 1e3
            return Percept(localisation=loc, nn1_mm=None, features=None, nn2_sc=None,
                           dphi_deg=None, timings_us=timings)
        hidden_px, centre = None, (loc.u_px, loc.v_px)
        ends, outline = self.optional.ends, self.optional.outline
        if ends is not None:
            read = ends.centre(normalised, loc)
            if read is not None:
                centre, hidden_px = read
            t_ends = clock()
            timings["ends"] = (t_ends - t2) / 1e3
            t2 = t_ends
        hidden_share, fit = None, None
        share = self.bundle.front.seen_share(loc.area_px)
        if hidden_px is None and outline is not None and outline.wanted(share):
            fit = outline.fit(normalised, loc)
            if fit is not None:
                centre, hidden_share = (fit.u_px, fit.v_px), 1.0 - share
            t_outline = clock()
            timings["outline"] = (t_outline - t2) / 1e3
            t2 = t_outline
        nn1_mm = self.translation_nets.half(centre)
        t3 = clock()
        timings.update(nn1=(t3 - t2) / 1e3, total=(t3 - t0) / 1e3)
        return Percept(localisation=loc, nn1_mm=nn1_mm, features=None, nn2_sc=None,
                       dphi_deg=None, timings_us=timings, normalised=normalised,
                       hidden_px=hidden_px, centre_px=centre, hidden_share=hidden_share,
                       outline_fit=fit, seen_share=None if hidden_px is not None else share)

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
        if fit is not None and self.optional.outline is not None:
            # the features see the part with its hidden part drawn in, centred on it
            frame, seen = self.optional.outline.completed(frame, loc, fit)
        roi = self.nn2.roi(frame, seen)
        t4 = clock()
        features = self.nn2.features(roi)
        t5 = clock()
        nn2_sc, nn2_deg, sc = self.nn2.turn(features)
        dphi, axis_deg = nn2_deg, None
        if self.optional.axis is not None:
            axis_deg = self.optional.axis.reading(roi, seen, percept.centre_px, nn2_deg)
            if axis_deg is not None:
                dphi = axis_deg
                sc = tuple(float(v) for v in angles.encode(dphi, self.bundle.kappa))
        rot_mm, near, full_mm = self.translation_nets.full(percept.centre_px, sc)
        t6 = clock()
        timings = dict(percept.timings_us)
        timings.update(roi=(t4 - t3) / 1e3, features=(t5 - t4) / 1e3, nn2=(t6 - t5) / 1e3,
                       total=timings["total"] + (t6 - t3) / 1e3)
        return Percept(localisation=loc, nn1_mm=percept.nn1_mm, features=features,
                       nn2_sc=nn2_sc, dphi_deg=dphi, timings_us=timings, full_mm=full_mm,
                       normalised=percept.normalised, rot_mm=rot_mm, near=near,
                       nn2_deg=nn2_deg, axis_deg=axis_deg, hidden_px=percept.hidden_px,
                       centre_px=percept.centre_px, hidden_share=percept.hidden_share,
                       outline_fit=fit, seen_share=percept.seen_share)

    def perceive(self, image: np.ndarray) -> Percept:
        """The whole path in one pass: corrective translation (NN1) and rotation (NN2).

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self.rotation(self.translation(image))
