"""Training a model bundle from the acquired datasets (the paper's NN1 and NN2).

``prepare_training``: intensity statistics and the localisation channel, threshold, area window
and shape of the part from all training images (the ``FrontEnd``; the baselines train theirs
with it too, after ``check_part``). ``train_bundle``: then NN1 on (u, v) -> (dx, dy), pinned to
zero at the taught pose; the full loop's translation net on (u, v, sin, cos of kappa dphi); NN2
on the Gabor features of the ROI -> (sin, cos) of kappa dphi (``train_nn2``, which the filter
search reuses on other banks).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np

from calibration_free import angles
from calibration_free.axis import AxisMap, fit_axis
from calibration_free.bundle import ModelBundle
from calibration_free.dataset import Dataset
from calibration_free.ends import EndMap, fit_ends
from calibration_free.errors import BundleError, TrainingError
from calibration_free.front_end import FEATURE_CEILING, FEATURE_FLOOR, FrontEnd, learn_chroma
from calibration_free.gabor import GaborBank, GaborConfig
from calibration_free.localise import (
    ColourEdge,
    Localisation,
    Polarity,
    binarise,
    elongation,
    localise,
    otsu_threshold,
)
from calibration_free.mlp import TrainedMLP, train_mlp
from calibration_free.outline import taught_outline, turned_outlines
from calibration_free.part_colour import PartColour, learn_part_colour, taught_blob
from calibration_free.pin import pinned
from calibration_free.preprocess import (
    Channel,
    IntensityStats,
    image_stats,
    max_and_saturation_u8,
    normalise,
)
from calibration_free.stages import StageName, check_stages
from drivers.core.pose import Pose

logger = logging.getLogger(__name__)

NN1_HIDDEN = (3,)
# The rotation-aware translation net, on (u, v, sin, cos of kappa dphi): the silhouette's
# centre circles the grasp point as the part turns, which three tanh units cannot follow; more
# units fit the taught spot too closely (the figures: docs/decisions/0025-perception-stages.md).
NN1_ROT_HIDDEN = (10,)
NN2_HIDDEN = (12,)
# Rprop steps. NN2 stops early: on the NN2 grid's 63 images more steps overfit.
NN1_EPOCHS = 2000
NN2_EPOCHS = 1500
# The near translation net needs at least this many samples in its range.
MIN_NEAR_SAMPLES = 9
# The near net's L2 penalty: it corrects nn1_rot where the samples say so and fades to no
# correction between them, instead of wiggling between the grid's three positions per axis.
NN1_NEAR_WEIGHT_DECAY = 1e-2
# A part without symmetry: its silhouette's centre circles the grasp point over the whole
# circle, and the near samples span every turn, which the looser fit follows.
NN1_NEAR_WEIGHT_DECAY_NO_SYMMETRY = 1e-3
# Training images whose label is this close to zero were taken at the taught pose.
NOMINAL_TOL_MM = 0.05
NOMINAL_TOL_DEG = 0.05
# L2 penalty on NN2's weights: 63 images cannot pin down 36 x 12 weights; without it NN2
# reads ~0 for any rotation within a few degrees of a grid angle (see mlp.train_mlp), and it
# keeps NN2 from amplifying the camera's noise. A part without symmetry (kappa 1) maps the
# whole circle and needs the looser fit.
NN2_WEIGHT_DECAY = 1e-2
NN2_WEIGHT_DECAY_NO_SYMMETRY = 1e-3
# NN2 of a part this round (kappa >= WIDEN_MIN_KAPPA: the nut) also learns from copies of each
# ROI widened on one side: the ROI's maximum with itself shifted by up to NN2_WIDEN_PX in a
# random direction, NN2_WIDEN_COPIES of them, with the same turn. A lamp-lit flank widens the
# outline on its side, and the hexagon's features change so little per degree that NN2 would
# read that as a turn; a part whose features change more learns without them.
NN2_WIDEN_PX = 1.0
NN2_WIDEN_COPIES = 4
WIDEN_MIN_KAPPA = 6
# A blob covering more of the image than this is the background, not the object.
MAX_OBJECT_FRACTION = 0.5
# Margin added to the relative half-range of the training areas (see prepare_training).
AREA_MARGIN = 0.2
# Factor on the most elongated training blob: the largest elongation still taken for the part.
ELONGATION_MARGIN = 1.3
# Otsu's threshold is computed on every OTSU_STRIDE-th pixel along each axis.
OTSU_STRIDE = 2


def default_nn2_weight_decay(kappa: int) -> float:
    """NN2's default L2 penalty for a part of symmetry count ``kappa`` (see NN2_WEIGHT_DECAY)."""
    return NN2_WEIGHT_DECAY_NO_SYMMETRY if kappa == 1 else NN2_WEIGHT_DECAY


def default_nn2_widen_px(kappa: int) -> float:
    """How far NN2's widened copies of its ROIs reach for a part of symmetry count ``kappa``
    (see NN2_WIDEN_PX; 0: no copies)."""
    return NN2_WIDEN_PX if kappa >= WIDEN_MIN_KAPPA else 0.0


def widened_copies(rois: list[np.ndarray], widen_px: float, copies: int,
                   rng: np.random.Generator) -> list[np.ndarray]:
    """``copies`` copies of each ROI (in order), each its maximum with itself shifted by a
    distance uniform in 0..``widen_px`` in a direction uniform in 0..360 deg: the outline
    widened on that side."""
    out = []
    for roi in rois:
        n_rows, n_cols = roi.shape
        for _ in range(copies):
            theta = rng.uniform(0.0, 2.0 * math.pi)
            d = rng.uniform(0.0, widen_px)
            shift = np.array([[1.0, 0.0, d * math.cos(theta)], [0.0, 1.0, d * math.sin(theta)]])
            out.append(np.maximum(roi, cv2.warpAffine(roi, shift, (n_cols, n_rows),
                                                      flags=cv2.INTER_LINEAR)))
    return out


