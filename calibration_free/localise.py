"""Object localisation: binarise the normalised image and find the object's sub-pixel centre.

Two paths give the same answer on a clean image:

* histogram path (fast): the column and row sums of the binary mask. If each has a single run
  of non-zero bins, the bounding box is compact for the area, and the area matches the trained
  object, the mask holds one object and its centroid is read off the two sums.
* connected components (cluttered images): every blob is measured; the one whose area matches
  the trained object's is picked. No match is ``no_object``; several matches are
  ``ambiguous``. Neither is ever turned into a guess.

Either way the blob's centre is then refined along its outline (``subpixel_centre``): the
mask alone moves in whole rows and columns.

Coordinates are pixel-centre coordinates: pixel (row i, column j) covers u in [j - 0.5, j + 0.5].
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from calibration_free.errors import ImageError
from calibration_free.kernels import (
    colour_coverage_moments,
    coverage_moments,
    filled_blob,
    object_mask,
)
from drivers.core.errors import ConfigError

Status = Literal["ok", "no_object", "ambiguous"]
# A further test of a candidate blob (its pixels within its bounding box x, y, w, h): True if
# it may be the part (``FrontEnd`` checks its colour).
BlobCheck = Callable[[np.ndarray, tuple[int, int, int, int]], bool]
Polarity = Literal["bright", "dark"]
Method = Literal["histogram", "components"]

# Blobs smaller than this (pixels) are noise, never an object.
MIN_BLOB_PX = 12
# A blob matches the trained object when |area / expected - 1| <= this.
AREA_TOLERANCE = 0.35
# Without an expected area, the largest blob is ambiguous if the runner-up has this fraction
# of its area or more.
AMBIGUITY_RATIO = 0.8
# Of several blobs matching the part, the one nearest the taught image position is taken only
# if it is nearer than this fraction of the runner-up's distance; otherwise: ambiguous.
NEAREST_RATIO = 0.5
# Elongation (major / minor axis of the blob's second moments) accepted when no limit is given.
NO_ELONGATION_LIMIT = float("inf")
# The histogram path trusts a mask whose bounding box is at most this many times its area
# (a square at any rotation fills at least half of its box); others go to components.
MAX_BOX_TO_AREA = 2.5


@dataclass(frozen=True)
class Localisation:
    """Result of localising the object in one image.

    Attributes:
        status: "ok" (one object found), "no_object" (nothing matches the trained object) or
            "ambiguous" (several blobs match equally well).
        u_px: column of the object's centroid (sub-pixel); None unless status is "ok".
        v_px: row of the object's centroid (sub-pixel); None unless status is "ok".
        area_px: area of the object's blob in pixels; None unless status is "ok".
        reason: human-readable explanation ("" when ok via the histogram path).
        method: which path decided: "histogram" or "components".
        part_mask: a uint8 image of the frame's size, 255 on the part's blob and 0 elsewhere
            (what the features may look at: ``FrontEnd.feature_roi``); None unless ok.
        coverage: where the centre was read from the frame's colour (``colour_centre``),
            the part's share of each pixel around it: (x0, y0, weights), the float32 weights
            of the frame's pixels from column x0 and row y0 on (1 inside the outline, the
            share along it, 0 beyond); None otherwise.
    """

    status: Status
    u_px: float | None
    v_px: float | None
    area_px: float | None
    reason: str
    method: Method
    part_mask: np.ndarray | None = field(default=None, repr=False, compare=False)
    coverage: tuple[int, int, np.ndarray] | None = field(default=None, repr=False,
                                                          compare=False)

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def binarise(normalised: np.ndarray, threshold: float, polarity: Polarity = "bright") \
        -> np.ndarray:
    """Object mask of a normalised image: float32 1.0 where the object is, 0.0 elsewhere.

    Args:
        normalised: HxW float32 image after ``preprocess.normalise``.
        threshold: grey level (normalised units) separating object and background.
        polarity: "bright" (object above the threshold) or "dark" (object below it).

    Raises:
        ImageError: the image is not a non-empty 2-D float32 array, or polarity is unknown.
    """
    _check_normalised(normalised)
    kind = cv2.THRESH_BINARY if _check_polarity(polarity) else cv2.THRESH_BINARY_INV
    return cv2.threshold(normalised, threshold, 1.0, kind)[1]


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold of a set of grey values: the level maximising between-class variance.

    Args:
        values: any array of finite grey values (e.g. all pixels of the normalised training
            images).
        bins: histogram resolution.

    Returns:
        The threshold, in the units of ``values``.

    Raises:
        ImageError: non-finite values, or fewer than two distinct values.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0 or not np.isfinite(v).all():
        raise ImageError("cannot choose a threshold: no values, or NaN/infinite values")
    lo, hi = float(v.min()), float(v.max())
    if not hi > lo:
        raise ImageError("cannot choose a threshold: the images have a single grey level")
    hist, edges = np.histogram(v, bins=bins, range=(lo, hi))
    centres = 0.5 * (edges[:-1] + edges[1:])
    # class 0 = bins 0..k, class 1 = bins k+1..; the threshold is the edge between them
    w0 = np.cumsum(hist)[:-1].astype(np.float64)
    w1 = v.size - w0
    s0 = np.cumsum(hist * centres)[:-1]
    s1 = float((hist * centres).sum()) - s0
    valid = (w0 > 0) & (w1 > 0)
    m0 = np.divide(s0, w0, out=np.zeros_like(s0), where=valid)
    m1 = np.divide(s1, w1, out=np.zeros_like(s1), where=valid)
    between = np.where(valid, w0 * w1 * (m0 - m1) ** 2, -1.0)
    return float(edges[1 + int(np.argmax(between))])


def _check_normalised(normalised: np.ndarray) -> None:
    if not isinstance(normalised, np.ndarray) or normalised.dtype != np.float32 \
            or normalised.ndim != 2 or normalised.size == 0:
        raise ImageError(f"normalised image: expected HxW float32, got "
                         f"{getattr(normalised, 'shape', None)} "
                         f"{getattr(normalised, 'dtype', type(normalised))}")


def _check_polarity(polarity: Polarity) -> bool:
    """True for a bright part."""
    if polarity not in ("bright", "dark"):
        raise ImageError(f"polarity: must be bright or dark, got {polarity!r}")
    return polarity == "bright"


def subpixel_centre(normalised: np.ndarray, polarity: Polarity, u_px: float, v_px: float,
                    area_px: float, part_mask: np.ndarray,
                    box: tuple[int, int, int, int] | None = None) -> tuple[float, float]:
    """The blob's centre with its outline weighted by how much of each edge pixel it covers.

    The binary mask's centroid moves only when an edge crosses a pixel's centre, in whole
    rows or columns along a straight edge: a part whose edges lie along the pixel grid
    steps by a third of a pixel at once and stays put in between. Around the blob found at
    (``u_px``, ``v_px``), its pixels a pixel inside the outline count fully, and the band from
    there to two pixels outside counts by the fraction of the way from the background's level
    (the ring three pixels out, clear of the lens blur) to the part's (the blob's inside):
    the part's coverage of the pixel on a sensor that integrates over the pixel's area.

    ``part_mask`` is the full-frame uint8 image that is 255 on the part's blob and 0
    elsewhere (``Localisation.part_mask``).
    ``box``: the blob's bounding box (x, y, w, h), for a blob longer than the square around
    its centre (``_blob_window``).
    Returns the binary centre unchanged when the window holds no blob or no contrast.
    """
    x0, x1, y0, y1 = _blob_window(normalised.shape, u_px, v_px, area_px, box)
    window = normalised[y0:y1, x0:x1]
    blob = part_mask[y0:y1, x0:x1]
    band = cv2.dilate(blob, _KERNEL_5)
    m00, m10, m01 = coverage_moments(window, cv2.erode(blob, _KERNEL_3), band,
                                     cv2.subtract(cv2.dilate(blob, _KERNEL_7), band),
                                     polarity == "bright")
    if not m00 > 0:
        return u_px, v_px
    return x0 + m10 / m00, y0 + m01 / m00


def _blob_window(shape: tuple[int, ...], u_px: float, v_px: float, area_px: float,
                 box: tuple[int, int, int, int] | None = None) -> tuple[int, int, int, int]:
    """Columns x0..x1 - 1 and rows y0..y1 - 1 of the frame around a blob of ``area_px``
    centred near (``u_px``, ``v_px``): the blob, its band and its ring, within the frame.
    The square around the centre holds a compact blob at any turn; an elongated one (a
    screw, a ledge) reaches beyond it, so the window also spans the blob's bounding
    ``box`` (x, y, w, h) and the ring around it."""
    height, width = shape[:2]
    half = int(math.ceil(0.75 * math.sqrt(area_px))) + _RING_PX
    cu, cv_ = int(round(u_px)), int(round(v_px))
    x0, x1, y0, y1 = cu - half, cu + half + 1, cv_ - half, cv_ + half + 1
    if box is not None:
        bx, by, bw, bh = box
        x0, x1 = min(x0, bx - _RING_PX), max(x1, bx + bw + _RING_PX)
        y0, y1 = min(y0, by - _RING_PX), max(y1, by + bh + _RING_PX)
    return max(x0, 0), min(x1, width), max(y0, 0), min(y1, height)


_KERNEL_3 = np.ones((3, 3), np.uint8)
# The widest ring either centre reads beyond the blob (``subpixel_centre``'s: three pixels).
_RING_PX = 3
# One dilation with these is two and three with the 3x3 square.
_KERNEL_5 = np.ones((5, 5), np.uint8)
_KERNEL_7 = np.ones((7, 7), np.uint8)

# The output gamma of an sRGB-like camera, the colour edge's default (``ColourEdge``;
# ``perception.camera_gamma``).
DEFAULT_CAMERA_GAMMA = 2.2

# The background's colour (the mean around the blob) must differ from the part's by this
# much across the part's colour (linear light, 0..1) for ``colour_centre`` to read a pixel's
# share of it: a part of the table's colour has none, and the grey-level coverage is read
# instead.
MIN_COLOUR_CONTRAST = 0.002
# Where the table just around one edge pixel has less than this (a cast shadow so dark that
# its colour cannot be told from the part's), that pixel reads the part's own share
# (``kernels.colour_coverage_moments``) instead of the whole frame falling back to grey levels.
LOCAL_COLOUR_CONTRAST = 0.002


@dataclass(frozen=True)
class ColourEdge:
    """How the part's edge is read from the frame's colour (``colour_centre``).

    Attributes:
        gamma: the camera's output gamma: a delivered grey level g is linear light
            (g / 255) ** gamma, in which a pixel's colour is the mix of what it covers.
        fill_holes: the centre is that of the part's outer outline: the blob's holes (a
            ledge's or a nut's through holes) count as part; False: their rims are read as
            edges too (model files written before it).
    """

    gamma: float
    fill_holes: bool = False
    linear: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.gamma, bool) or not isinstance(self.gamma, (int, float)) \
                or not 1.0 <= self.gamma <= 3.0:
            raise ConfigError(f"camera gamma must be a number in 1..3, got {self.gamma!r}")
        if not isinstance(self.fill_holes, bool):
            raise ConfigError(f"fill_holes must be true or false, got {self.fill_holes!r}")
        table = (np.arange(256, dtype=np.float64) / 255.0) ** float(self.gamma)
        object.__setattr__(self, "linear", table)


def colour_centre(image: np.ndarray, edge: ColourEdge, u_px: float, v_px: float,
                  area_px: float, part_mask: np.ndarray,
                  box: tuple[int, int, int, int] | None = None
                  ) -> tuple[float, float, tuple[int, int, np.ndarray]] | None:
    """The blob's centre with each edge pixel weighted by the part's share of its colour,
    and those weights (``Localisation.coverage``).

    A pixel on the part's outline holds part and table mixed by how much of it each covers,
    in linear light. The grey-level coverage of ``subpixel_centre`` reads that mix against
    one level for the part and one for the table; under a low side lamp the part's rounded
    edges are lit on one side and dark on the other, so the same outline reads as more part on
    the lit side and less on the dark one, and its centre moves by a quarter to half a pixel
    towards the lamp. The table's share does not depend on how the part's face is lit: with the
    part's colour direction c (its pixels just inside) and the table's colour b (its pixels
    just outside), the pixel p = alpha * c + beta * b, and the part covers 1 - beta. Beyond
    the blob, where a pixel is mostly table, a cast shadow whose edge runs along the part's
    can darken the table next to the part below what the ring shows; there the part's own
    share (alpha over the part's brightness just inside) is averaged in
    (``kernels.colour_coverage_moments``); where the table just around a pixel is too dark
    for its colour to be told from the part's (``LOCAL_COLOUR_CONTRAST``: the part's own
    black cast shadow), the pixel's light is the part's alone and its share is read from
    that. The band read runs from a pixel inside the
    blob's outline to one outside it (the blob's threshold cuts the edge's ramp near its
    middle).

    With ``edge.fill_holes`` the blob's holes count as part, and only its outer outline is
    read. What a through hole shows (the table beneath, the hole's far wall) depends on
    where the part lies in view and on how the lamp falls into it. At the taught pose, over
    12 headings of a ledge under a side lamp, its three holes moved the nets' reading along
    the bar by 0.12 mm on average between good and poor light and by 0.07 mm RMS from
    heading to heading (0.02 and 0.06 mm with the holes filled).

    ``box``: the blob's bounding box (x, y, w, h), as for ``subpixel_centre``.

    Returns None where this cannot be read (no background pixels around the blob, or a
    background of the part's own colour): the caller takes ``subpixel_centre``.
    """
    x0, x1, y0, y1 = _blob_window(part_mask.shape, u_px, v_px, area_px, box)
    blob = part_mask[y0:y1, x0:x1]
    if edge.fill_holes:
        blob = filled_blob(blob)
    band = cv2.dilate(blob, _KERNEL_3)
    weights = np.empty(blob.shape, np.float32)
    m00, m10, m01 = colour_coverage_moments(
        image[y0:y1, x0:x1], blob, cv2.erode(blob, _KERNEL_3), band,
        cv2.subtract(cv2.dilate(blob, _KERNEL_5), band), edge.linear, MIN_COLOUR_CONTRAST,
        LOCAL_COLOUR_CONTRAST, weights)
    if not m00 > 0:
        return None
    return x0 + m10 / m00, y0 + m01 / m00, (x0, y0, weights)


def _centre(normalised: np.ndarray, polarity: Polarity, u_px: float, v_px: float,
            area_px: float, part_mask: np.ndarray, image: np.ndarray | None,
            edge: ColourEdge | None, box: tuple[int, int, int, int]
            ) -> tuple[float, float, tuple[int, int, np.ndarray] | None]:
    """``colour_centre`` where the frame and its ``edge`` are given and it reads, else
    ``subpixel_centre`` (and no coverage); ``box``: the blob's bounding box (x, y, w, h)."""
    if image is not None and edge is not None:
        found = colour_centre(image, edge, u_px, v_px, area_px, part_mask, box)
        if found is not None:
            return found
    return (*subpixel_centre(normalised, polarity, u_px, v_px, area_px, part_mask, box),
            None)


def localise(normalised: np.ndarray, threshold: float, expected_area_px: float | None = None,
             *, polarity: Polarity = "bright", area_tolerance: float = AREA_TOLERANCE,
             min_blob_px: int = MIN_BLOB_PX,
             max_elongation: float = NO_ELONGATION_LIMIT,
             expected_uv: tuple[float, float] | None = None,
             blob_check: BlobCheck | None = None, image: np.ndarray | None = None,
             edge: ColourEdge | None = None) -> Localisation:
    """Find the object's centre in a normalised image: the blob of the part's area and shape
    in the binarised image (its histograms, or its connected components), its centre refined
    to sub-pixel by the grey levels along its outline (``subpixel_centre``).

    Args:
        normalised: HxW float32 image after ``preprocess.normalise``.
        threshold: binarisation level in normalised grey units.
        expected_area_px: the trained object's blob area; None picks the largest blob
            (used while training, before the area is known).
        polarity: "bright" or "dark": which side of the threshold the object is on.
        area_tolerance: a blob matches when |area / expected - 1| <= this.
        min_blob_px: blobs below this area are ignored as noise.
        max_elongation: a blob matches only if its ``elongation`` is at most this (the
            trained object's shape: a bar does not pass for a cube of the same area).
        expected_uv: where the part appeared at the taught pose. When several blobs match,
            the one nearest this point is taken if it is clearly nearest (closer than
            ``NEAREST_RATIO`` times the runner-up); otherwise the result is ambiguous.
        blob_check: where several blobs of the part's area and shape are measured (the
            components path), those this accepts are preferred; a lone candidate is taken
            whatever it says.
        image, edge: the HxWx3 uint8 RGB frame ``normalised`` was made from, and how its
            colour is read: with both, the centre is refined by ``colour_centre``.

    Returns:
        The Localisation; see its docstring for the three statuses.

    Raises:
        ImageError: the image is not HxW float32 or polarity is unknown.
        ConfigError: expected_area_px is not > 0.
    """
    if expected_area_px is not None and not expected_area_px > 0:
        raise ConfigError(f"expected_area_px: must be > 0, got {expected_area_px!r}")
    _check_normalised(normalised)
    mask, moments, box = object_mask(np.ascontiguousarray(normalised), np.float32(threshold),
                                     _check_polarity(polarity))
    area = float(moments[0])
    if area < min_blob_px:
        return Localisation("no_object", None, None, None,
                            f"only {area:.0f} px beyond the threshold", "histogram")
    matches = expected_area_px is None or \
        abs(area / expected_area_px - 1.0) <= area_tolerance
    if matches:
        # One blob: the mask's columns and rows each hold a single run, the box is compact
        # for the area, and the shape is the part's.
        x, width, y, height = box.tolist()
        _, s_u, s_v, s_uu, s_vv, s_uv = moments.tolist()
        u, v = s_u / area, s_v / area
        if width and height and width * height <= MAX_BOX_TO_AREA * area and (
                max_elongation == NO_ELONGATION_LIMIT
                or _elongation(s_uu / area - u * u, s_vv / area - v * v,
                               s_uv / area - u * v) <= max_elongation):
            u, v, coverage = _centre(normalised, polarity, u, v, area, mask, image, edge,
                                     (x, y, width, height))
            return Localisation("ok", u, v, area, "", "histogram", mask, coverage)
    loc, labels, stats, label = _by_components(mask, expected_area_px, area_tolerance,
                                               min_blob_px, max_elongation, expected_uv,
                                               blob_check)
    if loc.status != "ok":
        return loc
    part_mask = cv2.compare(labels, label, cv2.CMP_EQ)
    u, v, coverage = _centre(normalised, polarity, loc.u_px, loc.v_px, loc.area_px, part_mask,
                             image, edge, tuple(int(v) for v in stats[label, :4]))
    return dataclasses.replace(loc, u_px=u, v_px=v, part_mask=part_mask, coverage=coverage)


def elongation(mask: np.ndarray) -> float:
    """Major over minor axis of a binary blob (from its second central moments): 1 for a disc
    or a square, about 4 for a 4:1 bar. The mask holds 0 and one other value (1 or 255: the
    moments scale with it, their ratios do not). Pass the blob's bounding box only: it is
    cheap there."""
    mo = cv2.moments(mask)
    area = mo["m00"]
    if area <= 0:
        return NO_ELONGATION_LIMIT
    return _elongation(mo["mu20"] / area, mo["mu02"] / area, mo["mu11"] / area)


def _elongation(mu20: float, mu02: float, mu11: float) -> float:
    """``elongation`` from the blob's central second moments over its area."""
    half_sum = (mu20 + mu02) / 2.0
    spread = float(np.hypot((mu20 - mu02) / 2.0, mu11))
    minor = half_sum - spread
    return float(np.sqrt((half_sum + spread) / minor)) if minor > 1e-9 else NO_ELONGATION_LIMIT


def _by_components(mask: np.ndarray, expected_area_px: float | None, area_tolerance: float,
                   min_blob_px: int, max_elongation: float,
                   expected_uv: tuple[float, float] | None,
                   blob_check: BlobCheck | None = None) \
        -> tuple[Localisation, np.ndarray, np.ndarray, int]:
    """The blob of the part among the mask's connected components (``localise``'s second
    path), with the label image, the components' statistics (``stats[label, :4]``: a blob's
    box x, y, w, h) and the part's label (its binary centre, unrefined)."""
    n, labels, stats, centroids = cv2.connectedComponentsWithStatsWithAlgorithm(
        mask, 8, cv2.CV_32S, cv2.CCL_BBDT)
    areas = stats[1:n, cv2.CC_STAT_AREA].astype(np.float64)
    blobs = np.flatnonzero(areas >= min_blob_px)
    if blobs.size == 0:
        return (Localisation("no_object", None, None, None,
                             f"no blob of {min_blob_px} px or more", "components"), labels,
                stats, 0)
    if expected_area_px is None:
        order = blobs[np.argsort(areas[blobs])[::-1]]
        best = int(order[0])
        if order.size > 1 and areas[order[1]] >= AMBIGUITY_RATIO * areas[best]:
            return (Localisation(
                "ambiguous", None, None, None,
                f"the two largest blobs have similar areas ({areas[best]:.0f} and "
                f"{areas[order[1]]:.0f} px)", "components"), labels, stats, 0)
        picked = best
    else:
        close = blobs[np.abs(areas[blobs] / expected_area_px - 1.0) <= area_tolerance]
        if close.size and max_elongation != NO_ELONGATION_LIMIT:
            shaped = [i for i in close
                      if _blob_elongation(labels, stats, int(i) + 1) <= max_elongation]
            if not shaped:
                return (Localisation(
                    "no_object", None, None, None,
                    f"{close.size} blob(s) of the expected area, none of the trained shape "
                    f"(elongation above {max_elongation:.2f})", "components"), labels, stats, 0)
            close = np.array(shaped, dtype=close.dtype)
        if close.size == 0:
            return (Localisation(
                "no_object", None, None, None,
                f"no blob within {area_tolerance:.0%} of the expected {expected_area_px:.0f} px"
                f" (largest: {areas[blobs].max():.0f} px of {blobs.size} blobs)", "components"),
                labels, stats, 0)
        if blob_check is not None and close.size > 1:
            # Several candidates: those the check accepts (the part's colour) go first; with
            # none accepted, all stay and the nearest rule below decides.
            checked = [i for i in close if _blob_passes(labels, stats, int(i) + 1, blob_check)]
            if checked:
                close = np.array(checked, dtype=close.dtype)
        if close.size > 1:
            nearest = _clearly_nearest(centroids[close + 1], expected_uv)
            if nearest is None:
                found = ", ".join(f"{a:.0f}" for a in areas[close])
                return (Localisation(
                    "ambiguous", None, None, None,
                    f"{close.size} blobs match the expected {expected_area_px:.0f} px "
                    f"({found} px) and none is clearly nearest the taught position",
                    "components"), labels, stats, 0)
            close = close[nearest:nearest + 1]
        picked = int(close[0])
    u, v = centroids[picked + 1]
    others = blobs.size - 1
    return (Localisation("ok", float(u), float(v), float(areas[picked]),
                         f"picked among {others + 1} blobs" if others else "", "components"),
            labels, stats, picked + 1)


def _blob_passes(labels: np.ndarray, stats: np.ndarray, label: int, check: BlobCheck) -> bool:
    x, y, w, h = (int(v) for v in stats[label, :4])
    return check(labels[y:y + h, x:x + w] == label, (x, y, w, h))


def _blob_elongation(labels: np.ndarray, stats: np.ndarray, label: int) -> float:
    x, y, w, h = (int(v) for v in stats[label, :4])
    return elongation((labels[y:y + h, x:x + w] == label).astype(np.uint8))


def _clearly_nearest(centres: np.ndarray, expected_uv: tuple[float, float] | None) -> int | None:
    """Index of the centre nearest ``expected_uv`` if it is clearly nearest, else None."""
    if expected_uv is None:
        return None
    d = np.hypot(centres[:, 0] - expected_uv[0], centres[:, 1] - expected_uv[1])
    order = np.argsort(d)
    return int(order[0]) if d[order[0]] < NEAREST_RATIO * d[order[1]] else None
