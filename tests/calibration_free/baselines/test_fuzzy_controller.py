"""B-spline basis and the neuro-fuzzy controller: a fuzzy partition, and fits to known functions."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.pca.bspline import bspline_basis, clamped_knots
from calibration_free.baselines.pca.fuzzy_controller import (
    BSplineFuzzyController,
    fit_fuzzy_controller,
)
from calibration_free.errors import TrainingError
from drivers.core.errors import ConfigError


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_basis_is_a_fuzzy_partition(order):
    x = np.linspace(-1.5, 2.5, 401)  # beyond [lo, hi] = [-1, 2]: clamped
    b = bspline_basis(x, -1.0, 2.0, 6, order)
    assert b.shape == (401, 6)
    assert (b >= -1e-12).all()
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)


def test_order_two_memberships_are_triangles():
    b = bspline_basis(np.array([0.0, 0.25, 0.5, 1.0]), 0.0, 1.0, 3, 2)
    np.testing.assert_allclose(b, [[1, 0, 0], [0.5, 0.5, 0], [0, 1, 0], [0, 0, 1]], atol=1e-12)


def test_knots_and_bad_bases_are_checked():
    assert clamped_knots(0.0, 1.0, 5, 3).tolist() == [0, 0, 0, 1 / 3, 2 / 3, 1, 1, 1]
    with pytest.raises(ConfigError, match="n_basis"):
        bspline_basis(np.zeros(3), 0.0, 1.0, 2, 3)
    with pytest.raises(ConfigError, match="interval"):
        clamped_knots(1.0, 1.0, 4, 2)


def test_fits_a_smooth_1d_function_to_1e_3():
    x = np.linspace(0.0, np.pi, 40)[:, None]
    fc = fit_fuzzy_controller(x, np.sin(x), n_sets=9, order=3, smoothing=1e-7)
    grid = np.linspace(0.0, np.pi, 500)[:, None]  # between the training points, too
    assert np.abs(fc(grid) - np.sin(grid)).max() < 1e-3


def test_fits_two_outputs_of_three_inputs():
    rng = np.random.default_rng(0)
    x = rng.uniform(-1.0, 1.0, (300, 3))
    y = np.stack([x[:, 0] * x[:, 1] + 0.5 * x[:, 2], np.cos(x[:, 2]) - x[:, 0] ** 2], axis=1)
    fc = fit_fuzzy_controller(x, y, n_sets=5, order=3, smoothing=1e-6)
    probe = rng.uniform(-0.9, 0.9, (200, 3))
    truth = np.stack([probe[:, 0] * probe[:, 1] + 0.5 * probe[:, 2],
                      np.cos(probe[:, 2]) - probe[:, 0] ** 2], axis=1)
    assert np.abs(fc(probe) - truth).max() < 0.02
    assert fc(probe[0]).shape == (2,)
    np.testing.assert_allclose(fc.firing(probe).sum(axis=1), 1.0, atol=1e-12)


def test_smoothness_fills_rules_no_sample_fires():
    # samples only near the two ends of a line; the middle rules learn from the penalty
    x = np.concatenate([np.linspace(0.0, 0.2, 10), np.linspace(0.8, 1.0, 10)])[:, None]
    fc = fit_fuzzy_controller(x, 2.0 * x + 1.0, n_sets=9, order=2, smoothing=1e-3)
    assert abs(fc(np.array([0.5]))[0] - 2.0) < 0.01


def test_bad_training_data_is_refused():
    with pytest.raises(TrainingError, match="do not vary"):
        fit_fuzzy_controller(np.ones((5, 1)), np.zeros((5, 1)))
    with pytest.raises(TrainingError, match="rules"):
        fit_fuzzy_controller(np.random.default_rng(0).random((10, 6)), np.zeros((10, 1)),
                             n_sets=5)
    with pytest.raises(TrainingError, match="N >= 2"):
        fit_fuzzy_controller(np.zeros((3, 1)), np.zeros((4, 1)))
    with pytest.raises(ConfigError, match="smoothing"):
        fit_fuzzy_controller(np.zeros((3, 1)), np.zeros((3, 1)), smoothing=-1.0)


def test_controller_checks_its_parts_and_inputs():
    with pytest.raises(ConfigError, match="consequents"):
        BSplineFuzzyController(np.zeros(2), np.ones(2), 3, 2, np.zeros((8, 1)))
    fc = BSplineFuzzyController(np.zeros(2), np.ones(2), 3, 2, np.zeros((9, 1)))
    with pytest.raises(ConfigError, match="2 columns"):
        fc(np.zeros(3))
