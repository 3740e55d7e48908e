"""Shared fixtures of the calibration-free tests: a synthetic cube scene and a trained bundle."""

from __future__ import annotations

import pytest

from calibration_free.bundle import ModelBundle
from calibration_free.training import TrainingSettings, train_bundle
from tests.synthetic_scene import KAPPA, NOMINAL_POSE  # noqa: F401  (re-exported)


def _train(grids, channel: str) -> ModelBundle:
    nn1_data, nn2_data = grids
    return train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                        nominal_pose=NOMINAL_POSE, nn1_extra=nn2_data,
                        settings=TrainingSettings(seed=0, localisation_channel=channel))


@pytest.fixture(scope="session")
def bundle(grids) -> ModelBundle:
    """The paper's path: localisation and features on normalised max(R, G, B)."""
    return _train(grids, "max")


@pytest.fixture(scope="session")
def saturation_bundle(grids) -> ModelBundle:
    """Trained with the channel chosen automatically (saturation, for a yellow part on grey)."""
    return _train(grids, "auto")
