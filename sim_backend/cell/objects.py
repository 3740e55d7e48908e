"""The geometry of the catalogue's parts (``drivers.core.parts``), in one registry (``PARTS``).

Each part is meshed in its resting pose in a part frame whose origin lies on the table under
the grasp point, z up; the jaws close along the part's y axis, so the nominal tool x axis is the
part's x axis. kappa is the part's rotational symmetry about the vertical as the hand camera
sees it (the image repeats every 360/kappa deg), which is also the period of its grasp.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from drivers.core.parts import CUBE_EDGE_MM, SCREW_SHANK_RADIUS_MM, Part
from drivers.core.parts import PARTS as CATALOGUE
from drivers.core.pose import rot_y, rot_z
from sim_backend.cell import meshes
from sim_backend.cell.meshes import Mesh

# Friction coefficient of each material of the parts (a judgement: wood on a painted table
# top; the finger pads' own friction is in ``grasp_physics``).
MATERIAL_FRICTION = {"wood": 0.5}


@dataclass(frozen=True)
class Cylinder:
    """A collision cylinder: radius, length (mm) and pose (4x4, mm; the axis is its z)."""

    radius_mm: float
    length_mm: float
    pose_mm: np.ndarray


@dataclass(frozen=True)
class PartGeometry:
    """The visual mesh and the collision shape: the given cylinders, or when there are none
    the convex hull of the mesh."""

    mesh: Mesh
    cylinders: tuple[Cylinder, ...] = ()


@dataclass(frozen=True)
class PartSpec(Part):
    """One kind of part in the simulated cell: its catalogue entry (every field of
    ``drivers.core.parts.Part``) and ``build``, which makes its geometry (mm, part frame)."""

    build: Callable[[], PartGeometry]

    @cached_property
    def geometry(self) -> PartGeometry:
        return self.build()

    @property
    def mesh(self) -> Mesh:
        return self.geometry.mesh

    @property
    def friction(self) -> float:
        """Coulomb friction of the part's material (with the table and the finger pads)."""
        return MATERIAL_FRICTION[self.material]

    @cached_property
    def height_mm(self) -> float:
        """Height of the part's top above the table."""
        return float(self.mesh.bounds_mm()[1][2])

    @cached_property
    def footprint_radius_mm(self) -> float:
        """Largest horizontal distance of the part from its origin."""
        return float(np.hypot(self.mesh.vertices_mm[:, 0], self.mesh.vertices_mm[:, 1]).max())


def _cube() -> PartGeometry:
    # About 30 mm, widely rounded edges, a screw hole in every face: faces look like rings.
    mesh = meshes.holed_rounded_cube(CUBE_EDGE_MM, edge_radius_mm=6.0, hole_radius_mm=5.5,
                                     hole_depth_mm=11.0)
    return PartGeometry(mesh.transformed(np.eye(3), [0.0, 0.0, CUBE_EDGE_MM / 2.0]))


def _nut() -> PartGeometry:
    # Turned 90 deg so two flats face the jaws (+/-y).
    mesh = meshes.hex_nut(across_flats_mm=24.0, thickness_mm=12.0, hole_radius_mm=5.5,
                          chamfer_mm=1.5)
    return PartGeometry(mesh.transformed(rot_z(math.pi / 2), [0.0, 0.0, 0.0]))


def _ledge() -> PartGeometry:
    return PartGeometry(meshes.holed_ledge(holes=3, pitch_mm=25.0, width_mm=22.0, thickness_mm=8.0,
                                     hole_radius_mm=5.5))


SCREW_HEAD_RADIUS_MM = 10.5
SCREW_SHANK_LENGTH_MM = 32.0
HEAD_HEIGHT_MM = 8.0


def _screw() -> PartGeometry:
    mesh = meshes.round_head_screw(head_radius_mm=SCREW_HEAD_RADIUS_MM,
                                   head_height_mm=HEAD_HEIGHT_MM,
                                   shank_radius_mm=SCREW_SHANK_RADIUS_MM,
                                   shank_length_mm=SCREW_SHANK_LENGTH_MM, thread_pitch_mm=3.0,
                                   thread_depth_mm=0.9, slot_width_mm=2.2)
    # It lies on the rim of its head and the crests of its thread: the shank slopes down.
    tilt = math.asin((SCREW_HEAD_RADIUS_MM - SCREW_SHANK_RADIUS_MM) / SCREW_SHANK_LENGTH_MM)
    place = np.eye(4)
    place[:3, :3] = rot_y(tilt)
    lo, _ = mesh.transformed(place[:3, :3], [0.0, 0.0, 0.0]).bounds_mm()
    grasp_x = (SCREW_SHANK_LENGTH_MM / 2.0) * math.cos(tilt)  # middle of the shank
    place[:3, 3] = [-grasp_x, 0.0, -lo[2]]
    # Collision: head and shank as two cylinders along the screw's axis (a single hull would
    # fill the space between the head's rim and the tip: the jaws would feel a thicker shank).
    along_x = np.eye(4)
    along_x[:3, :3] = rot_y(math.pi / 2)
    head, shank = along_x.copy(), along_x.copy()
    head[0, 3] = -HEAD_HEIGHT_MM / 2.0
    shank[0, 3] = SCREW_SHANK_LENGTH_MM / 2.0
    return PartGeometry(
        mesh.transformed(place[:3, :3], place[:3, 3]),
        (Cylinder(SCREW_HEAD_RADIUS_MM, HEAD_HEIGHT_MM, place @ head),
         Cylinder(SCREW_SHANK_RADIUS_MM, SCREW_SHANK_LENGTH_MM, place @ shank)))


_BUILDERS: dict[str, Callable[[], PartGeometry]] = {
    "cube": _cube, "nut": _nut, "ledge": _ledge, "screw": _screw,
}
PARTS: dict[str, PartSpec] = {kind: PartSpec(**dataclasses.asdict(part), build=_BUILDERS[kind])
                              for kind, part in CATALOGUE.items()}
