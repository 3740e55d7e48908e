"""A card over one end of the ledge on the simulated cell: the translation is read from the
end the bar shows (``calibration_free.ends``), as if the whole bar were seen."""

from __future__ import annotations

import dataclasses
import math

import pytest

from calibration_free.perception import Perception
from controller.config import config_from_mapping
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from drivers.core.pose import ToolStep
from sim_backend.cell.sim_cell import SimCell

pytestmark = pytest.mark.slow


def test_the_ledge_under_a_card_is_read_from_the_end_it_shows(tmp_path):
    cfg = config_from_mapping({"scene": {"timing": "ideal", "object": {"kind": "ledge"}}})
    with open_devices(cfg, seed=0) as devices:
        fp = FinePositioner(devices, cfg, state_dir=tmp_path)
        fp.teach_auto()
        fp.acquire("nn1", progress=False)
        fp.acquire("nn2", progress=False)
        model = fp.train("gabor").model
    assert model.axis is not None and model.axis.ends is not None
    perception = Perception(model)
    whole = cfg.scene
    card = dataclasses.replace(whole, occluder=dataclasses.replace(whole.occluder, enabled=True,
                                                                   coverage=0.25))
    offsets = [ToolStep(0.0, 0.0, 0.0, 0.0), ToolStep(2.0, -1.5, 0.0, 0.0),
               ToolStep(-1.5, 1.0, 0.0, 6.0)]
    sides = set()
    for seed in (1, 2):  # the seed picks the card's side
        seen = []
        for scene in (whole, card):
            with SimCell(scene, seed=seed) as cell:
                nominal = cell.nominal_grasp_pose()
                frames = []
                for offset in offsets:
                    cell.move_arm(nominal.moved_in_tool_frame(offset))
                    frames.append(perception.perceive(cell.render()))
                seen.append(frames)
        for bare, hidden in zip(*seen, strict=True):
            assert bare.ok and hidden.ok and bare.hidden_px is None
            assert hidden.hidden_px is not None and hidden.hidden_px > 5.0
            # the blob seen is off by half the hidden length (4.4 mm in the loop); the centre
            # read is within a pixel or so (the axis of the shorter bar seen turns the end's
            # offset a little), well inside the 2 mm the grasp tolerates
            blob_off = math.dist((hidden.u_px, hidden.v_px), (bare.u_px, bare.v_px))
            assert blob_off > 4.0
            assert math.dist(hidden.centre_px, bare.centre_px) < 1.5
            assert math.dist(hidden.full_mm, bare.full_mm) < 1.2, (hidden.full_mm, bare.full_mm)
            sides.add(round(hidden.v_px - bare.v_px) > 0)
    assert sides == {True, False}  # the card lay on each end once
