"""The part's colour against its table: a localisation channel learned at the taught pose.

Each frame's colours are read relative to the frame's own table: the log of every channel
over the frame's median of that channel (the table fills most of the frame). A change of the
light's brightness, of its colour temperature or of the exposure multiplies each channel by a
factor; through any output gamma it is still a factor per channel, and the ratio to the
table's median takes it off. The part's colour is then a point cloud in that space (its faces
lit differently spread it along the brightness axis) that stays where training saw it.

``learn_part_colour`` finds the part in the frames taken at the taught pose (the blob that
stands out from the table's colours where teach-in put it) and fits a Gaussian to its colours
and up to four to the rest of the frame (the table's texture and shadows, the gripper's
fingers). ``PartColour.image`` is each pixel's log likelihood ratio, the part's Gaussian
against the likeliest of the table's, through a logistic: 255 where the part's colour is far
likelier, 127.5 where both are alike, 0 where the table's is. A card or a part of another
colour reads low too.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from calibration_free.errors import ImageError
from calibration_free.kernels import colour_likeness
from calibration_free.preprocess import check_rgb
from drivers.core.errors import ConfigError

# The frame is smoothed by a Gaussian of this many pixels first: a dark frame's noise, Bayer
# and JPEG artefacts differ from pixel to pixel, the part's colour does not.
BLUR_PX = 1.0
# Added to every grey level before its log: a dark pixel's ratio is then not camera noise over
# almost nothing.
LOG_OFFSET = 4.0
# The frame's table colour is the median of every STRIDE-th pixel along each axis.
STRIDE = 4
# The channel's logistic is this many nats of the likelihood ratio wide.
SCALE = 2.0
# The brightness axis's standard deviation (log units) added to every Gaussian's spread: a
# face or a patch of table lit otherwise than in training (another lamp direction, a shadow)
# changes in brightness, not in colour.
BRIGHTNESS_SPREAD = 0.35
# Added to every Gaussian's variance on every axis (log units squared): the camera's noise,
# Bayer and JPEG colour artefacts the taught frames may not show.
NOISE_VARIANCE = 0.02 ** 2
# The table's colours: the pixels nearest the frame's median, this share of them.
TABLE_SHARE = 0.7
# The part at the taught pose lies between the fingers, which the hand camera looks at: a blob
# with at least this many pixels, at most this share of the frame, clear of the frame's
# border, its centre within CENTRE_RADIUS times the frame's smaller side of the frame's middle.
MIN_PART_PX = 50
MAX_PART_SHARE = 0.5
CENTRE_RADIUS = 0.3
# The frames at the taught pose show the part in one place: a blob counts where its centre is
# within AGREE_PX of the blobs' median centre and its area within AGREE_AREA of their median.
AGREE_PX = 3.0
AGREE_AREA = 0.25
# The part's colour is learned from its blob eroded by this many pixels (edge pixels mix the
# part's colour with the table's), the table's from the pixels this far from the blob or more.
EDGE_PX = 1
TABLE_GAP_PX = 3
# The table's colours (its texture, shadows, the gripper's fingers) as at most this many
# Gaussians (k-means clusters, KMEANS_ATTEMPTS tries).
MAX_TABLE_COLOURS = 4
KMEANS_ATTEMPTS = 2

_LOG = np.log(np.arange(256, dtype=np.float32) + np.float32(LOG_OFFSET)).astype(np.float32)
_GREY = np.full(3, 1.0 / math.sqrt(3.0))
# Two axes orthogonal to the brightness axis (1, 1, 1): the colour without its brightness.
_CHROMA = np.array([[1.0, -1.0, 0.0], [1.0, 1.0, -2.0]]).T / np.array([math.sqrt(2.0),
                                                                       math.sqrt(6.0)])


def smoothed(image: np.ndarray) -> np.ndarray:
    """The frame through a Gaussian of ``BLUR_PX`` (the colours the channel compares).

    Raises:
        ImageError: the image is not HxWx3 uint8.
    """
    check_rgb(image)
    return cv2.GaussianBlur(image, (0, 0), BLUR_PX)


def _table_log(image: np.ndarray) -> np.ndarray:
    """The log of the frame's median colour (float32, 3)."""
    table = np.median(image[::STRIDE, ::STRIDE].reshape(-1, 3), axis=0)
    return np.log(table.astype(np.float32) + np.float32(LOG_OFFSET)).astype(np.float32)


