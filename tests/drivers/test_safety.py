"""The safety layer's pure checks: step limits and the workspace box, reject or clip."""

import logging

import numpy as np
import pytest

from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.safety import (
    SafetyLimits,
    check_target,
    check_tool_step,
    clip_step,
    split_step,
    split_target,
)

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


LIMITS = SafetyLimits(max_step_mm=10.0, max_step_deg=30.0)


def _end(start: Pose, steps) -> Pose:
    for step in steps:
        start = start.moved_in_tool_frame(step)
    return start


@pytest.mark.parametrize("step, count", [
    (ToolStep(3.0, 4.0, 0.0, 20.0), 1),     # within both limits: the step itself
    (ToolStep(3.0, 4.0, 0.0, 90.0), 3),     # the turn in three, the translation first
    (ToolStep(18.0, 24.0, 0.0, 10.0), 3),   # 30 mm in three
    (ToolStep(18.0, 24.0, 0.0, 100.0), 6),  # three moves, then four turns, one shared
    (ToolStep(0.0, 0.0, 0.0, -180.0), 6),
])
def test_split_step_keeps_every_command_within_the_limits_and_ends_where_the_step_does(
        step, count):
    start = Pose(300.0, 0.0, 65.0, -90.0, 90.0, 30.0)
    commands = split_step(step, LIMITS)
    assert len(commands) == count
    assert all(c.translation_mm <= LIMITS.max_step_mm + 1e-9
               and abs(c.dphi_deg) <= LIMITS.max_step_deg + 1e-9 for c in commands)
    end, whole = _end(start, commands), start.moved_in_tool_frame(step)
    assert np.allclose(end.position_mm, whole.position_mm, atol=1e-9)
    assert end.t_deg == pytest.approx(whole.t_deg, abs=1e-9)
    assert split_step(step, None) == [step]


def test_split_step_can_leave_the_translation_to_the_safety_check():
    commands = split_step(ToolStep(18.0, 24.0, 0.0, 100.0), LIMITS, turn_only=True)
    assert [c.translation_mm for c in commands] == [30.0, 0.0, 0.0, 0.0]


def test_split_step_turns_only_after_the_whole_translation():
    commands = split_step(ToolStep(18.0, 24.0, 0.0, 100.0), LIMITS)
    turned = [c.dphi_deg != 0.0 for c in commands]
    assert turned == [False, False, True, True, True, True]


def test_split_target_reaches_the_target_in_equal_parts():
    here = Pose(300.0, 0.0, 65.0, -90.0, 90.0, 0.0)
    target = here.moved_in_tool_frame(ToolStep(25.0, 0.0, 0.0, 45.0))
    poses = split_target(here, target, LIMITS)
    assert len(poses) == 3
    assert np.allclose(poses[-1].position_mm, target.position_mm, atol=1e-9)
    steps = [a.tool_step_to(b) for a, b in zip([here, *poses], poses, strict=False)]
    assert all(s.translation_mm <= LIMITS.max_step_mm + 1e-9
               and abs(s.dphi_deg) <= LIMITS.max_step_deg + 1e-9 for s in steps)
    assert split_target(here, target, None) == [target]
