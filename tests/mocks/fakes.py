"""In-memory fake devices implementing drivers.interfaces, with fault-injection knobs.

The fake arm is kinematically ideal (moves exactly where told) unless a knob says otherwise:
``tracking_offset`` adds a fixed tool-frame step to every executed move, ``fail_after_moves``
puts it into FAULT on the N-th move, ``lose_feedback`` makes pose reads time out.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable

import numpy as np

from drivers.core.errors import DeviceFaultError, DeviceTimeoutError
from drivers.core.pose import Pose, ToolStep
from drivers.interfaces import Arm, Camera, Frame, Wrench, WrenchSensor
from drivers.safety import SafetyLimits

HOME = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)


class FakeArm(Arm):
    """An ideal arm with a parallel gripper (open 40 mm, closed 0 mm or on the held width)."""

    def __init__(self, limits: SafetyLimits | None = None, start: Pose = HOME,
                 open_width_mm: float = 40.0, object_width_mm: float | None = None) -> None:
        super().__init__(limits)
        self._pose = start
        self.open_width_mm = open_width_mm
        self.object_width_mm = object_width_mm
        self._width_mm = open_width_mm
        self.speed_percent = 100.0
        self.moves: list[Pose] = []
        self.halts = 0
        # fault knobs
        self.tracking_offset = ToolStep()
        self.fail_after_moves: int | None = None
        self.lose_feedback = False

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _read_pose(self) -> Pose:
        if self.lose_feedback:
            raise DeviceTimeoutError("fake arm: no pose feedback")
        return self._pose

    def _move_to(self, target: Pose) -> Pose:
        if self.fail_after_moves is not None and len(self.moves) >= self.fail_after_moves:
            self.mark_fault("fake arm: injected fault")
            raise DeviceFaultError("fake arm: injected fault")
        self._pose = target.moved_in_tool_frame(self.tracking_offset)
        self.moves.append(self._pose)
        return self._pose

    def _set_speed(self, percent: float) -> None:
        self.speed_percent = percent

    def _halt(self) -> None:
        self.halts += 1

    def _set_gripper(self, closed: bool) -> float:
        if not closed:
            self._width_mm = self.open_width_mm
        else:
            self._width_mm = self.object_width_mm if self.object_width_mm is not None else 0.0
        return self._width_mm

    def _finger_width_mm(self) -> float:
        return self._width_mm


class FakeCamera(Camera):
    """Serves frames from ``render(pose_or_none) -> image``; defaults to a grey frame."""

    def __init__(self, render: Callable[[], np.ndarray] | None = None) -> None:
        super().__init__()
        self._render = render or (lambda: np.full((144, 192, 3), 100, np.uint8))
        self.stalled = False

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _grab(self) -> Frame:
        if self.stalled:
            raise DeviceTimeoutError("fake camera: no frame")
        return Frame(self._render(), time.monotonic())


class FakeWrenchSensor(WrenchSensor):
    """Returns ``reading()`` minus the bias; ``readings`` may be a scripted iterator."""

    def __init__(self, reading: Callable[[], Wrench] | None = None) -> None:
        super().__init__()
        self._reading = reading or (lambda: Wrench(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
        self._bias_values = np.zeros(6)
        self.count = itertools.count()

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _raw(self) -> np.ndarray:
        return np.array(list(self._reading().as_dict().values()))

    def _read(self) -> Wrench:
        next(self.count)
        return Wrench(*(self._raw() - self._bias_values))

    def _bias(self) -> None:
        self._bias_values = self._raw()
