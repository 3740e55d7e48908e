"""Training a bundle on synthetic grids and perceiving random frames with it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration_free import training
from calibration_free.angles import decode, encode
from calibration_free.dataset import Dataset, random_offsets
from calibration_free.errors import ImageError, TrainingError
from calibration_free.front_end import FEATURE_CEILING, FEATURE_FLOOR, FrontEnd
from calibration_free.gabor import GaborConfig
from calibration_free.perception import Perception
from calibration_free.synthetic import render, render_at
from calibration_free.training import (
    MIN_NEAR_SAMPLES,
    NN2_WIDEN_COPIES,
    TrainingSettings,
    default_nn2_weight_decay,
    default_nn2_widen_px,
    near_samples,
    train_bundle,
    train_nn2,
    widened_copies,
)
from drivers.core.errors import ConfigError

from .conftest import KAPPA, NOMINAL_POSE


def two_parts(cell, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """One frame with both parts: ``second``'s part pasted over ``first`` (pixels that are
    not table)."""
    part = np.abs(second.astype(int) - np.array(cell.table_rgb)).sum(axis=2) > 30
    out = first.copy()
    out[part] = second[part]
    return out


def errors(perception: Perception, cell, labels: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = []
    for label in labels:
        p = perception.perceive(render(cell, label, rng))
        assert p.ok, p.localisation
        dphi_err = decode(*encode(p.dphi_deg - label[2], KAPPA), KAPPA)
        out.append((p.nn1_mm[0] - label[0], p.nn1_mm[1] - label[1], dphi_err))
    return np.array(out)


def test_training_records_what_it_did(bundle):
    t = bundle.training
    assert t["samples"] == {"nn1": 63, "nn2": 63, "nn1_extra": 63}
    assert t["skipped"] == {"nn1": 0, "nn2": 0, "nn1_extra": 0}
    assert t["nn1"]["layers"] == [2, 3, 2] and t["nn2"]["layers"] == [36, 12, 2]
    for net in ("nn1", "nn2"):  # a summary, not the per-epoch curve
        assert "loss_curve" not in t[net] and t[net]["epochs"] > 1
        assert t[net]["final_loss"] < t[net]["first_loss"] / 100
        assert t[net]["seconds"] > 0
    assert t["seconds"] >= t["nn1"]["seconds"] + t["nn2"]["seconds"]
    assert bundle.object_kind == "cube" and bundle.nominal_pose == NOMINAL_POSE
    # the rotation-aware translation net: (u, v, sin, cos) -> 10 tanh units -> (dx, dy)
    assert t["nn1_rot"]["layers"] == [4, 10, 2]
    # the same net on the samples near the taught pose: the NN2 grid (+/-5 mm) and NN1's
    # grid centre, not NN1's grid at +/-25 mm
    assert t["nn1_near"]["layers"] == [4, 10, 2] and bundle.near_mm == 5.0
    assert t["nn1_near"]["samples"] == 63 + 7
    assert t["nn2"]["weight_decay"] == default_nn2_weight_decay(KAPPA)
    assert t["nn2"]["widen_px"] == 0.0  # the cube learns from its 63 ROIs alone
    assert 700 < bundle.front.expected_area_px < 950  # a 30 px rounded square minus its hole


def test_the_feature_floor_and_ceiling_are_learned_with_the_saturation_channel(
        bundle, saturation_bundle, cell):
    # the paper's max(R, G, B) path: no floor, no ceiling
    assert bundle.front.feature_floor == bundle.front.feature_ceiling == 0.0
    front = saturation_bundle.front
    assert front.channel == "saturation" and front.feature_floor == FEATURE_FLOOR
    assert front.feature_ceiling == FEATURE_CEILING
    p = Perception(saturation_bundle).perceive(render(cell, np.zeros(3),
                                                      np.random.default_rng(4)))
    size = saturation_bundle.gabor.roi_px
    roi = front.feature_roi(p.normalised, p.localisation, size)
    whole = dataclasses.replace(front, feature_floor=0.0, feature_ceiling=0.0).feature_roi(
        p.normalised, p.localisation, size)
    floor, ceiling = FEATURE_FLOOR * front.threshold, FEATURE_CEILING * front.threshold
    assert whole.max() > ceiling  # the part's inside is cut to the ceiling
    np.testing.assert_allclose(roi, np.clip(whole - floor, 0.0, ceiling - floor), rtol=1e-6)
    # a speck over the floor away from the part (noise in a dark cast shadow) is not seen,
    # one at the part's edge is
    u, v = int(p.u_px), int(p.v_px)
    specked = p.normalised.copy()
    specked[v - 22:v - 20, u - 22:u - 20] = 1.2 * front.threshold
    assert not p.localisation.part_mask[v - 24:v - 18, u - 24:u - 18].any()
    np.testing.assert_array_equal(front.feature_roi(specked, p.localisation, size), roi)
    assert dataclasses.replace(front, feature_ceiling=0.0).feature_roi(
        specked, p.localisation, size).max() > 0.4 * front.threshold
    # the whole frame cut the same way (the full-frame reference of bench perception): its
    # window on pixel centres is the cut window
    frame = front.feature_frame(specked, p.localisation)
    at = dataclasses.replace(p.localisation, u_px=u + 0.5, v_px=v + 0.5)
    np.testing.assert_array_equal(front.feature_roi(specked, at, size),
                                  frame[v - 24:v + 26, u - 24:u + 26])
    # a model file without the floor or the ceiling (written before them) keeps its features
    # whole, or cut at the floor only
    info = saturation_bundle.to_info()
    del info["localisation"]["feature_ceiling"]
    assert FrontEnd.from_info(info).feature_ceiling == 0.0
    floor_only = dataclasses.replace(front, feature_ceiling=0.0).feature_roi(
        p.normalised, p.localisation, saturation_bundle.gabor.roi_px)
    np.testing.assert_allclose(floor_only, np.maximum(whole - floor, 0.0), rtol=1e-6)
    del info["localisation"]["feature_floor"]
    assert FrontEnd.from_info(info).feature_floor == 0.0


@pytest.mark.parametrize("ceiling", [0.5, 0.75, -1.0, float("inf"), float("nan"), True, "1.5"])
def test_a_ceiling_not_above_the_floor_is_refused(saturation_bundle, ceiling):
    with pytest.raises(ConfigError, match="feature_ceiling"):
        dataclasses.replace(saturation_bundle.front, feature_ceiling=ceiling)


def test_the_near_net_gives_the_translation_only_near_the_taught_pose(bundle, cell):
    rng = np.random.default_rng(6)
    for offset, near in (((1.5, -2.0, 10.0), True), ((3.0, 3.0, -20.0), True),
                         ((15.0, -12.0, 5.0), False)):
        p = Perception(bundle).perceive(render(cell, np.array(offset), rng))
        assert p.near == near and (np.hypot(*p.rot_mm) <= bundle.near_mm) == near
        if near:  # both read the offset; the near net is the one fitted there
            assert np.allclose(p.full_mm, offset[:2], atol=0.3)
            assert np.allclose(p.full_mm, p.rot_mm, atol=0.5)
        else:
            assert p.full_mm == p.rot_mm


def test_near_samples_are_the_nn2_sets_range():
    nn2 = np.array([[5.0, -5.0, 0.0], [-5.0, 2.0, 10.0], [0.0, 0.0, 0.0]])
    dxdy = np.array([[0.0, 0.0], [5.0, 5.0], [5.5, 5.5], [25.0, 0.0], [0.0, -25.0]])
    near_mm, near = near_samples(np.repeat(dxdy, MIN_NEAR_SAMPLES, axis=0), nn2)
    assert near_mm == 5.0  # the corner (7.07 mm) plus 1 mm still holds (5.5, 5.5)
    assert near.reshape(-1, MIN_NEAR_SAMPLES)[:, 0].tolist() == [True, True, True, False,
                                                                  False]
    with pytest.raises(TrainingError, match="within 5.0 mm of the taught pose"):
        near_samples(dxdy, nn2)


def test_nn2_weight_decay_is_looser_for_a_part_without_symmetry():
    # a screw's NN2 maps the whole circle; symmetric parts are held tighter against noise
    decay = {kappa: default_nn2_weight_decay(kappa) for kappa in (1, 2, 4, 6)}
    assert decay[1] < decay[2] == decay[4] == decay[6]


def _disc(radius: float, n: int = 50) -> np.ndarray:
    """A soft disc ROI: 1 inside, a 1 px ramp at ``radius``, 0 beyond."""
    rows, cols = np.mgrid[0:n, 0:n]
    r = np.hypot(cols - (n - 1) / 2, rows - (n - 1) / 2)
    return np.clip(radius + 0.5 - r, 0.0, 1.0).astype(np.float32)


def test_widened_copies_widen_the_outline_on_one_side():
    roi = _disc(12.0)
    copies = widened_copies([roi, roi], 1.0, 3, np.random.default_rng(4))
    assert len(copies) == 6
    again = widened_copies([roi, roi], 1.0, 3, np.random.default_rng(4))
    assert all(np.array_equal(a, b) for a, b in zip(copies, again, strict=True))
    rows, cols = np.mgrid[0:50, 0:50]
    for copy in copies:
        assert copy.dtype == np.float32 and (copy >= roi).all()
        extra = copy - roi
        # only the outline grows, by under a pixel and a half, and on one side
        assert extra.max() <= 1.0 and extra.sum() < 1.5 * 2 * np.pi * 12.0
        assert (extra[np.hypot(cols - 24.5, rows - 24.5) < 10.5] == 0).all()
        u = (extra * (cols - 24.5)).sum() / max(extra.sum(), 1e-9)
        v = (extra * (rows - 24.5)).sum() / max(extra.sum(), 1e-9)
        assert extra.sum() == 0 or np.hypot(u, v) > 6.0  # off centre: one side


def test_nn2_learns_from_widened_copies_for_a_round_part_only(monkeypatch):
    # the nut (kappa 6) by default, not the cube, the ledge or the screw; 0 turns them off
    assert default_nn2_widen_px(6) == 1.0
    assert [default_nn2_widen_px(k) for k in (1, 2, 4)] == [0.0, 0.0, 0.0]
    seen = []

    def fake_train(x, y, hidden, **kw):
        seen.append((x.shape[0], y.copy()))
        raise RuntimeError("enough")
    monkeypatch.setattr(training, "train_mlp", fake_train)
    rois = [_disc(12.0), _disc(13.0)]
    labels = np.array([5.0, -5.0])
    for kappa, widen in ((6, None), (4, None), (6, 0.0), (4, 1.0)):
        with pytest.raises(RuntimeError, match="enough"):
            train_nn2(rois, labels, kappa, GaborConfig(), seed=0, widen_px=widen)
    assert [n for n, _ in seen] == [2 * (1 + NN2_WIDEN_COPIES), 2, 2, 2 * (1 + NN2_WIDEN_COPIES)]
    # each copy keeps its ROI's turn
    first = seen[0][1]
    assert np.allclose(first[2:2 + NN2_WIDEN_COPIES], first[0])
    assert np.allclose(first[2 + NN2_WIDEN_COPIES:], first[1])


def test_perception_corrects_random_poses_near_the_nominal(bundle, cell):
    """Tolerance on random poses in NN2's range (+-5 mm, +-45 deg): 0.5 mm and 3 deg RMS;
    the paper's grasp tolerance is about 2 mm and 5-8 deg (reading note 7)."""
    err = errors(Perception(bundle), cell, random_offsets(np.random.default_rng(5), 60, 5, 45),
                 seed=6)
    rms = np.sqrt((err**2).mean(axis=0))
    assert rms[0] < 0.5 and rms[1] < 0.5 and rms[2] < 3.0


