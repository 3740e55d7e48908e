"""Shared fixtures of the baseline tests: the synthetic cube scene, its training grids, a test
set, and both baseline systems trained once per session."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.hough_model import HoughModel
from calibration_free.baselines.hough_train import train_hough
from calibration_free.baselines.pca_model import PcaModel
from calibration_free.baselines.pca_train import train_pca
from calibration_free.dataset import Dataset, grid_offsets, random_offsets
from calibration_free.synthetic import SyntheticCell, render_dataset

KAPPA = 4
NOMINAL_POSE = {"x_mm": 10.0, "y_mm": 400.0, "z_mm": 120.0, "o_deg": -90.0, "a_deg": 90.0,
                "t_deg": 5.0}


@pytest.fixture(scope="session")
def cell() -> SyntheticCell:
    return SyntheticCell()


@pytest.fixture(scope="session")
def grids(cell) -> tuple[Dataset, Dataset]:
    """The paper's training sets: 3x3x7 grids with a = 25 mm (NN1) and 5 mm (NN2)."""
    rng = np.random.default_rng(1)
    return (render_dataset(cell, grid_offsets(25.0, 180.0 / KAPPA), rng),
            render_dataset(cell, grid_offsets(5.0, 180.0 / KAPPA), rng))


@pytest.fixture(scope="session")
def near_test_set(cell) -> Dataset:
    """Random poses within the NN2 range (where full loops run), unseen in training."""
    rng = np.random.default_rng(7)
    return render_dataset(cell, random_offsets(rng, 30, 5.0, 180.0 / KAPPA), rng)


@pytest.fixture(scope="session")
def pca_model(grids) -> PcaModel:
    nn1, nn2 = grids
    return train_pca(nn1, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE,
                     nn1_extra=nn2, seed=0)


@pytest.fixture(scope="session")
def hough_model(grids) -> HoughModel:
    nn1, nn2 = grids
    return train_hough(nn1, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE)


def wrapped_error_deg(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Rotation errors folded into the symmetry period (-180/kappa, 180/kappa]."""
    half = 180.0 / KAPPA
    return (np.asarray(estimate) - np.asarray(truth) + half) % (2 * half) - half
