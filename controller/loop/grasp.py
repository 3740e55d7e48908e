"""Force-guarded grasp hand-off: descend with the wrist sensor guarding, close, verify, lift.

From the fine-positioned pre-grasp pose: open the jaws, bias the sensor, descend along the
approach axis in small steps to the taught grasp depth while the guards watch every reading;
close; verify the grip by finger width; lift and verify again. A tripped guard ends the
descent; ``retreat`` guards (and any failed check) back off to the start pose. The outcome and
the force trace are reported; nothing is retried silently.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from controller.loop.guards import Guard, first_tripped
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, WrenchSensor

logger = logging.getLogger(__name__)

DEFAULT_GUARDS = (
    Guard("force_n", ">", 15.0, "retreat", "excessive force"),
    Guard("force_n", ">", 3.0, "retreat", "early contact"),
    Guard("force_n", ">", 3.0, "stop", "contact"),
)


@dataclass(frozen=True)
class GraspConfig:
    """Config section ``controller.grasp``.

    step_mm: descent per guarded step; contact_margin_mm: the last part of the descent in
    which contact is expected (guards named "early contact" are ignored there);
    width_tolerance_mm: finger width must be within this of the taught object width;
    lift_mm: how far to lift after closing; guards: evaluated in order after every step;
    min_held_weight_n: after the lift, the part's weight on the wrist sensor (the force along
    the approach axis against the bias taken with empty jaws) must be at least this; 0 turns
    the check off. Use it where the gripper reports no finger width (VAL has none); set it
    well above the sensor's resolution and below the part's weight (cube: 0.15 N).
    """

    step_mm: float = field(default=1.0, metadata={"min": 0.05, "max": 10.0})
    contact_margin_mm: float = field(default=2.0, metadata={"min": 0.0})
    width_tolerance_mm: float = field(default=4.0, metadata={"min": 0.0})
    lift_mm: float = field(default=30.0, metadata={"min": 0.0})
    min_held_weight_n: float = field(default=0.0, metadata={"min": 0.0})
    guards: tuple[Guard, ...] = DEFAULT_GUARDS


@dataclass
class GraspResult:
    """success: the part is held after the lift; reason: what ended the attempt;
    depth_mm: how far the descent got; width_mm: finger width after closing;
    max_force_n: largest force seen; forces_n: force magnitude after each descent step;
    held_weight_n: the part's weight measured after the lift (None when not lifted)."""

    success: bool
    reason: str
    depth_mm: float = 0.0
    width_mm: float | None = None
    max_force_n: float = 0.0
    forces_n: list[float] = field(default_factory=list)
    retreated: bool = False
    held_weight_n: float | None = None

    def as_dict(self) -> dict:
        """The result as a JSON-able dict, without the ``forces_n`` trace."""
        return {"success": self.success, "reason": self.reason, "depth_mm": self.depth_mm,
                "width_mm": self.width_mm, "max_force_n": self.max_force_n,
                "retreated": self.retreated, "held_weight_n": self.held_weight_n}


def guarded_grasp(arm: Arm, sensor: WrenchSensor, grasp_depth_mm: float,
                  object_width_mm: float, config: GraspConfig) -> GraspResult:
    """Run the grasp from the current (pre-grasp) pose. See the module docstring."""
    start: Pose = arm.pose()
    arm.open_gripper()
    sensor.bias()
    result = GraspResult(False, "")
    depth = 0.0

    def retreat(reason: str) -> GraspResult:
        logger.warning("grasp aborted: %s; retreating", reason)
        arm.halt()
        arm.open_gripper()
        arm.move_to(start)
        result.reason, result.retreated = reason, True
        return result

    while depth < grasp_depth_mm - 1e-9:
        step = min(config.step_mm, grasp_depth_mm - depth)
        arm.move_tool(ToolStep(dz_mm=step))
        depth += step
        result.depth_mm = depth
        wrench = sensor.read()
        result.forces_n.append(wrench.force_n)
        result.max_force_n = max(result.max_force_n, wrench.force_n)
        in_contact_zone = depth >= grasp_depth_mm - config.contact_margin_mm
        active = [g for g in config.guards if not (in_contact_zone and g.name == "early contact")]
        guard = first_tripped(wrench, active)
        if guard is not None:
            reason = (f"{guard.name or 'guard'}: {guard.quantity} {guard.op} {guard.limit:g} "
                      f"at depth {depth:.1f} mm")
            if guard.action == "retreat":
                return retreat(reason)
            arm.halt()
            result.reason = reason
            break

    width = arm.close_gripper()
    result.width_mm = width
    if abs(width - object_width_mm) > config.width_tolerance_mm:
        return retreat(f"grip check failed: finger width {width:.1f} mm, expected "
                       f"{object_width_mm:.1f} +/- {config.width_tolerance_mm:g} mm")
    if config.lift_mm > 0:
        arm.move_tool(ToolStep(dz_mm=-config.lift_mm))
        width = arm.finger_width_mm()
        if abs(width - object_width_mm) > config.width_tolerance_mm:
            result.width_mm = width
            return retreat(f"part slipped while lifting: finger width {width:.1f} mm")
        # The sensor was biased with empty jaws above the part: what it feels along the
        # approach axis now is the part hanging in the jaws.
        result.held_weight_n = abs(sensor.read().fz_n)
        if config.min_held_weight_n and result.held_weight_n < config.min_held_weight_n:
            return retreat(f"grip check failed: {result.held_weight_n:.3f} N on the wrist "
                           f"after lifting, expected at least {config.min_held_weight_n:g} N")
    result.success = True
    result.reason = result.reason or "held after lift"
    return result
