"""The part's colour against its table (calibration_free.part_colour)."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from calibration_free.dataset import Dataset, grid_offsets, staggered_grid_offsets
from calibration_free.errors import ImageError, TrainingError
from calibration_free.front_end import FrontEnd
from calibration_free.part_colour import SCALE, PartColour, learn_part_colour, part_masks
from calibration_free.preprocess import IntensityStats
from calibration_free.synthetic import SyntheticCell, image_pose, render_at, render_dataset
from calibration_free.training import _channel_and_polarity, prepare_training
from drivers.core.errors import ConfigError

# a blue part on a brown, textured table: neither max(R,G,B) nor saturation tells them apart
CELL = SyntheticCell(object_rgb=(60, 90, 170), hole_rgb=(20, 30, 60), table_rgb=(150, 110, 70),
                     noise_std=2.0)


def _textured(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The frame with a coarse brightness texture on everything (wood grain, a shadow)."""
    blotches = rng.uniform(0.6, 1.2, (9, 12)).astype(np.float32)
    field = cv2.resize(blotches, (image.shape[1], image.shape[0]),
                       interpolation=cv2.INTER_LINEAR)
    return np.clip(image * field[:, :, None], 0, 255).astype(np.uint8)


def _frames(n: int, seed: int, cell: SyntheticCell = CELL) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    u, v = cell.nominal_uv_px
    return [_textured(render_at(cell, u + rng.uniform(-0.5, 0.5), v, cell.object_angle_deg,
                                rng), rng) for _ in range(n)]


def _part_pixels(cell: SyntheticCell = CELL) -> tuple[np.ndarray, np.ndarray]:
    """Where the part's top face is in a noiseless frame at the nominal pose, and where
    anything of the part is (its edge, its hole) or its edge's blur reaches (a pixel on)."""
    clean = render_at(cell, *cell.nominal_uv_px, cell.object_angle_deg)
    footprint = np.any(clean != np.array(cell.table_rgb, np.uint8), axis=2)
    return (np.all(clean == np.array(cell.object_rgb, np.uint8), axis=2),
            cv2.dilate(footprint.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool))


def test_learned_at_the_taught_pose_the_channel_shows_the_part_alone():
    colour = learn_part_colour(_frames(4, seed=1))
    assert colour is not None
    channel = colour.image(_frames(1, seed=2)[0])
    part, footprint = _part_pixels()
    assert np.median(channel[part]) > 230
    assert np.mean(channel[~footprint] > 127.5) < 0.002


def test_a_change_of_brightness_and_colour_of_the_light_does_not_move_the_part():
    colour = learn_part_colour(_frames(4, seed=1))
    frame = _frames(1, seed=3)[0].astype(np.float32)
    warm_and_dim = np.clip(frame * np.array([0.55, 0.45, 0.3]), 0, 255).astype(np.uint8)
    part, footprint = _part_pixels()
    for image in (frame.astype(np.uint8), warm_and_dim):
        mask = colour.image(image) > 127.5
        assert (mask & part).sum() > 0.95 * part.sum()
        assert (mask & ~footprint).sum() < 0.02 * part.sum()


def test_nothing_standing_out_learns_nothing():
    flat = dataclasses.replace(CELL, object_rgb=CELL.table_rgb, hole_rgb=CELL.table_rgb)
    assert learn_part_colour(_frames(4, seed=4, cell=flat)) is None
    assert all(m is None for m in part_masks(_frames(4, seed=4, cell=flat)))


def test_no_frames_or_a_bad_frame_is_refused():
    with pytest.raises(ImageError, match="no frames"):
        learn_part_colour([])
    with pytest.raises(ImageError, match="HxWx3 uint8"):
        learn_part_colour([np.zeros((10, 10), np.uint8)])


def test_what_a_model_file_stores_reads_back_the_same():
    colour = learn_part_colour(_frames(4, seed=1))
    again = PartColour.from_info(colour.to_info())
    frame = _frames(1, seed=5)[0]
    np.testing.assert_array_equal(again.image(frame), colour.image(frame))


