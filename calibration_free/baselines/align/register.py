"""Registering one frame's soft silhouette to the taught pose's template.

The template is the mean silhouette of the frames taken at the taught pose, cut square around
the part's centre there (its reference point). A frame is registered in two steps: a scan over
the part's symmetry period (the template turned in steps about its reference point, each laid
on the frame at the part's blob centre and scored by normalised correlation), then
``cv2.findTransformECC`` (a Euclidean warp: turn and shift) from the best step. The result is
where the reference point lies in the frame and how far the part is turned in the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

# ECC's warp may scale the part's area by at most 1 / this either way (the training grid's
# nearest and farthest views differ by a factor of 3 in area, but a warp is refined from the
# blob's own position): beyond it the warp has run off (an occluded or foreign blob).
MIN_AREA_RATIO = 0.5


@dataclass(frozen=True)
class Registration:
    """One frame registered to the template.

    Attributes:
        u_px, v_px: where the template's reference point lies in the frame.
        angle_deg: the part's turn in the image against the template, in the symmetry
            period's half-open interval (-180/kappa, 180/kappa].
        correlation: the final normalised correlation of the frame and the warped template.
        refined: whether ECC converged (otherwise the result is the scan's best step, turned
            about the blob centre).
        scan_deg: the scan's best step.
    """

    u_px: float
    v_px: float
    angle_deg: float
    correlation: float
    refined: bool
    scan_deg: float


def _inverse_turn(angle_deg: float, centre: float) -> np.ndarray:
    """The 2x3 map from a turned template's pixels back to the template's (turn about the
    square's centre by ``angle_deg``, image axes)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    rt = np.array([[c, s], [-s, c]])  # R(a) transposed
    return np.hstack([rt, (np.array([centre, centre]) - rt @ (centre, centre))[:, None]])


def _unit(vectors: np.ndarray) -> np.ndarray:
    """Rows made zero-mean and unit-norm (a flat row stays zero)."""
    v = vectors - vectors.mean(axis=-1, keepdims=True)
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, norm, out=np.zeros_like(v), where=norm > 0)


def wrap_deg(angle_deg: float, period_deg: float) -> float:
    """``angle_deg`` in (-period/2, period/2]."""
    wrapped = math.remainder(angle_deg, period_deg)
    return period_deg / 2.0 if wrapped == -period_deg / 2.0 else wrapped


@dataclass(frozen=True, eq=False)
class Template:
    """The taught silhouette and its turned copies for the scan.

    Attributes:
        image: (T, T) float32, the mean silhouette around the reference point, which lies at
            its centre ((T - 1) / 2, (T - 1) / 2).
        kappa: the part's symmetry count (the scan covers 360 / kappa deg).
        scan_step_deg: the scan's step.
        ecc_iterations, ecc_epsilon: ECC's stopping rule.
    """

    image: np.ndarray
    kappa: int
    scan_step_deg: float
    ecc_iterations: int
    ecc_epsilon: float
    _turned: np.ndarray = field(init=False, repr=False)
    _steps: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        image = np.ascontiguousarray(self.image, dtype=np.float32)
        if image.ndim != 2 or image.shape[0] != image.shape[1] or image.shape[0] < 8 \
                or not np.isfinite(image).all() or not image.any():
            raise ValueError(f"align template: expected a square finite non-empty image of "
                             f"at least 8 px, got {image.shape}")
        object.__setattr__(self, "image", image)
        period = 360.0 / self.kappa
        n = max(1, math.ceil(period / self.scan_step_deg))
        steps = np.array([wrap_deg(k * period / n, period) for k in range(n)])
        size = image.shape[0]
        centre = (size - 1) / 2.0
        turned = np.stack([cv2.warpAffine(image, _inverse_turn(a, centre), (size, size),
                                          flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                          borderMode=cv2.BORDER_CONSTANT).ravel()
                           for a in steps])
        object.__setattr__(self, "_turned", _unit(turned.astype(np.float64)))
        object.__setattr__(self, "_steps", steps)

    @property
    def size(self) -> int:
        return int(self.image.shape[0])

    def register(self, frame: np.ndarray, u_px: float, v_px: float) -> Registration:
        """Register ``frame`` (the soft silhouette of the whole frame, float32) with the part's
        blob centre at (u_px, v_px) as the seed.

        ECC that does not converge (an occluded or foreign blob) leaves the scan's result, with
        its correlation, and ``refined`` False. The turn is the rotation part of the affine
        warp A = R S (S symmetric): atan2(A10 - A01, A00 + A11).
        """
        size = self.size
        centre = (size - 1) / 2.0
        window = cv2.getRectSubPix(frame, (size, size), (float(u_px), float(v_px)))
        scores = self._turned @ _unit(window.ravel().astype(np.float64))
        best = int(np.argmax(scores))
        scan = float(self._steps[best])
        warp = _warp(scan, centre, u_px, v_px)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, self.ecc_iterations,
                    self.ecc_epsilon)
        try:
            correlation, warp = cv2.findTransformECC(self.image, frame, warp.copy(),
                                                     cv2.MOTION_AFFINE, criteria, None, 1)
            # a warp that shrinks, grows or flips the part is no view of it from this camera
            area = float(np.linalg.det(warp[:, :2])) if np.isfinite(warp).all() else 0.0
            refined = MIN_AREA_RATIO <= area <= 1.0 / MIN_AREA_RATIO
        except cv2.error:
            refined = False
        if not refined:
            warp = _warp(scan, centre, u_px, v_px)
            correlation = float(scores[best])
        u, v = warp @ (centre, centre, 1.0)
        turn = math.atan2(warp[1, 0] - warp[0, 1], warp[0, 0] + warp[1, 1])
        angle = wrap_deg(math.degrees(turn), 360.0 / self.kappa)
        return Registration(float(u), float(v), angle, float(correlation), refined, scan)


def _warp(angle_deg: float, centre: float, u_px: float, v_px: float) -> np.ndarray:
    """The seed warp (template pixel -> frame pixel) that turns the template by
    ``angle_deg`` about its centre and lays that centre on (u_px, v_px)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    r = np.array([[c, -s], [s, c]])
    t = np.array([u_px, v_px]) - r @ (centre, centre)
    return np.hstack([r, t[:, None]]).astype(np.float32)