def test_translation_over_nn1s_range(bundle, cell):
    """Tolerance on random poses in NN1's range (+-25 mm): 1.5 mm RMS per axis."""
    perception = Perception(bundle)
    labels = random_offsets(np.random.default_rng(7), 40, 25, 45)
    rng = np.random.default_rng(8)
    err = []
    for label in labels:
        p = perception.translation(render(cell, label, rng))
        assert p.ok and p.features is None and p.nn2_sc is None and p.dphi_deg is None
        assert set(p.timings_us) == {"preprocess", "localise", "nn1", "total"}
        err.append(np.subtract(p.nn1_mm, label[:2]))
    assert (np.sqrt(np.mean(np.square(err), axis=0)) < 1.5).all()


def test_percept_carries_stages_and_the_full_loops_step(bundle, cell):
    frame = render(cell, np.array([1.5, -2.0, 20.0]), np.random.default_rng(9))
    perception = Perception(bundle)
    p = perception.perceive(frame)
    assert set(p.timings_us) == {"preprocess", "localise", "nn1", "roi", "features", "nn2",
                                 "total"}
    assert all(v >= 0 for v in p.timings_us.values())
    assert p.features.shape == (36,) and p.u_px == p.localisation.u_px
    # the full loop's translation: from (u, v) and NN2's rotation
    assert np.allclose(p.full_mm, (1.5, -2.0), atol=0.5)
    half = perception.translation(frame)
    assert half.nn1_mm == p.nn1_mm and half.full_mm is None
    again = perception.rotation(half)  # goes on from the same pass: the same numbers
    assert again.full_mm == p.full_mm and again.dphi_deg == p.dphi_deg
    assert np.array_equal(again.features, p.features)
    normalised, loc = perception.locate(frame)
    assert normalised.dtype == np.float32 and loc == p.localisation


