"""Re-zeroing a trained model in another light (``calibration_free.rezero``).

A light change is played on the synthetic cube by moving every frame taken at the taught pose
a fraction of a pixel (what a side lamp does to the part's silhouette): the translation nets
then read a few tenths of a millimetre there; re-zeroed on such frames they read zero on
them again, and a part that is not where it was taught, or not seen whole, changes nothing.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration_free.bundle import ModelBundle
from calibration_free.errors import TrainingError
from calibration_free.perception import Perception
from calibration_free.preprocess import mean_frame
from calibration_free.rezero import MAX_SHIFT_MM, NN2_MIN_DEG, rezero
from calibration_free.synthetic import render

SHIFT_PX = (0.4, -0.3)


def at_pose(cell, count: int, shift_px=(0.0, 0.0), seed: int = 1) -> list[np.ndarray]:
    """``count`` frames at the taught pose, moved by ``shift_px`` (u, v)."""
    rng = np.random.default_rng(seed)
    move = np.float32([[1, 0, shift_px[0]], [0, 1, shift_px[1]]])
    frames = [render(cell, np.zeros(3), rng) for _ in range(count)]
    return [cv2.warpAffine(f, move, (f.shape[1], f.shape[0]), flags=cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE) for f in frames]


def readings(bundle: ModelBundle, frames) -> dict[str, np.ndarray]:
    percepts = [Perception(bundle).perceive(f) for f in frames]
    return {name: np.mean([getattr(p, name) for p in percepts], axis=0)
            for name in ("nn1_mm", "rot_mm", "full_mm")}


def test_the_nets_read_zero_again_at_the_taught_pose_in_the_new_light(saturation_bundle,
                                                                     cell, tmp_path):
    moved = at_pose(cell, 8, SHIFT_PX)
    before = readings(saturation_bundle, moved)
    assert all(np.hypot(*v) > 0.15 for v in before.values()), before  # off by the "light"
    done = rezero(saturation_bundle, moved)
    assert done.frames_used == done.frames == 8
    assert np.allclose(done.shift_mm["nn1"], before["nn1_mm"])
    assert np.allclose(done.shift_mm["nn1_rot"], before["rot_mm"], atol=0.01)
    # on other frames in the same light, every net now reads zero at the pose
    after = readings(done.bundle, at_pose(cell, 6, SHIFT_PX, seed=7))
    assert all(np.hypot(*v) < 0.05 for v in after.values()), after
    # NN2 reads the moved part within NN2_MIN_DEG of zero: left as trained
    assert abs(done.nn2_deg) < NN2_MIN_DEG and not done.nn2_turned
    assert done.bundle.nn2 is saturation_bundle.nn2
    path = tmp_path / "m.fpm"
    done.bundle.save(path)
    again = ModelBundle.load(path)
    assert again.training["rezero"] == [done.report()]
    assert np.allclose(readings(again, moved)["full_mm"], 0.0, atol=1e-6)


def nn2_deg(bundle: ModelBundle, frames) -> float:
    return float(np.mean([Perception(bundle).perceive(f).nn2_deg for f in frames]))


def test_nn2_is_left_as_trained_where_it_reads_a_small_turn(saturation_bundle, cell):
    """A cube under a low lamp reads up to 0.6 deg at the taught pose, a reading that moves by
    +/-0.3 deg with its heading: turned back, the loop's angle got worse, so it is left."""
    rng = np.random.default_rng(4)
    turned = [render(cell, np.array([0.0, 0.0, 0.9]), rng) for _ in range(8)]
    before = nn2_deg(saturation_bundle, turned)
    assert 0.5 <= abs(before) < NN2_MIN_DEG, before
    done = rezero(saturation_bundle, turned)
    assert not done.nn2_turned and done.bundle.nn2 is saturation_bundle.nn2


def test_nn2_reads_zero_again_at_the_taught_pose(saturation_bundle, cell):
    """A light that shades one flank more makes NN2 read a small turn at the pose: played by
    turning the part 1.5 deg, NN2's output layer is turned back by what it reads there."""
    rng = np.random.default_rng(4)
    turned = [render(cell, np.array([0.0, 0.0, 1.5]), rng) for _ in range(8)]
    before = nn2_deg(saturation_bundle, turned)
    assert abs(before) >= NN2_MIN_DEG, before
    done = rezero(saturation_bundle, turned)
    assert done.nn2_deg == pytest.approx(before, abs=0.05) and done.nn2_turned
    assert abs(nn2_deg(done.bundle, turned)) < 0.05
    rng = np.random.default_rng(5)
    more = [render(cell, np.array([0.0, 0.0, 1.5]), rng) for _ in range(4)]
    assert abs(nn2_deg(done.bundle, more)) < 0.3  # other frames of that pose too
    assert all(np.hypot(*Perception(done.bundle).perceive(f).full_mm) < 0.1 for f in more)
    far = [render(cell, np.array([0.0, 0.0, 8.0]), rng) for _ in range(4)]
    with pytest.raises(TrainingError, match="over 3 deg: the part was turned since it was "
                                            "taught"):
        rezero(saturation_bundle, far)


