"""``finepos evaluate --mounts``: random cameras and the per-camera summary."""

import numpy as np

from controller.evaluation.mounts import (
    K1_RANGE,
    OFFSET_MM,
    TILT_DEG,
    camera_row,
    random_camera,
    summarise_mounts,
)
from sim_backend.cell import hand_camera
from sim_backend.cell.optics import resolve_camera
from sim_backend.cell.scene_config import CameraConfig


def test_random_cameras_stay_in_their_ranges_and_are_valid_lenses():
    rng = np.random.default_rng(4)
    for _ in range(40):
        cam = random_camera(rng, CameraConfig())
        model = resolve_camera(cam)  # raises if the lens folds the image
        assert abs(cam.mount.tilt_deg) <= TILT_DEG and abs(cam.mount.roll_deg) <= 4.0
        assert max(abs(v) for v in cam.mount.offset_mm) <= OFFSET_MM
        assert K1_RANGE[0] <= model.k1 <= K1_RANGE[1]
        assert abs(model.fov_deg / hand_camera.VFOV_DEG - 1.0) <= 0.15 + 1e-9
        assert model.auto and model.bayer == resolve_camera(CameraConfig()).bayer
        assert camera_row(cam)["mount"]["tilt_deg"] == cam.mount.tilt_deg


def _row(safe, rms_x):
    return {"safe_rate": {"2.5": safe}, "rms": {"2.5": {"x_mm": rms_x, "y_mm": 0.0,
                                                          "phi_deg": 0.1}},
            "grasp_success_rate": safe}


def test_summary_names_the_worst_and_the_median_camera():
    rows = [_row(1.0, 0.05), _row(0.96, 0.04), _row(1.0, 0.09)]
    summary = summarise_mounts(rows)
    assert summary["worst_camera"] == 1
    assert summary["worst"]["safe_rate"]["2.5"] == 0.96
    assert summary["worst"]["rms"]["2.5"]["x_mm"] == 0.09
    assert summary["median"]["rms"]["2.5"]["x_mm"] == 0.05
    assert summary["worst"]["grasp_success_rate"] == 0.96
