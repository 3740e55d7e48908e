"""The model of the expected Hough-peak constellation, which validates the peaks (paper 4.3, 5).

The part's outline, seen from above, is a polygon with kappa sides in kappa / 2 pairs of
parallel lines (the cube: 2 pairs, 90 deg apart). A constellation is a choice of lines from
the Hough peaks that fits the model:

* each line: at least ``min_votes`` edge points (a side, not a tangent to a rounded part);
* each pair: two lines whose normals differ by at most ``parallel_tol_deg``, lying on both
  sides of the object's centroid (the Hough origin), ``width_min_px``..``width_max_px`` apart;
* the pairs' directions, sorted around the half circle, are ``gap_min_deg``..``gap_max_deg``
  apart (nominally 360 / kappa).

The model is learned from the training images (``learn_model``), starting from a loose prior
scaled by the object's size (``prior_model``): a tilted camera foreshortens one pair and lets
the other converge, and the learned tolerances take that in. Of the valid constellations the
one with the most votes wins; if there is none, the peaks are rejected and the reason says
which test failed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from calibration_free.baselines.hough.transform import HoughLine
from calibration_free.errors import TrainingError
from drivers.core.errors import ConfigError

# Prior: widths from PRIOR_WIDTH * the expected width, normals parallel within
# PRIOR_PARALLEL_DEG, pair directions 360 / kappa +/- PRIOR_GAP_DEG apart.
PRIOR_WIDTH = (0.5, 2.0)
PRIOR_PARALLEL_DEG = 20.0
PRIOR_GAP_DEG = 30.0


def pair_count(kappa: int) -> int:
    """Pairs of parallel sides of a kappa-sided regular outline.

    Raises:
        ConfigError: kappa is not an even whole number >= 4 (no parallel pairs to model).
    """
    if isinstance(kappa, bool) or not isinstance(kappa, (int, np.integer)) or kappa < 4 \
            or kappa % 2:
        raise ConfigError(f"kappa: the Hough system models the outline as kappa / 2 pairs of "
                          f"parallel sides and needs an even kappa >= 4, got {kappa!r}")
    return int(kappa) // 2


@dataclass(frozen=True)
class ConstellationModel:
    """Tolerances of a valid constellation (see the module docstring)."""

    kappa: int
    width_min_px: float
    width_max_px: float
    parallel_tol_deg: float
    gap_min_deg: float
    gap_max_deg: float
    min_votes: float = 0.0

    def __post_init__(self) -> None:
        pair_count(self.kappa)
        values = (self.width_min_px, self.width_max_px, self.parallel_tol_deg,
                  self.gap_min_deg, self.gap_max_deg, self.min_votes)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values) \
                or self.min_votes < 0 or not 0 < self.width_min_px <= self.width_max_px \
                or not 0 <= self.parallel_tol_deg < 90 \
                or not 0 < self.gap_min_deg <= self.gap_max_deg:
            raise ConfigError(f"constellation model: inconsistent tolerances {values}")

    @property
    def pairs(self) -> int:
        return pair_count(self.kappa)


@dataclass(frozen=True)
class Constellation:
    """A validated set of lines.

    Attributes:
        lines: the 2 * pairs lines, pair by pair.
        angle_deg: the outline's orientation, the votes-weighted kappa-fold mean of the lines'
            normals, in (-180 / kappa, 180 / kappa].
        centre_px: (x, y) where the pairs' mid-lines cross (least squares for > 2 pairs).
        widths_px: distance between the lines of each pair.
        parallel_deg: angle between the normals of each pair's lines.
        gaps_deg: angles between consecutive pair directions around the half circle.
        votes: edge points supporting the lines.
    """

    lines: tuple[HoughLine, ...]
    angle_deg: float
    centre_px: tuple[float, float]
    widths_px: tuple[float, ...]
    parallel_deg: tuple[float, ...]
    gaps_deg: tuple[float, ...]
    votes: float


@dataclass(frozen=True)
class _Pair:
    i: int
    j: int
    direction_deg: float  # of the mid-line's normal, in [0, 180)
    mid_d_px: float
    width_px: float
    parallel_deg: float
    votes: float


def _pair(lines: list[HoughLine], i: int, j: int) -> _Pair:
    a, b = lines[i], lines[j]
    theta_b, d_b = b.theta_deg, b.d_px
    if abs(theta_b - a.theta_deg) > 90.0:  # express b with the normal on a's side
        theta_b += -180.0 if theta_b > a.theta_deg else 180.0
        d_b = -d_b
    direction = (a.votes * a.theta_deg + b.votes * theta_b) / (a.votes + b.votes)
    n_a = np.array([math.cos(math.radians(a.theta_deg)), math.sin(math.radians(a.theta_deg))])
    n_b = np.array([math.cos(math.radians(theta_b)), math.sin(math.radians(theta_b))])
    n = np.array([math.cos(math.radians(direction)), math.sin(math.radians(direction))])
    # mid-line: halfway between the two lines where they pass the origin's foot points
    mid = 0.5 * (a.d_px * (n_a @ n) + d_b * (n_b @ n))
    width = abs(a.d_px - d_b) if a.d_px * d_b < 0 else -1.0
    return _Pair(i, j, direction % 180.0, mid, width, abs(theta_b - a.theta_deg),
                 a.votes + b.votes)


def _gaps(directions: list[float]) -> list[float]:
    d = sorted(directions)
    return [d[k + 1] - d[k] for k in range(len(d) - 1)] + [180.0 + d[0] - d[-1]]


def _angle(lines: tuple[HoughLine, ...], kappa: int) -> float:
    z = sum(line.votes * complex(math.cos(math.radians(kappa * line.theta_deg)),
                                 math.sin(math.radians(kappa * line.theta_deg)))
            for line in lines)
    angle = math.degrees(math.atan2(z.imag, z.real)) / kappa
    return angle + 360.0 / kappa if angle <= -180.0 / kappa else angle


def _centre(pairs: tuple[_Pair, ...], origin_px: tuple[float, float]) -> tuple[float, float]:
    normals = np.array([[math.cos(math.radians(p.direction_deg)),
                         math.sin(math.radians(p.direction_deg))] for p in pairs])
    rel, *_ = np.linalg.lstsq(normals, np.array([p.mid_d_px for p in pairs]), rcond=None)
    return float(origin_px[0] + rel[0]), float(origin_px[1] + rel[1])


def find_constellation(lines: list[HoughLine], model: ConstellationModel,
                       origin_px: tuple[float, float]) -> tuple[Constellation | None, str]:
    """The best valid constellation among ``lines`` (d measured from ``origin_px``).

    Returns:
        (constellation, "") or (None, why the lines were rejected).
    """
    need = 2 * model.pairs
    lines = [line for line in lines if line.votes >= model.min_votes]
    if len(lines) < need:
        return None, (f"{len(lines)} Hough lines of {model.min_votes:.0f} edge points or more;"
                      f" the outline needs {need}")
    pairs = [p for p in (_pair(lines, i, j) for i, j in itertools.combinations(
        range(len(lines)), 2))
        if p.parallel_deg <= model.parallel_tol_deg
        and model.width_min_px <= p.width_px <= model.width_max_px]
    if len(pairs) < model.pairs:
        return None, (f"{len(pairs)} pairs of parallel lines (within "
                      f"{model.parallel_tol_deg:.0f} deg, {model.width_min_px:.0f}.."
                      f"{model.width_max_px:.0f} px apart around the centre) among "
                      f"{len(lines)} lines; the outline needs {model.pairs}")
    best: tuple[_Pair, ...] | None = None
    for combo in itertools.combinations(pairs, model.pairs):
        used = [k for p in combo for k in (p.i, p.j)]
        if len(set(used)) != len(used):
            continue
        gaps = _gaps([p.direction_deg for p in combo])
        if all(model.gap_min_deg <= g <= model.gap_max_deg for g in gaps) and (
                best is None or sum(p.votes for p in combo) > sum(p.votes for p in best)):
            best = combo
    if best is None:
        return None, (f"no {model.pairs} pairs of parallel lines {model.gap_min_deg:.0f}.."
                      f"{model.gap_max_deg:.0f} deg apart among {len(pairs)} pairs")
    chosen = tuple(lines[k] for p in best for k in (p.i, p.j))
    return Constellation(
        lines=chosen, angle_deg=_angle(chosen, model.kappa), centre_px=_centre(best, origin_px),
        widths_px=tuple(p.width_px for p in best),
        parallel_deg=tuple(p.parallel_deg for p in best),
        gaps_deg=tuple(_gaps([p.direction_deg for p in best])),
        votes=float(sum(p.votes for p in best))), ""


def prior_model(kappa: int, expected_width_px: float) -> ConstellationModel:
    """A loose model for a part about ``expected_width_px`` across, to find the training
    images' constellations with."""
    nominal = 360.0 / kappa
    return ConstellationModel(kappa, PRIOR_WIDTH[0] * expected_width_px,
                              PRIOR_WIDTH[1] * expected_width_px, PRIOR_PARALLEL_DEG,
                              nominal - PRIOR_GAP_DEG, nominal + PRIOR_GAP_DEG)


