"""The image-alignment servo on synthetic parts: registration, the fitted step, the model file."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from calibration_free.baselines.align.model import AlignConfig, AlignModel
from calibration_free.baselines.align.register import Template, wrap_deg
from calibration_free.baselines.align.train import train_align
from calibration_free.dataset import Dataset
from calibration_free.errors import BundleError, ImageError, TrainingError
from calibration_free.model_file import pack_model
from calibration_free.synthetic import image_pose, render
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping
from tests.synthetic_scene import KAPPA, NOMINAL_POSE, wrapped_error_deg


def _turned_l_shape(size: int, angle_deg: float, u: float, v: float) -> np.ndarray:
    """A soft L-shaped silhouette (no symmetry) on a size x size frame, turned by angle_deg
    about (u, v) (image axes), drawn 8x supersampled."""
    s = 8
    big = np.zeros((size * s, size * s), np.float32)
    points = np.array([[-10, -12], [10, -12], [10, -4], [-2, -4], [-2, 12], [-10, 12]], float)
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    centre = np.array([(u + 0.5) * s - 0.5, (v + 0.5) * s - 0.5])
    poly = np.round((centre + s * points @ rot.T) * 16).astype(np.int32)
    cv2.fillPoly(big, [poly], 200.0, cv2.LINE_8, 4)
    return cv2.resize(big, (size, size), interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("angle", [0.0, 37.0, 150.0, -120.0, 179.0])
def test_a_part_without_symmetry_is_registered_over_the_full_circle(angle):
    template = Template(_turned_l_shape(41, 0.0, 20.0, 20.0), kappa=1, scan_step_deg=5.0,
                        ecc_iterations=100, ecc_epsilon=1e-6)
    frame = _turned_l_shape(120, angle, 63.3, 51.8)
    # the seed: the silhouette's centroid, as localisation gives it
    m = cv2.moments(frame)
    centroid = np.array([m["m10"], m["m01"]]) / m["m00"]
    reg = template.register(frame, *centroid)
    assert reg.refined and reg.correlation > 0.99
    assert abs(wrap_deg(reg.angle_deg - angle, 360.0)) < 0.3
    assert math.hypot(reg.u_px - 63.3, reg.v_px - 51.8) < 0.2


def test_the_turn_is_read_within_the_symmetry_period(align_model, cell):
    """The cube turned by 40 and by -50 deg is the same view: one reading, within +-45 deg."""
    a = align_model.perceive(render(cell, np.array([0.0, 0.0, 40.0])))
    b = align_model.perceive(render(cell, np.array([0.0, 0.0, -50.0])))
    assert abs(a.registration.angle_deg - b.registration.angle_deg) < 0.5
    assert abs(a.registration.angle_deg) <= 45.0
    assert abs(wrapped_error_deg(a.step[2], 40.0)) < 2.0


def test_registration_follows_the_image_pose(align_model, cell):
    """On the straight-down synthetic camera the reference point moves with the part's centre
    and the image turn is the part's turn."""
    u0, v0, _ = image_pose(cell, np.zeros(3))
    for label in ([3.0, -2.0, 12.0], [-4.0, 1.5, -30.0], [15.0, 10.0, 5.0]):
        reg = align_model.perceive(render(cell, np.array(label))).registration
        u, v, _ = image_pose(cell, np.array(label))
        assert math.hypot(reg.u_px - u0 - (u - u0), reg.v_px - v0 - (v - v0)) < 0.3
        assert abs(wrapped_error_deg(reg.angle_deg, label[2])) < 0.5


def test_recovers_the_step_on_unseen_poses(align_model, near_test_set):
    steps = np.array([align_model.perceive(im).step for im in near_test_set.images])
    rot = wrapped_error_deg(steps[:, 2], near_test_set.labels[:, 2])
    trans = steps[:, :2] - near_test_set.labels[:, :2]
    assert np.sqrt(np.mean(rot ** 2)) < 1.0
    assert np.sqrt(np.mean(trans ** 2)) < 0.3
    assert align_model.training["refined"] == 126


def test_an_empty_table_and_a_wrong_frame(align_model, cell):
    frame = render(cell, np.array([3.0, -2.0, 20.0]))
    empty = np.full_like(frame, 125)
    p = align_model.perceive(empty)
    assert p.localisation.status == "no_object" and p.step is None and p.registration is None
    with pytest.raises(ImageError, match="trained on 192x144"):
        align_model.perceive(frame[:100])


def test_round_trip_gives_the_same_answers(align_model, cell, tmp_path):
    path = tmp_path / "cube.align"
    align_model.save(path)
    again = AlignModel.load(path, expect_object="cube")
    frame = render(cell, np.array([2.0, -3.0, 12.0]), np.random.default_rng(0))
    assert align_model.perceive(frame).step == again.perceive(frame).step
    assert again.config == align_model.config and again.front == align_model.front
    with pytest.raises(BundleError, match="taught on object 'cube', not 'nut'"):
        AlignModel.load(path, expect_object="nut")


def test_wrong_coefficients_or_template_are_refused(align_model):
    """The constructor checks what a model file gives it (``load`` reports it as one line)."""
    with pytest.raises(ConfigError, match="coefficients"):
        dataclasses.replace(align_model, phi=np.zeros(5))
    with pytest.raises(ConfigError, match="coefficients"):
        dataclasses.replace(align_model, xy=np.full((24, 2), np.nan))
    with pytest.raises(ValueError, match="square"):
        dataclasses.replace(align_model, template=np.zeros((10, 12), np.float32))


def test_a_damaged_file_is_refused_in_one_line(align_model, tmp_path):
    path = tmp_path / "cube.align"
    align_model.save(path)
    info = align_model.to_info()
    arrays = {**align_model.arrays(), "align.phi": np.zeros(3)}
    path.write_bytes(pack_model("align", 1, info, arrays))
    with pytest.raises(BundleError, match="inconsistent align model: .*coefficients"):
        AlignModel.load(path)


def test_training_needs_a_frame_at_the_taught_pose(grids):
    nn1, nn2 = grids
    away = np.hypot(nn1.labels[:, 0], nn1.labels[:, 1]) > 1.0
    off = Dataset(nn1.labels[away], images=nn1.images[away])
    away2 = np.hypot(nn2.labels[:, 0], nn2.labels[:, 1]) > 1.0
    off2 = Dataset(nn2.labels[away2], images=nn2.images[away2])
    with pytest.raises(TrainingError, match="no training image at the taught pose"):
        train_align(off, off2, object_kind="cube", kappa=KAPPA, nominal_pose=NOMINAL_POSE)


def test_config_is_checked():
    with pytest.raises(ConfigError, match="scan_step_deg"):
        from_mapping(AlignConfig, {"scan_step_deg": 0.0}, "align")


@pytest.mark.parametrize(("angle", "period", "wrapped"),
                         [(45.0, 90.0, 45.0), (-45.0, 90.0, 45.0), (50.0, 90.0, -40.0),
                          (-180.0, 360.0, 180.0), (359.0, 360.0, -1.0)])
def test_wrap_deg(angle, period, wrapped):
    assert wrap_deg(angle, period) == pytest.approx(wrapped)
