"""Training a model bundle from datasets, and running perception on frames with it.

Perception of one frame (``Perception.perceive``): max channel -> normalisation -> localisation
-> 50x50 ROI -> 36 Gabor features -> NN1 (centre -> dx, dy) and NN2 (features -> sin/cos of
kappa dphi) -> dphi. The half-loop fast path (``Perception.translation``) stops after NN1.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from calibration_free import angles
from calibration_free.bundle import ModelBundle
from calibration_free.dataset import Dataset
from calibration_free.errors import ImageError, TrainingError
from calibration_free.gabor import GaborBank, GaborConfig
from calibration_free.localise import (
    Localisation,
    Polarity,
    binarise,
    elongation,
    localise,
    otsu_threshold,
)
from calibration_free.mlp import TrainedMLP, train_mlp
from calibration_free.preprocess import (
    Channel,
    IntensityStats,
    image_stats,
    max_and_saturation_u8,
    normalise,
)
from calibration_free.roi import extract_roi
from drivers.core.pose import Pose, ToolStep

logger = logging.getLogger(__name__)

NN1_HIDDEN = (3,)
NN2_HIDDEN = (12,)
# Rprop steps. NN2 stops early: on 63 images more steps start to overfit (on synthetic
# cubes 400 steps gave ~1.0 deg RMS on random test poses, 1500 steps ~1.2 deg).
NN1_EPOCHS = 2000
NN2_EPOCHS = 1500
# Training images whose label is this close to zero were taken at the taught pose.
NOMINAL_TOL_MM = 0.05
NOMINAL_TOL_DEG = 0.05
# L2 penalty on NN2's weights: 63 images cannot pin down 36 x 12 weights; without it NN2
# reads ~0 for any rotation within a few degrees of a grid angle (see mlp.train_mlp).
NN2_WEIGHT_DECAY = 1e-3
# A blob covering more of the image than this is the background, not the object.
MAX_OBJECT_FRACTION = 0.5
# Margin added to the relative half-range of the training areas (see _prepare).
AREA_MARGIN = 0.2
# Factor on the most elongated training blob: the largest elongation still taken for the part.
ELONGATION_MARGIN = 1.3
# Otsu's threshold is computed on every OTSU_STRIDE-th pixel along each axis.
OTSU_STRIDE = 2


@dataclass(frozen=True)
class Percept:
    """What perception saw in one frame.

    Attributes:
        localisation: where the object is, or why it was not found.
        nn1_mm: NN1's corrective translation (dx_mm, dy_mm); None unless localisation is ok.
        features: the Gabor features (float32); None unless ok and rotation was asked for.
        nn2_sc: NN2's raw (sin, cos) of kappa dphi; None like ``features``.
        dphi_deg: the corrective rotation decoded from nn2_sc; None like ``features``.
        timings_us: microseconds per stage (preprocess, localise, roi, features, nn1, nn2,
            total); stages not run are absent.
        full_mm: the full loop's translation, from (u, v) and NN2's rotation (the bundle's
            ``nn1_rot``); None like ``features``.
    """

    localisation: Localisation
    nn1_mm: tuple[float, float] | None
    features: np.ndarray | None
    nn2_sc: tuple[float, float] | None
    dphi_deg: float | None
    timings_us: dict[str, float]
    full_mm: tuple[float, float] | None = None

    @property
    def ok(self) -> bool:
        return self.localisation.status == "ok"

    @property
    def u_px(self) -> float | None:
        return self.localisation.u_px

    @property
    def v_px(self) -> float | None:
        return self.localisation.v_px

    def tool_step(self) -> ToolStep | None:
        """The corrective step: NN1's translation on the translation-only path, the full
        loop's translation and rotation on the whole path; None if not ok."""
        if self.nn1_mm is None:
            return None
        if self.full_mm is None:
            return ToolStep(dx_mm=self.nn1_mm[0], dy_mm=self.nn1_mm[1])
        return ToolStep(dx_mm=self.full_mm[0], dy_mm=self.full_mm[1], dphi_deg=self.dphi_deg)