def refuses_a_part_away_from_the_taught_pose(do_rezero, cell) -> None:
    """``do_rezero`` (frames -> result) refuses, in one line, frames of the part 3 mm from
    where it was taught."""
    rng = np.random.default_rng(2)
    away = [render(cell, np.array([2.5, -1.5, 0.0]), rng) for _ in range(4)]
    with pytest.raises(TrainingError, match=f"over {MAX_SHIFT_MM:g} mm: the part is not where "
                                            "it was taught") as refused:
        do_rezero(away)
    assert "\n" not in str(refused.value)


def test_a_part_not_where_it_was_taught_changes_nothing(saturation_bundle, cell):
    refuses_a_part_away_from_the_taught_pose(lambda frames: rezero(saturation_bundle, frames),
                                             cell)


def test_a_part_not_seen_whole_changes_nothing(saturation_bundle, cell):
    frames = at_pose(cell, 4)
    bare = [np.full_like(f, f[0, 0]) for f in frames]  # the table alone
    with pytest.raises(TrainingError, match="seen whole in only 1 of 4 frames"):
        rezero(saturation_bundle, [frames[0], *bare[1:]])
    # a part with a card over a quarter of it is not whole either
    percept = Perception(saturation_bundle).perceive(frames[0])
    rows = np.flatnonzero((percept.localisation.part_mask > 0).any(axis=1))
    carded = [f.copy() for f in frames]
    for f in carded:
        f[:rows[0] + (rows[-1] - rows[0]) // 4, :] = (70, 80, 115)
    with pytest.raises(TrainingError, match="seen whole in only 0 of 4"):
        rezero(saturation_bundle, carded)
    with pytest.raises(TrainingError, match="no frames"):
        rezero(saturation_bundle, [])


def test_the_zero_is_read_on_the_frames_means_as_the_settling_look_reads(saturation_bundle,
                                                                         cell):
    moved = at_pose(cell, 8, SHIFT_PX)
    done = rezero(saturation_bundle, moved, average=3)
    # read on the means of frames 0-2, 3-5 and 6-7: what the nets read on those mean frames
    means = [mean_frame(moved[i:i + 3]) for i in (0, 3, 6)]
    assert np.allclose(done.shift_mm["nn1"], readings(saturation_bundle, means)["nn1_mm"])
    assert (done.frames_used, done.frames, done.average) == (8, 8, 3)
    assert done.report()["average"] == 3
    assert all(np.hypot(*v) < 0.05 for v in readings(done.bundle, means).values())
    # one mean frame without the part: its three frames are not used, and 5 of 8 is too few
    bare = np.full_like(moved[0], moved[0][0, 0])
    with pytest.raises(TrainingError, match="seen whole in only 5 of 8 frames"):
        rezero(saturation_bundle, [*moved[:3], bare, bare, bare, *moved[6:]], average=3)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(TrainingError, match="average must be a whole number"):
            rezero(saturation_bundle, moved, average=bad)


def test_the_report_tells_the_share_of_the_part_the_camera_clips(saturation_bundle, cell):
    """A part whose brightest face the camera drives to 255 (an exposure for a dark room
    under a lamp): the re-zero reports the share of the part's pixels clipped."""
    frames = at_pose(cell, 4)
    assert rezero(saturation_bundle, frames).clipped_share == 0.0
    mask = Perception(saturation_bundle).perceive(frames[0]).localisation.part_mask > 0
    rows = np.flatnonzero(mask.any(axis=1))
    top = mask & (np.arange(mask.shape[0])[:, None] < rows[len(rows) // 4])  # its top quarter
    blown = []
    for f in frames:
        f = f.copy()
        f[top, int(np.argmax(f[top].mean(axis=0)))] = 255  # its strongest channel at 255
        blown.append(f)
    done = rezero(saturation_bundle, blown)
    assert done.clipped_share == pytest.approx(top.sum() / mask.sum(), abs=0.05)
    assert done.report()["clipped_share"] == round(done.clipped_share, 3)