@pytest.mark.parametrize("change, message", [
    (lambda i: {**i, "table": []}, "1 to 4 colours"),
    (lambda i: {**i, "part": {**i["part"], "mean": [0.0, 1.0]}}, "part mean must be three"),
    (lambda i: {**i, "part": {**i["part"], "inverse_covariance": [1.0] * 9}},
     "symmetric and positive definite"),
    (lambda i: {**i, "part": {**i["part"], "weight": 0.0}}, "weight must be in"),
    (lambda i: {**i, "part": {**i["part"], "mean": [0.0, "x", 1.0]}}, "three finite"),
])
def test_a_damaged_colour_is_refused_with_what_is_wrong(change, message):
    info = learn_part_colour(_frames(4, seed=1)).to_info()
    with pytest.raises(ConfigError, match=message):
        PartColour.from_info(change(info))


def test_the_colour_channel_and_the_part_colour_go_together():
    colour = learn_part_colour(_frames(4, seed=1))
    stats = IntensityStats(100.0, 30.0)
    front = FrontEnd(144, 192, stats, 127.5, "bright", 400.0, channel="colour",
                     part_colour=colour)
    assert FrontEnd.from_info(front.to_info()).part_colour == colour
    with pytest.raises(ConfigError, match="needs the part's colour"):
        FrontEnd(144, 192, stats, 127.5, "bright", 400.0, channel="colour")
    with pytest.raises(ConfigError, match="needs the part's colour"):
        FrontEnd(144, 192, stats, 127.5, "bright", 400.0, channel="max", part_colour=colour)


def test_the_compiled_channel_is_the_logistic_of_the_likelihood_ratio():
    colour = learn_part_colour(_frames(4, seed=1))
    frame = _frames(1, seed=6)[0]
    ratio = np.clip(colour.log_ratio(frame) / SCALE, -30.0, 30.0)
    np.testing.assert_allclose(colour.image(frame), 255.0 / (1.0 + np.exp(-ratio)),
                               atol=0.02)


def _sets(cell: SyntheticCell) -> dict[str, Dataset]:
    rng = np.random.default_rng(11)
    taught = np.zeros((4, 3))  # four frames at the taught pose first, as acquisition takes them
    nn1 = np.concatenate([taught, grid_offsets(25.0, 45.0)])
    nn2 = np.concatenate([taught, staggered_grid_offsets(5.0, 45.0)])
    return {"nn1": render_dataset(cell, nn1, rng), "nn2": render_dataset(cell, nn2, rng)}


def test_trained_in_the_colour_channel_the_part_is_found_where_it_is():
    sets = _sets(CELL)
    prep = prepare_training(sets, "auto", "colour")
    assert prep.front.channel == "colour" and prep.front.part_colour is not None
    assert all(len(prep.usable[name]) == len(sets[name].labels) for name in sets)
    truth = np.array([image_pose(CELL, label)[:2] for label in sets["nn1"].labels])
    found = np.array([(loc.u_px, loc.v_px) for loc in prep.found["nn1"]])
    assert np.abs(found - truth).max() < 0.5
    again = FrontEnd.from_info(prep.front.to_info())
    frame = sets["nn2"].images[7]
    np.testing.assert_array_equal(again.preprocess(frame), prep.front.preprocess(frame))


def test_auto_takes_the_colour_channel_only_where_no_other_shows_the_part():
    assert prepare_training(_sets(SyntheticCell()), "auto", "auto").front.channel == \
        "saturation"
    sets = _sets(CELL)
    blank = np.zeros((144, 192), np.float32)
    blob = blank.copy()
    blob[60:80, 90:110] = 200.0
    shown = {name: [blob] * len(data.labels) for name, data in sets.items()}
    hidden = {name: [blank] * len(data.labels) for name, data in sets.items()}
    otsu = {"max": (100.0, 0.5), "colour": (100.0, 0.9)}
    assert _channel_and_polarity({"max": shown, "colour": shown}, otsu, sets, "auto") == \
        ("max", "bright")
    assert _channel_and_polarity({"max": hidden, "colour": shown}, otsu, sets, "auto") == \
        ("colour", "bright")


def test_the_colour_channel_where_the_part_does_not_stand_out_is_refused():
    flat = dataclasses.replace(CELL, object_rgb=CELL.table_rgb, hole_rgb=CELL.table_rgb)
    with pytest.raises(TrainingError, match="does not stand out"):
        prepare_training(_sets(flat), "auto", "colour")
