"""The hand camera's optics and sensor (sim_backend.cell.optics) and its mount."""

import dataclasses
import math

import cv2
import numpy as np
import pytest

from drivers.core.errors import ConfigError
from drivers.core.pose import ToolStep
from drivers.core.typed_config import from_mapping
from sim_backend.cell import hand_camera, optics
from sim_backend.cell.scene_config import (
    CameraConfig,
    ExposureConfig,
    LensConfig,
    MountConfig,
    SceneConfig,
)
from sim_backend.cell.sim_cell import SimCell

H, W = hand_camera.HEIGHT_PX, hand_camera.WIDTH_PX


def _plain(**values) -> optics.CameraModel:
    """The ideal camera with ``values`` changed (no noise unless given)."""
    base = {**optics.IDEAL, "noise_std": 0.0}
    return optics.CameraModel(**{**base, **values})


def test_ideal_preset_renders_todays_image_bit_for_bit():
    # Today's image: the pinhole render plus Gaussian noise from the cell's 4th seeded stream.
    with SimCell(SceneConfig(camera=CameraConfig(preset="ideal")), seed=3) as cell:
        assert cell.camera_model.ideal
        clean = cell.render(noisy=False)
        frame = cell.render()
    rng = np.random.default_rng(np.random.SeedSequence(3).spawn(5)[3])
    noise = rng.standard_normal(clean.shape, dtype=np.float32) * 2.0
    expected = np.clip(clean + noise + 0.5, 0, 255).astype(np.uint8)
    assert np.array_equal(frame, expected)


def test_zero_mount_is_the_standard_mount_exactly():
    assert np.array_equal(hand_camera.camera_in_tool(MountConfig()), hand_camera.camera_in_tool())


def test_mount_tilts_rolls_pans_and_offsets_the_camera():
    std = hand_camera.camera_in_tool()
    tilted = hand_camera.camera_in_tool(MountConfig(tilt_deg=5.0))
    cos = float(std[:3, 2] @ tilted[:3, 2])
    assert math.degrees(math.acos(min(cos, 1.0))) == pytest.approx(5.0)
    assert np.allclose(std[:3, 0], tilted[:3, 0])  # about the image's x axis
    rolled = hand_camera.camera_in_tool(MountConfig(roll_deg=3.0))
    assert np.allclose(rolled[:3, 2], std[:3, 2])  # about the optical axis
    panned = hand_camera.camera_in_tool(MountConfig(pan_deg=4.0))
    assert np.allclose(panned[:3, 1], std[:3, 1])  # about the image's y axis
    moved = hand_camera.camera_in_tool(MountConfig(offset_mm=(1.0, -2.0, 3.0)))
    assert np.allclose(moved[:3, 3] - std[:3, 3], [1.0, -2.0, 3.0])


@pytest.mark.parametrize("roll_deg", [0.0, 7.0, 30.0])
def test_distorted_point_lands_where_cv2_project_points_puts_it(roll_deg):
    model = _plain(k1=-0.25, k2=0.06, p1=0.001, p2=-0.0008, fov_deg=60.0,
                   sample_roll_deg=roll_deg)
    geometry = optics.LensGeometry(model)
    point = np.array([[38.0, -27.0, 120.0]])  # camera frame, mm: towards a corner
    expected, _ = cv2.projectPoints(point, np.zeros(3), np.zeros(3), model.camera_matrix(),
                                    model.distortion)
    expected = expected.reshape(2)
    assert np.allclose(optics.project_points(point, model)[0], expected, atol=1e-9)
    # A small bright spot at the point's pinhole position in the wide render (taken by the
    # camera turned by roll_deg about its axis)...
    f = geometry.focal_px
    in_render = np.linalg.inv(geometry.render_in_camera())[:3, :3] @ point[0]
    uc = in_render[0] / in_render[2] * f + geometry.width_px / 2.0 - 0.5
    vc = in_render[1] / in_render[2] * f + geometry.height_px / 2.0 - 0.5
    v, u = np.mgrid[0:geometry.height_px, 0:geometry.width_px]
    spot = np.exp(-((u - uc) ** 2 + (v - vc) ** 2) / (2 * 1.2**2)).astype(np.float32)
    # ...lands, through the lens, where OpenCV projects the point.
    out = geometry.resample(spot)
    vv, uu = np.mgrid[0:H, 0:W]
    win = (np.abs(uu - expected[0]) < 6) & (np.abs(vv - expected[1]) < 6)
    weight = out * win
    centroid = np.array([(weight * uu).sum(), (weight * vv).sum()]) / weight.sum()
    assert np.allclose(centroid, expected, atol=0.15)


