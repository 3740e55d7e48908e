"""The measured outline angle -> the corrective rotation, learned (Hough system, paper 4.3).

Seen vertically, the outline's angle is the part's rotation plus a constant. A tilted camera
foreshortens the outline, so the measured angle runs ahead of or behind the rotation, by an
amount that repeats every 360 / kappa. The map is a short Fourier series in the measured angle,
fitted by least squares to the (sin, cos) code of the labelled rotation (``angles.encode``) and
decoded with atan2, so it is continuous across the symmetry wrap:

    (sin, cos)(kappa dphi) ~ C^T [1, cos(kappa psi), sin(kappa psi), ..., sin(H kappa psi)]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration_free import angles
from calibration_free.errors import TrainingError
from drivers.core.errors import ConfigError


def _design(psi_deg: np.ndarray, kappa: int, harmonics: int) -> np.ndarray:
    a = np.radians(np.asarray(psi_deg, dtype=np.float64)) * kappa
    cols = [np.ones_like(a)]
    for h in range(1, harmonics + 1):
        cols += [np.cos(h * a), np.sin(h * a)]
    return np.stack(cols, axis=-1)


@dataclass(frozen=True, eq=False)
class AngleMap:
    """A fitted map. coefficients: (1 + 2 * harmonics, 2) for (sin, cos) of kappa dphi."""

    kappa: int
    harmonics: int
    coefficients: np.ndarray

    def __post_init__(self) -> None:
        c = np.asarray(self.coefficients, dtype=np.float64)
        if isinstance(self.harmonics, bool) or not isinstance(self.harmonics, int) \
                or self.harmonics < 1 or c.shape != (1 + 2 * self.harmonics, 2) \
                or not np.isfinite(c).all():
            raise ConfigError(f"angle map: need harmonics >= 1 and finite "
                              f"({1 + 2 * self.harmonics}, 2) coefficients, got {c.shape}")
        if isinstance(self.kappa, bool) or not isinstance(self.kappa, int) or self.kappa < 1:
            raise ConfigError(f"kappa: must be a whole number >= 1, got {self.kappa!r}")
        object.__setattr__(self, "coefficients", c)

    def code(self, psi_deg: float) -> tuple[float, float]:
        """The (sin, cos) of kappa dphi the map gives for the measured angle."""
        s, c = _design(np.array(psi_deg), self.kappa, self.harmonics) @ self.coefficients
        return float(s), float(c)

    def __call__(self, psi_deg: float) -> float:
        """The corrective rotation (deg, in (-180/kappa, 180/kappa]) for the measured angle."""
        return float(angles.decode(*self.code(psi_deg), self.kappa))


def fit_angle_map(psi_deg: np.ndarray, dphi_deg: np.ndarray, kappa: int,
                  harmonics: int = 2) -> AngleMap:
    """Least-squares fit of the map from measured angles to labelled rotations.

    Raises:
        TrainingError: sizes differ, values are not finite, or there are fewer samples than
            coefficients.
        ConfigError: kappa or harmonics invalid.
    """
    psi = np.asarray(psi_deg, dtype=np.float64).ravel()
    dphi = np.asarray(dphi_deg, dtype=np.float64).ravel()
    if psi.shape != dphi.shape or not (np.isfinite(psi).all() and np.isfinite(dphi).all()):
        raise TrainingError(f"angle map: need equally many finite angles and rotations, got "
                            f"{psi.shape} and {dphi.shape}")
    if isinstance(harmonics, bool) or not isinstance(harmonics, int) or harmonics < 1:
        raise ConfigError(f"harmonics: must be a whole number >= 1, got {harmonics!r}")
    if psi.size < 1 + 2 * harmonics:
        raise TrainingError(f"angle map: {psi.size} samples cannot fit {1 + 2 * harmonics} "
                            f"coefficients")
    s, c = angles.encode(dphi, kappa)
    coefficients, *_ = np.linalg.lstsq(_design(psi, kappa, harmonics), np.stack([s, c], 1),
                                       rcond=None)
    return AngleMap(int(kappa), harmonics, coefficients)
