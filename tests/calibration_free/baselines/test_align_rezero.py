"""Re-zeroing the image-alignment servo in another light: its template taken again.

As for the Gabor model (``tests/calibration_free/test_rezero.py``), a light change is played
by moving every frame at the taught pose a fraction of a pixel: the servo reads a few tenths
of a millimetre there; re-zeroed on such frames it reads zero on other frames in the same
"light", and a part not where it was taught, or not seen whole, changes nothing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration_free.baselines.align.model import AlignModel
from calibration_free.baselines.align.rezero import rezero_align
from calibration_free.errors import TrainingError
from calibration_free.synthetic import render
from tests.calibration_free.test_rezero import (
    SHIFT_PX,
    at_pose,
    refuses_a_part_away_from_the_taught_pose,
)


def reads(model: AlignModel, frames) -> np.ndarray:
    """The servo's mean step (dx_mm, dy_mm, dphi_deg) on ``frames``."""
    return np.mean([model.perceive(f).step for f in frames], axis=0)


def test_the_servo_reads_zero_again_at_the_taught_pose_in_the_new_light(align_model, cell,
                                                                        tmp_path):
    moved = at_pose(cell, 8, SHIFT_PX)
    before = reads(align_model, moved)
    assert math.hypot(*before[:2]) > 0.15, before  # off by the "light"
    done = rezero_align(align_model, moved)
    assert done.frames_used == done.frames == 8
    assert done.read_mm == pytest.approx(tuple(before[:2]), abs=1e-6)
    assert done.model.template.shape == align_model.template.shape
    assert np.array_equal(done.model.xy, align_model.xy)  # the maps stay as trained
    after = reads(done.model, at_pose(cell, 6, SHIFT_PX, seed=7))
    assert math.hypot(*after[:2]) < 0.05 and abs(after[2]) < 0.3, after
    # and where the light did not change, the old zero is what it reads now
    assert math.hypot(*reads(done.model, at_pose(cell, 4))[:2]) > 0.15
    path = tmp_path / "align.fpm"
    done.model.save(path)
    again = AlignModel.load(path)
    assert again.training["rezero"] == [done.report()]
    assert np.allclose(again.template, done.model.template)


def test_a_part_not_where_it_was_taught_or_not_whole_changes_nothing(align_model, cell):
    refuses_a_part_away_from_the_taught_pose(lambda frames: rezero_align(align_model, frames),
                                             cell)
    rng = np.random.default_rng(3)
    turned = [render(cell, np.array([0.0, 0.0, 8.0]), rng) for _ in range(4)]
    with pytest.raises(TrainingError, match="over 3 deg: the part was turned"):
        rezero_align(align_model, turned)
    frames = at_pose(cell, 4)
    bare = [np.full_like(f, f[0, 0]) for f in frames]  # the table alone
    with pytest.raises(TrainingError, match="seen whole in only 1 of 4 frames"):
        rezero_align(align_model, [frames[0], *bare[1:]])
    with pytest.raises(TrainingError, match="no frames"):
        rezero_align(align_model, [])
