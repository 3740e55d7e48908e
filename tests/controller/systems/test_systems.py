"""The PCA, Hough and image-alignment systems through the registry, as the controller runs
them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration_free.errors import BundleError
from calibration_free.synthetic import render
from controller.recipe import PerceptionConfig
from controller.systems.estimator import RotationEstimate, TranslationEstimate
from controller.systems.registry import SYSTEMS
from drivers.core.cell_state import CellState
from drivers.core.pose import Pose
from tests.synthetic_scene import KAPPA, NOMINAL_POSE, wrapped_error_deg

STATE = CellState(nominal_pose=Pose(**NOMINAL_POSE), object_kind="cube", kappa=KAPPA,
                  grasp_depth_mm=50.0, object_width_mm=30.0, source="auto", taught_at=0.0)


@pytest.fixture(scope="module", params=["pca", "hough", "align"])
def trained(request, grids):
    system = SYSTEMS[request.param]
    return system, system.train(*grids, STATE, PerceptionConfig())


def test_registered_with_the_protocol(trained):
    system, model = trained
    assert system.name == model.system and system.suffix.startswith(".")
    assert model.train_images == 126 and model.train_seconds > 0
    assert model.feature_count == {"pca": 3, "hough": 4, "align": 3}[system.name]


def test_estimator_recovers_a_known_step(trained, cell):
    system, model = trained
    estimator = system.estimator(model)
    assert estimator.name == system.name
    for label in ([2.0, -3.0, 12.0], [-4.0, 1.5, -30.0], [20.0, 15.0, 5.0]):
        frame = render(cell, np.array(label), np.random.default_rng(1))
        t = estimator.estimate_translation(frame)
        assert isinstance(t, TranslationEstimate) and t.status == "ok", t.reason
        assert math.hypot(t.dx_mm - label[0], t.dy_mm - label[1]) < 1.0
        assert math.isfinite(t.u_px) and math.isfinite(t.v_px)
        r = estimator.estimate_rotation(t)
        assert isinstance(r, RotationEstimate)
        assert abs(wrapped_error_deg(r.dphi_deg, label[2])) < 5.0
        assert r.record  # something for the iteration log


def test_no_object_has_a_reason_and_no_numbers(trained):
    system, model = trained
    t = system.estimator(model).estimate_translation(np.full((144, 192, 3), 125, np.uint8))
    assert t.status == "no_object" and t.reason and math.isnan(t.dx_mm)


def test_save_load_round_trip_and_object_check(trained, cell, tmp_path):
    system, model = trained
    path = tmp_path / f"model{system.suffix}"
    system.save(model, path)
    again = system.load(path, STATE)
    assert (again.system, again.train_images, again.feature_count) == \
        (model.system, model.train_images, model.feature_count)
    frame = render(cell, np.array([1.0, 1.0, 7.0]), np.random.default_rng(2))
    a = system.estimator(model).estimate_translation(frame)
    b = system.estimator(again).estimate_translation(frame)
    assert (a.dx_mm, a.dy_mm) == (b.dx_mm, b.dy_mm)
    nut = CellState(STATE.nominal_pose, "nut", 6, 50.0, 24.0, "auto", 0.0)
    with pytest.raises(BundleError, match="not 'nut'"):
        system.load(path, nut)
