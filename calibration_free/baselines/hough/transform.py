"""Straight-line Hough transform over (theta, d) with the back-transform (paper section 2.3).

A line is {p : (p - origin) . (cos theta, sin theta) = d} with theta in [0, 180) degrees and d
signed, in pixel-centre image coordinates (x = column, y = row, y down). Every edge point votes
for all the cells on its sinusoid d(theta) (``accumulate``).

The back-transform (Illingworth and Kittler, ref. [2]) sharpens the peaks: each point is traced
back along its sinusoid to the strongest cell it voted for, and the accumulator is rebuilt from
one vote per point at that cell (``back_transform``). The butterfly-shaped spread around a true
peak, and the spurious peaks where sinusoids of different lines cross, lose their votes to the
true peaks. Each point's surviving cell also says which line it belongs to, so a line's
parameters are refined by a total-least-squares fit to its own points (``fit_lines``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration_free.errors import ImageError

# Peak search looks at most at this many of the strongest cells.
MAX_PEAK_CANDIDATES = 20000
# A line is refitted without its points farther from the first fit than this many times the
# median distance (a cell is a pixel wide, so it also collects the ends of the lines crossing
# it, e.g. at a corner).
OUTLIER_FACTOR = 3.0


@dataclass(frozen=True, eq=False)
class HoughSpace:
    """An accumulator.

    Attributes:
        votes: (T, D) float64 votes; row t is theta = t * theta_step_deg, column k is
            d = -d_max_px + k * d_step_px.
        theta_step_deg, d_step_px: bin sizes.
        d_max_px: half range of d (a whole number of steps, so the d axis is symmetric).
        origin_px: (x, y) the distances are measured from.
    """

    votes: np.ndarray
    theta_step_deg: float
    d_step_px: float
    d_max_px: float
    origin_px: tuple[float, float]

    @property
    def thetas_deg(self) -> np.ndarray:
        return np.arange(self.votes.shape[0]) * self.theta_step_deg

    @property
    def ds_px(self) -> np.ndarray:
        return -self.d_max_px + np.arange(self.votes.shape[1]) * self.d_step_px


@dataclass(frozen=True)
class HoughLine:
    """A detected line: normal angle theta_deg in [0, 180), signed distance d_px from the
    space's origin, and the number of edge points supporting it."""

    theta_deg: float
    d_px: float
    votes: float