def test_no_object_and_ambiguous_carry_no_motion(bundle, cell):
    perception = Perception(bundle)
    empty = np.empty((cell.height_px, cell.width_px, 3), np.uint8)
    empty[:] = cell.table_rgb
    twins = two_parts(cell, render_at(cell, 50.0, 72.0, 0.0), render_at(cell, 140.0, 72.0, 30.0))
    for frame, status in ((empty, "no_object"), (twins, "ambiguous")):
        p = perception.perceive(frame)
        assert p.localisation.status == status and not p.ok
        assert p.nn1_mm is None and p.features is None and p.dphi_deg is None
        assert p.full_mm is None


def test_perception_ignores_gain_and_offset(bundle, cell):
    label = np.array([-2.0, 3.0, -25.0])
    base = Perception(bundle).perceive(render(cell, label, np.random.default_rng(1)))
    dim = Perception(bundle).perceive(render(cell, label, np.random.default_rng(1),
                                             gain=0.6, bias=20.0))
    assert dim.ok
    assert np.allclose(dim.nn1_mm, base.nn1_mm, atol=0.1)
    assert abs(dim.dphi_deg - base.dphi_deg) < 1.0


def test_bad_frames_are_refused(bundle):
    perception = Perception(bundle)
    with pytest.raises(ImageError, match="HxWx3 uint8"):
        perception.perceive(np.zeros((144, 192), np.uint8))
    with pytest.raises(ImageError, match="trained on 192x144 frames, got 320x240"):
        perception.translation(np.zeros((240, 320, 3), np.uint8))