def learn_model(constellations: list[Constellation], kappa: int, *, width_margin: float,
                angle_margin_deg: float, vote_fraction: float) -> ConstellationModel:
    """The tolerances spanned by the training constellations, grown by the margins.

    Args:
        constellations: those found in the training images.
        kappa: the part's symmetry.
        width_margin: widths may be this fraction smaller or larger than seen.
        angle_margin_deg: parallelism and gaps may be off by this much more than seen.
        vote_fraction: a line needs this fraction of the median training line's edge points.

    Raises:
        TrainingError: no constellations.
    """
    if not constellations:
        raise TrainingError("constellation model: no training image showed the outline's "
                            "parallel sides; check the edge thresholds and the view")
    widths = [w for c in constellations for w in c.widths_px]
    parallel = [a for c in constellations for a in c.parallel_deg]
    gaps = [g for c in constellations for g in c.gaps_deg]
    votes = [line.votes for c in constellations for line in c.lines]
    return ConstellationModel(
        kappa, min(widths) * (1.0 - width_margin), max(widths) * (1.0 + width_margin),
        min(89.0, max(parallel) + angle_margin_deg), max(1.0, min(gaps) - angle_margin_deg),
        max(gaps) + angle_margin_deg, vote_fraction * float(np.median(votes)))