def default_near_weight_decay(kappa: int) -> float:
    """The near translation net's L2 penalty for a part of symmetry count ``kappa`` (see
    NN1_NEAR_WEIGHT_DECAY)."""
    return NN1_NEAR_WEIGHT_DECAY_NO_SYMMETRY if kappa == 1 else NN1_NEAR_WEIGHT_DECAY


def _check_sets(sets: dict[str, Dataset]) -> tuple[int, int]:
    """(height, width) shared by every set's images; raises if a set has none or sizes differ."""
    shapes = set()
    for name, data in sets.items():
        if data.images is None or len(data) == 0:
            raise TrainingError(f"{name}: training needs a dataset with images")
        shapes.add(data.images.shape[1:3])
    if len(shapes) != 1:
        raise TrainingError(f"all training images must have one size, got {sorted(shapes)}")
    return shapes.pop()


def _usable(locs: list[Localisation], name: str) -> np.ndarray:
    """Indices of samples whose object was found; raises if fewer than half were."""
    ok = np.array([i for i, loc in enumerate(locs) if loc.ok], dtype=int)
    for i, loc in enumerate(locs):
        if not loc.ok:
            logger.warning("%s sample %d skipped: %s (%s)", name, i, loc.status, loc.reason)
    if ok.size < max(4, (len(locs) + 1) // 2):
        raise TrainingError(f"{name}: the object was found in only {ok.size} of {len(locs)} "
                            f"images; check the threshold polarity and the scene")
    return ok


@dataclass(frozen=True)
class PreparedSets:
    """Training images after the shared preprocessing and localisation.

    Attributes:
        front: what was learned (normalisation, channel, threshold, area window, shape);
            ``nominal_uv_px`` is None (``train_bundle`` sets it from NN1's samples).
        normalised: per set name, the preprocessed images (``FrontEnd.preprocess``).
        found: per set name, every image's localisation.
        usable: per set name, the indices of images where the object was found.
        seconds: time spent.
    """

    front: FrontEnd
    normalised: dict[str, list[np.ndarray]]
    found: dict[str, list[Localisation]]
    usable: dict[str, np.ndarray]
    seconds: float

    def centres(self, name: str) -> np.ndarray:
        """(n_usable, 2) object centroids (u_px, v_px) of set ``name``."""
        return np.array([(self.found[name][i].u_px, self.found[name][i].v_px)
                         for i in self.usable[name]]).reshape(-1, 2)


def _otsu(images: list[np.ndarray]) -> tuple[float, float]:
    """Otsu's threshold over (a subsample of) the images, and its separability in [0, 1]."""
    values = np.concatenate([n[::OTSU_STRIDE, ::OTSU_STRIDE].ravel() for n in images])
    threshold = otsu_threshold(values)
    below = values <= threshold
    if below.all() or not below.any():
        return threshold, 0.0
    w0 = below.mean()
    between = w0 * (1 - w0) * (values[below].mean() - values[~below].mean()) ** 2
    return threshold, float(between / max(values.var(), 1e-12))


def _taught_frames(sets: dict[str, Dataset]) -> list[tuple[str, int]]:
    """(set, index) of the frames taken at the taught pose, or of every NN2 frame (the
    smallest displacements) where none was."""
    frames = [(name, int(i)) for name, data in sets.items()
              for i in np.flatnonzero(at_taught_pose(data.labels))]
    if frames or "nn2" not in sets:
        return frames
    return [("nn2", i) for i in range(len(sets["nn2"].images))]


def _part_at_centre(mask: np.ndarray) -> bool:
    """Whether a binary mask holds the part where teach-in put it: a blob near the image's
    middle, which the hand camera looks at between the fingers (``part_colour.taught_blob``)."""
    return taught_blob(mask) is not None


def _channel_and_polarity(candidates: dict, otsu: dict, sets: dict[str, Dataset],
                          polarity: Polarity | Literal["auto"]) -> tuple[str, Polarity]:
    """The localisation channel and the part's polarity in it: of the channels, the most
    separable one (Otsu) in which, at the taught pose, the part shows as a blob where
    teach-in put it (``_part_at_centre``) in most frames, the part's colour
    (``part_colour``) only where neither max(R,G,B) nor saturation does; of the polarities
    (``auto``: bright, then dark), the first that does so. Where none does, the most
    separable channel, bright (training then says what it found instead)."""
    frames = _taught_frames(sets)
    polarities: tuple[Polarity, ...] = ("bright", "dark") if polarity == "auto" else (polarity,)
    for channel in sorted(otsu, key=lambda c: (c == "colour", -otsu[c][1])):
        threshold = otsu[channel][0]
        for pol in polarities:
            seen = sum(_part_at_centre(binarise(candidates[channel][name][i], threshold, pol)
                                       .astype(np.uint8)) for name, i in frames)
            if frames and seen * 2 > len(frames):
                return channel, pol
    return max(otsu, key=lambda c: otsu[c][1]), polarities[0]


def prepare_training(sets: dict[str, Dataset], polarity: Polarity | Literal["auto"] = "auto",
                     channel: Channel | Literal["auto"] = "max",
                     edge_gamma: float = 0.0) -> PreparedSets:
    """The front end every system trains first: intensity statistics, localisation channel
    and threshold, expected area and shape of the part, and the localisation of every image.

    Args:
        sets: the training sets by name (one of them named "nn2").
        polarity: "bright" if the object is brighter than the table in the channel, "dark"
            if darker, "auto": found from the frames at the taught pose
            (``_channel_and_polarity``).
        channel: "max", "saturation", "colour" or "auto": the channel in which the part
            stands out from its background best (Otsu's separability on the training images)
            and shows where teach-in put it (``_channel_and_polarity``); where the part is
            then not found across the grids in it (and ``polarity`` is "auto"), the part's
            colour.
        edge_gamma: the camera's output gamma: the part's edge is read from the frame's colour
            (``localise.colour_centre``); 0: from the channel's grey levels.

    Raises:
        TrainingError: a set has no images, the image sizes differ, an image is flat, the
            object is not found in at least half of a set's images, or the "object" is the
            table (wrong polarity).
    """
    start = time.perf_counter()
    height, width = _check_sets(sets)
    intensity, candidates, colour = _channel_images(sets, channel)
    otsu = {c: _otsu([n for ns in imgs.values() for n in ns]) for c, imgs in candidates.items()}
    asked = polarity
    channel, polarity = _channel_and_polarity(candidates, otsu, sets, polarity)
    logger.info("localisation channel %s, %s part (separability %s)", channel, polarity,
                ", ".join(f"{c} {v[1]:.2f}" for c, v in otsu.items()))
    try:
        front, found, usable = _front_end(sets, candidates[channel], otsu[channel][0], channel,
                                          polarity, intensity, colour, edge_gamma)
    except TrainingError as exc:
        if channel == "colour" or "colour" not in candidates or asked != "auto":
            raise
        # the part showed at the taught pose in that channel, but not across the grids
        logger.info("localisation channel %s: %s; the part's colour instead", channel, exc)
        channel, polarity = "colour", "bright"
        front, found, usable = _front_end(sets, candidates[channel], otsu[channel][0], channel,
                                          polarity, intensity, colour, edge_gamma)
    return PreparedSets(front, candidates[channel], found, usable,
                        time.perf_counter() - start)


def _front_end(sets: dict[str, Dataset], located: dict[str, list[np.ndarray]],
               threshold: float, channel: str, polarity: Polarity,
               intensity: IntensityStats, colour: PartColour | None, edge_gamma: float
               ) -> tuple[FrontEnd, dict[str, list[Localisation]], dict[str, np.ndarray]]:
    """The front end trained in one channel (``prepare_training``), the localisation of
    every image and the usable ones of each set.

    Raises:
        TrainingError: the object is not found in at least half of a set's images, or the
            "object" is the table.
    """
    height, width = located[next(iter(located))][0].shape
    edge = ColourEdge(edge_gamma, fill_holes=True) if edge_gamma else None
    expected_area, tolerance, max_elongation = _area_and_shape(
        sets, located, threshold, polarity, height * width)
    found = {name: [localise(n, threshold, expected_area, polarity=polarity,
                             area_tolerance=tolerance, max_elongation=max_elongation,
                             image=im, edge=edge)
                    for n, im in zip(located[name], sets[name].images, strict=True)]
             for name in sets}
    usable = {name: _usable(found[name], name) for name in sets}
    # The part's colour, so that a blob of its size and shape but another colour is not taken
    # for it in a cluttered image.
    blobs = [(sets[name].images[i], _blob_at(located[name][i], threshold, polarity,
                                             found[name][i]))
             for name in sets for i in usable[name]]
    learned = learn_chroma([im for im, _ in blobs], [b for _, b in blobs])
    chroma, chroma_tolerance = learned if learned is not None else (None, 0.0)
    taught, outline, turned = _taught_view(sets, found, usable)
    front = FrontEnd(height, width, intensity, threshold, polarity, expected_area, tolerance,
                     max_elongation, channel, chroma=chroma, chroma_tolerance=chroma_tolerance,
                     feature_floor=FEATURE_FLOOR if channel == "saturation" else 0.0,
                     feature_ceiling=FEATURE_CEILING if channel == "saturation" else 0.0,
                     taught_area_px=float(np.mean(taught)) if taught else None,
                     taught_outline_px=outline, turned_outlines_px=turned,
                     edge_gamma=float(edge_gamma), edge_fill_holes=bool(edge_gamma),
                     part_colour=colour if channel == "colour" else None)
    return front, found, usable


def _channel_images(sets: dict[str, Dataset], channel: Channel | Literal["auto"]
                    ) -> tuple[IntensityStats, dict[str, dict[str, list[np.ndarray]]],
                               PartColour | None]:
    """The sets' intensity statistics (of the max-channel images), each candidate
    channel's images (``channel`` alone, or for ``auto`` ``max`` (normalised max(R,G,B)),
    ``saturation`` and, where the part's colour stands out at the taught pose, ``colour``)
    and the part's colour learned there (``part_colour.learn_part_colour``; None where not
    learned).

    Raises:
        TrainingError: an image is flat; ``colour`` where the part's colour does not stand
            out at the taught pose.
    """
    split = {name: [max_and_saturation_u8(im) for im in data.images]
             for name, data in sets.items()}
    grays = {name: [g for g, _ in pairs] for name, pairs in split.items()}
    per_image = []
    for name, gs in grays.items():
        for i, g in enumerate(gs):
            stats = image_stats(g)
            if stats is None:
                raise TrainingError(f"{name} image {i} is flat (no contrast); check the camera")
            per_image.append(stats)
    intensity = IntensityStats(float(np.mean([s.mean for s in per_image])),
                               float(np.mean([s.std for s in per_image])))
    normalised = {name: [normalise(g, intensity) for g in gs] for name, gs in grays.items()}
    candidates = {"max": normalised}
    if channel in ("saturation", "auto"):
        candidates["saturation"] = {name: [sat.astype(np.float32) for _, sat in pairs]
                                    for name, pairs in split.items()}
    colour = None
    if channel in ("colour", "auto"):
        colour = learn_part_colour([sets[name].images[i] for name, i in _taught_frames(sets)])
        if colour is not None:
            candidates["colour"] = {name: [colour.image(im) for im in data.images]
                                    for name, data in sets.items()}
        elif channel == "colour":
            raise TrainingError("the part's colour does not stand out from the table's at the "
                                "taught pose; check the scene, or train with another "
                                "localisation channel")
    if channel != "auto":
        candidates = {channel: candidates[channel]}
    return intensity, candidates, colour


def _area_and_shape(sets: dict[str, Dataset], located: dict[str, list[np.ndarray]],
                    threshold: float, polarity: Polarity, image_area_px: int
                    ) -> tuple[float, float, float]:
    """The part's expected blob area, its relative tolerance and its largest elongation,
    from every training image.

    Raises:
        TrainingError: the part is found in no image, or covers most of one (the table).
    """
    # The blob's area changes with the displacement (the camera looks at a tilt: nearer is
    # bigger), so the accepted window spans every training image's area, plus a margin.
    areas = np.array([loc.area_px for name in sets
                      for loc in (localise(n, threshold, None, polarity=polarity)
                                  for n in located[name]) if loc.ok])
    if areas.size == 0:
        raise TrainingError("the object was found in none of the training images")
    lo, hi = float(areas.min()), float(areas.max())
    if hi > MAX_OBJECT_FRACTION * image_area_px:
        raise TrainingError(f"the 'object' covers {hi / image_area_px:.0%} of the "
                            f"image: it is the table; check the polarity ({polarity!r})")
    expected_area = (lo + hi) / 2.0
    tolerance = min(1.0, (hi - lo) / (hi + lo) + AREA_MARGIN)
    # The trained part's shape: clutter of the right area but another shape (a bar) is not it.
    shapes = [_elongation_of_largest_blob(n, threshold, polarity)
              for ns in located.values() for n in ns]
    return expected_area, tolerance, max(shapes) * ELONGATION_MARGIN


def _taught_view(sets: dict[str, Dataset], found: dict[str, list[Localisation]],
                 usable: dict[str, np.ndarray]) -> tuple[list[float], Any, tuple]:
    """The part's areas at the taught pose, its outline there (None: not seen there) and
    turned (``fit_outline_stage``): where the loop settles."""
    at_pose = [found[name][i] for name in sets
               for i in np.flatnonzero(at_taught_pose(sets[name].labels)) if found[name][i].ok]
    taught = [loc.area_px for loc in at_pose]
    return (taught, *fit_outline_stage(sets, found, usable, at_pose))


def fit_outline_stage(sets: dict[str, Dataset], found: dict[str, list[Localisation]],
                      usable: dict[str, np.ndarray], at_pose: list[Localisation]
                      ) -> tuple[Any, tuple]:
    """The ``outline`` stage's fit (``calibration_free.outline``): the part's outline in the
    first frame at the taught pose (``at_pose``; None: not seen there) and turned, as the NN2
    grid's images turn it over its symmetry period. The front end keeps both
    (``FrontEnd.taught_outline_px``, ``turned_outlines_px``)."""
    outline = (taught_outline(at_pose[0].part_mask, at_pose[0].u_px, at_pose[0].v_px)
               if at_pose else None)
    turned = ()
    if outline is not None and "nn2" in sets:
        nn2 = found["nn2"]
        turned = turned_outlines(
            sets["nn2"].labels[usable["nn2"], 2],
            [taught_outline(nn2[i].part_mask, nn2[i].u_px, nn2[i].v_px)
             for i in usable["nn2"]])
    return outline, turned


def _blob_at(preprocessed: np.ndarray, threshold: float, polarity: Polarity,
             loc: Localisation) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """The blob whose centroid is the localisation's (a nut's centroid lies in its hole),
    within its bounding box, and the box (x, y, w, h)."""
    mask = binarise(preprocessed, threshold, polarity).astype(np.uint8)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    label = 1 + int(np.argmin(np.hypot(centroids[1:, 0] - loc.u_px, centroids[1:, 1] - loc.v_px)))
    x, y, w, h = (int(v) for v in stats[label, :4])
    return labels[y:y + h, x:x + w] == label, (x, y, w, h)


def _elongation_of_largest_blob(normalised: np.ndarray, threshold: float,
                                polarity: Polarity) -> float:
    mask = binarise(normalised, threshold, polarity).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n < 2:
        return 1.0
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    x, y, w, h = (int(v) for v in stats[largest, :4])
    return elongation((labels[y:y + h, x:x + w] == largest).astype(np.uint8))


def _pose(nominal_pose: Pose | Mapping[str, float]) -> Pose:
    if isinstance(nominal_pose, Pose):
        pose = nominal_pose
    else:
        try:
            pose = Pose(**{k: float(v) for k, v in dict(nominal_pose).items()})
        except (TypeError, ValueError) as exc:
            raise TrainingError(f"nominal_pose: needs x_mm, y_mm, z_mm, o_deg, a_deg, t_deg as "
                                f"numbers ({exc})") from exc
    if not pose.is_finite():
        raise TrainingError(f"nominal_pose: must be finite, got {pose}")
    return pose


def check_part(object_kind: str, kappa: int, nominal_pose: Pose | Mapping[str, float]) \
        -> dict[str, float]:
    """Validate what a system is taught on (every system's training checks this first).

    Args:
        object_kind: name of the taught object.
        kappa: the object's rotational symmetry count.
        nominal_pose: the taught pose.

    Returns:
        The nominal pose as a dict {x_mm, y_mm, z_mm, o_deg, a_deg, t_deg}.

    Raises:
        TrainingError: an empty object kind, kappa not a whole number >= 1, or a bad pose.
    """
    if not isinstance(object_kind, str) or not object_kind:
        raise TrainingError(f"object_kind: must be a non-empty string, got {object_kind!r}")
    if isinstance(kappa, bool) or not isinstance(kappa, int) or kappa < 1:
        raise TrainingError(f"kappa: must be a whole number >= 1, got {kappa!r}")
    return _pose(nominal_pose).as_dict()


def _summary(result: TrainedMLP) -> dict:
    """What the model file's header keeps of one network's training: a summary (layers,
    seconds, epochs, first and final loss), not the per-epoch loss curve (thousands of numbers
    that made the header unreadable)."""
    return {"layers": list(result.model.layer_sizes), "seconds": result.seconds,
            "epochs": len(result.loss_curve), "first_loss": result.loss_curve[0],
            "final_loss": result.loss_curve[-1]}


def train_nn2(rois: np.ndarray | list[np.ndarray], dphi_deg: np.ndarray, kappa: int,
              gabor: GaborConfig, *, seed: int, hidden: tuple[int, ...] = NN2_HIDDEN,
              epochs: int = NN2_EPOCHS, weight_decay: float | None = None,
              widen_px: float | None = None) -> TrainedMLP:
    """NN2 as ``train_bundle`` trains it: ``gabor``'s features of the ROIs -> (sin, cos) of
    kappa dphi (Rprop, L2 penalty on the weights).

    Args:
        rois: the preprocessed roi_px x roi_px float32 ROIs, centred on the located object.
        dphi_deg: (N,) the ROIs' rotation labels (deg).
        kappa: the object's rotational symmetry count.
        gabor: the filter bank the features come from.
        seed: the bundle's training seed; NN2's initial weights are drawn from seed + 1
            (seed itself is NN1's).
        hidden: hidden layer sizes.
        epochs: Rprop steps (at most).
        weight_decay: L2 penalty on the weights (0 = none; None: the part's default,
            ``default_nn2_weight_decay(kappa)``).
        widen_px: NN2 also learns from NN2_WIDEN_COPIES copies of each ROI widened on one
            side by up to this many pixels (``widened_copies``; 0: none; None: the part's
            default, ``default_nn2_widen_px(kappa)``), drawn from seed + 11.

    Returns:
        The trained network, its loss curve and training time.

    Raises:
        TrainingError: fewer than two ROIs, or labels that do not match them.
        ImageError: an ROI is not roi_px x roi_px float32.
    """
    dphi_deg = np.asarray(dphi_deg)
    if len(rois) < 2 or dphi_deg.shape != (len(rois),):
        raise TrainingError(f"nn2: needs two or more ROIs and one label each, got "
                            f"{len(rois)} ROIs and labels of shape {dphi_deg.shape}")
    if widen_px is None:
        widen_px = default_nn2_widen_px(kappa)
    if widen_px:
        rois = list(rois)
        rois += widened_copies(rois, widen_px, NN2_WIDEN_COPIES,
                               np.random.default_rng(seed + 11))
        dphi_deg = np.concatenate([dphi_deg, np.repeat(dphi_deg, NN2_WIDEN_COPIES)])
    bank = GaborBank(gabor)
    features = np.stack([bank.features(roi) for roi in rois])
    s, c = angles.encode(dphi_deg, kappa)
    if weight_decay is None:
        weight_decay = default_nn2_weight_decay(kappa)
    return train_mlp(features, np.stack([s, c], axis=1), tuple(hidden), seed=seed + 1,
                     epochs=epochs, weight_decay=weight_decay)


def training_sets(nn1_data: Dataset, nn2_data: Dataset,
                  nn1_extra: Dataset | None = None) -> dict[str, Dataset]:
    """The sets a system trains on, by name: ``nn1``, ``nn2`` and, if given, ``nn1_extra``."""
    sets = {"nn1": nn1_data, "nn2": nn2_data}
    if nn1_extra is not None:
        sets["nn1_extra"] = nn1_extra
    return sets


def nn1_samples(sets: dict[str, Dataset], prep: PreparedSets) -> tuple[np.ndarray, np.ndarray]:
    """NN1's samples: the part's (u, v) in every usable image of ``nn1`` (and ``nn1_extra``),
    and each image's (dx_mm, dy_mm, dphi_deg) label, as (N, 2) and (N, 3) arrays."""
    names = [n for n in ("nn1", "nn1_extra") if n in sets]
    uv = np.concatenate([prep.centres(n) for n in names])
    labels = np.concatenate([sets[n].labels[prep.usable[n]] for n in names])
    return uv, labels


@dataclass(frozen=True)
class TrainingSettings:
    """How a bundle trains: the recipe's perception settings (``controller.recipe``).

    gabor: the filter bank (None: the paper's 36 even filters); nn2_hidden: NN2's hidden layer
    sizes; seed: seeds NN1 (NN2 uses seed + 1, the full loop's net seed + 2, its correction
    near the pose seed + 3); polarity: ``bright``, ``dark`` or ``auto``
    (``prepare_training``); nn1_epochs / nn2_epochs: the Rprop steps (at most);
    nn2_weight_decay: L2 penalty on NN2's weights (0: none; None: the part's default,
    ``default_nn2_weight_decay``); nn2_widen_px: NN2 also learns from copies of its ROIs
    widened on one side by up to this many pixels (``train_nn2``; None: the part's default,
    ``default_nn2_widen_px``); localisation_channel: ``max``, ``saturation`` or ``auto``
    (``prepare_training``); fine_axis: for an elongated part (screw, ledge), fit the map from
    its long axis to the turn near the taught pose (``calibration_free.axis``; False: NN2
    alone); edge_gamma: the camera's output gamma, with which the part's centre is read from
    the colour along its edge (``localise.colour_centre``; 0: from the channel's grey levels);
    stages: the optional perception stages the bundle runs (``stages.OPTIONAL_STAGES``): each
    is fitted, and one that cannot be is refused in one line; the bundle keeps the list
    (``training["stages"]``). None: every one the part's training fits, as it fits them.
    """

    gabor: GaborConfig | None = None
    nn2_hidden: tuple[int, ...] = NN2_HIDDEN
    seed: int = 0
    polarity: Polarity | Literal["auto"] = "auto"
    nn1_epochs: int = NN1_EPOCHS
    nn2_epochs: int = NN2_EPOCHS
    nn2_weight_decay: float | None = None
    nn2_widen_px: float | None = None
    localisation_channel: Channel | Literal["auto"] = "auto"
    fine_axis: bool = True
    edge_gamma: float = 0.0
    stages: tuple[StageName, ...] | None = None


def train_bundle(nn1_data: Dataset, nn2_data: Dataset, *, object_kind: str, kappa: int,
                 nominal_pose: Pose | Mapping[str, float], nn1_extra: Dataset | None = None,
                 settings: TrainingSettings = TrainingSettings()) -> ModelBundle:
    """Train NN1 and NN2 from image datasets and pack everything into a ModelBundle.

    Steps: the front end (``prepare_training``: intensity statistics of the max-channel
    images, the localisation channel and its Otsu threshold, the area window and shape of the
    part, the localisation of every image), then the translation nets (``fit_translation_nets``:
    NN1 on (u, v) -> (dx, dy), the full loop's translation net on (u, v, sin, cos of kappa
    dphi) and its correction near the pose), NN2 on Gabor features -> (sin, cos)(kappa dphi)
    (``train_nn2``) and, for an elongated part, the long axis (``fit_axis_stage``, with a
    bar's ends: ``fit_ends_stage``). Images where
    the object is not found are skipped with a warning and counted.

    Args:
        nn1_data: NN1's set (paper: 3x3x7 grid, a = 25 mm).
        nn2_data: NN2's set (paper: 3x3x7 grid, a = 5 mm, b = 180/kappa deg).
        object_kind: name of the taught object, stored in the bundle.
        kappa: the object's rotational symmetry count.
        nominal_pose: the taught pose.
        nn1_extra: more (u, v) -> (dx, dy) samples for NN1, typically ``nn2_data``, so NN1 is
            precise near the nominal pose, where the positioning loop settles.
        settings: how it trains (``TrainingSettings``).

    Returns:
        The bundle: the front end (with the taught pose's image position), the networks and
        the training metadata.

    Raises:
        TrainingError: an argument is invalid, a dataset has no images or the sets' image
            sizes differ, a training image is flat, the "object" covers most of the image
            (wrong polarity), or the object is found in fewer than half of a set's images.
    """
    seed, stages = settings.seed, settings.stages
    start = time.perf_counter()
    gabor = settings.gabor or GaborConfig()
    pose = check_part(object_kind, kappa, nominal_pose)
    sets = training_sets(nn1_data, nn2_data, nn1_extra)
    prep = prepare_training(sets, settings.polarity, settings.localisation_channel,
                            settings.edge_gamma)
    nets = fit_translation_nets(sets, prep, nn2_data, kappa, seed, settings.nn1_epochs)
    nn2_weight_decay, nn2_widen_px = settings.nn2_weight_decay, settings.nn2_widen_px
    if nn2_weight_decay is None:
        nn2_weight_decay = default_nn2_weight_decay(kappa)
    if nn2_widen_px is None:
        nn2_widen_px = default_nn2_widen_px(kappa)
    rois = [prep.front.feature_roi(prep.normalised["nn2"][i], prep.found["nn2"][i], gabor.roi_px)
            for i in prep.usable["nn2"]]
    nn2_labels = nn2_data.labels[prep.usable["nn2"]]
    nn2 = train_nn2(rois, nn2_labels[:, 2], kappa, gabor, seed=seed,
                    hidden=settings.nn2_hidden, epochs=settings.nn2_epochs,
                    weight_decay=nn2_weight_decay, widen_px=nn2_widen_px)
    axis = _fit_optional_stages(prep, rois, nn2_labels, object_kind, kappa, gabor.roi_px,
                                settings)
    training = {
        "seed": seed,
        "samples": {name: len(d) for name, d in sets.items()},
        "skipped": {name: len(sets[name]) - int(prep.usable[name].size) for name in sets},
        "preprocess_seconds": prep.seconds,
        **nets.training(kappa),
        "nn2": {**_summary(nn2), "weight_decay": nn2_weight_decay, "widen_px": nn2_widen_px},
        "axis": _axis_summary(axis),
        **({} if stages is None else {"stages": list(stages)}),
        "seconds": time.perf_counter() - start,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    logger.info("trained %s bundle in %.2f s (NN1 loss %.2e, NN2 loss %.2e)", object_kind,
                training["seconds"], nets.nn1.loss_curve[-1], nn2.loss_curve[-1])
    front = dataclasses.replace(prep.front, nominal_uv_px=nets.nominal_uv)
    bundle = ModelBundle(object_kind=object_kind, kappa=kappa, nominal_pose=pose, front=front,
                         gabor=gabor, nn1=nets.nn1.model, nn1_rot=nets.nn1_rot.model,
                         nn1_near=nets.nn1_near.model, near_mm=nets.near_mm, nn2=nn2.model,
                         axis=axis, training=training)
    # every frame at the taught pose once (``nn1_extra`` is mostly the NN2 set again)
    distinct = {id(data): data for data in sets.values()}.values()
    return pinned_as_read(bundle, [data.images[i] for data in distinct
                                   for i in np.flatnonzero(at_taught_pose(data.labels))])


def _fit_optional_stages(prep: PreparedSets, rois: list[np.ndarray], nn2_labels: np.ndarray,
                         object_kind: str, kappa: int, roi_px: int,
                         settings: TrainingSettings) -> AxisMap | None:
    """The axis map with the ends where ``settings`` ask for them (``fit_axis_stage``,
    ``fit_ends_stage``; the outline stage's fit is the front end's), after checking that
    every stage ``settings.stages`` names has its data.

    Raises:
        TrainingError: a stage named could not be fitted for this part (one line).
    """
    stages, axis = settings.stages, None
    if settings.fine_axis and _named(stages, "axis", "ends"):
        axis = fit_axis_stage(prep, rois, nn2_labels, kappa, roi_px)
        if axis is not None and kappa == 2 and _named(stages, "ends"):
            axis = dataclasses.replace(
                axis, ends=fit_ends_stage(prep, nn2_labels, axis.direction))
    try:
        check_stages(stages, axis, prep.front)
    except BundleError as exc:
        raise TrainingError(f"{object_kind}: {exc}") from exc
    return axis


def _named(stages: tuple[str, ...] | None, *names: str) -> bool:
    """Whether a stage list names one of ``names`` (None names every stage)."""
    return stages is None or any(name in stages for name in names)


def _axis_summary(axis: AxisMap | None) -> dict | None:
    """What the model file's training metadata keeps of the axis map's fit."""
    if axis is None:
        return None
    return {"samples": axis.samples, "whole_rms_deg": axis.whole_rms_deg,
            "near_rms_deg": axis.near_rms_deg, "elongation": axis.elongation,
            "ends_rms_px": None if axis.ends is None else list(axis.ends.rms_px)}


@dataclass
class FittedTranslationNets:
    """The trained translation nets (``fit_translation_nets``) and what their training left."""

    nn1: TrainedMLP
    nn1_zero_offset: list[float]
    nn1_rot: TrainedMLP
    nn1_rot_zero_offset: list[float]
    nn1_near: TrainedMLP
    nn1_near_zero_offset: list[float]
    near_mm: float
    near_samples: int
    nominal_uv: tuple[float, ...]

    def training(self, kappa: int) -> dict:
        """The bundle's training metadata of the three nets."""
        return {
            "nn1": {**_summary(self.nn1), "zero_offset_mm": self.nn1_zero_offset},
            "nn1_rot": {**_summary(self.nn1_rot), "zero_offset_mm": self.nn1_rot_zero_offset},
            "nn1_near": {**_summary(self.nn1_near), "zero_offset_mm": self.nn1_near_zero_offset,
                         "samples": self.near_samples, "near_mm": self.near_mm,
                         "weight_decay": default_near_weight_decay(kappa)},
        }


def fit_translation_nets(sets: dict[str, Dataset], prep: PreparedSets, nn2_data: Dataset,
                         kappa: int, seed: int, epochs: int) -> FittedTranslationNets:
    """The translation nets' fit: NN1 on (u, v) -> (dx, dy); the full loop's translation net
    on (u, v, sin, cos of kappa dphi); and its correction near the taught pose; each pinned on
    the frames there."""
    uv, labels = nn1_samples(sets, prep)
    uvsc, dxdy, at_nominal = _translation_samples(uv, labels, kappa)
    if not at_nominal.any():
        logger.warning("no training image at the taught pose: NN1's zero is not pinned")
    nominal_uv = tuple(float(v) for v in (uv[at_nominal] if at_nominal.any() else uv)
                       .mean(axis=0))
    nn1, nn1_zero_offset = _train_pinned(uv, dxdy, at_nominal, seed, epochs, NN1_HIDDEN)
    # The full loop knows the rotation (NN2) before it moves: the silhouette's centre shifts a
    # little with the part's rotation in the image, which (u, v) alone cannot tell apart from
    # a translation, so the full loop's translation also sees sin/cos(kappa dphi).
    nn1_rot, nn1_rot_zero_offset = _train_pinned(uvsc, dxdy, at_nominal, seed + 2, epochs,
                                                 NN1_ROT_HIDDEN)
    # Where the loop makes its full loops and settles, a correction of that net fitted to the
    # samples near the taught pose: over the whole +/-25 mm range its error near zero
    # follows the part's turn by up to 0.15 mm.
    if "nn1_extra" not in sets:  # the NN2 set is not among NN1's samples: add it here
        uvsc, dxdy, at_nominal = _translation_samples(
            np.concatenate([uv, prep.centres("nn2")]),
            np.concatenate([labels, nn2_data.labels[prep.usable["nn2"]]]), kappa)
    near_mm, near = near_samples(dxdy, nn2_data.labels)
    residual = dxdy[near] - nn1_rot.model(uvsc[near])
    nn1_near, nn1_near_zero_offset = _train_pinned(uvsc[near], residual, at_nominal[near],
                                                   seed + 3, epochs, NN1_ROT_HIDDEN,
                                                   default_near_weight_decay(kappa))
    return FittedTranslationNets(nn1, nn1_zero_offset, nn1_rot, nn1_rot_zero_offset, nn1_near,
                           nn1_near_zero_offset, near_mm, int(near.sum()), nominal_uv)


def fit_axis_stage(prep: PreparedSets, rois: list[np.ndarray], nn2_labels: np.ndarray,
                   kappa: int, roi_px: int) -> AxisMap | None:
    """The ``axis`` stage's fit: an elongated part's long axis, which reads the turn near the
    taught pose (``calibration_free.axis``; None for a part that is not elongated), on the
    part's coverage where every NN2 image's centre was read from colour, else on the
    features' ROIs."""
    at_taught = at_taught_pose(nn2_labels)
    found = [prep.found["nn2"][i] for i in prep.usable["nn2"]]
    coverage = [prep.front.coverage_roi(loc, roi_px) for loc in found]
    return (fit_axis(coverage, prep.centres("nn2"), nn2_labels[:, 2], at_taught, kappa,
                     "coverage") if all(c is not None for c in coverage) else
            fit_axis(rois, prep.centres("nn2"), nn2_labels[:, 2], at_taught, kappa))


def fit_ends_stage(prep: PreparedSets, nn2_labels: np.ndarray,
                   direction: tuple[float, float]) -> EndMap | None:
    """The ``ends`` stage's fit: a bar's ends (``calibration_free.ends``) on the NN2 set's
    images, along the long axis' ``direction`` at the taught pose (None: too few images
    near it)."""
    usable = prep.usable["nn2"]
    return fit_ends([prep.normalised["nn2"][i] for i in usable],
                    [prep.found["nn2"][i].part_mask for i in usable],
                    prep.centres("nn2"), at_taught_pose(nn2_labels), direction,
                    prep.front.threshold)


def pinned_as_read(bundle: ModelBundle, taught_images: list[np.ndarray]) -> ModelBundle:
    """The bundle with its translation nets pinned once more on the frames at the taught pose,
    as the loop reads them: with NN2's (or the axis map's) turn there, not the label's zero
    (``calibration_free.pin``). Its ``training["pinned_as_read_mm"]`` keeps each shift (None:
    no frame at the taught pose shows the part whole, and the nets stay as trained)."""
    try:
        shifted, shift = pinned(bundle, taught_images)
    except TrainingError as exc:
        logger.warning("the translation nets are not pinned as read: %s", exc)
        shifted, shift = bundle, None
    record = None if shift is None else {k: [round(v, 4) for v in s] for k, s in shift.items()}
    return dataclasses.replace(shifted, training={**bundle.training,
                                                  "pinned_as_read_mm": record})


def _translation_samples(uv: np.ndarray, labels: np.ndarray, kappa: int
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The translation nets' samples from the part's (u, v) and the images' labels: inputs
    (u, v, sin, cos of kappa dphi), targets (dx_mm, dy_mm), and which were taken at the
    taught pose."""
    s_rot, c_rot = angles.encode(labels[:, 2], kappa)
    return (np.column_stack([uv, s_rot, c_rot]), np.ascontiguousarray(labels[:, :2]),
            at_taught_pose(labels))


def at_taught_pose(labels: np.ndarray) -> np.ndarray:
    """Which of the (N, 3) labels [dx_mm, dy_mm, dphi_deg] were taken at the taught pose
    (within ``NOMINAL_TOL_MM`` and ``NOMINAL_TOL_DEG``)."""
    return (np.hypot(labels[:, 0], labels[:, 1]) < NOMINAL_TOL_MM) \
        & (np.abs(labels[:, 2]) < NOMINAL_TOL_DEG)


def near_samples(dxdy: np.ndarray, nn2_labels: np.ndarray) -> tuple[float, np.ndarray]:
    """Where the near translation net takes over, and which of the translation samples it
    learns from.

    The near range is the NN2 set's: its largest offset along x or y (the paper's a = 5 mm).
    The net learns from every sample within the range's corner plus 1 mm (the NN2 grid's
    corners, the taught-pose frames, NN1's grid centre), so it interpolates wherever it is used.

    Args:
        dxdy: (N, 2) the translation samples' (dx_mm, dy_mm).
        nn2_labels: (M, 3) the NN2 set's labels.

    Returns:
        (near_mm, mask over ``dxdy``).

    Raises:
        TrainingError: fewer than ``MIN_NEAR_SAMPLES`` samples in that range.
    """
    near_mm = float(np.abs(nn2_labels[:, :2]).max())
    near = np.hypot(dxdy[:, 0], dxdy[:, 1]) <= near_mm * math.sqrt(2.0) + 1.0
    if int(near.sum()) < MIN_NEAR_SAMPLES:
        raise TrainingError(f"only {int(near.sum())} training images lie within "
                            f"{near_mm:.1f} mm of the taught pose; the near translation net "
                            f"needs {MIN_NEAR_SAMPLES} (acquire the NN2 set)")
    return near_mm, near


def _train_pinned(x: np.ndarray, y: np.ndarray, at_nominal: np.ndarray, seed: int,
                  epochs: int, hidden: tuple[int, ...], weight_decay: float = 0.0
                  ) -> tuple[TrainedMLP, list[float]]:
    """A translation network (``hidden`` units, Rprop) whose output is pinned to zero at the
    samples taken at the taught pose: that is where the correction is zero by definition,
    and where the loop settles (a 3-hidden-unit fit over +/-25 mm otherwise misses it by a
    few tenths of a millimetre). Returns the network and the offset subtracted."""
    trained = train_mlp(x, y, hidden, seed=seed, epochs=epochs, weight_decay=weight_decay)
    if not at_nominal.any():
        return trained, [0.0, 0.0]
    offset = trained.model(x[at_nominal]).mean(axis=0).tolist()
    return dataclasses.replace(trained, model=trained.model.shifted(offset)), offset