def test_barrel_lens_sees_more_than_the_pinhole():
    geometry = optics.LensGeometry(_plain(k1=-0.2))
    assert geometry.width_px > W and geometry.height_px > H
    assert geometry.vfov_deg > hand_camera.VFOV_DEG


def test_vignetting_darkens_corners_by_the_configured_factor():
    model = _plain(vignetting=0.4, gamma=1.0)
    pipeline = optics.CameraPipeline(model, np.random.default_rng(0))
    grey = int(round(255 * 0.8 ** (1 / optics.DISPLAY_GAMMA)))
    render = np.full((pipeline.geometry.height_px, pipeline.geometry.width_px, 3), grey,
                     np.uint8)
    out = pipeline.process(render).astype(float)
    centre = out[H // 2 - 1:H // 2 + 1, W // 2 - 1:W // 2 + 1].mean()
    corner = out[0, 0].mean()
    r2 = (W / 2 - 0.5) ** 2 + (H / 2 - 0.5) ** 2
    expected = 1.0 - 0.4 * r2 / ((W / 2) ** 2 + (H / 2) ** 2)  # pixel (0, 0)'s centre
    assert corner / centre == pytest.approx(expected, abs=0.01)
    assert corner / centre < 0.62


def test_auto_exposure_follows_a_change_of_light_over_a_few_frames():
    model = _plain(auto=True, target_grey=110.0, speed=0.5, gamma=2.2)
    pipeline = optics.CameraPipeline(model, np.random.default_rng(0))
    shape = (pipeline.geometry.height_px, pipeline.geometry.width_px, 3)
    bright, dim = np.full(shape, 160, np.uint8), np.full(shape, 70, np.uint8)
    means = [pipeline.process(bright).mean() for _ in range(12)]
    assert means[0] > 150 and abs(means[-1] - 110.0) < 2.0
    means = [pipeline.process(dim).mean() for _ in range(12)]
    assert means[0] < 60  # the light went down: the first frame is dark...
    assert abs(means[2] - 110.0) > abs(means[5] - 110.0)  # ...and it catches up
    assert abs(means[-1] - 110.0) < 2.0


def test_fixed_exposure_does_not_move():
    pipeline = optics.CameraPipeline(_plain(gain=1.5), np.random.default_rng(0))
    shape = (pipeline.geometry.height_px, pipeline.geometry.width_px, 3)
    for _ in range(3):
        pipeline.process(np.full(shape, 90, np.uint8))
    assert pipeline.factor == 1.5


def test_bayer_mosaic_and_demosaicing_keep_a_flat_colour():
    pipeline = optics.CameraPipeline(_plain(bayer=True), np.random.default_rng(0))
    shape = (pipeline.geometry.height_px, pipeline.geometry.width_px, 3)
    out = pipeline.process(np.broadcast_to(np.array([200, 120, 40], np.uint8), shape).copy())
    assert np.abs(out[10:-10, 10:-10].astype(int) - [200, 120, 40]).max() <= 1


def test_shot_noise_grows_with_the_signal():
    pipeline = optics.CameraPipeline(_plain(full_well_e=2000.0, gamma=1.0),
                                     np.random.default_rng(1))
    shape = (pipeline.geometry.height_px, pipeline.geometry.width_px, 3)
    dark = pipeline.process(np.full(shape, 90, np.uint8)).astype(float)
    bright = pipeline.process(np.full(shape, 220, np.uint8)).astype(float)
    assert 0.5 < dark.std() < bright.std()


def test_jpeg_compresses_the_frame():
    spot = np.zeros((H + 40, W + 40, 3), np.uint8)
    spot[60:100, 80:130] = (230, 200, 30)
    raw = optics.CameraPipeline(_plain(), np.random.default_rng(0))
    jpeg = optics.CameraPipeline(_plain(jpeg_quality=50), np.random.default_rng(0))
    geometry_shape = (raw.geometry.height_px, raw.geometry.width_px, 3)
    render = cv2.resize(spot, geometry_shape[1::-1])
    a, b = raw.process(render), jpeg.process(render)
    assert 0.0 < np.abs(a.astype(int) - b).mean() < 5.0


def test_realistic_preset_is_the_default_and_renders():
    assert CameraConfig().preset == "realistic"
    with SimCell(SceneConfig(), seed=2) as cell:
        assert not cell.camera_model.ideal
        frame = cell.render()
        labels = cell.render_labels()
    assert frame.shape == (H, W, 3) and frame.dtype == np.uint8
    assert labels.shape == (H, W)


def test_knocking_the_camera_moves_the_image():
    with SimCell(SceneConfig(camera=CameraConfig(preset="ideal", noise_std=0.0))) as cell:
        before = cell.render()
        cell.set_camera_mount(MountConfig(tilt_deg=5.0))
        after = cell.render()
        assert cell.camera_mount.tilt_deg == 5.0
    assert np.abs(before.astype(int) - after).mean() > 5.0


def test_a_wrong_key_under_lens_names_its_full_path():
    with pytest.raises(ConfigError, match=r"scene\.camera\.lens\.k3: unknown key"):
        from_mapping(SceneConfig, {"camera": {"lens": {"k3": 0.1}}}, "scene")
    with pytest.raises(ConfigError, match=r"scene\.camera\.mount\.tilt_deg: must be <= 30"):
        from_mapping(SceneConfig, {"camera": {"mount": {"tilt_deg": 45}}}, "scene")
    with pytest.raises(ConfigError, match=r"scene\.camera\.preset: must be one of"):
        from_mapping(SceneConfig, {"camera": {"preset": "perfect"}}, "scene")


def test_a_lens_that_folds_the_image_is_refused_at_load():
    with pytest.raises(ConfigError, match=r"scene\.camera: lens: k1 -0.35, k2 0 fold"):
        from_mapping(SceneConfig, {"camera": {"lens": {"k1": -0.35, "k2": 0.0}}}, "scene")


def test_presets_resolve_with_overrides():
    cam = from_mapping(CameraConfig, {"preset": "ideal", "lens": {"vignetting": 0.2},
                                      "exposure": {"auto": True}}, "scene.camera")
    model = optics.resolve_camera(cam)
    assert model.vignetting == 0.2 and model.auto and not model.ideal and model.k1 == 0.0
    assert optics.resolve_camera(CameraConfig()).k1 == optics.REALISTIC["k1"]


def test_test_mount_replaces_the_mount_at_test():
    cam = CameraConfig(test_mount=MountConfig(tilt_deg=2.0))
    assert cam.at_test().mount.tilt_deg == 2.0 and cam.at_test().test_mount is None
    assert CameraConfig().at_test() == CameraConfig()
    assert dataclasses.replace(cam, exposure=ExposureConfig(auto=False)).lens == LensConfig()


def test_each_pixel_integrates_over_its_area():
    # realistic: 2 x 2 samples a pixel averaged; the part's outline gets greys in between
    # its level and the table's, which one sample a pixel (ideal) never shows along an edge
    assert optics.REALISTIC["pixel_samples"] == 2 and optics.IDEAL["pixel_samples"] == 1
    scenes = {n: SceneConfig(camera=CameraConfig(preset="ideal", pixel_samples=n))
              for n in (1, 2)}
    grey = {}
    for n, scene in scenes.items():
        with SimCell(scene, seed=3) as cell:
            assert cell.camera_model.pixel_samples == n
            grey[n] = cell.render(noisy=False).max(axis=2).astype(np.int16)
    levels = {n: len(np.unique(g)) for n, g in grey.items()}
    assert levels[2] > levels[1]
    assert np.abs(grey[2] - grey[1]).mean() < 3.0  # the same scene, only its edges differ
    with pytest.raises(ConfigError, match="pixel_samples"):
        from_mapping(CameraConfig, {"pixel_samples": 0}, "scene.camera")


def test_a_pixel_averages_its_samples_light_not_their_levels():
    # half its samples at full light, half dark: half the light, which a gamma of 2.2
    # encodes as level 186, not the mean level 127.5 (an edge pixel read too dark)
    samples = np.zeros((4, 4, 3), np.uint8)
    samples[:, ::2] = 255
    pixels = optics.integrate_samples(samples, 2)
    assert pixels.shape == (2, 2, 3) and pixels.dtype == np.float32
    assert np.allclose(pixels, 0.5, atol=1e-6)
    model = optics.resolve_camera(CameraConfig(preset="ideal"))
    frame = optics.CameraPipeline(model, np.random.default_rng(0)).process_light(
        np.full((144, 192, 3), 0.5, np.float32), noisy=False)
    assert np.all(frame == 186)
    flat = np.full((4, 4, 3), 77, np.uint8)
    light = (77 / 255) ** optics.DISPLAY_GAMMA
    assert np.allclose(optics.integrate_samples(flat, 2), light, rtol=1e-5)
    assert np.allclose(optics.integrate_samples(flat, 1), light, rtol=1e-5)


def test_the_shadow_map_shades_each_sample_through_its_own_ray():
    # the rays of a pixel's 2 x 2 samples surround the pixel's own ray
    model = optics.resolve_camera(CameraConfig())
    assert model.pixel_samples == 2 and model.sample_roll_deg == 7.0  # the realistic default
    geometry = optics.LensGeometry(model)
    rays = geometry.sample_rays()
    assert rays.shape == (geometry.height_px * 2, geometry.width_px * 2, 3)
    centres = rays.reshape(geometry.height_px, 2, geometry.width_px, 2, 3).mean(axis=(1, 3))
    assert np.allclose(centres, hand_camera.pixel_rays(geometry.width_px, geometry.height_px,
                                                       geometry.focal_px))


def _outline_rows(roll_deg: float) -> np.ndarray:
    """(tool x offset mm, the part's image row) as the tool steps along x over the cube,
    whose near and far edges lie along the pixel rows."""
    scene = SceneConfig(camera=CameraConfig(noise_std=0.0, full_well_e=0.0,
                                            exposure=ExposureConfig(auto=False),
                                            sample_roll_deg=roll_deg))
    rows = []
    with SimCell(scene, seed=3) as cell:
        nominal = cell.nominal_grasp_pose()
        for dx in np.linspace(-0.3, 0.3, 25):
            cell.move_arm(nominal.moved_in_tool_frame(ToolStep(dx_mm=float(dx))))
            rgb = cell.render(noisy=False).astype(float)
            top = rgb.max(axis=2)
            weight = np.clip(((top - rgb.min(axis=2)) / np.maximum(top, 1.0) - 0.3) / 0.4, 0, 1)
            rows.append((cell.ground_truth_error()[0],
                         (weight * np.mgrid[0:H, 0:W][0]).sum() / weight.sum()))
    return np.array(rows)


def test_a_turned_sample_grid_moves_an_edge_along_the_rows_smoothly():
    # On the pixel grid the 2 x 2 samples of a whole row flip at once as the edge crosses
    # them: the part's row stands still over about 0.15 mm of travel and then jumps by
    # 0.15 px. On a grid turned by 7 deg the samples along the edge flip one after another.
    fits = {}
    for roll in (0.0, 7.0):
        rows = _outline_rows(roll)
        slope, offset = np.polyfit(rows[:, 0], rows[:, 1], 1)
        fits[roll] = (slope, float(np.std(rows[:, 1] - (slope * rows[:, 0] + offset))),
                      float(np.abs(np.diff(rows[:, 1])).max()))
    (slope0, residual0, jump0), (slope7, residual7, jump7) = fits[0.0], fits[7.0]
    assert 0.85 < slope0 < 1.0 and 0.85 < slope7 < 1.0  # px per mm: the same image scale
    assert residual7 < 0.02 < 0.03 < residual0  # px (0.015 and 0.038 measured)
    assert jump7 < 0.08 < 0.12 < jump0  # the largest step between 0.025 mm moves (0.07, 0.19)


def test_a_turned_sample_grid_renders_the_same_image():
    images = {}
    for roll in (0.0, 7.0):
        scene = SceneConfig(camera=CameraConfig(preset="ideal", pixel_samples=2,
                                                noise_std=0.0, sample_roll_deg=roll))
        with SimCell(scene, seed=3) as cell:
            images[roll] = cell.render(noisy=False).astype(np.int16)
    assert np.abs(images[7.0] - images[0.0]).mean() < 1.0  # only along edges, by a grey
    with pytest.raises(ConfigError, match="sample_roll_deg"):
        from_mapping(CameraConfig, {"sample_roll_deg": 50}, "scene.camera")