class Perception:
    """Runs a trained bundle on hand-camera frames (HxWx3 uint8 RGB)."""

    def __init__(self, bundle: ModelBundle):
        self.bundle = bundle
        self._bank = GaborBank(bundle.gabor)
        self._roi_px = bundle.gabor.roi_px
        self._frame_shape = (bundle.frame_height_px, bundle.frame_width_px)

    def _preprocess(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The image the features are taken from and the one localisation binarises: both
        the normalised max(R, G, B) image, or both the saturation image."""
        gray, sat = max_and_saturation_u8(image)
        if gray.shape != self._frame_shape:
            raise ImageError(f"image: the bundle was trained on {self._frame_shape[1]}x"
                             f"{self._frame_shape[0]} frames, got {gray.shape[1]}x"
                             f"{gray.shape[0]}")
        if self.bundle.channel == "saturation":
            located = sat.astype(np.float32)
            return located, located
        normalised = normalise(gray, self.bundle.intensity)
        return normalised, normalised

    def locate(self, image: np.ndarray) -> tuple[np.ndarray, Localisation]:
        """The normalised image and the object's localisation in it.

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        normalised, located = self._preprocess(image)
        return normalised, self._localise(located)

    def _localise(self, located: np.ndarray) -> Localisation:
        b = self.bundle
        return localise(located, b.threshold, b.expected_area_px, polarity=b.polarity,
                        area_tolerance=b.area_tolerance, max_elongation=b.max_elongation,
                        expected_uv=b.nominal_uv_px)

    def translation(self, image: np.ndarray) -> Percept:
        """NN1 only: the corrective translation (the half-loop fast path).

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self._run(image, rotation=False)

    def perceive(self, image: np.ndarray) -> Percept:
        """The whole path: corrective translation (NN1) and rotation (NN2).

        Raises:
            ImageError: the frame is not HxWx3 uint8 of the size the bundle was trained on.
        """
        return self._run(image, rotation=True)

    def _run(self, image: np.ndarray, rotation: bool) -> Percept:
        clock = time.perf_counter_ns
        t0 = clock()
        normalised, located = self._preprocess(image)
        t1 = clock()
        loc = self._localise(located)
        t2 = clock()
        timings = {"preprocess": (t1 - t0) / 1e3, "localise": (t2 - t1) / 1e3}
        if loc.status != "ok":
            timings["total"] = (t2 - t0) / 1e3
            return Percept(loc, None, None, None, None, timings)
        dx, dy = self.bundle.nn1(np.array((loc.u_px, loc.v_px)))
        t3 = clock()
        timings["nn1"] = (t3 - t2) / 1e3
        if not rotation:
            timings["total"] = (t3 - t0) / 1e3
            return Percept(loc, (float(dx), float(dy)), None, None, None, timings)
        roi = extract_roi(normalised, loc.u_px, loc.v_px, self._roi_px)
        t4 = clock()
        features = self._bank.features(roi)
        t5 = clock()
        s, c = self.bundle.nn2(features)
        dphi = angles.decode(float(s), float(c), self.bundle.kappa)
        norm = max(float(np.hypot(s, c)), 1e-9)
        dx_rot, dy_rot = self.bundle.nn1_rot(
            np.array((loc.u_px, loc.v_px, float(s) / norm, float(c) / norm)))
        t6 = clock()
        timings.update(roi=(t4 - t3) / 1e3, features=(t5 - t4) / 1e3, nn2=(t6 - t5) / 1e3,
                       total=(t6 - t0) / 1e3)
        return Percept(loc, (float(dx), float(dy)), features, (float(s), float(c)), dphi,
                       timings, (float(dx_rot), float(dy_rot)))


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
class _Prepared:
    """Training images after preprocessing and localisation."""

    intensity: IntensityStats
    channel: Channel
    threshold: float
    expected_area_px: float
    area_tolerance: float
    max_elongation: float
    normalised: dict[str, list[np.ndarray]]
    found: dict[str, list[Localisation]]
    usable: dict[str, np.ndarray]


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


def _prepare(sets: dict[str, Dataset], polarity: Polarity, image_area_px: int,
             channel: Channel | Literal["auto"] = "max") -> _Prepared:
    """Intensity statistics, localisation channel and threshold, expected area and shape, and
    the localisation of every image. ``auto`` picks the channel in which the part stands out
    from its background best (Otsu's separability on the training images)."""
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
        if channel == "saturation":
            del candidates["max"]
    otsu = {c: _otsu([n for ns in imgs.values() for n in ns]) for c, imgs in candidates.items()}
    channel = max(otsu, key=lambda c: otsu[c][1])
    threshold = otsu[channel][0]
    located = candidates[channel]
    logger.info("localisation channel %s (separability %s)", channel,
                ", ".join(f"{c} {v[1]:.2f}" for c, v in otsu.items()))

    def find(name: str, area: float | None) -> list[Localisation]:
        return [localise(n, threshold, area, polarity=polarity) for n in located[name]]

    # The blob's area changes with the displacement (the camera looks at a tilt: nearer is
    # bigger), so the accepted window spans every training image's area, plus a margin.
    areas = np.array([loc.area_px for name in sets for loc in find(name, None) if loc.ok])
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
    max_elongation = max(shapes) * ELONGATION_MARGIN
    found = {name: [localise(n, threshold, expected_area, polarity=polarity,
                             area_tolerance=tolerance, max_elongation=max_elongation)
                    for n in located[name]]
             for name in sets}
    return _Prepared(intensity, channel, threshold, expected_area, tolerance, max_elongation,
                     located, found, {name: _usable(found[name], name) for name in sets})


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


def _summary(result: TrainedMLP) -> dict:
    return {"layers": list(result.model.layer_sizes), "seconds": result.seconds,
            "epochs": len(result.loss_curve), "final_loss": result.loss_curve[-1],
            "loss_curve": result.loss_curve}


def train_bundle(nn1_data: Dataset, nn2_data: Dataset, *, object_kind: str, kappa: int,
                 nominal_pose: Pose | Mapping[str, float], gabor: GaborConfig | None = None,
                 nn2_hidden: tuple[int, ...] = NN2_HIDDEN, seed: int = 0,
                 nn1_extra: Dataset | None = None, polarity: Polarity = "bright",
                 nn1_epochs: int = NN1_EPOCHS, nn2_epochs: int = NN2_EPOCHS,
                 nn2_weight_decay: float = NN2_WEIGHT_DECAY,
                 localisation_channel: Channel | Literal["auto"] = "auto") -> ModelBundle:
    """Train NN1 and NN2 from image datasets and pack everything into a ModelBundle.

    Steps: intensity statistics (mean of the per-image means and standard deviations of the
    max-channel images), Otsu threshold of the normalised images, localisation (largest blob)
    and the expected blob area (median over ``nn2_data``, where the object is always whole),
    then NN1 on (u, v) -> (dx, dy) and NN2 on Gabor features -> (sin, cos)(kappa dphi).
    Images where the object is not found are skipped with a warning and counted.

    Args:
        nn1_data: NN1's set (paper: 3x3x7 grid, a = 25 mm).
        nn2_data: NN2's set (paper: 3x3x7 grid, a = 5 mm, b = 180/kappa deg).
        object_kind: name of the taught object, stored in the bundle.
        kappa: the object's rotational symmetry count.
        nominal_pose: the taught pose.
        gabor: filter bank; None is the paper's 36 even filters.
        nn2_hidden: NN2's hidden layer sizes.
        seed: seeds both networks (NN2 uses seed + 1).
        nn1_extra: more (u, v) -> (dx, dy) samples for NN1, typically ``nn2_data``, so NN1 is
            precise near the nominal pose, where the positioning loop settles.
        polarity: "bright" if the object is brighter than the table after max(R, G, B).
        nn1_epochs: NN1's Rprop steps (at most).
        nn2_epochs: NN2's Rprop steps (at most).
        nn2_weight_decay: L2 penalty on NN2's weights (0 = none).
        localisation_channel: the image the object is binarised and localised in: "max"
            (normalised max(R, G, B), the paper's), "saturation" (unchanged by light and
            shadow for a coloured part on a grey table) or "auto" (whichever separates part
            and background better on the training images).

    Raises:
        TrainingError: an argument is invalid, a dataset has no images or the sets' image
            sizes differ, a training image is flat, the "object" covers most of the image
            (wrong polarity), or the object is found in fewer than half of a set's images.
    """
    start = time.perf_counter()
    gabor = gabor or GaborConfig()
    if not isinstance(object_kind, str) or not object_kind:
        raise TrainingError(f"object_kind: must be a non-empty string, got {object_kind!r}")
    if isinstance(kappa, bool) or not isinstance(kappa, int) or kappa < 1:
        raise TrainingError(f"kappa: must be a whole number >= 1, got {kappa!r}")
    pose = _pose(nominal_pose)
    sets = {"nn1": nn1_data, "nn2": nn2_data}
    if nn1_extra is not None:
        sets["nn1_extra"] = nn1_extra
    height, width = _check_sets(sets)
    prep = _prepare(sets, polarity, height * width, localisation_channel)
    prep_seconds = time.perf_counter() - start

    def centres(name: str) -> list[tuple[float, float]]:
        return [(prep.found[name][i].u_px, prep.found[name][i].v_px) for i in prep.usable[name]]

    nn1_names = [n for n in ("nn1", "nn1_extra") if n in sets]
    uv = np.concatenate([centres(n) for n in nn1_names])
    dxdy = np.concatenate([sets[n].labels[prep.usable[n], :2] for n in nn1_names])
    labels = np.concatenate([sets[n].labels[prep.usable[n]] for n in nn1_names])
    at_nominal = (np.hypot(labels[:, 0], labels[:, 1]) < NOMINAL_TOL_MM) \
        & (np.abs(labels[:, 2]) < NOMINAL_TOL_DEG)
    if not at_nominal.any():
        logger.warning("no training image at the taught pose: NN1's zero is not pinned")
    nominal_uv = tuple(float(v) for v in (uv[at_nominal] if at_nominal.any() else uv)
                       .mean(axis=0))
    nn1, nn1_zero_offset = _train_pinned(uv, dxdy, at_nominal, seed, nn1_epochs)
    # The full loop knows the rotation (NN2) before it moves: the silhouette's centre shifts a
    # little with the part's rotation in the image, which (u, v) alone cannot tell apart from
    # a translation, so the full loop's translation also sees sin/cos(kappa dphi).
    s_rot, c_rot = angles.encode(labels[:, 2], kappa)
    uvsc = np.column_stack([uv, s_rot, c_rot])
    nn1_rot, nn1_rot_zero_offset = _train_pinned(uvsc, dxdy, at_nominal, seed + 2, nn1_epochs)

    bank = GaborBank(gabor)
    features = np.stack([bank.features(extract_roi(prep.normalised["nn2"][i], u, v,
                                                   gabor.roi_px))
                         for i, (u, v) in zip(prep.usable["nn2"], centres("nn2"), strict=True)])
    s, c = angles.encode(nn2_data.labels[prep.usable["nn2"], 2], kappa)
    nn2 = train_mlp(features, np.stack([s, c], axis=1), tuple(nn2_hidden), seed=seed + 1,
                    epochs=nn2_epochs, weight_decay=nn2_weight_decay)

    training = {
        "seed": seed,
        "samples": {name: len(d) for name, d in sets.items()},
        "skipped": {name: len(sets[name]) - int(prep.usable[name].size) for name in sets},
        "preprocess_seconds": prep_seconds,
        "nn1": {**_summary(nn1), "zero_offset_mm": nn1_zero_offset},
        "nn1_rot": {**_summary(nn1_rot), "zero_offset_mm": nn1_rot_zero_offset},
        "nn2": _summary(nn2),
        "seconds": time.perf_counter() - start,
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    logger.info("trained %s bundle in %.2f s (NN1 loss %.2e, NN2 loss %.2e)", object_kind,
                training["seconds"], nn1.loss_curve[-1], nn2.loss_curve[-1])
    return ModelBundle(object_kind=object_kind, kappa=kappa, nominal_pose=pose.as_dict(),
                       frame_height_px=height, frame_width_px=width,
                       intensity=prep.intensity, threshold=prep.threshold, polarity=polarity,
                       expected_area_px=prep.expected_area_px, area_tolerance=prep.area_tolerance,
                       max_elongation=prep.max_elongation, channel=prep.channel,
                       nominal_uv_px=nominal_uv,
                       gabor=gabor, nn1=nn1.model, nn1_rot=nn1_rot.model, nn2=nn2.model,
                       training=training)


def _train_pinned(x: np.ndarray, y: np.ndarray, at_nominal: np.ndarray, seed: int,
                  epochs: int) -> tuple[TrainedMLP, list[float]]:
    """A translation network (NN1_HIDDEN, Rprop) whose output is pinned to zero at the
    samples taken at the taught pose: that is where the correction is zero by definition,
    and where the loop settles (a 3-hidden-unit fit over +/-25 mm otherwise misses it by a
    few tenths of a millimetre). Returns the network and the offset subtracted."""
    trained = train_mlp(x, y, NN1_HIDDEN, seed=seed, epochs=epochs)
    if not at_nominal.any():
        return trained, [0.0, 0.0]
    offset = trained.model(x[at_nominal]).mean(axis=0).tolist()
    return dataclasses.replace(trained, model=trained.model.shifted(offset)), offset
