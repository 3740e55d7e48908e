"""The translation nets pinned at the taught pose as the loop reads them
(``calibration_free.pin``, and training's ``pinned_as_read``).

The loop feeds ``nn1_rot`` and the near correction NN2's reading of the turn, not the label's
zero the nets were first pinned with. Played on the synthetic cube by frames whose part is
turned a little (NN2 reads that turn): pinned on them, the nets read zero there through the
loop's own path; without a frame that shows the part, nothing is pinned.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.errors import TrainingError
from calibration_free.perception import Perception
from calibration_free.pin import pinned
from calibration_free.synthetic import render
from calibration_free.training import at_taught_pose
from tests.calibration_free.test_rezero import readings


def turned_frames(cell, turn_deg: float, count: int = 6, seed: int = 3) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [render(cell, np.array([0.0, 0.0, turn_deg]), rng) for _ in range(count)]


def test_pinned_reads_zero_through_the_loops_path(saturation_bundle, cell):
    frames = turned_frames(cell, 1.2)
    percepts = [Perception(saturation_bundle).perceive(f) for f in frames]
    assert abs(np.mean([p.nn2_deg for p in percepts])) > 0.3  # NN2 reads the turn
    before = readings(saturation_bundle, frames)
    assert np.hypot(*before["rot_mm"]) > 1e-3, before
    done, shift = pinned(saturation_bundle, frames)
    assert np.allclose(shift["nn1"], before["nn1_mm"])
    assert np.allclose(shift["nn1_rot"], before["rot_mm"])
    after = readings(done, frames)
    for name, value in after.items():
        assert np.allclose(value, 0.0, atol=1e-6), (name, value)
    assert done.nn2 is saturation_bundle.nn2  # the turn reading itself is left as trained


def test_a_check_refuses_before_anything_is_shifted(saturation_bundle, cell):
    seen = []

    def refuse(mm: float) -> None:
        seen.append(mm)
        raise TrainingError("refused")

    with pytest.raises(TrainingError, match="refused"):
        pinned(saturation_bundle, turned_frames(cell, 0.0, count=2), check=refuse)
    assert len(seen) == 1 and 0.0 <= seen[0] < 0.5


def test_frames_without_the_part_pin_nothing(saturation_bundle, cell):
    blank = [np.full_like(f, 128) for f in turned_frames(cell, 0.0, count=3)]
    with pytest.raises(TrainingError, match="none of the 3 frames at the taught pose shows "
                                            "the part whole"):
        pinned(saturation_bundle, blank)


def test_training_pins_the_nets_on_its_taught_frames_as_read(saturation_bundle, grids):
    record = saturation_bundle.training["pinned_as_read_mm"]
    assert set(record) == {"nn1", "nn1_rot", "nn1_near"}
    # every frame at the taught pose once (the NN2 set is also NN1's extra set here)
    taught = [data.images[i] for data in grids
              for i in np.flatnonzero(at_taught_pose(data.labels))]
    assert taught
    # on the frames it was pinned on, the loop's reading is zero on average
    full = np.mean([Perception(saturation_bundle).perceive(f).full_mm for f in taught], axis=0)
    assert np.allclose(full, 0.0, atol=1e-6), full
