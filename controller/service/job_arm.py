"""The arm as the service's jobs see it: preemptible, with its last pose and its command in flight.

``PreemptibleArm`` wraps the configured Arm and offers the same public methods (the library code
only calls those). Once ``preempt()`` was called, every motion command is refused with
MotionRejectedError("aborted") before anything is sent, so an abort stops acquisition, teach-in
and the grasp at their next move as well as the positioning loop; ``resume()`` (at the start of
the next job) lifts that. ``halt()`` is passed straight through, also while preempted.

It also remembers the last pose read or reached (so ``status`` needs no serial exchange) and
since when the current command has been running (so the watchdog can tell a hung command).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TypeVar

from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Descent, Lifecycle, Motion
from drivers.safety import SafetyLimits

T = TypeVar("T")


class PreemptibleArm:
    """Delegates to ``arm``; see the module docstring."""

    def __init__(self, arm: Arm) -> None:
        self.inner = arm
        self._preempted = threading.Event()
        self._busy_since: float | None = None
        self._last_pose: tuple[Pose, float] | None = None

    # -- preemption and bookkeeping ----------------------------------------------------------
    def preempt(self) -> None:
        """Refuse every motion command from now on (thread-safe)."""
        self._preempted.set()

    def resume(self) -> None:
        """Accept motion commands again after ``preempt`` (called as each job starts)."""
        self._preempted.clear()

    def last_pose(self) -> tuple[Pose, float] | None:
        """The last pose read or reached and when (UNIX time), or None before the first."""
        return self._last_pose

    def busy_for_s(self) -> float:
        """How long the command now running has been running (0 when none is)."""
        since = self._busy_since
        return 0.0 if since is None else time.monotonic() - since

    def _run(self, call: Callable[[], T]) -> T:
        self._busy_since = time.monotonic()
        try:
            return call()
        finally:
            self._busy_since = None

    def _move(self, call: Callable[[], T]) -> T:
        if self._preempted.is_set():
            raise MotionRejectedError("aborted")
        return self._run(call)

    def _seen(self, pose: Pose) -> Pose:
        self._last_pose = (pose, time.time())
        return pose

    # -- the Arm's public methods ------------------------------------------------------------
    @property
    def state(self) -> Lifecycle:
        """The wrapped arm's lifecycle state."""
        return self.inner.state

    @property
    def fault_reason(self) -> str | None:
        """Why the wrapped arm is in FAULT (None otherwise)."""
        return self.inner.fault_reason

    @property
    def limits(self) -> SafetyLimits | None:
        """The wrapped arm's safety limits (None: motions are not checked)."""
        return self.inner.limits

    def pose(self, fresh: bool = True) -> Pose:
        """Current tool pose (mm, deg), from the arm (see ``Arm.pose``), kept as the last pose."""
        return self._seen(self._run(lambda: self.inner.pose(fresh)))

    def tool_rotation_deg(self) -> float:
        """Rotation of the tool about its approach axis, deg (a fresh pose reading)."""
        return self.pose().approach_rotation_deg

    def move_to(self, target: Pose) -> Motion:
        """Absolute Cartesian move to ``target``; returns what was done and keeps the pose reached.

        Raises:
            MotionRejectedError: ``aborted`` after ``preempt`` (nothing sent), or the arm
                refused it.
        """
        motion = self._move(lambda: self.inner.move_to(target))
        self._seen(motion.pose)
        return motion

    def move_tool(self, step: ToolStep) -> Motion:
        """Relative move in the current tool frame; returns what was done, keeps the pose reached.

        Raises:
            MotionRejectedError: ``aborted`` after ``preempt`` (nothing sent), or the arm
                refused it.
        """
        motion = self._move(lambda: self.inner.move_tool(step))
        self._seen(motion.pose)
        return motion

    @property
    def runs_programs(self) -> bool:
        """Whether the wrapped arm runs the guarded descent as a program (``Arm.runs_programs``)."""
        return self.inner.runs_programs

    def guarded_descent(self, via: Pose, target: Pose, guard_speed_percent: float,
                        guard_mm: float, lift_mm: float | None = None,
                        ready: Callable[[], object] | None = None) -> Descent:
        """The wrapped arm's guarded descent (``Arm.guarded_descent``), keeping the pose
        reached (refused after ``preempt``)."""
        descent = self._move(lambda: self.inner.guarded_descent(
            via, target, guard_speed_percent, guard_mm, lift_mm, ready))
        self._seen(descent.pose)
        return descent

    def set_speed(self, percent: float) -> None:
        """Monitor speed in percent, 0 < percent <= 100 (refused after ``preempt``)."""
        self._move(lambda: self.inner.set_speed(percent))

    def open_gripper(self) -> float:
        """Open the jaws; returns the finger width in mm (refused after ``preempt``)."""
        return self._move(self.inner.open_gripper)

    def close_gripper(self) -> float:
        """Close the jaws; returns the finger width in mm (refused after ``preempt``)."""
        return self._move(self.inner.close_gripper)

    def finger_width_mm(self) -> float:
        """Current distance between the fingers, mm (also after ``preempt``)."""
        return self._run(self.inner.finger_width_mm)

    def halt(self) -> None:
        """Stop any motion now (not refused while preempted: this is what an abort sends)."""
        self.inner.halt()
