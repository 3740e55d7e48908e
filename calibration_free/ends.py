"""A bar whose one end is hidden: where its centre is.

Something lying across one end of a bar-shaped part (the ledge: kappa 2, both ends alike)
hides that end: the blob is shorter along its long axis, and its centre lies half the hidden
length off the part's, towards the hidden end (the loop settled 4.3 mm off). The silhouette
alone cannot say which end is hidden (the edge of whatever lies across the bar looks like the
bar's end), but the image beyond each end can: the table there, or something that is not the
table. So, where the bar is seen shorter than at the taught pose (by MIN_HIDDEN_SHARE) and
exactly one end has something beyond it (the localisation channel there stands more than
BEYOND_SHARE of the way from the table's level to the part's threshold), the centre is read
from the other end, the one seen: from where its edge lies (sub-pixel) and the
axis' turn, by a least-squares map fitted at training on the NN2 set's images (``fit_ends``:
the bar whole, turned within FIT_DEG of the taught pose, the blob's centre as the target).
The map, not a fixed half length, because the camera looks at the bar from an angle: its near
half is longer in the image than its far half, and an end moves further in the image than
the centre as the camera moves. Away from the taught heading (beyond READ_DEG) nothing is
moved: the loop's first full loop turns the part into that range.

A screw (kappa 1) is not moved: where its head is hidden nothing says which way it points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from calibration_free.errors import BundleError

# Something lies beyond an end when the channel there stands this share of the way from the
# table's level (the frame's median) to the part's threshold: a slate card over the ledge in
# saturation 0.7-1.0 of the way in good light, 0.4-0.55 in poor light (whose dark table reads
# a noisy saturation); bare table 0.0-0.05 and 0.0-0.05 (0.45 once, at an end in a shadow).
BEYOND_SHARE = 0.3
# Beyond an end means from BEYOND_PX[0] to BEYOND_PX[1] px past it along the axis, within a
# quarter of the blob's width either side of the axis.
BEYOND_PX = (2, 6)
# An end's edge is found on the profile from EDGE_PX inside to EDGE_PX beyond the mask's end,
# sampled every EDGE_STEP px: the mask's end moves in whole pixels (about 1 mm of the ledge).
EDGE_PX = 3.0
EDGE_STEP = 0.25
# A bar seen shorter than at the taught pose by less than this share is taken as whole (its
# image length changes by about 1 px a mm as the camera moves along it, 75 px at the taught
# pose; a dark table's noisy saturation can look like something beyond an end in poor light).
MIN_HIDDEN_SHARE = 0.05
# The map is fitted on images turned within FIT_DEG of the taught pose and read within
# READ_DEG (the axis' image turn from the taught direction). Ledge under a card, 40 trials,
# seeds 1-3, safe within 2.5 loops: 20 / 30 deg 100 / 82.5 / 100%, 30 / 40 deg 100 / 95 / 100%
# (fit 0.50-0.59 px RMS), 45 / 60 deg 95 / 95 (fit 0.75-0.93 px).
FIT_DEG = 40.0
READ_DEG = 30.0
MIN_FIT_SAMPLES = 12
TERMS = 5  # 1, the end's u and v, psi, psi^2 (psi in rad)


@dataclass(frozen=True)
class EndMap:
    """Where a bar's centre lies, read from one end.

    Attributes:
        direction: the bar's axis at the taught pose (unit vector in the image); "low" is the
            end against it, "high" the end along it.
        low, high: per end, the coefficients (TERMS for u, then TERMS for v) of the centre on
            (1, the end's edge point u and v, psi, psi^2), psi the axis' turn from
            ``direction`` (rad).
        length_px: the bar's length between the edges at the taught pose (px).
        rms_px: the fit's RMS error on its samples (px), per end.
    """

    direction: tuple[float, float]
    low: tuple[float, ...]
    high: tuple[float, ...]
    length_px: float
    rms_px: tuple[float, float]

    def __post_init__(self) -> None:
        numbers = (*self.direction, *self.low, *self.high, self.length_px, *self.rms_px)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                   for v in numbers):
            raise BundleError("axis.ends: needs finite numbers")
        if len(self.direction) != 2 or abs(math.hypot(*self.direction) - 1.0) > 1e-6 \
                or len(self.low) != 2 * TERMS or len(self.high) != 2 * TERMS \
                or len(self.rms_px) != 2 or self.length_px <= 0.0:
            raise BundleError(f"axis.ends: needs a unit direction, {2 * TERMS} coefficients "
                              f"per end, two RMS values and a length > 0")

    def to_info(self) -> dict[str, Any]:
        return {"direction": list(self.direction), "low": list(self.low),
                "high": list(self.high), "length_px": self.length_px,
                "rms_px": list(self.rms_px)}

    @classmethod
    def from_info(cls, info: Any) -> EndMap:
        """The map from the model file's JSON (``to_info``'s).

        Raises:
            BundleError: not a mapping with those keys and values.
        """
        keys = ("direction", "high", "length_px", "low", "rms_px")
        if not isinstance(info, dict) or sorted(info) != list(keys):
            raise BundleError(f"axis.ends: needs the keys {', '.join(keys)}")
        try:
            return cls(tuple(info["direction"]), tuple(info["low"]), tuple(info["high"]),
                       info["length_px"], tuple(info["rms_px"]))
        except TypeError as exc:
            raise BundleError(f"axis.ends: {exc}") from None


@dataclass(frozen=True)
class BlobAxis:
    """A blob's long axis: its centroid, the unit vector along the axis (image u, v), and the
    extents of its pixels along the axis (``low``, ``high``: from the centroid, px) and across
    it (``width``, px)."""

    centre: tuple[float, float]
    direction: tuple[float, float]
    low: float
    high: float
    width: float

    @property
    def length(self) -> float:
        return self.high - self.low + 1.0


def blob_axis(part_mask: np.ndarray) -> BlobAxis | None:
    """The long axis of the non-zero pixels of ``part_mask`` (HxW uint8), or None for fewer
    than three pixels: the centroid and axis from the blob's moments, the extents from its
    outline's pixels."""
    x, y, w, h = cv2.boundingRect(part_mask)
    crop = part_mask[y:y + h, x:x + w]
    m = cv2.moments(crop, binaryImage=True)
    if m["m00"] < 3.0:
        return None
    cu, cv_ = m["m10"] / m["m00"], m["m01"] / m["m00"]
    angle = 0.5 * math.atan2(2.0 * m["mu11"], m["mu20"] - m["mu02"])
    along = (math.cos(angle), math.sin(angle))
    # the extremes along any direction are corners of the outline, which SIMPLE keeps
    contours, _ = cv2.findContours(crop, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    pts = np.concatenate([c.reshape(-1, 2) for c in contours]).astype(np.float64)
    du, dv = pts[:, 0] - cu, pts[:, 1] - cv_
    s = du * along[0] + dv * along[1]
    t = dv * along[0] - du * along[1]
    return BlobAxis((cu + x, cv_ + y), along, float(s.min()), float(s.max()),
                    float(t.max() - t.min() + 1.0))


def oriented(axis: BlobAxis, direction: tuple[float, float]) -> BlobAxis:
    """``axis`` with its direction turned to point the way of ``direction`` (within 90 deg):
    the eigenvector's sign is arbitrary."""
    au, av = axis.direction
    if au * direction[0] + av * direction[1] >= 0.0:
        return axis
    return BlobAxis(axis.centre, (-au, -av), -axis.high, -axis.low, axis.width)


def _beyond(channel: np.ndarray, axis: BlobAxis, end: float, sign: float) -> float:
    """The channel's mean just beyond one end of the blob (NaN if all of it is off the
    frame)."""
    (cu, cv_), (au, av) = axis.centre, axis.direction
    s = end + sign * np.arange(BEYOND_PX[0], BEYOND_PX[1] + 1, dtype=np.float64)[:, None]
    q = np.linspace(-axis.width / 4.0, axis.width / 4.0, 5)[None, :]
    u = np.rint(cu + au * s - av * q).astype(np.intp).ravel()
    v = np.rint(cv_ + av * s + au * q).astype(np.intp).ravel()
    height, width = channel.shape
    inside = (u >= 0) & (u < width) & (v >= 0) & (v < height)
    return float(channel[v[inside], u[inside]].mean()) if inside.any() else math.nan


def _edge(channel: np.ndarray, axis: BlobAxis, end: float, sign: float, threshold: float,
          inside: float) -> float:
    """Where the part's edge crosses ``threshold`` near one end of the blob (px along the
    axis from its centroid, sub-pixel): the channel's profile along the axis over the middle
    half of the blob's width, from EDGE_PX inside the end to EDGE_PX beyond it, linearly
    interpolated where it leaves the part's side of the threshold (``inside``: +1 where the
    part is above it). The mask's end where the profile does not cross."""
    t = np.arange(-EDGE_PX, EDGE_PX + EDGE_STEP / 2.0, EDGE_STEP)
    q = np.linspace(-axis.width / 4.0, axis.width / 4.0, 5)
    au, av = axis.direction
    s = end + sign * t
    u = axis.centre[0] + au * s[:, None] - av * q[None, :]
    v = axis.centre[1] + av * s[:, None] + au * q[None, :]
    samples = cv2.remap(channel, u.astype(np.float32), v.astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE)
    profile = inside * (samples.mean(axis=1) - threshold)
    if profile[0] <= 0.0:
        return end
    out = np.nonzero(profile <= 0.0)[0]
    if out.size == 0:
        return end
    i = int(out[0])
    frac = profile[i - 1] / (profile[i - 1] - profile[i])
    return end + sign * float(t[i - 1] + frac * EDGE_STEP)


def _terms(point: tuple[float, float], psi_rad: float) -> np.ndarray:
    return np.array([1.0, point[0], point[1], psi_rad, psi_rad * psi_rad])


def _psi(axis: BlobAxis, direction: tuple[float, float]) -> float:
    """The axis' turn from ``direction`` (rad; ``axis`` oriented along it)."""
    au, av = axis.direction
    return math.atan2(direction[0] * av - direction[1] * au,
                      direction[0] * au + direction[1] * av)


def table_level(channel: np.ndarray) -> float:
    """The table's level: the median of every fourth pixel each way (the part covers a small
    share of the frame)."""
    return float(np.median(channel[::4, ::4]))


def _edges(channel: np.ndarray, axis: BlobAxis, threshold: float
           ) -> tuple[tuple[float, float], tuple[float, float]]:
    """The edge points (u, v) at the low and the high end of ``axis``."""
    inside = 1.0 if threshold > table_level(channel) else -1.0
    (cu, cv_), (au, av) = axis.centre, axis.direction
    low = _edge(channel, axis, axis.low, -1.0, threshold, inside)
    high = _edge(channel, axis, axis.high, 1.0, threshold, inside)
    return (cu + au * low, cv_ + av * low), (cu + au * high, cv_ + av * high)


def fit_ends(channels: list[np.ndarray], masks: list[np.ndarray], centres: np.ndarray,
             at_taught: np.ndarray, direction: tuple[float, float], threshold: float
             ) -> EndMap | None:
    """The end map from training images of the whole bar, or None with fewer than
    MIN_FIT_SAMPLES of them turned within FIT_DEG of the taught pose.

    Args:
        channels: each image's localisation channel (normalised, float32).
        masks: each image's part mask (``Localisation.part_mask``).
        centres: (N, 2) each image's localisation centre, the target.
        at_taught: (N,) which were taken at the taught pose (the length is theirs).
        direction: the bar's axis at the taught pose (unit vector in the image).
        threshold: the part's threshold in the channel.
    """
    rows: list[tuple[np.ndarray, np.ndarray, np.ndarray, float, bool]] = []
    for channel, mask, centre, here in zip(channels, masks, centres, at_taught, strict=True):
        axis = blob_axis(mask)
        if axis is None:
            continue
        axis = oriented(axis, direction)
        psi = _psi(axis, direction)
        if abs(math.degrees(psi)) > FIT_DEG:
            continue
        low, high = _edges(channel, axis, threshold)
        rows.append((_terms(low, psi), _terms(high, psi), np.asarray(centre, dtype=float),
                     math.dist(low, high), bool(here)))
    if len(rows) < MIN_FIT_SAMPLES or not any(r[4] for r in rows):
        return None
    target = np.array([r[2] for r in rows])
    coefs, rms = [], []
    for k in (0, 1):
        x = np.array([r[k] for r in rows])
        c, *_ = np.linalg.lstsq(x, target, rcond=None)
        coefs.append(tuple(float(v) for v in c.T.ravel()))
        rms.append(float(np.sqrt(np.mean(np.sum((x @ c - target) ** 2, axis=1)))))
    length = float(np.mean([r[3] for r in rows if r[4]]))
    return EndMap(direction, coefs[0], coefs[1], length, (rms[0], rms[1]))


def hidden_end_shift(channel: np.ndarray, part_mask: np.ndarray, u_px: float, v_px: float,
                     ends: EndMap, threshold: float) -> tuple[float, float, float] | None:
    """Where one end of the bar is hidden: (du, dv, hidden_px), the move of the localisation's
    centre to where the seen end puts it, and how much shorter than at the taught pose the
    bar is seen; None where no end or both ends have something beyond them, the bar is
    turned more than READ_DEG from the taught pose, the seen end is at the frame's edge, or
    the bar is seen less than MIN_HIDDEN_SHARE shorter than at the taught pose.

    Args:
        channel: the localisation channel the blob was found in (the normalised frame,
            float32).
        part_mask: the full-frame mask of the part's blob (``Localisation.part_mask``).
        u_px, v_px: the localisation's centre.
        ends: the end map (``fit_ends``).
        threshold: the part's threshold in ``channel``.
    """
    axis = blob_axis(part_mask)
    if axis is None:
        return None
    axis = oriented(axis, ends.direction)
    psi = _psi(axis, ends.direction)
    # the outline's extent is within a pixel of the edges' distance: a whole bar stops here
    if abs(math.degrees(psi)) > READ_DEG \
            or axis.length > (1.0 - MIN_HIDDEN_SHARE) * ends.length_px + 1.0:
        return None
    table = table_level(channel)
    level = table + BEYOND_SHARE * (threshold - table)
    above = [(b - level) * (threshold - table) > 0.0
             for b in (_beyond(channel, axis, axis.high, 1.0),
                       _beyond(channel, axis, axis.low, -1.0))]
    if above[0] == above[1]:
        return None
    seen_low = above[0]  # something beyond the high end: the low end is the one seen
    end, sign = (axis.low, -1.0) if seen_low else (axis.high, 1.0)
    au, av = axis.direction
    height, width = channel.shape
    reach = end + sign * BEYOND_PX[1]
    if not (0.0 <= axis.centre[0] + au * reach <= width - 1.0
            and 0.0 <= axis.centre[1] + av * reach <= height - 1.0):
        return None  # the seen end may be the frame's edge, not the part's
    inside = 1.0 if threshold > table else -1.0
    edge = _edge(channel, axis, end, sign, threshold, inside)
    # the bar seen: from the edge seen to the outline's other end
    hidden = ends.length_px - abs(edge - (axis.high if seen_low else axis.low))
    if hidden < MIN_HIDDEN_SHARE * ends.length_px:
        return None  # as long as the whole bar: what lies beyond an end hides none of it
    point = (axis.centre[0] + au * edge, axis.centre[1] + av * edge)
    c = np.asarray(ends.low if seen_low else ends.high).reshape(2, TERMS)
    u, v = c @ _terms(point, psi)
    return float(u - u_px), float(v - v_px), float(hidden)
