"""The part's long axis: the rotation of an elongated part (screw, ledge) read from its outline.

NN2 reads the rotation from 36 low-frequency Gabor features of the ROI. For a part with a long
axis a silhouette of the part around its centre also gives the axis' direction from its second
central moments, a sum over every pixel of the outline that a side lamp's shading of the part
barely moves: at the taught pose, over 24 placements of the screw in poor light, the axis of
the features' soft silhouette (``FrontEnd.feature_roi``) moved by 1.0 deg in the image (0.7 deg
of tool turn) where NN2's reading moved by 2.2 deg. That silhouette's outline is the saturation
of a part/table mix, weighted by brightness, so the lamp-lit side of the part still reads
wider than the shaded one; where the frame's colour gives the part's share of each outline
pixel (``FrontEnd.coverage_roi``, the centre's own reading) the axis is read from that: the
screw's angle in poor light, 0.86 -> 0.33 deg RMS after 2.5 loops (200 trials, seed 3).

The axis does not tell a screw's head from its tip, and its image direction is not the tool's
turn (the camera looks at the part from an angle and from one side), so NN2 stays: it picks
which way the part points (of the two directions along the axis, the one whose turn lies
nearer NN2's reading), and a reading further than ``agree_deg`` from NN2's is not taken (the
silhouette is not the taught one: a card over the part). The turn is mapped from the axis'
direction relative to the taught pose's, psi, by least squares fitted on the NN2 set's images
(``fit_axis``): over the whole circle the turn is psi plus a few harmonics of kappa psi and the
part's image shift (where that fits the images within WHOLE_MAX_RMS_DEG; elsewhere NN2 reads
away from the taught pose); within ``window_deg`` of the taught pose a finer map, fitted on
the images near it (psi, its cube and the shift), takes over.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np

from calibration_free.ends import EndMap
from calibration_free.errors import BundleError

logger = logging.getLogger(__name__)

# The near map is fitted on the NN2 set's images within NEAR_FIT_DEG of the taught pose and
# reads where the whole-circle map reads within WINDOW_DEG.
NEAR_FIT_DEG = 25.0
WINDOW_DEG = 15.0
# An axis reading further than this from NN2's is not taken (the silhouette is not the
# taught one). Near the taught pose in poor light NN2 reads up to 21 deg off where the axis
# reads within 3 deg (the screw, 200 poor-light trials): a tighter limit dropped the right
# reading there and the loop took NN2's wrong one.
AGREE_DEG = 30.0
# The whole-circle map reads only if it fits its samples this well; otherwise NN2 reads away
# from the taught pose and the near map near it. Screw 0.72 deg; the ledge 1.10 deg: the bar
# reaches past the 50 px ROI, whose edge cuts it differently as it turns (on 80 test poses
# within 4 mm, turned 45-90 deg, 1.03 deg RMS against NN2's 0.27).
WHOLE_MAX_RMS_DEG = 0.9
# A part is elongated when the taught pose's silhouette is this much longer than wide
# (square root of the ratio of the second moments' eigenvalues); a frame whose silhouette
# is less than AXIS_ELONGATION_SHARE of the taught elongation gives no axis.
MIN_ELONGATION = 1.3
AXIS_ELONGATION_SHARE = 0.8
MIN_NEAR_SAMPLES = 8
NEAR_TERMS = 4  # psi, psi^3 / 1e3, du, dv
HARMONICS = 4
# The silhouette an axis map reads (``AxisMap.silhouette``).
Silhouette = Literal["coverage", "features"]
WHOLE_TERMS = 2 * HARMONICS + 3  # 1, (sin, cos)(n kappa psi) for n = 1..HARMONICS, du, dv


def axis_of(roi: np.ndarray) -> tuple[float, float]:
    """The long axis of a non-negative weight image: its direction in the image (deg in
    (-90, 90], from the u axis towards v) and its elongation (>= 1; 1 for no axis)."""
    m = cv2.moments(roi)
    mu20, mu02, mu11 = m["mu20"], m["mu02"], m["mu11"]
    half_diff = 0.5 * (mu20 - mu02)
    root = math.hypot(half_diff, mu11)
    mean = 0.5 * (mu20 + mu02)
    if mean <= 0.0:
        return 0.0, 1.0
    small = max(mean - root, 1e-12)
    angle = 0.5 * math.degrees(math.atan2(2.0 * mu11, mu20 - mu02))
    return angle, math.sqrt((mean + root) / small)


def _wrap(deg: float | np.ndarray, period: float) -> float | np.ndarray:
    """``deg`` wrapped to [-period / 2, period / 2) (period 180: an axis direction)."""
    return (deg + period / 2.0) % period - period / 2.0


def _near_terms(psi: np.ndarray, du: np.ndarray, dv: np.ndarray) -> np.ndarray:
    return np.column_stack([psi, psi ** 3 / 1e3, du, dv])


def _whole_terms(psi: np.ndarray, du: np.ndarray, dv: np.ndarray, kappa: int) -> np.ndarray:
    cols = [np.ones_like(psi)]
    for n in range(1, HARMONICS + 1):
        arg = np.radians(n * kappa * psi)
        cols += [np.sin(arg), np.cos(arg)]
    return np.column_stack([*cols, du, dv])


@dataclass(frozen=True)
class AxisMap:
    """The tool turn (deg) from the part's long axis in the ROI (module docstring).

    Attributes:
        kappa: the part's rotational symmetry count (1 or 2: a part with a long axis).
        axis0_deg: the axis' image direction at the taught pose (mean of its frames).
        elongation: the taught pose's elongation (mean).
        uv0_px: the part's image position at the taught pose.
        whole: the whole-circle map's coefficients: the turn is psi plus these on (1, sin and
            cos of n kappa psi for n = 1..HARMONICS, du, dv), psi the axis' direction from
            ``axis0_deg`` (deg, of the two along the axis the one NN2 says), du, dv the
            part's shift from ``uv0_px`` (px).
        near: the near map's coefficients on (psi, psi^3 / 1e3, du, dv).
        near_range_deg: the largest |psi| among the near map's samples.
        whole_reads: the whole-circle map reads (it fitted within WHOLE_MAX_RMS_DEG); if
            not, the near map reads only where NN2 reads within ``window_deg``.
        window_deg: where the whole-circle map (or NN2) reads within this, the near map
            reads.
        agree_deg: a reading further than this from NN2's is not taken.
        whole_rms_deg, near_rms_deg: each map's RMS error on the samples it was fitted on.
        samples: how many samples the whole-circle map was fitted on.
        ends: for a bar (kappa 2), the map from either end to its centre, for a bar one of
            whose ends is hidden (``calibration_free.ends``); None: none (a screw, too few
            images near the taught pose, or a model file before version 7).
        silhouette: which silhouette the map was fitted on and reads: "coverage" (the part's
            share of each pixel, read from the frame's colour: ``FrontEnd.coverage_roi``)
            or "features" (the soft silhouette NN2's features see; model files before
            format 8).
    """

    kappa: int
    axis0_deg: float
    elongation: float
    uv0_px: tuple[float, float]
    whole: tuple[float, ...]
    near: tuple[float, ...]
    near_range_deg: float
    whole_reads: bool = True
    window_deg: float = WINDOW_DEG
    agree_deg: float = AGREE_DEG
    whole_rms_deg: float = 0.0
    near_rms_deg: float = 0.0
    samples: int = 0
    ends: EndMap | None = None
    silhouette: Silhouette = "features"

    @property
    def direction(self) -> tuple[float, float]:
        """The axis at the taught pose as a unit vector in the image (u, v)."""
        a = math.radians(self.axis0_deg)
        return math.cos(a), math.sin(a)

    def __post_init__(self) -> None:
        numbers = (self.axis0_deg, self.elongation, *self.uv0_px, *self.whole, *self.near,
                   self.near_range_deg, self.window_deg, self.agree_deg, self.whole_rms_deg,
                   self.near_rms_deg)
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(v) for v in numbers):
            raise BundleError("axis: needs finite numbers")
        if self.kappa not in (1, 2):
            raise BundleError(f"axis: kappa must be 1 or 2 (a part with a long axis), got "
                              f"{self.kappa!r}")
        if len(self.whole) != WHOLE_TERMS or len(self.near) != NEAR_TERMS \
                or len(self.uv0_px) != 2:
            raise BundleError(f"axis: whole needs {WHOLE_TERMS} numbers, near {NEAR_TERMS} "
                              f"and uv0_px 2, got {len(self.whole)}, {len(self.near)} and "
                              f"{len(self.uv0_px)}")
        if not isinstance(self.whole_reads, bool):
            raise BundleError(f"axis: whole_reads must be true or false, got "
                              f"{self.whole_reads!r}")
        if not (self.elongation >= 1.0 and 0.0 < self.near_range_deg <= 90.0
                and self.window_deg > 0.0 and self.agree_deg > 0.0):
            raise BundleError("axis: needs elongation >= 1, 0 < near_range_deg <= 90, "
                              "window_deg and agree_deg > 0")
        if self.ends is not None and not isinstance(self.ends, EndMap):
            raise BundleError("axis: ends must be an end map")
        if self.silhouette not in ("coverage", "features"):
            raise BundleError(f"axis: silhouette must be coverage or features, got "
                              f"{self.silhouette!r}")

    def reading(self, roi: np.ndarray, u_px: float, v_px: float, nn2_deg: float
                ) -> float | None:
        """The tool turn (deg) the ROI's axis reads, of the two directions along it the one
        nearer NN2's reading; None where it gives none (no clear axis) or disagrees with
        NN2's by more than ``agree_deg``."""
        angle, elongation = axis_of(roi)
        if elongation < AXIS_ELONGATION_SHARE * self.elongation:
            return None
        period = 360.0 / self.kappa
        du = np.full(2, u_px - self.uv0_px[0])
        dv = np.full(2, v_px - self.uv0_px[1])
        near_psi = float(_wrap(angle - self.axis0_deg, 180.0))
        turn = nn2_deg
        if self.whole_reads:
            psi = near_psi + np.array([0.0, 180.0])
            turns = _wrap(psi + _whole_terms(psi, du, dv, self.kappa) @ np.asarray(self.whole),
                          period)
            gaps = np.abs(_wrap(turns - nn2_deg, period))
            best = int(np.argmin(gaps))
            if gaps[best] > self.agree_deg:
                return None
            turn = float(turns[best])
        if abs(turn) <= self.window_deg and abs(near_psi) <= self.near_range_deg:
            near = float(_near_terms(np.array([near_psi]), du[:1], dv[:1])[0]
                         @ np.asarray(self.near))
            return near if abs(_wrap(near - nn2_deg, period)) <= self.agree_deg else None
        return turn if self.whole_reads else None

    def to_info(self) -> dict[str, Any]:
        """The model file's JSON for the map."""
        return {"kappa": self.kappa, "axis0_deg": self.axis0_deg,
                "elongation": self.elongation, "uv0_px": list(self.uv0_px),
                "whole": list(self.whole), "near": list(self.near),
                "near_range_deg": self.near_range_deg, "whole_reads": self.whole_reads,
                "window_deg": self.window_deg,
                "agree_deg": self.agree_deg, "whole_rms_deg": self.whole_rms_deg,
                "near_rms_deg": self.near_rms_deg, "samples": self.samples,
                "ends": None if self.ends is None else self.ends.to_info(),
                "silhouette": self.silhouette}

    @classmethod
    def from_info(cls, info: Any) -> AxisMap:
        """The map from the model file's JSON (``ends`` may be missing: a file before
        version 7; ``silhouette`` too: a file before version 8, which read "features").

        Raises:
            BundleError: not a mapping with the fields ``to_info`` writes.
        """
        keys = ("kappa", "axis0_deg", "elongation", "uv0_px", "whole", "near",
                "near_range_deg", "whole_reads", "window_deg", "agree_deg", "whole_rms_deg",
                "near_rms_deg", "samples")
        if not isinstance(info, dict) or sorted(set(info) - {"ends", "silhouette"}) \
                != sorted(keys):
            raise BundleError(f"axis: needs the keys {', '.join(keys)} (and ends, "
                              f"silhouette)")
        try:
            return cls(**{**info, "uv0_px": tuple(info["uv0_px"]),
                          "whole": tuple(info["whole"]), "near": tuple(info["near"]),
                          "samples": int(info["samples"]),
                          "ends": (None if info.get("ends") is None
                                   else EndMap.from_info(info["ends"]))})
        except (TypeError, ValueError) as exc:
            raise BundleError(f"axis: {exc}") from None


def fit_axis(rois: list[np.ndarray], uv: np.ndarray, dphi_deg: np.ndarray,
             at_taught: np.ndarray, kappa: int, silhouette: Silhouette = "features"
             ) -> AxisMap | None:
    """The axis map from the NN2 set's ROIs, or None for a part without a clear long axis
    (kappa above 2, or a silhouette at the taught pose less elongated than MIN_ELONGATION).

    Args:
        rois: the NN2 set's usable images' silhouettes around the part (``silhouette``
            says which: the coverage or the features' ROIs).
        uv: (N, 2) the part's image position in each.
        dphi_deg: (N,) each image's rotation label (deg).
        at_taught: (N,) which were taken at the taught pose.
        kappa: the part's rotational symmetry count.

    An elongated part with fewer than MIN_NEAR_SAMPLES images near the taught pose (a
    smaller NN2 grid than the default) gets none either, with a warning.
    """
    if kappa > 2 or not at_taught.any():
        return None
    axes = np.array([axis_of(roi) for roi in rois])
    elongation = float(axes[at_taught, 1].mean())
    if elongation < MIN_ELONGATION:
        return None
    # the taught direction: a mean over half-turn-periodic angles (doubled on the circle)
    doubled = np.radians(2.0 * axes[at_taught, 0])
    axis0 = 0.5 * math.degrees(math.atan2(np.sin(doubled).mean(), np.cos(doubled).mean()))
    uv0 = uv[at_taught].mean(axis=0)
    du, dv = uv[:, 0] - uv0[0], uv[:, 1] - uv0[1]
    period = 360.0 / kappa
    near_psi = _wrap(axes[:, 0] - axis0, 180.0)
    # of the two directions along the axis, the one nearer the label's turn
    psi = np.where(np.abs(_wrap(near_psi - dphi_deg, period))
                   <= np.abs(_wrap(near_psi + 180.0 - dphi_deg, period)),
                   near_psi, near_psi + 180.0)
    clear = axes[:, 1] >= AXIS_ELONGATION_SHARE * elongation
    whole_terms = _whole_terms(psi[clear], du[clear], dv[clear], kappa)
    target = _wrap(dphi_deg[clear] - psi[clear], period)
    whole, *_ = np.linalg.lstsq(whole_terms, target, rcond=None)
    whole_rms = float(np.sqrt(np.mean((whole_terms @ whole - target) ** 2)))
    near = clear & (np.abs(dphi_deg) <= NEAR_FIT_DEG) & (np.abs(near_psi) < 80.0)
    if int(near.sum()) < MIN_NEAR_SAMPLES:
        logger.warning("no axis map: only %d NN2 images of the elongated part within %.0f deg "
                       "of the taught pose, it needs %d (NN2 reads the turn alone)",
                       int(near.sum()), NEAR_FIT_DEG, MIN_NEAR_SAMPLES)
        return None
    near_terms = _near_terms(near_psi[near], du[near], dv[near])
    near_coef, *_ = np.linalg.lstsq(near_terms, dphi_deg[near], rcond=None)
    near_rms = float(np.sqrt(np.mean((near_terms @ near_coef - dphi_deg[near]) ** 2)))
    return AxisMap(kappa=kappa, axis0_deg=float(axis0), elongation=elongation,
                   uv0_px=(float(uv0[0]), float(uv0[1])),
                   whole=tuple(float(c) for c in whole),
                   near=tuple(float(c) for c in near_coef),
                   near_range_deg=float(min(np.abs(near_psi[near]).max(), 90.0)),
                   whole_reads=whole_rms <= WHOLE_MAX_RMS_DEG,
                   whole_rms_deg=whole_rms, near_rms_deg=near_rms, samples=int(clear.sum()),
                   silhouette=silhouette)