def test_training_refuses_unusable_data(grids):
    nn1_data, nn2_data = grids
    with pytest.raises(TrainingError, match="images"):
        train_bundle(Dataset(nn1_data.labels), nn2_data, object_kind="cube", kappa=KAPPA,
                     nominal_pose=NOMINAL_POSE)
    with pytest.raises(TrainingError, match="nominal_pose"):
        train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                     nominal_pose={"x_mm": 1.0})
    with pytest.raises(TrainingError, match="kappa"):
        train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=0, nominal_pose=NOMINAL_POSE)
    small = Dataset(nn2_data.labels, nn2_data.images[:, :100])
    with pytest.raises(TrainingError, match="one size"):
        train_bundle(nn1_data, small, object_kind="cube", kappa=KAPPA,
                     nominal_pose=NOMINAL_POSE)
    with pytest.raises(TrainingError, match="polarity"):
        train_bundle(nn1_data, nn2_data, object_kind="cube", kappa=KAPPA,
                     nominal_pose=NOMINAL_POSE, settings=TrainingSettings(polarity="dark"))
    mostly_empty = nn1_data.images.copy()
    mostly_empty[:40] = mostly_empty[:40, :1, :1]  # table colour only: no object in 40 of 63
    with pytest.raises(TrainingError, match="nn1 image 0 is flat"):
        train_bundle(Dataset(nn1_data.labels, mostly_empty), nn2_data, object_kind="cube",
                     kappa=KAPPA, nominal_pose=NOMINAL_POSE)
    noise = np.random.default_rng(0).normal(0.0, 2.0, mostly_empty[:40].shape)
    mostly_empty[:40] = np.clip(mostly_empty[:40] + noise, 0, 255).astype(np.uint8)
    with pytest.raises(TrainingError, match="nn1: the object was found in only 23 of 63"):
        train_bundle(Dataset(nn1_data.labels, mostly_empty), nn2_data, object_kind="cube",
                     kappa=KAPPA, nominal_pose=NOMINAL_POSE,
                     settings=TrainingSettings(nn1_epochs=5, nn2_epochs=5))


def test_auto_picks_saturation_for_a_coloured_part_on_grey(saturation_bundle, bundle):
    assert saturation_bundle.front.channel == "saturation" and bundle.front.channel == "max"


