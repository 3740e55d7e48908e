"""Force-guarded grasp hand-off: descend with the wrist sensor guarding, close, verify, lift.

From the fine-positioned pre-grasp pose: open the jaws, bias the sensor, descend along the
approach axis to the taught grasp depth (free space in one move, guarded steps where a finger
can meet the part's top or rim, the rest in one move) while the guards watch every reading;
close; lift; verify. The positioning loop's converged step, where it was left for the grasp
(``PositioningLoop.run``'s ``carry_final_step``), is made with the first descent move: that
move translates and turns by it as it descends, so the pose the loop read is reached without a
move of its own. A tripped guard ends the descent; ``retreat`` guards (and any failed
check) back off to the start pose. The outcome and the force trace are reported; nothing is
retried silently.

The verification rests on what the real cell can measure (``GraspConfig.check``): by default
the wrist sensor (``weight``): the mean of ``weight_samples`` readings with open jaws at the
bottom of the descent, again after closing (a finger jammed on the part pushes on it), and
after the lift, when the part hangs in the jaws: its weight along the approach axis must be
at least ``min_held_weight_n`` (default: half the part's catalogue weight). The mean of N
readings has 1/sqrt(N) of one reading's noise: with an ATI sensor at 20 counts per newton and
about one count of noise, 16 readings give about 0.013 N against the 15 g cube's 0.147 N.
``width`` checks the finger width instead, for grippers that measure it (the VAL gripper
reports none: its width is a configured nominal).

On an arm that runs programs (``Arm.runs_programs``) the descent is one controller program
stopped by the wrist sensor's own monitor output, and with the weight check and a lift the
same run also closes the jaws and lifts: the open-jaw mean is read before the descent (same
approach axis, no contact), the sensor's contact condition stays armed through the close and
the lift (a finger pushing on the part stops the run before the lift: a jam), and the host
reads the sensor once more, on the lifted part. A contact on the way down stops the run before
the close; the host then goes on as above.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from controller.loop.guards import Guard, first_tripped
from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Descent, MonitorCondition, Wrench, WrenchSensor

GraspCheck = Literal["weight", "width", "both"]

logger = logging.getLogger(__name__)

DEFAULT_GUARDS = (
    Guard("force_n", ">", 15.0, "retreat", "excessive force"),
    Guard("force_n", ">", 3.0, "retreat", "early contact"),
    Guard("force_n", ">", 3.0, "stop", "contact"),
)


@dataclass(frozen=True)
class GraspConfig:
    """Config section ``controller.grasp``.

    free_descent_mm: the first move's length (the guards read after it). The part's top
    lies ``APPROACH_HEIGHT_MM`` (35 mm; on the simulated cube a finger over its edge or rim
    meets it from 35.1 mm on) below the pre-grasp pose, so the default ends at it, before
    any contact, and the way there is free space the camera has just seen; step_mm /
    guard_zone_mm: below the free descent, guarded steps of ``step_mm`` go down
    ``guard_zone_mm``, where a finger over the part's top or edge meets it (on the
    simulated cube down to 41 mm for a finger 0.5 mm over the edge), so no contact is pushed
    deeper than one step (at the simulated contact's 10 N/mm, 1.2 mm stays under the 15 N
    "excessive force" limit); below that the fingers pass beside the part's faces and the
    rest of the descent is one move (the guards read after it). Each step is one VAL
    exchange and one move (about 0.35 s at 9600 baud); a large zone (100) steps all the way
    down, as a crowded table may need; contact_margin_mm: the last part of
    the descent in which contact is expected (guards named "early contact" are ignored there);
    carry_final_step: where a grasp follows the positioning loop in the same run
    (``finepos position --grasp``, the service's ``position`` job with ``grasp``, the
    evaluation), the converged look's step (the recipe's ``loop.final_step``) is made by the
    first descent move instead of a move of its own (one VAL command and its motion fewer);
    false: the loop makes it;
    guard_speed_percent / guard_clearance_mm / contact_axis: on an arm that runs programs
    (``arm.programs``: the program path) the descent is one controller program: at the set speed to
    ``free_descent_mm - guard_clearance_mm`` (1 mm above the part's top by default), at
    ``guard_speed_percent`` of it to
    ``free_descent_mm + guard_zone_mm`` (past the rim), the rest at the set speed, stopped
    by the controller itself wherever the wrist sensor's monitor output trips: the sensor's
    condition is ``contact_axis`` below minus the limit of the first
    ``stop`` guard (a finger meeting something pushes against the approach direction);
    check: how the grip is verified (see the module docstring): ``weight`` (the wrist
    sensor; works on every gripper), ``width`` (the finger width, for grippers that measure
    it) or ``both``; width_tolerance_mm: finger width must be within this of the taught
    object width; lift_mm: how far to lift after closing (the weight check needs the part off
    the table); min_held_weight_n: the least weight (N) the lifted part must put on the wrist
    sensor (None: half the part's catalogue weight); weight_samples: readings averaged for the
    two weight measurements (open jaws at the bottom, or on the program path before the
    descent; the lifted part); closing_samples: readings
    averaged after closing for the jam check (its 5 N limit is a hundred times one reading's
    noise); max_closing_force_n: a larger change of the mean force while the jaws close means
    a finger jammed on the part; guards: evaluated in order after every descent move.
    """

    step_mm: float = field(default=1.2, metadata={"min": 0.05, "max": 10.0})
    free_descent_mm: float = field(default=35.0, metadata={"min": 0.0, "max": 100.0})
    guard_zone_mm: float = field(default=6.0, metadata={"min": 0.0, "max": 1000.0})
    contact_margin_mm: float = field(default=2.0, metadata={"min": 0.0})
    carry_final_step: bool = True
    guard_speed_percent: float = field(default=10.0, metadata={"min": 1.0, "max": 100.0})
    guard_clearance_mm: float = field(default=1.0, metadata={"min": 0.0, "max": 100.0})
    contact_axis: Literal["fx_n", "fy_n", "fz_n"] = "fz_n"
    check: GraspCheck = "weight"
    width_tolerance_mm: float = field(default=4.0, metadata={"min": 0.0})
    lift_mm: float = field(default=10.0, metadata={"min": 0.0})
    min_held_weight_n: float | None = field(default=None, metadata={"min": 0.0,
                                                                    "exclusive_min": True})
    weight_samples: int = field(default=16, metadata={"min": 1, "max": 1000})
    closing_samples: int = field(default=4, metadata={"min": 1, "max": 1000})
    max_closing_force_n: float = field(default=5.0, metadata={"min": 0.0, "exclusive_min": True})
    guards: tuple[Guard, ...] = DEFAULT_GUARDS

    def __post_init__(self) -> None:
        if self.check != "width" and self.lift_mm <= 0.0:
            raise ValueError(f"lift_mm: the {self.check!r} check weighs the lifted part and "
                             f"needs lift_mm > 0, got {self.lift_mm:g}")


@dataclass
class GraspResult:
    """success: the part is held after the lift; reason: what ended the attempt;
    depth_mm: how far the descent got; width_mm: finger width after closing;
    max_force_n: largest force seen; forces_n: force magnitude after each descent step;
    held_weight_n: the part's weight measured after the lift (None when not lifted);
    closing_force_n: how much the mean force changed while the jaws closed (None when they
    did not close, or closed in the descent's program run without a jam); carried_step: the
    positioning loop's converged step the first descent move made (None: none carried)."""

    success: bool
    reason: str
    depth_mm: float = 0.0
    width_mm: float | None = None
    max_force_n: float = 0.0
    forces_n: list[float] = field(default_factory=list)
    retreated: bool = False
    held_weight_n: float | None = None
    closing_force_n: float | None = None
    carried_step: ToolStep | None = None

    def as_dict(self) -> dict:
        """The result as a JSON-able dict, without the ``forces_n`` trace."""
        return {"success": self.success, "reason": self.reason, "depth_mm": self.depth_mm,
                "width_mm": self.width_mm, "max_force_n": self.max_force_n,
                "retreated": self.retreated, "held_weight_n": self.held_weight_n,
                "closing_force_n": self.closing_force_n,
                "carried_step": (self.carried_step.as_dict()
                                 if self.carried_step is not None else None)}


def contact_condition(config: GraspConfig) -> MonitorCondition:
    """The sensor's monitor condition for the program path's descent: ``contact_axis`` below
    minus the limit of the first ``stop`` guard (3 N by default)."""
    limit = next((g.limit for g in config.guards if g.action == "stop"), None)
    if limit is None:
        raise ValueError("controller.grasp.guards: the program path needs a 'stop' guard "
                         "whose limit is the contact threshold")
    return MonitorCondition(config.contact_axis, "<", -abs(limit))


def mean_force(sensor: WrenchSensor, samples: int) -> np.ndarray:
    """The mean force vector (Fx, Fy, Fz; N, tool frame) of ``samples`` samples: the
    sensor's own moving average where it keeps one (``WrenchSensor.read_mean``: one query)."""
    return _force(sensor.read_mean(samples))


def _force(wrench: Wrench) -> np.ndarray:
    return np.array([wrench.fx_n, wrench.fy_n, wrench.fz_n])


def guarded_grasp(arm: Arm, sensor: WrenchSensor, grasp_depth_mm: float,
                  object_width_mm: float, config: GraspConfig,
                  part_weight_n: float | None = None, carried: ToolStep | None = None,
                  on_carried: Callable[[], None] | None = None,
                  lift: bool = True) -> GraspResult:
    """Run the grasp from the current (pre-grasp) pose. See the module docstring.

    Args:
        part_weight_n: the part's weight (N), for the weight check's default threshold.
        lift: False: the jaws close on the part after the guarded descent (with the jam and
            width checks) and stay there, closed, without the lift and its checks (to
            centre the part between them).
        carried: the positioning loop's converged step, made by the first descent move
            (its dz is ignored; None: the first move descends only).
        on_carried: called after that move has made it (the caller reads the pose reached).

    Raises:
        ValueError: the weight check has neither ``min_held_weight_n`` nor the part's weight.
    """
    threshold = config.min_held_weight_n
    if config.check in ("weight", "both") and threshold is None:
        if part_weight_n is None or part_weight_n <= 0.0:
            raise ValueError("controller.grasp.min_held_weight_n: not set and the part's "
                             "weight is unknown: the weight check has no threshold")
        threshold = part_weight_n / 2.0
    start: Pose = arm.pose(fresh=False)
    if not arm.runs_programs:  # the descent program opens them as the arm starts
        arm.open_gripper()
        sensor.bias()  # the program path's with its monitor condition (_program_descent)
    attempt = _Attempt(arm, sensor, config, grasp_depth_mm, start, GraspResult(False, ""),
                       carried, on_carried)
    ended = (_program_descent(attempt, threshold, lift) if arm.runs_programs
             else _host_descent(attempt))
    if ended is not None:
        return ended
    return _close_and_lift(attempt, object_width_mm, threshold, lift)


@dataclass
class _Attempt:
    """One grasp attempt (``guarded_grasp``): the devices, the settings, the pose it started
    from, the result so far and the loop's step the first descent move makes."""

    arm: Arm
    sensor: WrenchSensor
    config: GraspConfig
    grasp_depth_mm: float
    start: Pose
    result: GraspResult
    carried: ToolStep | None
    on_carried: Callable[[], None] | None

    def retreat(self, reason: str) -> GraspResult:
        """Halt, open the jaws and go back to the start pose; the result says why."""
        logger.warning("grasp aborted: %s; retreating", reason)
        self.arm.halt()
        self.arm.open_gripper()
        self.arm.move_to(self.start)
        self.result.reason, self.result.retreated = reason, True
        return self.result

    def carried_made(self) -> None:
        """Record that the first descent move made the loop's step, and tell the caller."""
        self.result.carried_step = dataclasses.replace(self.carried, dz_mm=0.0)
        if self.on_carried is not None:
            self.on_carried()

    def tripped(self, depth: float, contact: bool = False) -> Guard | None:
        """Read the sensor at ``depth`` (mm) into the result and return the first guard it
        trips (the early-contact guard is off in the contact zone). ``contact``: the
        controller's monitor stopped the descent; where no guard tripped on the reading, the
        zone's guard (``stop`` in the contact zone, early contact above it) stands for it."""
        config, result = self.config, self.result
        wrench = self.sensor.read()
        result.forces_n.append(wrench.force_n)
        result.max_force_n = max(result.max_force_n, wrench.force_n)
        in_contact_zone = depth >= self.grasp_depth_mm - config.contact_margin_mm
        active = [g for g in config.guards if not (in_contact_zone and g.name == "early contact")]
        guard = first_tripped(wrench, active)
        if contact and guard is None:
            guard = next((g for g in active if g.action == "stop"), None) if in_contact_zone \
                else next((g for g in active if g.name == "early contact"), None)
        return guard


def _guard_reason(guard: Guard, depth: float) -> str:
    """What a tripped guard ended the descent with."""
    return (f"{guard.name or 'guard'}: {guard.quantity} {guard.op} {guard.limit:g} "
            f"at depth {depth:.1f} mm")


def _program_descent(attempt: _Attempt, threshold: float | None,
                     lift: bool) -> GraspResult | None:
    """The descent as one controller program stopped by the sensor's monitor output (with the
    weight check and a lift, the close and the lift in the same run). Returns the finished
    result, or None where the host goes on to close the jaws."""
    arm, sensor, config, result = attempt.arm, attempt.sensor, attempt.config, attempt.result
    grasp_depth_mm, start, carried = attempt.grasp_depth_mm, attempt.start, attempt.carried
    # the controller stops the descent itself on the sensor's output: one command
    fast = min(max(0.0, config.free_descent_mm - config.guard_clearance_mm), grasp_depth_mm)
    lateral = carried if carried is not None else ToolStep()
    via = start.moved_in_tool_frame(dataclasses.replace(lateral, dz_mm=fast))
    target = start.moved_in_tool_frame(dataclasses.replace(lateral, dz_mm=grasp_depth_mm))
    # the close and the lift in the same run where nothing need be read between them:
    # the weight check's reference is then read here (open jaws, no contact, the same
    # approach axis), and the sensor's condition watches the close for a jam
    grip = lift and config.check == "weight" and config.lift_mm > 0
    # the bias, the condition and the reference on the sensor's line while the arm's line
    # carries the descent's locations; the run starts once they are done
    setup = sensor.prepare_contact_guard(contact_condition(config),
                                         config.weight_samples if grip else None)
    try:
        descent = arm.guarded_descent(
            via, target, config.guard_speed_percent,
            config.free_descent_mm + config.guard_zone_mm - fast,
            config.lift_mm if grip else None, ready=setup.wait)
    except MotionRejectedError as exc:
        result.reason = f"descent refused: {exc}"
        logger.warning("grasp: %s", result.reason)
        return result
    finally:
        setup.join()
    reference = _force(setup.wait()) if grip else None
    if carried is not None:
        attempt.carried_made()
    if descent.closed and reference is not None:
        return _gripped_in_the_run(arm, sensor, descent, result, reference,
                                   grasp_depth_mm, config, threshold, attempt.retreat)
    depth = start.tool_step_to(descent.pose).dz_mm
    result.depth_mm = depth
    guard = attempt.tripped(depth, contact=descent.contact)
    if guard is not None:
        if guard.action == "retreat":
            return attempt.retreat(_guard_reason(guard, depth))
        result.reason = _guard_reason(guard, depth)
    return None


def _host_descent(attempt: _Attempt) -> GraspResult | None:
    """The descent in moves from the host, the sensor read after each: free space in one
    move, guarded steps through the zone where a finger can meet the part, the rest in one.
    Returns the finished result (a guard made it retreat), or None where the host goes on to
    close the jaws."""
    arm, config, result = attempt.arm, attempt.config, attempt.result
    grasp_depth_mm, carried = attempt.grasp_depth_mm, attempt.carried
    depth = 0.0
    zone_end = config.free_descent_mm + config.guard_zone_mm
    while depth < grasp_depth_mm - 1e-9:
        if depth == 0.0:
            step = max(config.step_mm, config.free_descent_mm)
        elif depth < zone_end - 1e-9:
            step = min(config.step_mm, zone_end - depth)
        else:
            step = grasp_depth_mm - depth
        step = min(step, grasp_depth_mm - depth)
        if depth == 0.0 and carried is not None:
            # a tool step translates in the tool frame, then turns about its approach axis:
            # the descent and the loop's step in one command end where the two would
            arm.move_tool(dataclasses.replace(carried, dz_mm=step))
            attempt.carried_made()
        else:
            arm.move_tool(ToolStep(dz_mm=step))
        depth += step
        result.depth_mm = depth
        guard = attempt.tripped(depth)
        if guard is not None:
            if guard.action == "retreat":
                return attempt.retreat(_guard_reason(guard, depth))
            arm.halt()
            result.reason = _guard_reason(guard, depth)
            break
    return None


def _close_and_lift(attempt: _Attempt, object_width_mm: float, threshold: float | None,
                    lift: bool) -> GraspResult:
    """Close the jaws at the bottom of the descent, check for a jam and the width, then lift
    and weigh the part (``GraspConfig.check``)."""
    arm, sensor, config, result = attempt.arm, attempt.sensor, attempt.config, attempt.result
    samples = config.weight_samples
    open_jaws = mean_force(sensor, samples)
    width = arm.close_gripper()
    result.width_mm = width
    closing = mean_force(sensor, config.closing_samples) - open_jaws
    result.closing_force_n = float(np.linalg.norm(closing))
    if result.closing_force_n > config.max_closing_force_n:
        return attempt.retreat(f"grip check failed: the force changed by "
                               f"{result.closing_force_n:.1f} N while the jaws closed (a "
                               f"finger jammed on the part)")
    check_width = config.check in ("width", "both")
    if check_width and abs(width - object_width_mm) > config.width_tolerance_mm:
        return attempt.retreat(f"grip check failed: finger width {width:.1f} mm, expected "
                               f"{object_width_mm:.1f} +/- {config.width_tolerance_mm:g} mm")
    if not lift:
        result.success, result.reason = True, "closed on the part"
        return result
    if config.lift_mm > 0:
        arm.move_tool(ToolStep(dz_mm=-config.lift_mm))
        if check_width:
            width = arm.finger_width_mm()
            if abs(width - object_width_mm) > config.width_tolerance_mm:
                result.width_mm = width
                return attempt.retreat(f"part slipped while lifting: finger width "
                                       f"{width:.1f} mm")
        # Against the open jaws at the bottom (same orientation, no contact): what the sensor
        # feels more along the approach axis now is the part hanging in the jaws.
        result.held_weight_n = float(mean_force(sensor, samples)[2] - open_jaws[2])
        if config.check in ("weight", "both") and result.held_weight_n < threshold:
            return attempt.retreat(f"grip check failed: {result.held_weight_n:.3f} N on the "
                                   f"wrist after lifting (mean of {samples}), expected at "
                                   f"least {threshold:.3f} N")
    result.success = True
    result.reason = result.reason or "held after lift"
    return result


def _gripped_in_the_run(arm: Arm, sensor: WrenchSensor, descent: Descent,
                        result: GraspResult, reference: np.ndarray, grasp_depth_mm: float,
                        config: GraspConfig, threshold: float,
                        retreat: Callable[[str], GraspResult]) -> GraspResult:
    """The rest of a grasp whose descent run also closed the jaws and lifted (the program
    path): a jam stopped the run (the sensor's contact condition held after the close), or
    the lifted part is weighed against ``reference``, the mean force read with open jaws
    before the descent."""
    result.depth_mm = grasp_depth_mm
    result.width_mm = arm.finger_width_mm()
    if descent.contact:  # the condition held once the jaws closed: a finger on the part
        closing = mean_force(sensor, config.closing_samples) - reference
        result.closing_force_n = float(np.linalg.norm(closing))
        result.max_force_n = max(result.max_force_n, result.closing_force_n)
        limit = contact_condition(config)
        return retreat(f"grip check failed: {limit.axis} {limit.op} {limit.limit:g} N once "
                       f"the jaws closed (a finger jammed on the part)")
    samples = config.weight_samples
    held = mean_force(sensor, samples) - reference
    result.forces_n.append(float(np.linalg.norm(held)))
    result.max_force_n = max(result.max_force_n, result.forces_n[-1])
    result.held_weight_n = float(held[2])
    if result.held_weight_n < threshold:
        return retreat(f"grip check failed: {result.held_weight_n:.3f} N on the wrist "
                       f"after lifting (mean of {samples}), expected at least "
                       f"{threshold:.3f} N")
    result.success, result.reason = True, "held after lift"
    return result