def _check_points(points_xy: np.ndarray) -> np.ndarray:
    p = np.asarray(points_xy, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or not np.isfinite(p).all():
        raise ImageError(f"edge points: expected finite (K, 2) (x, y), got shape {p.shape}")
    return p


def _d_indices(points: np.ndarray, space: HoughSpace) -> np.ndarray:
    """(K, T) d-bin index of every point's sinusoid at every theta."""
    theta = np.radians(space.thetas_deg)
    rel = points - np.asarray(space.origin_px)
    d = rel[:, :1] * np.cos(theta)[None, :] + rel[:, 1:] * np.sin(theta)[None, :]
    k = np.rint((d + space.d_max_px) / space.d_step_px).astype(np.int64)
    return np.clip(k, 0, space.votes.shape[1] - 1)


def accumulate(points_xy: np.ndarray, *, origin_px: tuple[float, float], d_max_px: float,
               theta_step_deg: float = 1.0, d_step_px: float = 1.0) -> HoughSpace:
    """The Hough accumulator of the edge points.

    Args:
        points_xy: (K, 2) edge points (x, y).
        origin_px: (x, y) origin of the distances.
        d_max_px: largest |d| represented (rounded up to whole steps); points farther from
            the origin vote into the border bins.
        theta_step_deg: theta bin size; 180 must be a whole multiple of it.
        d_step_px: d bin size.

    Raises:
        ImageError: bad points, or bin sizes that do not fit.
    """
    points = _check_points(points_xy)
    n_theta = 180.0 / theta_step_deg if theta_step_deg > 0 else 0.0
    if not (n_theta >= 2 and abs(n_theta - round(n_theta)) < 1e-9):
        raise ImageError(f"theta_step_deg: 180 must be a whole multiple of it, got "
                         f"{theta_step_deg!r}")
    if not (d_step_px > 0 and d_max_px > 0 and math.isfinite(d_max_px)):
        raise ImageError(f"d_step_px and d_max_px must be > 0, got {d_step_px!r}, "
                         f"{d_max_px!r}")
    half = math.ceil(d_max_px / d_step_px)
    shape = (round(n_theta), 2 * half + 1)
    empty = HoughSpace(np.zeros(shape), float(theta_step_deg), float(d_step_px),
                       half * float(d_step_px), (float(origin_px[0]), float(origin_px[1])))
    if not points.size:
        return empty
    flat = (np.arange(shape[0])[None, :] * shape[1] + _d_indices(points, empty)).ravel()
    votes = np.bincount(flat, minlength=shape[0] * shape[1]).astype(np.float64)
    return HoughSpace(votes.reshape(shape), empty.theta_step_deg, empty.d_step_px,
                      empty.d_max_px, empty.origin_px)


def back_transform(points_xy: np.ndarray, space: HoughSpace) \
        -> tuple[HoughSpace, np.ndarray]:
    """Sharpen ``space`` (built from the same points): one vote per point at its best cell.

    Returns:
        The sharpened space and (K, 2) int cells (theta index, d index) each point voted for.

    Raises:
        ImageError: bad points.
    """
    points = _check_points(points_xy)
    sharp = HoughSpace(np.zeros_like(space.votes), space.theta_step_deg, space.d_step_px,
                       space.d_max_px, space.origin_px)
    if not points.size:
        return sharp, np.zeros((0, 2), dtype=np.int64)
    k = _d_indices(points, space)
    t = np.argmax(space.votes[np.arange(space.votes.shape[0])[None, :], k], axis=1)
    owner = np.stack([t, k[np.arange(points.shape[0]), t]], axis=1)
    np.add.at(sharp.votes, (owner[:, 0], owner[:, 1]), 1.0)
    return sharp, owner


def _close(theta_a_deg: float, d_a_px: float, theta_b_deg: np.ndarray, d_b_px: np.ndarray,
           window_deg: float, window_px: float) -> np.ndarray:
    """Whether line a lies within the window of each line b, across the theta wrap (theta +
    180 with -d is the same line)."""
    dt = np.abs(theta_b_deg - theta_a_deg)
    wrapped = dt > 90.0
    dt = np.where(wrapped, 180.0 - dt, dt)
    dd = np.abs(np.where(wrapped, d_a_px + d_b_px, d_a_px - d_b_px))
    return (dt <= window_deg) & (dd <= window_px)


def _near(space: HoughSpace, a: tuple[int, int], b: np.ndarray, window_deg: float,
          window_px: float) -> np.ndarray:
    """Whether cell a lies within the window of each cell in b (N, 2)."""
    return _close(a[0] * space.theta_step_deg, -space.d_max_px + a[1] * space.d_step_px,
                  b[:, 0] * space.theta_step_deg, -space.d_max_px + b[:, 1] * space.d_step_px,
                  window_deg, window_px)


def find_peaks(space: HoughSpace, *, max_peaks: int, window_deg: float = 4.0,
               window_px: float = 3.0) -> np.ndarray:
    """The strongest cells, each at least a window away from every stronger one.

    Returns:
        (P, 2) int cells (theta index, d index), strongest first, P <= max_peaks; cells with
        no votes are never peaks.
    """
    flat = space.votes.ravel()
    candidates = np.flatnonzero(flat > 0)
    if candidates.size > MAX_PEAK_CANDIDATES:
        candidates = candidates[np.argpartition(-flat[candidates], MAX_PEAK_CANDIDATES)
                                [:MAX_PEAK_CANDIDATES]]
    candidates = candidates[np.argsort(-flat[candidates], kind="stable")]
    peaks: list[tuple[int, int]] = []
    for c in candidates:
        cell = divmod(int(c), space.votes.shape[1])
        if peaks and _near(space, cell, np.asarray(peaks), window_deg, window_px).any():
            continue
        peaks.append(cell)
        if len(peaks) >= max_peaks:
            break
    return np.asarray(peaks, dtype=np.int64).reshape(-1, 2)


def peak_to_sidelobe(space: HoughSpace, peaks: np.ndarray, window_deg: float = 4.0,
                     window_px: float = 3.0) -> float:
    """The weakest peak's votes over the strongest cell outside every peak's window (inf when
    nothing votes outside): how clearly the peaks stand out of the accumulator."""
    if len(peaks) == 0:
        return 0.0
    t, k = np.meshgrid(np.arange(space.votes.shape[0]), np.arange(space.votes.shape[1]),
                       indexing="ij")
    cells = np.stack([t.ravel(), k.ravel()], axis=1)
    outside = np.ones(cells.shape[0], dtype=bool)
    for p in peaks:
        outside &= ~_near(space, (int(p[0]), int(p[1])), cells, window_deg, window_px)
    side = float(space.votes.ravel()[outside].max()) if outside.any() else 0.0
    weakest = float(min(space.votes[p[0], p[1]] for p in peaks))
    return weakest / side if side > 0 else math.inf


def fit_line(points_xy: np.ndarray, origin_px: tuple[float, float]) -> tuple[float, float]:
    """Total-least-squares line through >= 2 points: (theta_deg in [0, 180), d_px)."""
    p = _check_points(points_xy)
    if p.shape[0] < 2:
        raise ImageError(f"a line fit needs at least 2 points, got {p.shape[0]}")
    centre = p.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((p - centre).T))
    normal = vecs[:, 0]  # smallest eigenvalue: across the line
    theta = math.degrees(math.atan2(normal[1], normal[0]))
    if theta < 0.0:
        theta += 180.0
        normal = -normal
    if theta >= 180.0:
        theta -= 180.0
        normal = -normal
    d = float((centre - np.asarray(origin_px)) @ normal)
    return theta, d


