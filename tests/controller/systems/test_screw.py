"""The screw (kappa 1) on the simulated cell: NN2 reads its rotation over the whole circle, and
the screw's long axis reads it finer (``calibration_free.axis``)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.perception import Perception
from controller.config import config_from_mapping
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.teach.acquisition import acquire, random_set

pytestmark = pytest.mark.slow


def test_screw_rotation_is_read_over_the_full_circle(tmp_path):
    cfg = config_from_mapping({"scene": {"timing": "ideal", "object": {"kind": "screw"}}})
    with open_devices(cfg, seed=0) as devices:
        fp = FinePositioner(devices, cfg, state_dir=tmp_path)
        state = fp.teach_auto()
        assert state.kappa == 1
        nn2 = fp.acquire("nn2", progress=False)
        # the default NN2 grid: 63 distinct rotations over the whole circle, after the frames
        # at the taught pose
        taught = cfg.controller.acquisition.taught_pose_frames
        assert np.abs(nn2.labels[:taught]).max() < 0.05
        assert len(np.unique(nn2.labels[taught:, 2].round(1))) == 63
        assert np.ptp(nn2.labels[:, 2]) > 340.0
        fp.acquire("nn1", progress=False)
        model = fp.train("gabor")
        offsets = random_set(np.random.default_rng(4), 24, 4.0, 1)
        test = acquire(devices.arm, devices.camera, state.nominal_pose, offsets, name="test",
                       limits=cfg.safety, progress=False)
    perception = Perception(model.model)
    assert model.model.axis is not None and model.model.axis.kappa == 1
    # the axis is read from the part's share of each pixel (the default colour edge)
    assert model.model.axis.silhouette == "coverage"
    err, err_nn2 = [], []
    for image, label in zip(test.images, test.labels, strict=True):
        p = perception.perceive(image)
        assert p.ok, p.localisation.reason
        assert p.axis_deg is not None and p.dphi_deg == p.axis_deg
        err.append((p.dphi_deg - label[2] + 180.0) % 360.0 - 180.0)
        err_nn2.append((p.nn2_deg - label[2] + 180.0) % 360.0 - 180.0)
    err, err_nn2 = np.array(err), np.array(err_nn2)
    assert np.abs(test.labels[:, 2]).max() > 150.0  # the test reaches the wrap
    assert np.sqrt(np.mean(err_nn2**2)) < 3.0 and np.abs(err_nn2).max() < 10.0, \
        err_nn2.round(1)
    # the axis: within a degree everywhere, and finer than NN2
    rms, rms_nn2 = np.sqrt(np.mean(err**2)), np.sqrt(np.mean(err_nn2**2))
    assert np.abs(err).max() < 1.5 and rms < 0.7 * rms_nn2, (err.round(2), rms, rms_nn2)
