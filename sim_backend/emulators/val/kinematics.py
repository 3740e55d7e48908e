"""Joint angles for the VAL emulator: the PUMA 260 kinematics of ``sim_backend.cell.puma260`` in the
wrapped arm's pose frame.

The wrapped arm works in Cartesian tool poses only; the emulator needs joints for the ``JT1..JT6``
lines of ``where``, for ``do drive`` and for precision points (``#name``). Joint angles are in
the hardware notes' zero convention (not necessarily the one a real controller prints), degrees.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose
from sim_backend.cell import puma260

Joints = tuple[float, float, float, float, float, float]

READY_DEG: Joints = (0.0, 90.0, -90.0, 0.0, 0.0, 0.0)  # arm straight up
NEST_DEG: Joints = (0.0, -60.0, 50.0, 0.0, 90.0, 0.0)  # arm folded down
# Elbow up, tool pointing down: the first guess when nothing better is known (the same one
# sim_backend.cell.sim_cell starts from, so the emulator reports the simulated arm's wrist branch).
TOOL_DOWN_DEG: Joints = (0.0, 30.0, -180.0, -180.0, 30.0, 0.0)


def within_ranges(joints_deg: Sequence[float]) -> bool:
    return puma260.within_limits(np.radians(np.asarray(joints_deg, dtype=float)))


@dataclass(frozen=True)
class Puma260:
    """The arm in the pose frame. base_mm: the robot base (DH frame 0) in the arm's pose frame;
    tool_length_mm: tool centre point beyond the flange, along the approach axis."""

    base_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tool_length_mm: float = 0.0

    def forward(self, joints_deg: Sequence[float]) -> Pose:
        """Tool pose for the given joint angles."""
        flange = puma260.flange_transform(np.radians(np.asarray(joints_deg, dtype=float)))
        position = flange[:3, 3] + self.tool_length_mm * flange[:3, 2] + np.asarray(self.base_mm)
        return Pose.from_matrix(position, flange[:3, :3])

    def inverse(self, pose: Pose, seed_deg: Sequence[float]) -> Joints | None:
        """Joint angles within range reaching ``pose``, nearest ``seed_deg``; None if none."""
        rotation = pose.rotation()
        flange = np.eye(4)
        flange[:3, :3] = rotation
        flange[:3, 3] = pose.position_mm - np.asarray(self.base_mm) \
            - self.tool_length_mm * rotation[:, 2]
        try:
            joints_rad = puma260.inverse_kinematics(flange, np.radians(np.asarray(seed_deg)))
        except MotionRejectedError:
            return None
        return tuple(float(q) for q in np.degrees(joints_rad))  # type: ignore[return-value]
