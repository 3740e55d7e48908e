"""The PCA system end to end on synthetic cubes: training, accuracy, model file."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.pca.model import PcaConfig, PcaModel
from calibration_free.baselines.pca.train import train_pca
from calibration_free.errors import BundleError, ImageError, TrainingError
from calibration_free.model_file import pack_model
from calibration_free.synthetic import render
from drivers.core.errors import ConfigError
from tests.synthetic_scene import KAPPA, NOMINAL_POSE, wrapped_error_deg


def test_recovers_rotation_and_translation_on_unseen_poses(pca_model, near_test_set):
    percepts = [pca_model.perceive(im) for im in near_test_set.images]
    assert all(p.dphi_deg is not None for p in percepts)
    rot = wrapped_error_deg([p.dphi_deg for p in percepts], near_test_set.labels[:, 2])
    trans = np.array([p.nn1_mm for p in percepts]) - near_test_set.labels[:, :2]
    assert np.sqrt(np.mean(rot ** 2)) < 3.0  # measured 1.1 deg
    assert np.sqrt(np.mean(trans ** 2)) < 0.5  # measured 0.13 mm
    assert pca_model.feature_count == 3 and percepts[0].features.shape == (3,)


def test_translation_only_path_and_an_empty_table(pca_model, cell):
    frame = render(cell, np.array([3.0, -2.0, 20.0]))
    fast = pca_model.translation(frame)
    assert fast.features is None and fast.nn1_mm is not None
    empty = np.full_like(frame, 125)
    p = pca_model.perceive(empty)
    assert p.localisation.status == "no_object" and p.nn1_mm is None
    with pytest.raises(ImageError, match="trained on 192x144"):
        pca_model.perceive(frame[:100])


def test_round_trip_gives_the_same_answers(pca_model, cell, tmp_path):
    path = tmp_path / "cube.pca"
    pca_model.save(path)
    again = PcaModel.load(path, expect_object="cube")
    frame = render(cell, np.array([2.0, -3.0, 12.0]), np.random.default_rng(0))
    a, b = pca_model.perceive(frame), again.perceive(frame)
    assert (a.nn1_mm, a.fc_sc, a.dphi_deg) == (b.nn1_mm, b.fc_sc, b.dphi_deg)
    assert again.config == pca_model.config and again.front == pca_model.front
    assert again.training["images"] == 126
    with pytest.raises(BundleError, match="taught on object 'cube', not 'nut'"):
        PcaModel.load(path, expect_object="nut")


def test_a_file_without_channel_and_nominal_uv_loads_as_before(pca_model, cell, tmp_path):
    """Baseline files from before the front end stored its channel and the taught pose's
    image position: localisation in max(R, G, B), several matching blobs ambiguous."""
    info = pca_model.to_info()
    del info["localisation"]["channel"], info["localisation"]["nominal_uv_px"]
    path = tmp_path / "old.pca"
    path.write_bytes(pack_model("pca", 1, info, pca_model.arrays()))
    old = PcaModel.load(path)
    assert old.front == pca_model.front
    assert (old.front.channel, old.front.nominal_uv_px) == ("max", None)
    frame = render(cell, np.array([2.0, -3.0, 12.0]), np.random.default_rng(0))
    a, b = pca_model.perceive(frame), old.perceive(frame)
    assert (a.nn1_mm, a.fc_sc, a.dphi_deg) == (b.nn1_mm, b.fc_sc, b.dphi_deg)


def test_corrupt_file_is_refused(pca_model, tmp_path):
    path = tmp_path / "cube.pca"
    pca_model.save(path)
    data = bytearray(path.read_bytes())
    data[-11] ^= 0x20
    path.write_bytes(bytes(data))
    with pytest.raises(BundleError, match="checksum"):
        PcaModel.load(path)


def test_more_eigenimages_fit_the_training_rotations_better(grids):
    nn1, nn2 = grids
    fits = [train_pca(nn1, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE,
                      config=PcaConfig(eigenimages=m, fuzzy_sets=4))
            for m in (1, 3)]
    assert fits[0].training["fuzzy"]["fit_rms"] > fits[1].training["fuzzy"]["fit_rms"]
    assert fits[0].eigen.explained_variance < fits[1].eigen.explained_variance


def test_bad_configs_and_arguments_are_refused(grids):
    with pytest.raises(ConfigError, match="rules"):
        PcaConfig(eigenimages=6, fuzzy_sets=5)
    with pytest.raises(ConfigError, match="fuzzy_order"):
        PcaConfig(fuzzy_sets=2, fuzzy_order=3)
    with pytest.raises(TrainingError, match="kappa"):
        train_pca(*grids, object_kind="cube", kappa=0, nominal_pose=NOMINAL_POSE)
