"""Eigenimages: reconstruction error falls with m and vanishes at the data's rank."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.pca.eigenimages import Eigenimages, fit_eigenimages, roi_vector
from calibration_free.errors import ImageError, TrainingError


@pytest.fixture()
def low_rank_images() -> np.ndarray:
    """20 'images' of 100 px: a mean plus combinations of 4 patterns, plus nothing else."""
    rng = np.random.default_rng(3)
    patterns = rng.normal(size=(4, 100))
    return 5.0 + rng.normal(size=(20, 4)) * [4.0, 2.0, 1.0, 0.5] @ patterns


def reconstruction_error(eigen: Eigenimages, x: np.ndarray) -> float:
    return float(np.linalg.norm(eigen.reconstruct(eigen.project(x)) - x))


def test_reconstruction_error_falls_with_m_and_is_zero_at_the_rank(low_rank_images):
    errors = [reconstruction_error(fit_eigenimages(low_rank_images, m), low_rank_images)
              for m in (1, 2, 3, 4)]
    assert all(a > b for a, b in zip(errors, errors[1:], strict=False))
    assert errors[-1] < 1e-9 * np.linalg.norm(low_rank_images)


def test_eigenimages_are_orthonormal_and_ordered(low_rank_images):
    eigen = fit_eigenimages(low_rank_images, 3)
    np.testing.assert_allclose(eigen.basis @ eigen.basis.T, np.eye(3), atol=1e-12)
    variances = eigen.project(low_rank_images).var(axis=0)
    assert (np.diff(variances) < 0).all()
    assert 0.9 < eigen.explained_variance < 1.0
    assert eigen.project(low_rank_images[0]).shape == (3,)


def test_m_beyond_the_rank_and_bad_data_are_refused(low_rank_images):
    with pytest.raises(TrainingError, match=r"1\.\.4"):
        fit_eigenimages(low_rank_images, 5)
    with pytest.raises(TrainingError, match="two finite"):
        fit_eigenimages(low_rank_images[:1], 1)
    with pytest.raises(ImageError, match="100 values"):
        fit_eigenimages(low_rank_images, 2).project(np.zeros(99))


def test_roi_vector_is_unit_length_and_brightness_invariant():
    roi = np.random.default_rng(0).uniform(10, 200, (50, 50)).astype(np.float32)
    v = roi_vector(roi)
    assert v.shape == (2500,) and abs(np.linalg.norm(v) - 1.0) < 1e-12
    np.testing.assert_allclose(roi_vector(roi * 0.4), v, atol=1e-7)
    with pytest.raises(ImageError, match="all zero"):
        roi_vector(np.zeros((4, 4), np.float32))
