"""The geometry of the catalogue's parts (``drivers.core.parts``) in the simulated cell.

The built-in parts' meshes are built here (``PARTS``); a declared part's comes from its mesh
file (``sim_backend.cell.mesh_files``). ``spec_for`` gives any catalogue entry's.

Each part is meshed in its resting pose in a part frame whose origin lies on the table under
the grasp point, z up; the jaws close along the part's y axis, so the nominal tool x axis is the
part's x axis. kappa is the part's rotational symmetry about the vertical as the hand camera
sees it (the image repeats every 360/kappa deg), which is also the period of its grasp.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from drivers.core.errors import ConfigError
from drivers.core.parts import PARTS as CATALOGUE
from drivers.core.parts import Part
from drivers.core.pose import rot_y, rot_z
from sim_backend.cell import mesh_files, meshes
from sim_backend.cell.meshes import Mesh

# Friction coefficient of each material of the parts with a painted table top (a judgement,
# from handbook values for dry contact; the finger pads' own friction is in ``grasp_physics``).
MATERIAL_FRICTION = {"wood": 0.5, "plastic": 0.4, "metal": 0.3}

CUBE_EDGE_MM = 30.0
SCREW_SHANK_RADIUS_MM = 5.5


@dataclass(frozen=True)
class Cylinder:
    """A collision cylinder: radius, length (mm) and pose (4x4, mm; the axis is its z)."""

    radius_mm: float
    length_mm: float
    pose_mm: np.ndarray


@dataclass(frozen=True)
class PartGeometry:
    """The visual mesh and the collision shape: the given cylinders, or the convex pieces
    ``hulls_obj`` (OBJ text, mm, part frame), or when there are neither the convex hull of
    the mesh."""

    mesh: Mesh
    cylinders: tuple[Cylinder, ...] = ()
    hulls_obj: str | None = None


@dataclass(frozen=True)
class PartSpec(Part):
    """One kind of part in the simulated cell: its catalogue entry (every field of
    ``drivers.core.parts.Part``) and ``build``, which makes its geometry (mm, part frame)."""

    build: Callable[[], PartGeometry] = dataclasses.field(kw_only=True)

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
    def symmetry(self) -> int:
        """The part's rotational symmetry about the vertical: the declared kappa, else the
        mesh's own (``mesh_files.rotational_symmetry``: the simulator's ground truth, which
        teach-in does not read; it finds kappa from images)."""
        if self.kappa is not None:
            return self.kappa
        return mesh_files.rotational_symmetry(self.mesh.vertices_mm)

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


def _from_file(part: Part) -> PartGeometry:
    loaded = mesh_files.load_part_mesh(part.mesh_file, part.mesh_scale, f"parts.{part.kind}.mesh")
    return PartGeometry(loaded.mesh, hulls_obj=loaded.hulls_obj)


_BUILDERS: dict[str, Callable[[], PartGeometry]] = {
    "cube": _cube, "nut": _nut, "ledge": _ledge, "screw": _screw,
}


@functools.lru_cache(maxsize=64)
def spec_for(part: Part) -> PartSpec:
    """The simulated cell's part for catalogue entry ``part``: a built-in part's built mesh,
    or a declared part's mesh file (read and checked once, on first use of its geometry).

    Raises:
        ConfigError: a declared part without a mesh file, or a material the simulated cell
            has no friction for.
    """
    if part.material not in MATERIAL_FRICTION:
        raise ConfigError(f"parts.{part.kind}.material: the simulated cell knows "
                          f"{' | '.join(MATERIAL_FRICTION)}, got {part.material!r}")
    if part.mesh_file is not None:
        build = functools.partial(_from_file, part)
    elif part.kind in _BUILDERS and CATALOGUE.get(part.kind) == part:
        build = _BUILDERS[part.kind]
    else:
        raise ConfigError(f"parts.{part.kind}.mesh: the simulated cell needs the part's mesh "
                          "file (STL, OBJ or PLY, in mm)")
    return PartSpec(**{f.name: getattr(part, f.name) for f in dataclasses.fields(Part)},
                    build=build)


PARTS: dict[str, PartSpec] = {kind: spec_for(part) for kind, part in CATALOGUE.items()}