def relative_log(image: np.ndarray) -> np.ndarray:
    """Each pixel's log colour over the frame's median colour (HxWx3 float32), of the
    ``smoothed`` frame.

    Raises:
        ImageError: the image is not HxWx3 uint8.
    """
    image = smoothed(image)
    return _LOG[image] - _table_log(image)


def _gaussian(values: np.ndarray, extra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and inverse covariance of N x 3 values, ``extra`` added to the covariance."""
    covariance = np.cov(values.T) + extra
    icov = np.linalg.inv(covariance)
    return values.mean(axis=0), 0.5 * (icov + icov.T)


def _numbers(values: Any, count: int, name: str, what: str) -> np.ndarray:
    """``values`` as ``count`` finite float64 numbers, or ConfigError naming ``name``."""
    try:
        numbers = np.array([float(v) for v in values], np.float64)
    except (TypeError, ValueError):
        numbers = np.zeros(0)
    if numbers.size != count or not np.isfinite(numbers).all():
        raise ConfigError(f"part colour: {name} must be {what} finite numbers")
    return numbers


def _matrix(values: Any, name: str) -> np.ndarray:
    matrix = _numbers(values, 9, name, "nine").reshape(3, 3)
    if not np.allclose(matrix, matrix.T) or np.linalg.eigvalsh(matrix).min() <= 0:
        raise ConfigError(f"part colour: {name} must be symmetric and positive definite")
    return matrix


def _vector(values: Any, name: str) -> np.ndarray:
    return _numbers(values, 3, name, "three")


@dataclass(frozen=True)
class PartColour:
    """The part's colours and the table's, relative to the table (``relative_log``), as
    learned at the taught pose: a Gaussian each.

    Attributes:
        part_mean, table_mean: the mean relative log colour (R, G, B).
        part_inverse_covariance, table_inverse_covariance: the inverses of their
            covariances (3x3, row by row); the part's with ``BRIGHTNESS_SPREAD`` and
            ``NOISE_VARIANCE`` added, the table's with ``NOISE_VARIANCE``.
    """

    part: tuple[tuple[float, ...], tuple[float, ...], float]
    table: tuple[tuple[tuple[float, ...], tuple[float, ...], float], ...]

    def __post_init__(self) -> None:
        try:
            table = tuple(self.table)
        except TypeError:
            table = ()
        if not 1 <= len(table) <= MAX_TABLE_COLOURS:
            raise ConfigError(f"part colour: the table needs 1 to {MAX_TABLE_COLOURS} colours")
        components = [_component(c, f"table colour {i + 1}") for i, c in enumerate(table)]
        part = _component(self.part, "part")
        object.__setattr__(self, "part", _as_tuple(part))
        object.__setattr__(self, "table", tuple(_as_tuple(c) for c in components))
        object.__setattr__(self, "_part", _compiled(part))
        object.__setattr__(self, "_table", [_compiled(c) for c in components])
        compiled = [self._part, *self._table]
        object.__setattr__(self, "_means", np.stack([c[0] for c in compiled]))
        object.__setattr__(self, "_icovs", np.stack([c[1] for c in compiled]))
        object.__setattr__(self, "_consts", np.array([c[2] for c in compiled], np.float32))

    def log_ratio(self, image: np.ndarray) -> np.ndarray:
        """Each pixel's log likelihood ratio, the part's colour against the likeliest of the
        table's (HxW float32; > 0 where the part's is likelier)."""
        values = relative_log(image)
        part = _log_likelihood(values, self._part)
        table = _log_likelihood(values, self._table[0])
        for component in self._table[1:]:
            np.maximum(table, _log_likelihood(values, component), out=table)
        return part - table

    def image(self, image: np.ndarray) -> np.ndarray:
        """The channel the part is localised in: 255 where the part's colour is far likelier
        than the table's, 127.5 where both are alike, 0 where the table's is far likelier
        (HxW float32; the log likelihood ratio through a logistic, ``SCALE`` nats wide)."""
        image = smoothed(image)
        return colour_likeness(image, _LOG, _table_log(image), self._means, self._icovs,
                               self._consts, np.float32(1.0 / SCALE))

    def to_info(self) -> dict[str, Any]:
        """JSON: ``part`` and ``table`` (a list), each colour as ``mean``,
        ``inverse_covariance`` (row by row) and ``weight``."""
        def info(c):
            return {"mean": list(c[0]), "inverse_covariance": list(c[1]), "weight": c[2]}
        return {"part": info(self.part), "table": [info(c) for c in self.table]}

    @classmethod
    def from_info(cls, info: Mapping[str, Any]) -> PartColour:
        def component(c):
            return (c["mean"], c["inverse_covariance"], c["weight"])
        return cls(component(info["part"]), tuple(component(c) for c in info["table"]))


def _component(value: Any, name: str) -> tuple[np.ndarray, np.ndarray, float]:
    try:
        mean, icov, weight = value
        weight = float(weight)
    except (TypeError, ValueError):
        raise ConfigError(f"part colour: {name} needs a mean, an inverse covariance and a "
                          f"weight") from None
    if not 0.0 < weight <= 1.0:
        raise ConfigError(f"part colour: {name}: weight must be in (0, 1], got {weight!r}")
    return _vector(mean, f"{name} mean"), _matrix(icov, f"{name} inverse covariance"), weight


def _as_tuple(c: tuple[np.ndarray, np.ndarray, float]) -> tuple:
    return (tuple(float(v) for v in c[0]), tuple(float(v) for v in c[1].ravel()), c[2])


def _compiled(c: tuple[np.ndarray, np.ndarray, float]) -> tuple:
    """Mean, inverse covariance (float32) and the log density's constant: log weight
    + log |inverse covariance| / 2."""
    constant = math.log(c[2]) + 0.5 * np.linalg.slogdet(c[1])[1]
    return c[0].astype(np.float32), c[1].astype(np.float32), np.float32(constant)


def _log_likelihood(values: np.ndarray, c: tuple) -> np.ndarray:
    diff = values - c[0]
    return c[2] - np.float32(0.5) * np.einsum("hwi,ij,hwj->hw", diff, c[1], diff)


def taught_blob(mask: np.ndarray) -> np.ndarray | None:
    """The blob of a uint8 mask where teach-in put the part (``MIN_PART_PX``,
    ``MAX_PART_SHARE``, ``CENTRE_RADIUS``), the nearest the frame's middle; None if there is
    none."""
    height, width = mask.shape
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    best, best_k = CENTRE_RADIUS * min(height, width), 0
    for k in range(1, count):
        x, y, w, h, area = stats[k]
        if area < MIN_PART_PX or area > MAX_PART_SHARE * height * width:
            continue
        if x == 0 or y == 0 or x + w == width or y + h == height:
            continue
        distance = float(np.hypot(*(centroids[k] - centre)))
        if distance <= best:
            best, best_k = distance, k
    return labels == best_k if best_k else None


def _outliers(values: np.ndarray) -> np.ndarray:
    """Each pixel's Mahalanobis distance from the table's colours (``TABLE_SHARE`` of the
    pixels nearest the median), for N x H x W x K values."""
    flat = values.reshape(-1, values.shape[-1]).astype(np.float64)
    norm = np.linalg.norm(flat, axis=1)
    table = flat[norm <= np.quantile(norm, TABLE_SHARE)]
    centre = table.mean(axis=0)
    icov = np.linalg.inv(np.cov(table.T).reshape(flat.shape[1], flat.shape[1])
                         + np.eye(flat.shape[1]) * NOISE_VARIANCE)
    diff = flat - centre
    return np.sqrt(np.einsum("ni,ij,nj->n", diff, icov, diff)).reshape(values.shape[:-1])


def _otsu(values: np.ndarray) -> float:
    lo, hi = float(values.min()), float(values.max())
    if not hi > lo:
        return hi
    scaled = ((values - lo) * (255.0 / (hi - lo))).astype(np.uint8)
    level = cv2.threshold(scaled.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)[0]
    return lo + level * (hi - lo) / 255.0


def part_masks(images: Sequence[np.ndarray]) -> list[np.ndarray | None]:
    """The part's blob in each frame taken at the taught pose (None where it is not found):
    the pixels whose colour stands out from the table's (Otsu's threshold on the distance
    from them), first by colour alone (a shadow is the table's colour, darker), then, where
    that finds the part in fewer than half of the frames, by colour and brightness."""
    logs = np.stack([relative_log(im) for im in images])
    found: list[np.ndarray | None] = []
    for values in (logs @ _CHROMA, logs):
        distance = _outliers(values)
        level = _otsu(distance[:, ::2, ::2].ravel())
        found = _agreeing([taught_blob((d > level).astype(np.uint8)) for d in distance])
        if sum(m is not None for m in found) * 2 > len(found):
            break
    return found


def _agreeing(blobs: list[np.ndarray | None]) -> list[np.ndarray | None]:
    """The blobs that agree with the others' median centre (within ``AGREE_PX``) and area
    (within ``AGREE_AREA``): the frames show the part at one pose, a blob elsewhere or of
    another size is something else (noise, the table's grain)."""
    shapes = [(np.argwhere(b).mean(axis=0), float(b.sum())) if b is not None else None
              for b in blobs]
    known = [s for s in shapes if s is not None]
    if not known:
        return blobs
    centre = np.median([c for c, _ in known], axis=0)
    area = float(np.median([a for _, a in known]))
    return [b if s is not None and np.hypot(*(s[0] - centre)) <= AGREE_PX
            and abs(s[1] / area - 1.0) <= AGREE_AREA else None
            for b, s in zip(blobs, shapes, strict=True)]


def learn_part_colour(images: Sequence[np.ndarray]) -> PartColour | None:
    """The part's colour from the frames taken at the taught pose (``part_masks``); None
    where the part stands out in fewer than half of them.

    Raises:
        ImageError: no frames, or a frame that is not HxWx3 uint8.
    """
    if not images:
        raise ImageError("part colour: no frames at the taught pose")
    masks = part_masks(images)
    if sum(m is not None for m in masks) * 2 <= len(masks):
        return None
    kernel = np.ones((2 * EDGE_PX + 1, 2 * EDGE_PX + 1), np.uint8)
    around = np.ones((2 * TABLE_GAP_PX + 1, 2 * TABLE_GAP_PX + 1), np.uint8)
    part, table = [], []
    for im, mask in zip(images, masks, strict=True):
        if mask is None:
            continue
        values = relative_log(im)
        blob = mask.astype(np.uint8)
        inner = cv2.erode(blob, kernel).astype(bool)
        part.append(values[inner if inner.sum() >= MIN_PART_PX // 2 else mask])
        table.append(values[~cv2.dilate(blob, around).astype(bool)])
    spread = np.eye(3) * NOISE_VARIANCE + BRIGHTNESS_SPREAD ** 2 * np.outer(_GREY, _GREY)
    part_mean, part_icov = _gaussian(np.concatenate(part).astype(np.float64), spread)
    table_values = np.concatenate(table).astype(np.float32)
    _, labels, _ = cv2.kmeans(table_values, MAX_TABLE_COLOURS, None,
                              (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 1e-3),
                              KMEANS_ATTEMPTS, cv2.KMEANS_PP_CENTERS)
    components = []
    for k in range(MAX_TABLE_COLOURS):
        members = table_values[labels.ravel() == k].astype(np.float64)
        if len(members) >= MIN_PART_PX:
            mean, icov = _gaussian(members, spread)
            components.append((tuple(mean), tuple(icov.ravel()), len(members) / len(table_values)))
    return PartColour((tuple(part_mean), tuple(part_icov.ravel()), 1.0), tuple(components))
