"""Tool poses in VAL's (X, Y, Z, O, A, T) form and the tool-frame arithmetic on them.

Convention (kept in this one module): the tool's rotation matrix is

    R(O, A, T) = Rz(O) . Ry(A + 90 deg) . Rz(T)

with the columns of R being the tool's x, y and z axes in world coordinates, z being the
approach axis. So (O, A, T) = (-90, 90, 0) is the tool pointing straight down with its x axis
along world +y, as on VAL. Straight down is the Euler singularity; there O is reported as -90
and the rotation about the approach axis goes into T (VAL does the same).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Below this sin(A + 90 deg) the pose counts as pointing straight up/down (about 0.006 deg).
_SINGULAR_SIN = 1e-4
# O reported at the singularity.
_SINGULAR_O_DEG = -90.0


def wrap_deg(angle_deg: float, period_deg: float = 360.0) -> float:
    """Wrap an angle into (-period/2, period/2]."""
    half = period_deg / 2.0
    wrapped = math.fmod(angle_deg + half, period_deg)
    if wrapped <= 0.0:
        wrapped += period_deg
    return wrapped - half


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True)
class ToolStep:
    """A relative motion expressed in the current tool frame.

    dx_mm, dy_mm: along the tool's x and y axes; dz_mm: along the approach axis (positive =
    towards the object); dphi_deg: rotation about the approach axis (right-handed about +z).
    """

    dx_mm: float = 0.0
    dy_mm: float = 0.0
    dz_mm: float = 0.0
    dphi_deg: float = 0.0

    @property
    def translation_mm(self) -> float:
        return math.sqrt(self.dx_mm**2 + self.dy_mm**2 + self.dz_mm**2)

    def as_dict(self) -> dict[str, float]:
        return {"dx_mm": self.dx_mm, "dy_mm": self.dy_mm, "dz_mm": self.dz_mm,
                "dphi_deg": self.dphi_deg}


@dataclass(frozen=True)
class Pose:
    """Tool pose as VAL reports it: position in mm, Euler angles O, A, T in degrees."""

    x_mm: float
    y_mm: float
    z_mm: float
    o_deg: float
    a_deg: float
    t_deg: float

    @property
    def position_mm(self) -> np.ndarray:
        return np.array([self.x_mm, self.y_mm, self.z_mm])

    def rotation(self) -> np.ndarray:
        """3x3 rotation matrix; columns are the tool's x, y, z (approach) axes."""
        return (rot_z(math.radians(self.o_deg)) @ rot_y(math.radians(self.a_deg + 90.0))
                @ rot_z(math.radians(self.t_deg)))

    @property
    def approach_rotation_deg(self) -> float:
        """Rotation of the tool about the vertical: heading of its x axis in the world XY plane."""
        r = self.rotation()
        return math.degrees(math.atan2(r[1, 0], r[0, 0]))

    @classmethod
    def from_matrix(cls, position_mm, rotation: np.ndarray) -> Pose:
        """Build a pose from a position and a rotation matrix (inverse of ``rotation()``)."""
        r = np.asarray(rotation, dtype=float)
        beta = math.acos(max(-1.0, min(1.0, r[2, 2])))  # = A + 90 deg
        if math.sin(beta) > _SINGULAR_SIN:
            o = math.atan2(r[1, 2], r[0, 2])
            t = math.atan2(r[2, 1], -r[2, 0])
        else:
            o = math.radians(_SINGULAR_O_DEG)
            if r[2, 2] < 0:  # pointing down: R = Rz(O - T) Ry(180)
                o_minus_t = math.atan2(-r[1, 0], -r[0, 0])
                t = o - o_minus_t
            else:  # pointing up: R = Rz(O + T)
                t = math.atan2(r[1, 0], r[0, 0]) - o
        p = [float(v) for v in position_mm]
        return cls(p[0], p[1], p[2], wrap_deg(math.degrees(o)), math.degrees(beta) - 90.0,
                   wrap_deg(math.degrees(t)))

    def moved_in_tool_frame(self, step: ToolStep) -> Pose:
        """The pose reached by applying ``step`` in this pose's tool frame."""
        r = self.rotation()
        p = self.position_mm + r @ np.array([step.dx_mm, step.dy_mm, step.dz_mm])
        return Pose.from_matrix(p, r @ rot_z(math.radians(step.dphi_deg)))

    def tool_step_to(self, other: Pose) -> ToolStep:
        """The tool-frame step that takes this pose to ``other`` (ignores tilt differences)."""
        r = self.rotation()
        d = r.T @ (other.position_mm - self.position_mm)
        rel = r.T @ other.rotation()
        dphi = math.degrees(math.atan2(rel[1, 0], rel[0, 0]))
        return ToolStep(float(d[0]), float(d[1]), float(d[2]), dphi)

    def as_dict(self) -> dict[str, float]:
        return {"x_mm": self.x_mm, "y_mm": self.y_mm, "z_mm": self.z_mm,
                "o_deg": self.o_deg, "a_deg": self.a_deg, "t_deg": self.t_deg}

    def is_finite(self) -> bool:
        return all(math.isfinite(v) for v in self.as_dict().values())
