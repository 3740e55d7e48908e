"""Eigenimages: the principal components of a set of image vectors (paper section 2.2).

The eigenimages are the eigenvectors of the covariance matrix of the training vectors with the
largest eigenvalues. They are computed from the SVD of the centred (c x n) data matrix, which
gives the same vectors without ever forming the n x n covariance matrix (the paper's hours of
training went into that matrix on 1999 hardware). A vector is represented by its m projections
on the eigenimages.

ROI vectors follow Murase and Nayar (ref. [5]): the ROI of the normalised image, flattened and
scaled to unit length, so a global change of brightness inside the ROI does not move the
projections.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration_free.errors import ImageError, TrainingError

# Singular values below this fraction of the largest count as zero (rank deficiency).
RANK_TOLERANCE = 1e-10


@dataclass(frozen=True, eq=False)
class Eigenimages:
    """The mean vector and the leading principal directions of a training set.

    Attributes:
        mean: (n,) mean training vector.
        basis: (m, n) orthonormal eigenimages, by decreasing eigenvalue.
        singular_values: all singular values of the centred data matrix (eigenvalue_j =
            s_j ** 2 / c), kept to report how much variance m components hold.
    """

    mean: np.ndarray
    basis: np.ndarray
    singular_values: np.ndarray

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=np.float64)
        basis = np.asarray(self.basis, dtype=np.float64)
        sv = np.asarray(self.singular_values, dtype=np.float64)
        if mean.ndim != 1 or basis.ndim != 2 or basis.shape[1] != mean.size \
                or basis.shape[0] < 1 or sv.ndim != 1:
            raise ImageError(f"eigenimages: need a (n,) mean and an (m, n) basis, got "
                             f"{mean.shape} and {basis.shape}")
        if not (np.isfinite(mean).all() and np.isfinite(basis).all()
                and np.isfinite(sv).all()):
            raise ImageError("eigenimages: values must be finite")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "basis", basis)
        object.__setattr__(self, "singular_values", sv)

    @property
    def m(self) -> int:
        return self.basis.shape[0]

    @property
    def explained_variance(self) -> float:
        """Fraction of the training set's variance the m eigenimages hold."""
        power = self.singular_values ** 2
        total = float(power.sum())
        return float(power[: self.m].sum() / total) if total > 0 else 1.0

    def project(self, x: np.ndarray) -> np.ndarray:
        """The m projections of one vector (n,) or a batch (N, n) on the eigenimages.

        Raises:
            ImageError: the vectors do not have n finite components.
        """
        x = np.asarray(x, dtype=np.float64)
        if x.shape[-1] != self.mean.size or x.ndim not in (1, 2) or not np.isfinite(x).all():
            raise ImageError(f"eigenimages: expected finite vectors of {self.mean.size} "
                             f"values, got shape {x.shape}")
        return (x - self.mean) @ self.basis.T

    def reconstruct(self, p: np.ndarray) -> np.ndarray:
        """The vector(s) the projections ``p`` (m,) or (N, m) stand for."""
        return self.mean + np.asarray(p, dtype=np.float64) @ self.basis


def fit_eigenimages(vectors: np.ndarray, m: int) -> Eigenimages:
    """The m leading eigenimages of the training vectors (rows of ``vectors``).

    Args:
        vectors: (c, n) training vectors, c >= 2.
        m: number of eigenimages, 1 <= m <= rank of the centred data.

    Raises:
        TrainingError: fewer than two vectors, non-finite values, or m outside 1..rank.
    """
    x = np.asarray(vectors, dtype=np.float64)
    if x.ndim != 2 or x.shape[0] < 2 or not np.isfinite(x).all():
        raise TrainingError(f"eigenimages: need at least two finite vectors (c, n), got "
                            f"{x.shape}")
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    rank = int(np.count_nonzero(s > RANK_TOLERANCE * s[0])) if s[0] > 0 else 0
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or not 1 <= m <= rank:
        raise TrainingError(f"eigenimages: m must be a whole number in 1..{rank} (the rank of "
                            f"the {x.shape[0]} centred training vectors), got {m!r}")
    return Eigenimages(mean, vt[:m], s)


def roi_vector(roi: np.ndarray) -> np.ndarray:
    """A ROI (HxW float32 of the normalised image) as a unit-length float64 vector.

    Raises:
        ImageError: the ROI is not a non-empty finite 2-D array, or it is all zero.
    """
    if not isinstance(roi, np.ndarray) or roi.ndim != 2 or roi.size == 0 \
            or not np.isfinite(roi).all():
        raise ImageError(f"ROI: expected a finite HxW array, got {getattr(roi, 'shape', None)}")
    v = roi.astype(np.float64).ravel()
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        raise ImageError("ROI: all zero, cannot scale to unit length")
    return v / norm
