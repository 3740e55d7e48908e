"""The simulated cell: geometry, ground truth, images, light, occluder and clutter."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from drivers.core.pose import ToolStep
from drivers.core.typed_config import from_mapping
from sim_backend.cell import hand_camera, puma260
from sim_backend.cell.pybullet_quiet import p
from sim_backend.cell.robot_model import GRIPPER_LINK
from sim_backend.cell.scene_config import CameraConfig, SceneConfig
from sim_backend.cell.sim_cell import (
    GRIPPER_FOOTPRINT_TOOL_MM,
    LABEL_BACKGROUND,
    LABEL_CLUTTER,
    LABEL_OCCLUDER,
    LABEL_PART,
    LABEL_ROBOT,
    TOOL_IN_FLANGE,
    SimCell,
)

QUIET = SceneConfig(camera=CameraConfig(preset="ideal", noise_std=0.0))


def _scene(**sections) -> SceneConfig:
    data = {"camera": {"preset": "ideal", "noise_std": 0.0}, **sections}
    return from_mapping(SceneConfig, data, "scene")


def _bbox(mask: np.ndarray) -> tuple[int, int, int, int]:
    ys, xs = np.nonzero(mask)
    return int(xs.min()), int(xs.max()), int(ys.min()), int(ys.max())


def _centroid(mask: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()])


@pytest.fixture(scope="module")
def cell():
    with SimCell(QUIET) as c:
        yield c


@pytest.fixture
def fresh(cell):
    """The shared cell back at its default state (part placed, arm at the nominal pose)."""
    obj = SceneConfig().object
    cell.open_gripper()
    cell.set_lighting("good")
    cell.place_object(obj.x_mm, obj.y_mm, obj.phi_deg)
    cell.move_arm(cell.nominal_grasp_pose())
    return cell


def test_nominal_pose_points_down_above_the_part(fresh):
    nominal = fresh.nominal_grasp_pose()
    assert nominal.rotation()[:, 2] == pytest.approx([0.0, 0.0, -1.0])
    assert (nominal.x_mm, nominal.y_mm) == pytest.approx((300.0, 0.0))
    assert nominal.z_mm == pytest.approx(30.0 + fresh.approach_height_mm)
    assert fresh.grasp_depth_mm == pytest.approx(fresh.approach_height_mm + 15.0)
    assert fresh.kappa == 4 and fresh.object_kind == "cube"


def test_pybullet_model_matches_the_kinematics(fresh):
    state = p.getLinkState(fresh._robot.body_id, GRIPPER_LINK, computeForwardKinematics=True,
                           physicsClientId=fresh._client)
    flange = puma260.flange_transform(np.radians(fresh.joint_angles_deg()))
    np.testing.assert_allclose(np.array(state[4]) * 1000.0, flange[:3, 3], atol=1e-3)
    rot = np.array(p.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    np.testing.assert_allclose(rot, flange[:3, :3], atol=1e-6)
    true_tool = fresh.true_tool_pose()
    np.testing.assert_allclose((flange @ TOOL_IN_FLANGE)[:3, 3], true_tool.position_mm, atol=1e-6)


def test_relative_moves_change_the_ground_truth_by_the_step(fresh):
    tol_mm, tol_deg = 2 * fresh.arm_config.repeatability_mm, 2 * fresh.arm_config.repeatability_deg
    before = np.array(fresh.ground_truth_error())
    for step in (ToolStep(5.0, -3.0, 0.0, 10.0), ToolStep(-12.0, 4.0, 0.0, -25.0),
                 ToolStep(0.5, 0.25, 0.0, 0.5)):
        # The arm reports the commanded pose; a relative move starts from that report.
        fresh.move_arm(fresh.arm_pose().moved_in_tool_frame(step))
        after = np.array(fresh.ground_truth_error())
        done_x, done_y = after[:2] - before[:2]
        # Steps compose in the tool frame: rotate the step into the nominal frame.
        heading = math.radians(before[2])
        expect = np.array([[math.cos(heading), -math.sin(heading)],
                           [math.sin(heading), math.cos(heading)]]) @ [step.dx_mm, step.dy_mm]
        # Slack: the step starts from the reported pose, whose heading differs from the real
        # one by up to the rotational repeatability.
        assert abs(done_x - expect[0]) <= tol_mm + 0.01
        assert abs(done_y - expect[1]) <= tol_mm + 0.01
        assert abs(after[2] - before[2] - step.dphi_deg) <= tol_deg + 1e-6
        before = after


def test_repeatability_error_is_bounded_and_seeded(fresh):
    nominal = fresh.nominal_grasp_pose()
    errors = []
    for _ in range(20):
        fresh.move_arm(nominal)
        assert fresh.arm_pose().tool_step_to(nominal).translation_mm < 1e-6, "reports command"
        errors.append(fresh.ground_truth_error())
    errors = np.array(errors)
    assert np.abs(errors[:, :2]).max() <= fresh.arm_config.repeatability_mm + 1e-9
    assert np.abs(errors[:, 2]).max() <= fresh.arm_config.repeatability_deg + 1e-9
    assert np.abs(errors).max() > 0.0
    with SimCell(QUIET, seed=5) as a, SimCell(QUIET, seed=5) as b:
        for c in (a, b):
            c.move_arm(c.nominal_grasp_pose().moved_in_tool_frame(ToolStep(1.0)))
        assert a.ground_truth_error() == b.ground_truth_error()


def test_rotation_error_is_wrapped_by_the_symmetry(fresh):
    fresh.move_arm(fresh.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dphi_deg=80.0)))
    assert fresh.ground_truth_error()[2] == pytest.approx(-10.0, abs=0.05)
    fresh.move_arm(fresh.nominal_grasp_pose().moved_in_tool_frame(ToolStep(dphi_deg=-44.0)))
    assert fresh.ground_truth_error()[2] == pytest.approx(-44.0, abs=0.05)


def test_place_object_moves_the_nominal_pose(fresh):
    fresh.place_object(330.0, -40.0, 100.0)
    assert fresh.object_pose() == pytest.approx((330.0, -40.0, 100.0))
    nominal = fresh.nominal_grasp_pose()
    assert (nominal.x_mm, nominal.y_mm) == pytest.approx((330.0, -40.0))
    # Square to the faces, the equivalent turn nearest the reference heading: 100 - 90 = 10.
    assert nominal.approach_rotation_deg == pytest.approx(10.0)
    with pytest.raises(ValueError, match="out of the arm's reach"):
        fresh.place_object(900.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        fresh.place_object(float("nan"), 0.0, 0.0)


def test_the_cube_fills_about_40_px_below_the_fingertips(fresh):
    labels = fresh.render_labels()
    x0, x1, y0, y1 = _bbox(labels == LABEL_PART)
    assert 35 <= x1 - x0 + 1 <= 45
    assert abs((x0 + x1) / 2 - hand_camera.WIDTH_PX / 2) < 2
    assert 40 < (y0 + y1) / 2 < 85
    # The fingertips show at the upper rim, one on each side of the part.
    robot = labels == LABEL_ROBOT
    rows = np.nonzero(robot.any(axis=1))[0]
    assert rows.min() == 0 and rows.max() < y0 - 10
    top = robot[0]
    assert top[: hand_camera.WIDTH_PX // 2].any() and top[hand_camera.WIDTH_PX // 2:].any()


@pytest.mark.slow
def test_the_cube_stays_fully_visible_over_the_nn1_grid(fresh):
    nominal = fresh.nominal_grasp_pose()
    grow = np.ones((3, 3), bool)
    for dx, dy in itertools.product((-25.0, 0.0, 25.0), repeat=2):
        for dphi in np.arange(-180.0, 180.0, 15.0):
            fresh.move_arm(nominal.moved_in_tool_frame(ToolStep(dx, dy, 0.0, dphi)))
            labels = fresh.render_labels()
            part = labels == LABEL_PART
            x0, x1, y0, y1 = _bbox(part)
            assert min(x0, y0, hand_camera.WIDTH_PX - 1 - x1, hand_camera.HEIGHT_PX - 1 - y1) > 2
            padded = np.pad(part, 1)
            near = np.zeros_like(part)
            for i, j in zip(*np.nonzero(grow), strict=True):
                near |= padded[i:i + part.shape[0], j:j + part.shape[1]]
            assert not (near & (labels == LABEL_ROBOT)).any(), "fingers cover the part"


def test_the_part_moves_smoothly_and_monotonically_in_the_image(fresh):
    nominal = fresh.nominal_grasp_pose()
    for axis, image_axis in ((0, 1), (1, 0)):
        track = []
        for d in np.arange(-25.0, 26.0, 5.0):
            offset = [0.0, 0.0]
            offset[axis] = d
            fresh.move_arm(nominal.moved_in_tool_frame(ToolStep(*offset)))
            track.append(_centroid(fresh.render_labels() == LABEL_PART)[image_axis])
        steps = np.diff(track)
        # Tool +x (the way the camera looks) moves the part down the image; tool +y is the
        # image's right, so the part moves left.
        assert (steps > 0).all() if axis == 0 else (steps < 0).all(), track
        assert steps.std() < 0.5 * abs(steps.mean()), "nearly linear"
    fresh.move_arm(nominal.moved_in_tool_frame(ToolStep(10.0)))
    down = _centroid(fresh.render_labels() == LABEL_PART)
    fresh.move_arm(nominal)
    centre = _centroid(fresh.render_labels() == LABEL_PART)
    assert down[1] > centre[1] + 5


def test_images_are_deterministic_except_for_noise():
    with SimCell(QUIET, seed=2) as a, SimCell(QUIET, seed=2) as b:
        assert np.array_equal(a.render(), b.render())
        assert np.array_equal(a.render(), a.render())
    noisy = SceneConfig(camera=CameraConfig(preset="ideal"))
    with SimCell(noisy, seed=2) as a, SimCell(noisy, seed=2) as b:
        first = a.render()
        assert np.array_equal(first, b.render()), "the noise is seeded"
        second = a.render()
        assert not np.array_equal(first, second)
        assert abs(float(first.astype(float).mean() - second.astype(float).mean())) < 0.5
        assert 1.0 < float((first.astype(float) - second).std()) < 4.0


def _table_stats(cell: SimCell) -> tuple[float, float]:
    """Mean brightness and the share of table pixels in deep shadow."""
    image = cell.render(noisy=False).astype(float)
    grey = image.max(axis=2)
    table = cell.render_labels() == LABEL_BACKGROUND
    values = grey[table]
    return float(grey.mean()), float((values < 0.65 * np.median(values)).mean())


def test_lighting_presets_change_the_image_as_expected(fresh):
    stats = {}
    for preset in ("good", "dim", "side", "poor"):
        fresh.set_lighting(preset)
        stats[preset] = _table_stats(fresh)
    mean = {k: v[0] for k, v in stats.items()}
    shadow = {k: v[1] for k, v in stats.items()}
    assert mean["good"] > mean["side"] > mean["poor"]
    assert mean["good"] > 1.8 * mean["dim"]
    assert mean["poor"] < 0.5 * mean["good"]
    assert shadow["side"] > 0.05 and shadow["poor"] > 0.05, "hard cast shadows"
    assert shadow["good"] < 0.01 and shadow["dim"] < 0.01


def test_side_light_casts_the_parts_shadow_away_from_the_lamp(fresh):
    fresh.set_lighting("side")
    image = fresh.render(noisy=False).astype(float).max(axis=2)
    labels = fresh.render_labels()
    x0, x1, y0, y1 = _bbox(labels == LABEL_PART)
    band = slice(y0 + (y1 - y0) // 2, y1)
    # The lamp is on the robot's left (+y world) = the image's left: shadow to the right.
    left = image[band, max(0, x0 - 12):x0 - 2].mean()
    right = image[band, x1 + 2:x1 + 12].mean()
    assert right < 0.6 * left
    fresh.set_lighting(from_mapping(type(fresh.scene.lighting), {"preset": "side",
                                                                "shadows": False}, "l"))
    flat = fresh.render(noisy=False).astype(float).max(axis=2)
    assert flat[band, x1 + 2:x1 + 12].mean() > 0.9 * flat[band, max(0, x0 - 12):x0 - 2].mean()


def test_occluder_hides_the_given_share_of_the_part():
    visible = {}
    for coverage in (0.0, 0.3, 0.6):  # seed 1: the card over the far end, where it can
        with SimCell(_scene(occluder={"enabled": True, "coverage": coverage}), seed=1) as c:
            labels = c.render_labels()
            visible[coverage] = int((labels == LABEL_PART).sum())
            assert (labels == LABEL_OCCLUDER).sum() > 0
    assert visible[0.0] > visible[0.3] > visible[0.6] > 0


def test_visible_fraction_measures_what_the_card_hides():
    with SimCell(_scene(occluder={"enabled": True, "coverage": 0.3}), seed=1) as c:
        part_before = c.object_pose()
        hidden = c.visible_fraction()
        assert 0.4 < hidden < 0.85
        assert c.object_pose() == part_before  # the card is back on the part
        assert (c.render_labels() == LABEL_OCCLUDER).sum() > 0
        assert c.visible_fraction() == pytest.approx(hidden)
    with SimCell(_scene(), seed=1) as c:
        assert c.visible_fraction() == 1.0


def test_a_further_lamp_adds_its_light_and_a_dark_one_nothing():
    images = {}
    for name, lamps in (("none", []), ("dark", [{"diffuse": 0.0}]),
                        ("lit", [{"direction": [-1, 0, 1], "diffuse": 0.5,
                                  "shadow_strength": 0.8}])):
        with SimCell(_scene(lighting={"preset": "dim", "lamps": lamps}), seed=2) as c:
            images[name] = c.render(noisy=False).astype(float)
    assert np.array_equal(images["none"], images["dark"])
    assert images["lit"].mean() > images["none"].mean() + 10


@pytest.mark.parametrize("kind", ["cube", "nut", "ledge", "screw"])
def test_the_card_rests_on_the_part_and_the_table_and_hides_its_share_in_view(kind):
    """A quarter card leans from the part's end to the table (it touches both, and nothing
    is under it), whichever end it lies over. Over the far end it hides about a quarter of
    the part as the camera sees it at the pre-grasp pose; over the near end it also hides
    that end's side faces, so never much less (a screw's ends differ: its head is wide)."""
    def part_px(scene, seed):
        with SimCell(scene, seed=seed) as c:
            c.move_arm(c.nominal_grasp_pose())
            card = c._occluder
            if card is None:
                return int((c.render_labels() == LABEL_PART).sum()), None, None, None
            low = p.getAABB(card.body_id, physicsClientId=c._client)[0][2] * 1000.0
            gap = min(q[8] for q in p.getClosestPoints(card.body_id, c._part.body_id, 0.01,
                                                       physicsClientId=c._client)) * 1000.0
            return int((c.render_labels() == LABEL_PART).sum()), card, low, gap
    whole = part_px(_scene(object={"kind": kind}), 0)[0]
    hidden = {}
    for seed in range(4):
        seen, card, low, gap = part_px(_scene(object={"kind": kind},
                                              occluder={"enabled": True, "coverage": 0.25}),
                                       seed)
        assert 0.0 <= low <= 0.5 and -1.0 <= gap <= 1.0, (low, gap)  # on table and part
        assert abs(card.relative[2, 0]) > 0.05  # sloped, not flat at the part's height
        hidden[card.relative[0, 3] > 0] = 1.0 - seen / whole
    assert set(hidden) == {True, False}  # both ends among the seeds
    assert 0.1 <= hidden[True] <= 0.35, hidden  # the far end (the camera looks from -x)
    assert 0.2 <= hidden[False] <= 0.6, hidden


def test_clutter_lies_around_clear_of_the_part_and_the_gripper():
    with SimCell(_scene(clutter={"count": 6}), seed=4) as c:
        assert len(c._clutter) == 6
        target = c._part.body_id
        nominal = c.nominal_grasp_pose()
        for item in c._clutter:
            assert not p.getClosestPoints(item.body_id, target, 0.003,
                                          physicsClientId=c._client), "touches the part"
            pos, _ = p.getBasePositionAndOrientation(item.body_id, physicsClientId=c._client)
            rel = nominal.rotation().T @ (np.array(pos) * 1000.0 - nominal.position_mm)
            for x0, x1, y0, y1 in GRIPPER_FOOTPRINT_TOOL_MM:
                assert not (x0 < rel[0] < x1 and y0 < rel[1] < y1)
        # The descent to the grasp meets no clutter.
        for _ in range(int(c.grasp_depth_mm)):
            c.move_arm(c.arm_pose().moved_in_tool_frame(ToolStep(dz_mm=1.0)))
        clutter_ids = {item.body_id for item in c._clutter}
        assert not [t for t in c._touching() if t.body_b in clutter_ids]
        assert (c.render_labels() == LABEL_PART).any()
    with SimCell(_scene(clutter={"count": 6}), seed=4) as a, \
            SimCell(_scene(clutter={"count": 6}), seed=4) as b:
        clutter = a.render_labels() == LABEL_CLUTTER
        assert clutter.any() and np.array_equal(clutter, b.render_labels() == LABEL_CLUTTER)


def test_every_part_kind_is_in_view_at_its_nominal_pose():
    for kind in ("nut", "ledge", "screw"):
        with SimCell(_scene(object={"kind": kind})) as c:
            assert c.kappa == {"nut": 6, "ledge": 2, "screw": 1}[kind]
            x0, x1, y0, y1 = _bbox(c.render_labels() == LABEL_PART)
            assert x0 > 0 and y0 > 0 and x1 < hand_camera.WIDTH_PX - 1


def test_textured_tables_render():
    for texture in ("wood", "checker", "noise"):
        with SimCell(_scene(table={"texture": texture, "color": [0.7, 0.6, 0.5]})) as c:
            grey = c.render(noisy=False).astype(float).max(axis=2)
            table = c.render_labels() == LABEL_BACKGROUND
            assert grey[table].std() > 5.0, texture


def test_close_is_idempotent():
    c = SimCell(QUIET)
    assert c.is_open
    c.close()
    c.close()
    assert not c.is_open


def test_frames_of_an_unchanged_scene_are_the_ones_a_fresh_render_gives():
    """Reused shaded samples give exactly the frames fresh renders give: over moves, a light
    change and the jaws closing and opening (the noise sequence included)."""
    def frames(reuse: bool) -> list[np.ndarray]:
        out = []
        with SimCell(SceneConfig(), seed=3) as c:
            if not reuse:
                c._scene_key = object  # a key that never matches the last one
            nominal = c.nominal_grasp_pose()
            for step in (ToolStep(3, -2, 0, 5), ToolStep(0, 0, 0, 0)):
                c.move_arm(nominal.moved_in_tool_frame(step))
                out += [c.render(), c.render()]
            c.set_lighting("poor")
            out += [c.render(), c.render()]
            c.move_arm(nominal)
            c.close_gripper()
            out += [c.render()]
            c.open_gripper()
            out += [c.render()]
        return out

    for fresh, reused in zip(frames(False), frames(True), strict=True):
        assert np.array_equal(fresh, reused)