def _refit(points: np.ndarray, origin_px: tuple[float, float]) -> tuple[float, float]:
    """TLS line, refitted once without the points beyond OUTLIER_FACTOR median distances."""
    theta, d = fit_line(points, origin_px)
    normal = np.array([math.cos(math.radians(theta)), math.sin(math.radians(theta))])
    off = np.abs((points - np.asarray(origin_px)) @ normal - d)
    inliers = off <= max(OUTLIER_FACTOR * float(np.median(off)), 1e-9)
    if 2 <= inliers.sum() < points.shape[0]:
        theta, d = fit_line(points[inliers], origin_px)
    return theta, d


def fit_lines(points_xy: np.ndarray, owner: np.ndarray, space: HoughSpace, peaks: np.ndarray,
              window_deg: float = 4.0, window_px: float = 3.0,
              min_votes: float = 2.0) -> list[HoughLine]:
    """Lines refined from the points whose back-transformed cell lies in each peak's window.

    Each peak's points are fitted by total least squares (refitted once without outliers, see
    OUTLIER_FACTOR). The back-transform can split one line between peaks more than a window
    apart (its sub-segments each find a slightly turned cell): peaks whose fitted lines lie
    within a window of each other are merged and refitted.

    Args:
        points_xy: the (K, 2) edge points the space was built from.
        owner: (K, 2) cells from ``back_transform``.
        space: the (sharpened) space the peaks were found in.
        peaks: (P, 2) cells from ``find_peaks``.
        window_deg, window_px: the peaks' windows.
        min_votes: lines supported by fewer points are dropped.

    Returns:
        The lines with enough points, strongest first.
    """
    points = _check_points(points_xy)
    taken = np.zeros(points.shape[0], dtype=bool)
    groups: list[tuple[np.ndarray, tuple[float, float]]] = []
    for p in peaks:
        mine = ~taken & _near(space, (int(p[0]), int(p[1])), owner, window_deg, window_px)
        taken |= mine
        if mine.sum() < 2:
            continue
        params = _refit(points[mine], space.origin_px)
        for g, (members, fitted) in enumerate(groups):
            if _close(*params, np.array(fitted[0]), np.array(fitted[1]), window_deg,
                      window_px):
                merged = members | mine
                groups[g] = (merged, _refit(points[merged], space.origin_px))
                break
        else:
            groups.append((mine, params))
    lines = [HoughLine(theta, d, float(members.sum())) for members, (theta, d) in groups
             if members.sum() >= max(2.0, min_votes)]
    return sorted(lines, key=lambda line: -line.votes)
