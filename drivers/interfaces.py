"""The device interfaces every backend implements: arm, camera, wrench sensor.

Real drivers (VAL serial arm, ATI sensor, OpenCV camera), the PyBullet work cell and the test
fakes all implement these, and ``drivers.contract`` checks each of them the same way.

Lifecycle of every device: DISCONNECTED -> connect() -> INACTIVE -> activate() -> ACTIVE.
An arm moves only while ACTIVE. A device that loses its link or sees a controller error goes to
FAULT; it refuses motion until ``reset()`` (which reconnects) succeeds.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.core.errors import DeviceFaultError, DeviceNotConnectedError, MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.core.timing import VAL_SPEED_MAX, VAL_SPEED_MIN
from drivers.safety import SafetyLimits, check_target, check_tool_step

logger = logging.getLogger(__name__)

MOVE_UNTIL_STEP_MM = 0.5  # Arm.move_until's default checks its stop condition this often


class Lifecycle(enum.Enum):
    DISCONNECTED = "disconnected"
    INACTIVE = "inactive"
    ACTIVE = "active"
    FAULT = "fault"


class Device(ABC):
    """Connection lifecycle shared by all devices. Use as a context manager."""

    def __init__(self) -> None:
        self._state = Lifecycle.DISCONNECTED
        self._fault_reason: str | None = None

    # -- lifecycle -------------------------------------------------------------------------
    @property
    def state(self) -> Lifecycle:
        return self._state

    @property
    def fault_reason(self) -> str | None:
        """Why the device is in FAULT (None otherwise)."""
        return self._fault_reason if self._state is Lifecycle.FAULT else None

    @property
    def is_connected(self) -> bool:
        return self._state in (Lifecycle.INACTIVE, Lifecycle.ACTIVE)

    def connect(self) -> None:
        """Open the link; DISCONNECTED/FAULT -> INACTIVE. Idempotent when connected."""
        if self.is_connected:
            return
        self._open()
        self._state = Lifecycle.INACTIVE
        self._fault_reason = None

    def activate(self) -> None:
        """INACTIVE -> ACTIVE: from now on the device acts on commands."""
        self._require_connected()
        self._state = Lifecycle.ACTIVE

    def deactivate(self) -> None:
        """ACTIVE -> INACTIVE: commands are refused, readings still work."""
        self._require_connected()
        self._state = Lifecycle.INACTIVE

    def disconnect(self) -> None:
        """Close the link. Safe to call in any state, also twice."""
        if self._state is Lifecycle.DISCONNECTED:
            return
        try:
            self._close()
        finally:
            self._state = Lifecycle.DISCONNECTED

    def reset(self) -> None:
        """Leave FAULT by reconnecting; ends INACTIVE (activate again to move)."""
        self.disconnect()
        self.connect()

    def mark_fault(self, reason: str) -> None:
        """Enter FAULT (called by implementations on lost links, controller errors...)."""
        logger.error("%s fault: %s", type(self).__name__, reason)
        self._state = Lifecycle.FAULT
        self._fault_reason = reason

    def __enter__(self):
        self.connect()
        self.activate()
        return self

    def __exit__(self, *exc_info) -> None:
        self.disconnect()

    def _require_connected(self) -> None:
        if self._state is Lifecycle.FAULT:
            raise DeviceFaultError(f"{type(self).__name__} is in fault: {self._fault_reason}")
        if not self.is_connected:
            raise DeviceNotConnectedError(f"{type(self).__name__} is not connected")

    # -- implemented by backends -------------------------------------------------------------
    @abstractmethod
    def _open(self) -> None:
        """Open the link to the device (raise on failure)."""

    @abstractmethod
    def _close(self) -> None:
        """Close the link; must not raise for an already broken link."""


@dataclass(frozen=True)
class Descent:
    """What a guarded descent (``Arm.guarded_descent``) did.

    pose: the tool pose where the arm stands; contact: the contact input stopped it (before
    the target; with ``closed``, after the jaws closed: before or during the lift); False: it
    reached the target, and the lift's end when asked for, without the input tripping;
    closed: the same run closed the jaws at the target (a descent asked to lift, that met
    no contact on the way down); lifted: it then lifted the part the whole way.
    """

    pose: Pose
    contact: bool
    closed: bool = False
    lifted: bool = False


@dataclass(frozen=True)
class Motion:
    """What a motion command did.

    requested: the step (or, for absolute moves, the target as a step) that was asked for;
    sent: the step actually commanded after the safety layer (equal unless clipped);
    pose: the tool pose reached; clipped: whether the safety layer changed the command.
    """

    requested: ToolStep
    sent: ToolStep
    pose: Pose
    clipped: bool


class Arm(Device):
    """A 6-DOF arm with a parallel-jaw gripper, commanded in Cartesian tool poses.

    Every motion passes ``drivers.safety`` with the limits given at construction; a command
    beyond them is rejected (MotionRejectedError, nothing moves) or clipped, as configured.
    Motions block until the arm stands still.
    """

    #: Moves start from the pose the last completed move reached (on a controller whose
    #: prompt confirms a move done: its target) instead of a fresh pose reading, and ``open``
    #: is not sent again to jaws this arm itself last opened. Either is forgotten on any halt,
    #: fault, reset, reconnect or failed command, which then reads (or opens) afresh.
    #: Backends that pay for a reading (VAL: a ``where`` is 273 ms at 9600 baud) set it.
    reuse_reached_pose: bool = False

    def __init__(self, limits: SafetyLimits | None = None) -> None:
        super().__init__()
        self.limits = limits
        self._reached: Pose | None = None  # see reuse_reached_pose
        self._jaws_open = False  # this arm opened the jaws and nothing happened since
        self._move_start: Pose | None = None  # the pose the move under way starts from

    # -- public API -----------------------------------------------------------------------
    def pose(self, fresh: bool = True) -> Pose:
        """Current tool pose (mm, deg). ``fresh=False``: the pose the last completed move
        reached when the arm keeps it (``reuse_reached_pose``; no exchange), else a reading."""
        self._require_connected()
        if not fresh and self.reuse_reached_pose and self._reached is not None:
            return self._reached
        return self._read_pose()

    def tool_rotation_deg(self) -> float:
        """Rotation of the tool about its (vertical) approach axis, deg."""
        return self.pose().approach_rotation_deg

    def move_to(self, target: Pose) -> Motion:
        """Absolute Cartesian move to ``target``; returns what was done."""
        self._require_active()
        current = self._start_pose()
        decision = check_target(target, current, self.limits) if self.limits else None
        sent_target = decision.target if decision else target
        reached = self._move(current, sent_target)
        return Motion(current.tool_step_to(target), current.tool_step_to(sent_target), reached,
                      bool(decision and decision.clipped))

    def move_tool(self, step: ToolStep) -> Motion:
        """Relative move in the current tool frame (computed from a fresh pose reading)."""
        self._require_active()
        for name, v in step.as_dict().items():
            if not math.isfinite(v):
                raise MotionRejectedError(f"{name} is not a finite number: {v!r}")
        current = self._start_pose()
        sent, clipped = step, False
        if self.limits:
            decision = check_tool_step(step, current, self.limits)
            sent, clipped = decision.step, decision.clipped
        reached = self._move(current, current.moved_in_tool_frame(sent))
        return Motion(step, sent, reached, clipped)

    @property
    def runs_programs(self) -> bool:
        """Whether ``guarded_descent`` runs: the arm's controller stops a descent on its
        contact input by itself (VAL with ``arm.programs``, the simulated arm)."""
        return False

    def guarded_descent(self, via: Pose, target: Pose, guard_speed_percent: float,
                        guard_mm: float, lift_mm: float | None = None,
                        ready: Callable[[], object] | None = None) -> Descent:
        """Open the jaws as the arm starts, move to ``via`` at the set speed, on along the
        approach axis for ``guard_mm`` at ``guard_speed_percent`` of it, and the rest of the
        way to ``target`` at the set speed again, stopping at once wherever the contact input
        (the wrist sensor's monitor output) trips: one controller command. With ``lift_mm``
        the same command then closes the jaws at ``target`` (waiting the hand time) and lifts
        ``lift_mm`` back along the approach axis, the input still armed: high after the close
        (a finger pushing on the part), the lift stops or never starts.

        ``ready`` (e.g. ``GuardSetup.wait``: the wrist sensor's bias and monitor condition
        under way on its own line) is called once before the command that starts the run,
        after what goes on the arm's line before it (VAL: the locations): its error ends the
        descent with nothing moved; a halt meanwhile refuses it.

        Every pose passes the safety layer first (rejected, nothing moves, when one is beyond
        it). Raises MotionRejectedError when the input is already high (nothing moves), or
        when the arm does not run programs (``runs_programs``).
        """
        self._require_active()
        if not self.runs_programs:
            raise MotionRejectedError(f"{type(self).__name__} runs no guarded descent")
        if not 0.0 < guard_speed_percent <= 100.0:
            raise MotionRejectedError(f"guard speed must be in (0, 100] percent, got "
                                      f"{guard_speed_percent!r}")
        if not guard_mm >= 0.0:
            raise MotionRejectedError(f"guard length must be >= 0 mm, got {guard_mm!r}")
        if lift_mm is not None and not lift_mm > 0.0:
            raise MotionRejectedError(f"lift must be > 0 mm, got {lift_mm!r}")
        current = self._start_pose()
        poses = [via, target]
        if lift_mm is not None:
            poses.append(target.moved_in_tool_frame(ToolStep(dz_mm=-lift_mm)))
        if self.limits:
            for pose in poses:
                decision = check_target(pose, current, self.limits)
                if decision.clipped:
                    raise MotionRejectedError(f"guarded descent beyond the safety limits at "
                                              f"{pose}")
        self._reached, self._move_start = None, current
        try:
            descent = self._guarded_descent(via, target, guard_speed_percent, guard_mm,
                                            lift_mm, ready or _nothing)
        finally:
            self._move_start = None
        self._reached = descent.pose
        self._jaws_open = not descent.closed
        return descent

    @staticmethod
    def guard_end(via: Pose, target: Pose, guard_mm: float) -> tuple[Pose, float]:
        """Where a guarded descent's slow part ends, ``guard_mm`` past ``via`` towards
        ``target`` along the approach axis (not past ``target``), and how far before
        ``target`` that is (mm)."""
        rest_mm = max(0.0, via.tool_step_to(target).dz_mm - guard_mm)
        return target.moved_in_tool_frame(ToolStep(dz_mm=-rest_mm)), rest_mm

    def move_until(self, target: Pose, stop: Callable[[], bool], speed_factor: float = 1.0,
                   setup: bool = True, settle: bool = True) -> tuple[Pose, bool]:
        """Absolute move to ``target`` that ends at once where ``stop()`` turns true (what a
        controller program's motion does under a reaction); returns the pose reached and
        whether ``stop`` ended it. ``speed_factor``: the program's speed on top of the set
        speed; ``setup``: the move pays the controller's set-up (the first motion of a program
        run; later ones do not); ``settle``: it pays the settling at its end (where the program
        stops the arm: before a hand instruction, at its end; not where another motion
        follows). A stop always settles. This default checks ``stop`` every
        ``MOVE_UNTIL_STEP_MM`` of a stepped move and ignores both timings; timed backends
        override it."""
        self._require_active()
        start = self.pose(fresh=False)
        step = start.tool_step_to(target)
        distance = math.hypot(step.dx_mm, step.dy_mm, step.dz_mm)
        count = max(1, math.ceil(distance / MOVE_UNTIL_STEP_MM))
        for i in range(1, count + 1):
            if stop():
                return self.pose(fresh=False), True
            scaled = ToolStep(*(v * i / count for v in step.as_dict().values()))
            self.move_to(start.moved_in_tool_frame(scaled) if i < count else target)
        return self.pose(fresh=False), stop()

    def _guarded_descent(self, via: Pose, target: Pose, guard_speed_percent: float,
                         guard_mm: float, lift_mm: float | None,
                         ready: Callable[[], object]) -> Descent:
        """Backends that run programs implement this (see ``guarded_descent``); they call
        ``ready()`` once, before the command that starts the run."""
        raise MotionRejectedError(f"{type(self).__name__} runs no guarded descent")

    def set_speed(self, percent: float) -> None:
        """Monitor speed in percent: VAL's range, 0.01..327.67, 100 normal."""
        self._require_connected()
        if not (isinstance(percent, (int, float)) and VAL_SPEED_MIN <= percent <= VAL_SPEED_MAX):
            raise MotionRejectedError(f"speed must be in {VAL_SPEED_MIN:g}..{VAL_SPEED_MAX:g} "
                                      f"percent, got {percent!r}")
        self._set_speed(float(percent))

    def halt(self) -> None:
        """Stop any motion now. Works in every connected state, also INACTIVE and FAULT."""
        if self._state is Lifecycle.DISCONNECTED:
            return
        self._forget()
        self._halt()

    def open_gripper(self) -> float:
        """Open the jaws; returns the finger width in mm. With ``reuse_reached_pose``, jaws
        this arm itself opened last are not commanded again."""
        self._require_active()
        if self.reuse_reached_pose and self._jaws_open:
            return self._finger_width_mm()
        self._jaws_open = False
        width = self._set_gripper(closed=False)
        self._jaws_open = True
        return width

    def close_gripper(self) -> float:
        """Close the jaws (until they meet or hold something); returns the width in mm."""
        self._require_active()
        self._jaws_open = False
        return self._set_gripper(closed=True)

    def finger_width_mm(self) -> float:
        """Current distance between the fingers, mm."""
        self._require_connected()
        return self._finger_width_mm()

    def _require_active(self) -> None:
        self._require_connected()
        if self._state is not Lifecycle.ACTIVE:
            raise MotionRejectedError(f"arm is {self._state.value}, motion needs active")

    def _start_pose(self) -> Pose:
        """Where the next move starts: the reached pose when kept, else a fresh reading."""
        if self.reuse_reached_pose and self._reached is not None:
            return self._reached
        return self._read_pose()

    def _move(self, start: Pose, target: Pose) -> Pose:
        """``_move_to`` from ``start`` (``_move_start`` for backends that split moves); the
        reached pose is kept when it succeeds and forgotten when it does not."""
        self._reached, self._move_start = None, start
        try:
            reached = self._move_to(target)
        finally:
            self._move_start = None
        self._reached = reached
        return reached

    def _forget(self) -> None:
        """Drop the kept pose and jaw state: the next move reads, the next open is sent."""
        self._reached = None
        self._jaws_open = False

    def disconnect(self) -> None:
        self._forget()
        super().disconnect()

    def mark_fault(self, reason: str) -> None:
        self._forget()
        super().mark_fault(reason)

    # -- implemented by backends -------------------------------------------------------------
    @abstractmethod
    def _read_pose(self) -> Pose: ...

    @abstractmethod
    def _move_to(self, target: Pose) -> Pose:
        """Move to the (already checked) target; return the pose reached."""

    @abstractmethod
    def _set_speed(self, percent: float) -> None: ...

    @abstractmethod
    def _halt(self) -> None: ...

    @abstractmethod
    def _set_gripper(self, closed: bool) -> float: ...

    @abstractmethod
    def _finger_width_mm(self) -> float: ...


@dataclass(frozen=True)
class Frame:
    """One camera image: HxWx3 uint8 RGB, and the time it was taken (time.monotonic(), s)."""

    image: np.ndarray
    timestamp_s: float


class Camera(Device):
    """A colour camera delivering fixed-size RGB frames."""

    width_px: int = 192
    height_px: int = 144

    def grab(self) -> Frame:
        """Take one frame (blocks until it arrives or the timeout passes)."""
        self._require_connected()
        return self._grab()

    @abstractmethod
    def _grab(self) -> Frame: ...


@dataclass(frozen=True)
class Wrench:
    """Forces [N] and torques [N*m] in the sensor frame (z = tool approach axis)."""

    fx_n: float
    fy_n: float
    fz_n: float
    tx_nm: float
    ty_nm: float
    tz_nm: float

    def as_dict(self) -> dict[str, float]:
        return {"fx_n": self.fx_n, "fy_n": self.fy_n, "fz_n": self.fz_n,
                "tx_nm": self.tx_nm, "ty_nm": self.ty_nm, "tz_nm": self.tz_nm}

    @property
    def force_n(self) -> float:
        return math.sqrt(self.fx_n**2 + self.fy_n**2 + self.fz_n**2)


@dataclass(frozen=True)
class MonitorCondition:
    """A threshold the sensor evaluates itself, switching its discrete output (ATI "monitor
    condition"): ``axis op limit`` on the biased reading, e.g. ``fz_n < -3.0``.

    axis: one wrench component (``fx_n`` .. ``tz_nm``); op: ``>`` or ``<``; limit: N or N*m.
    """

    axis: str
    op: str
    limit: float

    def __post_init__(self) -> None:
        if self.axis not in ("fx_n", "fy_n", "fz_n", "tx_nm", "ty_nm", "tz_nm"):
            raise ValueError(f"axis: one of fx_n, fy_n, fz_n, tx_nm, ty_nm, tz_nm, got "
                             f"{self.axis!r}")
        if self.op not in (">", "<"):
            raise ValueError(f"op: '>' or '<', got {self.op!r}")
        if not math.isfinite(self.limit):
            raise ValueError(f"limit: must be finite, got {self.limit!r}")

    def tripped(self, wrench: Wrench) -> bool:
        value = getattr(wrench, self.axis)
        return value > self.limit if self.op == ">" else value < self.limit


class GuardSetup:
    """A wrist sensor's guard set-up (``WrenchSensor.prepare_contact_guard``): done at once,
    or with ``background`` under way in a thread of its own (the sensor's own line, while the
    caller's thread talks to the arm). ``on_wait`` runs once in the first ``wait`` (a
    simulated sensor charges there what is left of its time).

    wait(): blocks until it is done, then returns the mean read (None: none asked for) or
    raises the error that ended it; join(): blocks until it is done, never raises;
    background: whether it ran (or runs) in a thread of its own.
    """

    def __init__(self, work: Callable[[], Wrench | None], background: bool = False,
                 on_wait: Callable[[], None] | None = None) -> None:
        self._mean: Wrench | None = None
        self._error: BaseException | None = None
        self._done = threading.Event()
        self._on_wait = on_wait
        self.background = background
        if background:
            threading.Thread(target=self._run, args=(work,), name="wrench-guard-setup",
                             daemon=True).start()
        else:
            self._run(work)

    def _run(self, work: Callable[[], Wrench | None]) -> None:
        try:
            self._mean = work()
        except BaseException as exc:  # handed to the waiting thread by wait()
            self._error = exc
        finally:
            self._done.set()

    def wait(self) -> Wrench | None:
        self._done.wait()
        on_wait, self._on_wait = self._on_wait, None
        if on_wait is not None:
            on_wait()
        if self._error is not None:
            raise self._error
        return self._mean

    def join(self) -> None:
        self._done.wait()


def _nothing() -> None:
    """A guarded descent's ``ready`` when the caller gives none."""


class WrenchSensor(Device):
    """A 6-axis wrist force-torque sensor."""

    def read_mean(self, samples: int) -> Wrench:
        """The mean of the sensor's last ``samples`` samples (biased), for a load at rest.
        Controllers that average on their own (ATI ``SA n``) answer it with one query; this
        default takes ``samples`` readings."""
        self._require_connected()
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        return self._read_mean(samples)

    def _read_mean(self, samples: int) -> Wrench:
        readings = [self._read() for _ in range(samples)]
        return Wrench(*(sum(values) / samples
                        for values in zip(*(r.as_dict().values() for r in readings),
                                          strict=True)))

    def set_monitor_condition(self, condition: MonitorCondition | None) -> None:
        """Have the sensor switch its output while ``condition`` holds on its biased
        readings (None: clear it, the output stays low). Raises DeviceFaultError when the
        sensor has no such output."""
        self._require_connected()
        self._set_monitor_condition(condition)

    def _set_monitor_condition(self, condition: MonitorCondition | None) -> None:
        raise DeviceFaultError(f"{type(self).__name__} has no monitor output")

    def prepare_contact_guard(self, condition: MonitorCondition,
                              samples: int | None = None) -> GuardSetup:
        """What a guarded descent needs from the sensor before the arm's first motion: the
        bias (the load at rest as zero), ``condition`` on the sensor's output
        (``set_monitor_condition``) and, with ``samples``, the mean of that many samples
        (``read_mean``, after the bias). A sensor on a line of its own does it in the
        background (``GuardSetup.background``) while the caller talks to the arm; the caller
        uses the sensor for nothing else until ``GuardSetup.wait`` or ``join`` returned. The
        arm must stand still until then (the bias and the mean are of the load at rest)."""
        self._require_connected()
        if samples is not None and samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        return self._prepare_contact_guard(condition, samples)

    def _prepare_contact_guard(self, condition: MonitorCondition,
                               samples: int | None) -> GuardSetup:
        """This default does it at once, in the caller's thread."""
        return GuardSetup(lambda: self._contact_guard_steps(condition, samples))

    def _contact_guard_steps(self, condition: MonitorCondition,
                             samples: int | None) -> Wrench | None:
        self._bias()
        self._set_monitor_condition(condition)
        return self._read_mean(samples) if samples is not None else None

    def read(self) -> Wrench:
        """One biased reading."""
        self._require_connected()
        return self._read()

    def bias(self) -> None:
        """Take the current load as zero for later readings."""
        self._require_connected()
        self._bias()

    @abstractmethod
    def _read(self) -> Wrench: ...

    @abstractmethod
    def _bias(self) -> None: ...
