"""The Hough system end to end on synthetic cubes: training, accuracy, honest failures, file."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.hough.model import HoughModel
from calibration_free.baselines.hough.train import train_hough
from calibration_free.dataset import random_offsets
from calibration_free.errors import BundleError, TrainingError
from calibration_free.synthetic import SyntheticCell, render, render_at, render_dataset
from tests.synthetic_scene import KAPPA, NOMINAL_POSE, wrapped_error_deg


def test_recovers_rotation_and_translation_on_unseen_poses(hough_model, near_test_set, cell):
    far = render_dataset(cell, random_offsets(np.random.default_rng(11), 20, 25.0, 45.0),
                         np.random.default_rng(12))
    for data, trans_tol_mm in ((near_test_set, 0.2), (far, 0.3)):
        percepts = [hough_model.perceive(im) for im in data.images]
        assert [p.status for p in percepts] == ["ok"] * len(data)
        rot = wrapped_error_deg([p.dphi_deg for p in percepts], data.labels[:, 2])
        trans = np.array([p.dxdy_mm for p in percepts]) - data.labels[:, :2]
        assert np.sqrt(np.mean(rot ** 2)) < 1.0  # measured 0.2 deg
        assert np.sqrt(np.mean(trans ** 2)) < trans_tol_mm  # measured 0.04 mm


def test_psom_is_exact_at_the_node_images(hough_model, grids):
    nn1 = grids[0]
    nodes = hough_model.psom.weights.reshape(-1, 5)
    assert nodes.shape[0] == 27  # the paper's 3 x 3 x 3
    for u, v, dphi, dx, dy in nodes[::4]:
        s, w = hough_model.psom.complete(np.array([u, v, dphi]))
        np.testing.assert_allclose(w[3:], (dx, dy), atol=1e-6)
    assert set(np.round(nodes[:, 2]).tolist()) == {-30.0, 0.0, 30.0}
    assert len(nn1) == 63


def test_no_straight_outline_is_no_object_with_the_reason(hough_model):
    # a round part with the cube's area (392 mm^2 = pi * (22.34 mm / 2)^2): found, no lines
    disc = SyntheticCell(side_mm=22.34, corner_mm=11.17, holes_mm=(), noise_std=0.0)
    p = hough_model.perceive(render_at(disc, 98.0, 70.0, 0.0))
    assert p.status == "no_object" and p.reason.startswith("Hough peaks rejected")
    assert p.dphi_deg is None and p.dxdy_mm is None and p.outline is not None
    empty = np.full((144, 192, 3), 125, np.uint8)
    assert hough_model.perceive(empty).status == "no_object"


def test_poor_contrast_makes_it_fail(hough_model, cell):
    dim = render(cell, np.array([1.0, 2.0, 10.0]), np.random.default_rng(3), gain=0.35)
    noisy = SyntheticCell(noise_std=25.0)
    bad = render(noisy, np.array([1.0, 2.0, 10.0]), np.random.default_rng(4), gain=0.35)
    assert hough_model.perceive(dim).status == "ok"  # normalisation copes with dim light
    assert hough_model.perceive(bad).status == "no_object"  # but not with noise on top


def test_round_trip_gives_the_same_answers(hough_model, cell, tmp_path):
    path = tmp_path / "cube.hough"
    hough_model.save(path)
    again = HoughModel.load(path, expect_object="cube")
    frame = render(cell, np.array([2.0, -3.0, 12.0]), np.random.default_rng(0))
    a, b = hough_model.perceive(frame), again.perceive(frame)
    assert (a.dxdy_mm, a.dphi_deg) == (b.dxdy_mm, b.dphi_deg)
    assert again.constellation == hough_model.constellation
    assert again.edge_settings == hough_model.edge_settings
    with pytest.raises(BundleError, match="'hough' model, not a 'pca'"):
        from calibration_free.baselines.pca.model import PcaModel
        PcaModel.load(path)


def test_truncated_file_is_refused(hough_model, tmp_path):
    path = tmp_path / "cube.hough"
    hough_model.save(path)
    path.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(BundleError, match="truncated|corrupt"):
        HoughModel.load(path)


def test_untrainable_inputs_are_refused(grids):
    nn1, nn2 = grids
    with pytest.raises(TrainingError, match="even kappa"):
        train_hough(nn1, nn2, object_kind="screw", kappa=1, nominal_pose=NOMINAL_POSE)
    random_set = render_dataset(SyntheticCell(), random_offsets(np.random.default_rng(0), 30,
                                                                25.0, 45.0), None)
    with pytest.raises(TrainingError, match="grid"):
        train_hough(random_set, nn2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE)
