"""PUMA 260 kinematics: forward/inverse round trips, joint limits, reach."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

from drivers.core.errors import MotionRejectedError
from sim_backend.cell import puma260
from sim_backend.cell.scene_config import ObjectConfig
from sim_backend.cell.sim_cell import FLANGE_IN_TOOL, tool_down_rotation

LIMITS = np.radians(np.array(puma260.JOINT_LIMITS_DEG))


def _pose_error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Position error (mm) and rotation error (deg) between two 4x4 poses."""
    rel = a[:3, :3].T @ b[:3, :3]
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1.0) / 2.0))))
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3])), angle


def test_zero_pose_matches_the_dh_geometry():
    frames = puma260.link_frames(np.zeros(6))
    # Upper arm horizontal along x, forearm straight up, shoulder + elbow offsets sideways.
    np.testing.assert_allclose(frames[4][:3, 3], [203.2, 127.0, 330.2 + 203.2], atol=1e-9)
    np.testing.assert_allclose(frames[6][:3, 3], [203.2, 127.0, 330.2 + 203.2 + 63.5], atol=1e-9)


def test_fk_ik_round_trip_is_exact():
    rng = np.random.default_rng(1)
    for _ in range(300):
        q = rng.uniform(LIMITS[:, 0], LIMITS[:, 1])
        target = puma260.flange_transform(q)
        seed = q + rng.normal(0.0, 0.1, 6)
        solved = puma260.inverse_kinematics(target, seed)
        assert puma260.within_limits(solved)
        pos_mm, rot_deg = _pose_error(puma260.flange_transform(solved), target)
        assert pos_mm < 1e-3 and rot_deg < 1e-3


def test_ik_keeps_the_seed_configuration():
    q = np.radians([-20.0, 40.0, -170.0, -150.0, 40.0, 10.0])
    np.testing.assert_allclose(puma260.inverse_kinematics(puma260.flange_transform(q), q), q,
                               atol=1e-9)


def test_unreachable_target_is_rejected_with_a_reason():
    target = np.eye(4)
    target[:3, 3] = [900.0, 0.0, 300.0]
    with pytest.raises(MotionRejectedError, match="out of reach") as err:
        puma260.inverse_kinematics(target, np.zeros(6))
    assert "wrist centre" in err.value.reason


def test_joint_limits_reject_a_pose_only_reachable_outside_them():
    # Turned far to the left with the upper arm pointing down: every branch leaves a range.
    q = np.radians([129.0, -168.0, 83.0, 0.0, 131.0, 0.0])
    assert not puma260.within_limits(q)
    assert "joint 1 at 129.0 deg not in [-180, 110]" in puma260.limit_violations(q)
    with pytest.raises(MotionRejectedError, match="outside the joint limits: joint 1 at"):
        puma260.inverse_kinematics(puma260.flange_transform(q), np.zeros(6))


def test_tool_down_reach_around_the_default_part_position():
    seed = np.radians([0.0, 30.0, -180.0, -180.0, 30.0, 0.0])
    for dx in (-60.0, 0.0, 60.0):
        for dy in (-60.0, 0.0, 60.0):
            for heading in range(-180, 181, 45):
                for z_mm in (5.0, 65.0, 140.0):
                    seed = puma260.inverse_kinematics(_tool_down(300.0 + dx, dy, z_mm, heading),
                                                      seed)


def test_tool_down_reach_over_the_configurable_part_positions():
    meta = {f.name: f.metadata for f in dataclasses.fields(ObjectConfig)}
    seed = np.radians([0.0, 30.0, -180.0, -180.0, 30.0, 0.0])
    for ox in (meta["x_mm"]["min"], meta["x_mm"]["max"]):
        for oy in (meta["y_mm"]["min"], meta["y_mm"]["max"]):
            for dx, dy in itertools.product((-30.0, 30.0), repeat=2):
                for heading in range(-180, 181, 45):
                    for z_mm in (5.0, 140.0):
                        seed = puma260.inverse_kinematics(
                            _tool_down(ox + dx, oy + dy, z_mm, heading), seed)


def _tool_down(x_mm: float, y_mm: float, z_mm: float, heading_deg: float) -> np.ndarray:
    """Flange pose (4x4) putting the tool straight down with its TCP at (x, y, z)."""
    tool = np.eye(4)
    tool[:3, :3] = tool_down_rotation(heading_deg)
    tool[:3, 3] = [x_mm, y_mm, z_mm]
    return tool @ FLANGE_IN_TOOL
