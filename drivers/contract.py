"""One contract checker for every device implementation (simulator, serial drivers, fakes).

Each ``check_*`` takes a factory that builds a fresh, disconnected device and raises
AssertionError naming the broken promise. Tests run these over every backend with
``pytest.mark.parametrize``. The arm factory must give an arm whose safety limits reject
(not clip) and allow at least a 10 mm / 10 deg step around its start pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from drivers.core.errors import DeviceNotConnectedError, MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Camera, Lifecycle, Wrench, WrenchSensor


def _close(a: Pose, b: Pose, tol_mm: float, tol_deg: float) -> bool:
    step = a.tool_step_to(b)
    return (math.hypot(step.dx_mm, step.dy_mm, step.dz_mm) <= tol_mm
            and abs(step.dphi_deg) <= tol_deg)


def _raises(exc_type, fn, *args) -> bool:
    try:
        fn(*args)
    except exc_type:
        return True
    return False


def check_arm(make_arm: Callable[[], Arm], tol_mm: float = 0.3, tol_deg: float = 0.3) -> None:
    """Check lifecycle, pose reading, relative and absolute motion, safety, gripper, halt."""
    arm = make_arm()
    assert arm.state is Lifecycle.DISCONNECTED, "a new arm must start disconnected"
    assert _raises(DeviceNotConnectedError, arm.pose), "pose() before connect must raise"
    try:
        arm.connect()
        assert arm.state is Lifecycle.INACTIVE, "connect() must leave the arm inactive"
        start = arm.pose()
        assert start.is_finite(), f"pose must be finite, got {start}"
        assert _raises(MotionRejectedError, arm.move_tool, ToolStep(1.0, 0, 0, 0)), \
            "an inactive arm must refuse motion"
        assert _close(arm.pose(), start, 1e-6 + tol_mm, tol_deg), "a refused move moved the arm"

        arm.activate()
        assert arm.state is Lifecycle.ACTIVE
        step = ToolStep(4.0, -3.0, 0.0, 6.0)
        motion = arm.move_tool(step)
        assert motion.sent == step and not motion.clipped, "an in-limit step must be sent as is"
        after = arm.pose()
        done = start.tool_step_to(after)
        assert abs(done.dx_mm - step.dx_mm) <= tol_mm and abs(done.dy_mm - step.dy_mm) <= tol_mm \
            and abs(done.dz_mm) <= tol_mm and abs(done.dphi_deg - step.dphi_deg) <= tol_deg, \
            f"move_tool({step}) moved by {done}"
        assert _close(motion.pose, after, tol_mm, tol_deg), "Motion.pose must be the pose reached"
        assert abs(after.approach_rotation_deg - arm.tool_rotation_deg()) < 1e-6

        arm.move_to(start)
        assert _close(arm.pose(), start, tol_mm, tol_deg), "move_to(start) did not return"

        for bad in (ToolStep(float("nan")), ToolStep(dphi_deg=float("inf"))):
            assert _raises(MotionRejectedError, arm.move_tool, bad), f"{bad} must be rejected"
        if arm.limits is not None and arm.limits.on_violation == "reject":
            big = ToolStep(arm.limits.max_step_mm * 2.0, 0.0, 0.0, 0.0)
            before = arm.pose()
            assert _raises(MotionRejectedError, arm.move_tool, big), "over-limit step not rejected"
            assert _close(arm.pose(), before, tol_mm, tol_deg), "a rejected step moved the arm"

        for bad_speed in (0, -5, 327.68, float("nan")):
            assert _raises(MotionRejectedError, arm.set_speed, bad_speed), \
                f"speed {bad_speed} must be rejected"
        arm.set_speed(50)

        opened = arm.open_gripper()
        assert math.isfinite(opened) and opened > 0, f"open width {opened}"
        assert abs(arm.finger_width_mm() - opened) <= 1.0, "finger_width_mm disagrees with open"
        closed = arm.close_gripper()
        assert closed < opened, f"closing ({closed} mm) must narrow the jaws ({opened} mm)"
        arm.open_gripper()
        arm.halt()

        arm.deactivate()
        assert _raises(MotionRejectedError, arm.move_to, start), "deactivated arm moved"
    finally:
        arm.disconnect()
    assert arm.state is Lifecycle.DISCONNECTED
    assert _raises(DeviceNotConnectedError, arm.pose), "pose() after disconnect must raise"
    arm.disconnect()  # twice is fine
    arm.halt()  # harmless when disconnected

    with make_arm() as arm2:
        assert arm2.state is Lifecycle.ACTIVE, "the context manager must connect and activate"
    assert arm2.state is Lifecycle.DISCONNECTED, "leaving the context must disconnect"


def check_camera(make_camera: Callable[[], Camera]) -> None:
    """Check lifecycle and frame format: HxWx3 uint8 at the camera's size, rising timestamps."""
    cam = make_camera()
    assert _raises(DeviceNotConnectedError, cam.grab), "grab() before connect must raise"
    with cam:
        f1, f2 = cam.grab(), cam.grab()
        for f in (f1, f2):
            assert isinstance(f.image, np.ndarray) and f.image.dtype == np.uint8
            assert f.image.shape == (cam.height_px, cam.width_px, 3), f.image.shape
        assert f2.timestamp_s >= f1.timestamp_s, "timestamps must not go back"
    assert _raises(DeviceNotConnectedError, cam.grab), "grab() after disconnect must raise"


def check_wrench(make_sensor: Callable[[], WrenchSensor], rest_tol_n: float = 0.5) -> None:
    """Check lifecycle, finite readings, and that bias() zeroes the reading at rest."""
    sensor = make_sensor()
    assert _raises(DeviceNotConnectedError, sensor.read), "read() before connect must raise"
    with sensor:
        w = sensor.read()
        assert isinstance(w, Wrench) and all(math.isfinite(v) for v in w.as_dict().values())
        sensor.bias()
        w0 = sensor.read()
        assert w0.force_n <= rest_tol_n, f"after bias() at rest the force must be ~0, got {w0}"
    assert _raises(DeviceNotConnectedError, sensor.read), "read() after disconnect must raise"
