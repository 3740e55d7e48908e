"""Shared fixtures of the baseline tests: the synthetic cube scene, its training grids, a test
set, and the baseline systems trained once per session."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.align.model import AlignModel
from calibration_free.baselines.align.train import train_align
from calibration_free.baselines.hough.model import HoughModel
from calibration_free.baselines.hough.train import train_hough
from calibration_free.baselines.pca.model import PcaModel
from calibration_free.baselines.pca.train import train_pca
from calibration_free.dataset import Dataset, random_offsets
from calibration_free.synthetic import render_dataset
from tests.synthetic_scene import KAPPA, NOMINAL_POSE  # noqa: F401  (re-exported)


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


@pytest.fixture(scope="session")
def align_model(grids) -> AlignModel:
    nn1, nn2 = grids
    return train_align(nn1, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE)
