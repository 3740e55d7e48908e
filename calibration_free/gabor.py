"""Gabor filter bank of Eq. (1)-(2) of the paper, and the features it computes on an ROI.

Kernel for centre (p, q), orientation theta, in ROI edge coordinates (pixel (i, j) has its centre
at x = j + 0.5, y = i + 0.5; y points down the image; a 50 px ROI spans [0, 50] with its centre
at 25):

    dx, dy   = x - p, y - q
    x'       =  dx cos(theta) + dy sin(theta)
    y'       = -dx sin(theta) + dy cos(theta)
    g        = exp(-(x'^2 + alpha^2 y'^2) / (2 sigma^2))
    even     = g * (cos(2 pi x' / lambda) - c_even)
    odd      = g * (-sin(2 pi x' / lambda) - c_odd)      (imaginary part of Eq. (1))

The constants c are the envelope-weighted means of the wave over the window, so every kernel
sums to exactly zero on the (possibly clipped) window: a constant image gives 0 (reading note 2;
for an unclipped even kernel c tends to the analytic exp(-2 pi^2 sigma^2 / lambda^2)).
The paper's dilation 2^-m is not a separate parameter: it is a choice of lambda and sigma.

Filter order: centres row-major (q outer, p inner), orientations innermost; with the default
3 x 3 centres and 4 orientations, feature k belongs to q = centres[k // 12],
p = centres[(k // 4) % 3], theta = orientations[k % 4].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from calibration_free.errors import ImageError
from drivers.core.errors import ConfigError

Kind = Literal["even", "odd", "magnitude"]


@dataclass(frozen=True)
class GaborConfig:
    """Filter-bank configuration; the default is the paper's winning set of 36 even filters.

    Attributes:
        centres_px: filter centres along each ROI axis, in ROI edge coordinates; the bank uses
            every (p, q) pair (3 x 3 grid by default, reading note 1: 13, 25, 37).
        orientations_deg: filter orientations theta.
        lambda_px: wavelength of the planar wave.
        sigma_px: width of the Gaussian envelope along the wave.
        alpha: aspect ratio; the envelope is sigma / alpha wide across the wave (reading note 4).
        kind: "even" (cosine), "odd" (sine) or "magnitude" (sqrt(even^2 + odd^2) responses).
        roi_px: side of the square ROI the kernels are laid out on.
    """

    centres_px: tuple[float, ...] = field(default=(13.0, 25.0, 37.0), metadata={"min": 0.0})
    orientations_deg: tuple[float, ...] = (0.0, 45.0, 90.0, 135.0)
    lambda_px: float = field(default=30.0, metadata={"min": 0.0, "exclusive_min": True})
    sigma_px: float = field(default=12.5, metadata={"min": 0.0, "exclusive_min": True})
    alpha: float = field(default=1.0, metadata={"min": 0.0, "exclusive_min": True})
    kind: Kind = "even"
    roi_px: int = field(default=50, metadata={"min": 1, "max": 512})  # max: a camera image

    def __post_init__(self) -> None:
        if not self.centres_px or not self.orientations_deg:
            raise ConfigError("gabor: centres_px and orientations_deg must not be empty")
        if any(not 0.0 <= c <= self.roi_px for c in self.centres_px):
            raise ConfigError(f"gabor.centres_px: every centre must lie in [0, {self.roi_px}] "
                              f"(the ROI), got {list(self.centres_px)}")
        if self.kind not in ("even", "odd", "magnitude"):
            raise ConfigError(f"gabor.kind: must be even, odd or magnitude, got {self.kind!r}")

    @property
    def n_filters(self) -> int:
        """Number of features the bank produces."""
        return len(self.centres_px) ** 2 * len(self.orientations_deg)


def gabor_kernel(p_px: float, q_px: float, theta_deg: float, config: GaborConfig,
                 phase: Literal["even", "odd"]) -> np.ndarray:
    """One DC-free Gabor kernel on the roi_px x roi_px window, as float64 (see module doc)."""
    coords = np.arange(config.roi_px, dtype=np.float64) + 0.5
    dx = coords[None, :] - p_px
    dy = coords[:, None] - q_px
    theta = math.radians(theta_deg)
    xr = dx * math.cos(theta) + dy * math.sin(theta)
    yr = -dx * math.sin(theta) + dy * math.cos(theta)
    envelope = np.exp(-(xr**2 + config.alpha**2 * yr**2) / (2.0 * config.sigma_px**2))
    arg = 2.0 * math.pi * xr / config.lambda_px
    wave = np.cos(arg) if phase == "even" else -np.sin(arg)
    dc = float((envelope * wave).sum() / envelope.sum())
    return envelope * (wave - dc)


def _bank(config: GaborConfig, phase: Literal["even", "odd"]) -> np.ndarray:
    return np.stack([gabor_kernel(p, q, theta, config, phase)
                     for q in config.centres_px
                     for p in config.centres_px
                     for theta in config.orientations_deg])


class GaborBank:
    """The configured kernels, applied to an ROI as one matrix-vector product.

    Attributes:
        config: the GaborConfig it was built from.
        kernels: (n, roi, roi) float64 kernels; for kind "magnitude" complex128 with the even
            kernel as real and the odd kernel as imaginary part (the DC-free Eq. (1)).
    """

    def __init__(self, config: GaborConfig = GaborConfig()):
        self.config = config
        self._n = config.n_filters
        if config.kind == "magnitude":
            even, odd = _bank(config, "even"), _bank(config, "odd")
            self.kernels = even + 1j * odd
            rows = np.concatenate([even, odd])
        else:
            self.kernels = _bank(config, config.kind)
            rows = self.kernels
        self._matrix = np.ascontiguousarray(
            rows.reshape(rows.shape[0], -1).astype(np.float32))
        self._shape = (config.roi_px, config.roi_px)

    @property
    def n_features(self) -> int:
        return self._n

    def features(self, roi: np.ndarray) -> np.ndarray:
        """The n scalar products of the kernels with ``roi``, as float32.

        Raises:
            ImageError: ``roi`` is not a roi_px x roi_px float32 array.
        """
        if not isinstance(roi, np.ndarray) or roi.shape != self._shape \
                or roi.dtype != np.float32:
            raise ImageError(f"ROI: expected {self._shape} float32, got "
                             f"{getattr(roi, 'shape', None)} {getattr(roi, 'dtype', type(roi))}")
        responses = self._matrix @ roi.reshape(-1)
        if self.config.kind == "magnitude":
            return np.hypot(responses[:self._n], responses[self._n:])
        return responses
