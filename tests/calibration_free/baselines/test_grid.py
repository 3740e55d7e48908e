"""Recovering the acquisition grid from the labels, both as stored by synthetic sets and as
measured on the arm (translation turned by the rotation)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.grid import grid_indices
from calibration_free.dataset import grid_offsets
from calibration_free.errors import TrainingError


def turned(labels: np.ndarray) -> np.ndarray:
    """Labels as acquisition measures them: (dx, dy) turned by dphi, plus tiny pose noise."""
    a = np.radians(labels[:, 2])
    out = labels.copy()
    out[:, 0] = np.cos(a) * labels[:, 0] - np.sin(a) * labels[:, 1]
    out[:, 1] = np.sin(a) * labels[:, 0] + np.cos(a) * labels[:, 1]
    return out + np.random.default_rng(0).normal(0.0, 0.01, labels.shape)


@pytest.mark.parametrize("reading", [lambda x: x, turned])
def test_indices_and_levels_of_the_paper_grid(reading):
    grid = grid_offsets(25.0, 45.0)
    order = np.random.default_rng(1).permutation(len(grid))  # any acquisition order
    idx, levels = grid_indices(reading(grid[order]))
    np.testing.assert_allclose(levels[0], [-25, 0, 25], atol=0.05)
    np.testing.assert_allclose(levels[2], np.linspace(-45, 45, 7), atol=0.05)
    for k, (ix, iy, ip) in enumerate(idx):
        np.testing.assert_allclose([levels[0][ix], levels[1][iy], levels[2][ip]],
                                   grid[order][k], atol=0.05)


def test_incomplete_or_random_sets_are_refused():
    with pytest.raises(TrainingError, match="complete"):
        grid_indices(grid_offsets(25.0, 45.0)[:-1])
    with pytest.raises(TrainingError, match="complete"):
        grid_indices(np.random.default_rng(0).uniform(-25, 25, (63, 3)))
