"""The safety layer's pure checks: step limits and the workspace box, reject or clip."""

import logging

import numpy as np
import pytest

from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.safety import SafetyLimits, check_target, check_tool_step, clip_step

HERE = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)
REJECT = SafetyLimits(max_step_mm=10.0, max_step_deg=20.0, on_violation="reject")
CLIP = SafetyLimits(max_step_mm=10.0, max_step_deg=20.0, on_violation="clip")


def test_step_within_limits_passes_unchanged():
    d = check_tool_step(ToolStep(6.0, -8.0, 0.0, 19.0), HERE, REJECT)
    assert d.step == ToolStep(6.0, -8.0, 0.0, 19.0) and not d.clipped


def test_too_long_step_is_rejected_and_logged(caplog):
    with caplog.at_level(logging.WARNING), pytest.raises(MotionRejectedError, match="max_step_mm"):
        check_tool_step(ToolStep(8.0, 8.0), HERE, REJECT)
    assert "rejected" in caplog.text


def test_too_long_step_is_clipped_keeping_its_direction(caplog):
    with caplog.at_level(logging.WARNING):
        d = check_tool_step(ToolStep(30.0, 40.0, 0.0, -50.0), HERE, CLIP)
    assert d.clipped and "clipped" in caplog.text
    assert (d.step.dx_mm, d.step.dy_mm) == pytest.approx((6.0, 8.0))
    assert d.step.dphi_deg == pytest.approx(-20.0)


def test_clip_step_is_pure():
    step = ToolStep(30.0, 0.0, 0.0, 0.0)
    assert clip_step(step, CLIP)[0] == clip_step(step, CLIP)[0]
    assert step == ToolStep(30.0, 0.0, 0.0, 0.0)


def test_workspace_box_rejects_and_clips():
    box = dict(workspace_min_mm=(0.0, -100.0, 100.0), workspace_max_mm=(400.0, 100.0, 300.0),
               max_step_mm=100.0)
    down = ToolStep(dz_mm=60.0)  # z 150 -> 90, below the box floor
    with pytest.raises(MotionRejectedError, match="outside workspace"):
        check_tool_step(down, HERE, SafetyLimits(**box, on_violation="reject"))
    d = check_tool_step(down, HERE, SafetyLimits(**box, on_violation="clip"))
    assert d.clipped and HERE.moved_in_tool_frame(d.step).z_mm == pytest.approx(100.0)


def test_absolute_target_check():
    far = Pose(300.0, 50.0, 150.0, -90.0, 90.0, 0.0)
    with pytest.raises(MotionRejectedError):
        check_target(far, HERE, REJECT)
    d = check_target(far, HERE, CLIP)
    assert d.clipped and np.linalg.norm(d.target.position_mm - HERE.position_mm) == \
        pytest.approx(10.0)
    with pytest.raises(MotionRejectedError, match="not finite"):
        check_target(Pose(float("nan"), 0, 0, 0, 0, 0), HERE, CLIP)


def test_inverted_workspace_is_refused():
    with pytest.raises(ValueError, match="workspace_min_mm"):
        SafetyLimits(workspace_min_mm=(0, 0, 0), workspace_max_mm=(0, 10, 10))
