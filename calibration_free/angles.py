"""Angle codec for an object with kappa-fold rotational symmetry (Eq. (3), reading note 3).

An object that looks the same after a turn of 360/kappa degrees has no defined rotation beyond
that period, so NN2 learns (sin(kappa dphi), cos(kappa dphi)), which is continuous across the
wrap, and the rotation is decoded with atan2 into the shortest correction
(-180/kappa, 180/kappa] degrees.
"""

from __future__ import annotations

import math

import numpy as np

from drivers.core.errors import ConfigError

ArrayOrFloat = np.ndarray | float


def _check_kappa(kappa: int) -> None:
    if isinstance(kappa, bool) or not isinstance(kappa, (int, np.integer)) or kappa < 1:
        raise ConfigError(f"kappa: must be a whole number >= 1, got {kappa!r}")


def encode(dphi_deg: ArrayOrFloat, kappa: int) -> tuple[ArrayOrFloat, ArrayOrFloat]:
    """(sin(kappa dphi), cos(kappa dphi)) of a rotation in degrees (scalar or array).

    Raises:
        ConfigError: kappa is not a whole number >= 1.
    """
    _check_kappa(kappa)
    angle_rad = np.radians(np.asarray(dphi_deg, dtype=np.float64)) * kappa
    s, c = np.sin(angle_rad), np.cos(angle_rad)
    if np.ndim(dphi_deg) == 0:
        return float(s), float(c)
    return s, c


def decode(s: ArrayOrFloat, c: ArrayOrFloat, kappa: int) -> ArrayOrFloat:
    """The rotation in (-180/kappa, 180/kappa] degrees whose code is (s, c).

    (s, c) need not be on the unit circle (network outputs are not); only their direction
    counts. (0, 0) decodes to 0.

    Raises:
        ConfigError: kappa is not a whole number >= 1.
    """
    _check_kappa(kappa)
    half_period_deg = 180.0 / kappa
    if np.ndim(s) == 0 and np.ndim(c) == 0:
        dphi = math.degrees(math.atan2(s, c)) / kappa
        return dphi + 2.0 * half_period_deg if dphi <= -half_period_deg else dphi
    dphi = np.degrees(np.arctan2(s, c)) / kappa
    return np.where(dphi <= -half_period_deg, dphi + 2.0 * half_period_deg, dphi)