def test_saturation_path_ignores_gain_and_shade(saturation_bundle, cell):
    """Saturation is unchanged by dimming (gain), where max(R, G, B) of a shaded face is not;
    an added offset (a*I + b with b > 0) does change it: that invariance is the max path's."""
    label = np.array([-2.0, 3.0, -25.0])
    base = Perception(saturation_bundle).perceive(render(cell, label, np.random.default_rng(1)))
    dim = Perception(saturation_bundle).perceive(render(cell, label, np.random.default_rng(1),
                                                        gain=0.4))
    assert base.ok and dim.ok
    assert np.allclose(dim.nn1_mm, base.nn1_mm, atol=0.1)
    assert abs(dim.dphi_deg - base.dphi_deg) < 1.0


def test_nn1_reads_zero_at_the_taught_pose(bundle, saturation_bundle, cell):
    for b in (bundle, saturation_bundle):
        p = Perception(b).perceive(render(cell, np.zeros(3), np.random.default_rng(2)))
        assert np.hypot(*p.nn1_mm) < 0.05 and np.hypot(*p.full_mm) < 0.05
        assert b.training["nn1"]["zero_offset_mm"] is not None
        assert b.training["nn1_rot"]["zero_offset_mm"] is not None
        assert p.near and b.training["nn1_near"]["zero_offset_mm"] is not None


def test_clearly_nearest_of_two_matching_blobs_is_taken(bundle, cell):
    """Two identical parts: the one near the taught image position is the part, unless
    both are about as near (then: ambiguous)."""
    u0, v0 = bundle.front.nominal_uv_px
    near_far = two_parts(cell, render_at(cell, u0 + 3.0, v0, 0.0),
                         render_at(cell, u0 + 70.0, v0, 30.0))
    p = Perception(bundle).perceive(near_far)
    assert p.ok and abs(p.u_px - (u0 + 3.0)) < 1.0
    both_far = two_parts(cell, render_at(cell, u0 - 45.0, v0, 0.0),
                         render_at(cell, u0 + 45.0, v0, 30.0))
    assert Perception(bundle).perceive(both_far).localisation.status == "ambiguous"


def test_of_two_candidates_the_one_of_the_parts_colour_is_taken(bundle, cell):
    """Clutter of the part's size and shape: the blob of the trained colour is the part, even
    where the other is nearer the taught position. A lone part of another colour is still
    taken (a red cube for a yellow one), and two of another colour fall back to the nearest
    rule."""
    u0, v0 = bundle.front.nominal_uv_px
    green = dataclasses.replace(cell, object_rgb=(50, 140, 60))
    frame = two_parts(cell, render_at(cell, u0 + 45.0, v0, 0.0),
                      render_at(green, u0 - 40.0, v0, 30.0))
    p = Perception(bundle).perceive(frame)
    assert p.ok and abs(p.u_px - (u0 + 45.0)) < 1.0
    alone = Perception(bundle).perceive(render_at(green, u0 - 40.0, v0, 30.0))
    assert alone.ok
    both = two_parts(green, render_at(green, u0 - 40.0, v0, 30.0),
                     render_at(green, u0 + 45.0, v0, 0.0))
    assert Perception(bundle).perceive(both).localisation.status == "ambiguous"
    near = two_parts(green, render_at(green, u0 + 3.0, v0, 30.0),
                     render_at(green, u0 + 70.0, v0, 0.0))
    p = Perception(bundle).perceive(near)
    assert p.ok and abs(p.u_px - (u0 + 3.0)) < 1.0


def test_a_part_darker_than_its_table_is_found_dark_at_the_taught_pose():
    from calibration_free.dataset import grid_offsets, staggered_grid_offsets
    from calibration_free.synthetic import SyntheticCell, render_dataset

    dark = SyntheticCell(object_rgb=(70, 45, 35), hole_rgb=(25, 20, 15),
                         table_rgb=(205, 200, 190))
    rng = np.random.default_rng(3)
    sets = {"nn1": render_dataset(dark, grid_offsets(25.0, 180.0 / KAPPA), rng),
            "nn2": render_dataset(dark, staggered_grid_offsets(5.0, 180.0 / KAPPA), rng)}
    prep = training.prepare_training(sets, channel="max")
    assert prep.front.polarity == "dark"
    assert len(prep.usable["nn1"]) == len(sets["nn1"].images)
    centre = prep.centres("nn2").mean(axis=0)
    assert np.hypot(*(centre - dark.nominal_uv_px)) < 3.0
    with pytest.raises(TrainingError, match="it is the table"):
        training.prepare_training(sets, polarity="bright", channel="max")
