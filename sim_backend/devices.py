"""The simulated devices: SimArm, SimCamera, SimWrenchSensor on one shared SimCell.

They implement ``drivers.interfaces`` exactly like the real drivers, so the controller cannot
tell them apart. The cell belongs to whoever created it: disconnecting a device leaves the cell
open (close the cell, or use it as a context manager, when done).

Arm moves are atomic (inverse kinematics, then the joints are set), so ``halt`` has nothing to
stop and the speed setting is only remembered. The wrench sensor reads the cell's contact
model: forces the environment exerts on the tool, in the tool frame (z = approach axis), so
pressing down onto the table gives Fz < 0.
"""

from __future__ import annotations

import time

import numpy as np

from drivers.core.errors import DeviceFaultError
from drivers.core.pose import Pose
from drivers.interfaces import Arm, Camera, Frame, Wrench, WrenchSensor
from drivers.safety import SafetyLimits
from sim_backend.cell import hand_camera
from sim_backend.cell.sim_cell import SimCell


def _require_open(cell: SimCell, device: str) -> None:
    if not cell.is_open:
        raise DeviceFaultError(f"{device}: the simulated cell is closed")


class SimArm(Arm):
    """The simulated PUMA 260 with its parallel-jaw gripper."""

    def __init__(self, cell: SimCell, limits: SafetyLimits | None = None) -> None:
        super().__init__(limits)
        self.cell = cell
        self.speed_percent = 100.0

    def _open(self) -> None:
        _require_open(self.cell, "SimArm")

    def _close(self) -> None:
        """Nothing to release: the cell stays open for the other devices."""

    def _read_pose(self) -> Pose:
        return self.cell.arm_pose()

    def _move_to(self, target: Pose) -> Pose:
        return self.cell.move_arm(target)

    def _set_speed(self, percent: float) -> None:
        self.speed_percent = percent

    def _halt(self) -> None:
        """Moves are atomic: by the time halt can be called, the arm stands still."""

    def _set_gripper(self, closed: bool) -> float:
        return self.cell.close_gripper() if closed else self.cell.open_gripper()

    def _finger_width_mm(self) -> float:
        return self.cell.finger_width_mm()


class SimCamera(Camera):
    """The hand camera: 192x144 RGB frames rendered from the cell."""

    width_px = hand_camera.WIDTH_PX
    height_px = hand_camera.HEIGHT_PX

    def __init__(self, cell: SimCell) -> None:
        super().__init__()
        self.cell = cell

    def _open(self) -> None:
        _require_open(self.cell, "SimCamera")

    def _close(self) -> None:
        """Nothing to release."""

    def _grab(self) -> Frame:
        return Frame(self.cell.render(), time.monotonic())


class SimWrenchSensor(WrenchSensor):
    """The wrist force-torque sensor: the cell's contact model, minus the bias."""

    def __init__(self, cell: SimCell) -> None:
        super().__init__()
        self.cell = cell
        self._offset = np.zeros(6)

    def _open(self) -> None:
        _require_open(self.cell, "SimWrenchSensor")

    def _close(self) -> None:
        """Nothing to release."""

    def _read(self) -> Wrench:
        return Wrench(*(float(v) for v in self.cell.wrench() - self._offset))

    def _bias(self) -> None:
        self._offset = self.cell.wrench()
