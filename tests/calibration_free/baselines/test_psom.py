"""PSOM: exact at its nodes, smooth between them, and completion inverts the manifold."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.hough.psom import PSOM, lagrange
from calibration_free.errors import ImageError, TrainingError


def smooth(a: np.ndarray) -> np.ndarray:
    """A smooth map (x, y, z) -> 5 components: 3 'features', 2 'commands'."""
    x, y, z = a[..., 0], a[..., 1], a[..., 2]
    return np.stack([10 * x + 2 * y * z, 8 * y - x * x + z, 5 * z + 0.5 * x * y,
                     np.sin(x) + 0.3 * y, np.cos(y) * (1 + 0.1 * z)], axis=-1)


@pytest.fixture()
def psom() -> PSOM:
    levels = np.array([-1.0, 0.0, 1.0])
    grid = np.stack(np.meshgrid(levels, levels, levels, indexing="ij"), axis=-1)
    weights = smooth(grid)
    scale = weights[..., :3].reshape(-1, 3).std(axis=0)
    return PSOM((np.arange(3.0),) * 3, weights, (0, 1, 2), scale)


def test_lagrange_basis_is_a_partition_with_the_right_derivative():
    nodes = np.array([0.0, 1.0, 2.5])
    np.testing.assert_allclose(lagrange(1.0, nodes)[0], [0, 1, 0], atol=1e-12)
    for s in (-0.3, 0.7, 1.9):
        values, derivs = lagrange(s, nodes)
        assert abs(values.sum() - 1.0) < 1e-12
        numeric = (lagrange(s + 1e-6, nodes)[0] - lagrange(s - 1e-6, nodes)[0]) / 2e-6
        np.testing.assert_allclose(derivs, numeric, atol=1e-6)


def test_interpolates_its_training_nodes_exactly(psom):
    for index in np.ndindex(3, 3, 3):
        np.testing.assert_allclose(psom.at(np.array(index, dtype=float)),
                                   psom.weights[index], atol=1e-12)


# Lagrange remainder of 3-node interpolation on [-1, 1]: max|d3f| / 3! * max|(x+1) x (x-1)|
# = 1/6 * 2/(3 sqrt 3) = 0.064 for sin; the other components are quadratic per axis (exact).
SIN_BOUND = 0.065


def test_between_nodes_it_follows_a_smooth_function(psom):
    rng = np.random.default_rng(0)
    for s in rng.uniform(0.0, 2.0, (30, 3)):
        error = np.abs(psom.at(s) - smooth(s - 1.0))  # parameters 0..2 stand for -1..1
        assert error[:3].max() < 1e-12
        assert error[3:].max() < SIN_BOUND


def test_completion_recovers_the_commands_from_the_features(psom):
    rng = np.random.default_rng(1)
    for a in rng.uniform(-0.9, 0.9, (20, 3)):
        full = smooth(a)
        s, w = psom.complete(full[:3])
        np.testing.assert_allclose(w[:3], full[:3], atol=1e-8)
        np.testing.assert_allclose(s, a + 1.0, atol=0.05)
        np.testing.assert_allclose(w[3:], full[3:], atol=SIN_BOUND)


def test_jacobian_matches_finite_differences(psom):
    s = np.array([0.3, 1.4, 0.8])
    numeric = np.stack([(psom.at(s + h) - psom.at(s - h)) / 2e-6
                        for h in np.eye(3) * 1e-6], axis=1)
    np.testing.assert_allclose(psom.jacobian(s), numeric, atol=1e-5)


def test_bad_psoms_and_inputs_are_refused(psom):
    with pytest.raises(TrainingError, match="do not fit"):
        PSOM((np.arange(3.0),) * 2, psom.weights, (0, 1), np.ones(2))
    with pytest.raises(TrainingError, match="increasing"):
        PSOM((np.array([0.0, 0.0, 1.0]),) * 3, psom.weights, (0, 1, 2), np.ones(3))
    with pytest.raises(TrainingError, match="inputs"):
        PSOM(psom.nodes, psom.weights, (0, 0, 1), np.ones(3))
    with pytest.raises(ImageError, match="3 finite inputs"):
        psom.complete(np.array([1.0, np.nan, 0.0]))
