"""The synthetic cube scene shared by the perception and baseline tests: its constants and
fixtures (made once per test session, whichever folder asks first)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.dataset import Dataset, grid_offsets, staggered_grid_offsets
from calibration_free.synthetic import SyntheticCell, render_dataset

KAPPA = 4
NOMINAL_POSE = {"x_mm": 10.0, "y_mm": 400.0, "z_mm": 120.0, "o_deg": -90.0, "a_deg": 90.0,
                "t_deg": 5.0}


@pytest.fixture(scope="session")
def cell() -> SyntheticCell:
    return SyntheticCell()


@pytest.fixture(scope="session")
def grids(cell) -> tuple[Dataset, Dataset]:
    """The training sets as finepos acquires them: the paper's 3x3x7 grids with a = 25 mm
    (NN1) and 5 mm (NN2), NN2's rotations staggered over its positions (the default,
    ``controller.acquisition.nn2.staggered``)."""
    rng = np.random.default_rng(1)
    return (render_dataset(cell, grid_offsets(25.0, 180.0 / KAPPA), rng),
            render_dataset(cell, staggered_grid_offsets(5.0, 180.0 / KAPPA), rng))


def wrapped_error_deg(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Rotation errors folded into the symmetry period (-180/kappa, 180/kappa]."""
    half = 180.0 / KAPPA
    return (np.asarray(estimate) - np.asarray(truth) + half) % (2 * half) - half
