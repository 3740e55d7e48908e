"""Fixtures shared by the controller's tests."""

from __future__ import annotations

import pytest

from controller.config import load_config
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner


@pytest.fixture(scope="session")
def trained(tmp_path_factory):
    """A cell state folder taught, acquired and trained on the default simulated scene (read
    only: tests that change a state folder copy it first)."""
    state = tmp_path_factory.mktemp("state")
    cfg = load_config(None)
    with open_devices(cfg) as devices:
        fp = FinePositioner(devices, cfg, state_dir=state)
        fp.teach_auto()
        fp.acquire("nn1", progress=False)
        fp.acquire("nn2", progress=False)
        model = fp.train()
    assert model.train_images == 2 * (63 + cfg.controller.acquisition.taught_pose_frames)
    return state
