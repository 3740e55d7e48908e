"""The parts catalogue: what the cell knows of each part it positions and grasps.

The built-in parts (the toy construction set's cube, nut, ledge and screw) are a data file of
the package, ``drivers/core/parts.yaml``; a cell config declares further parts under its
``parts:`` section in the same format (``declare``). A ``Catalogue`` holds both, and every
command looks a part up there, so a declared part works wherever a built-in one does.

The real cell reads it (teach-in takes a part's symmetry and grasp geometry from here) and so
does the simulated cell (which builds the built-in parts' meshes and loads a declared part's
mesh file, ``sim_backend.cell.objects``), so both agree on every figure. kappa is the part's
rotational symmetry about the vertical as the hand camera sees it (the image repeats every
360/kappa deg), which is also the period of its grasp; a declared part may leave it out, and
teach-in then finds it from the part's own images (``controller.teach.symmetry``).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, load_yaml_file

# The parallel-jaw gripper's full opening (mm); before a grasp the jaws open to the part's
# ``jaw_opening_mm``.
GRIPPER_MAX_OPENING_MM = 40.0
# Where the pre-grasp (taught) pose holds the fingertips above the part's top (mm): the grasp
# descends this plus the part's grip depth.
APPROACH_HEIGHT_MM = 35.0
# The jaws open this much wider than the part either side when a declaration does not say.
JAW_CLEARANCE_MM = 1.5
MAX_KAPPA = 360  # as ``drivers.core.cell_state`` stores it

BUILTIN_FILE = Path(__file__).with_name("parts.yaml")
DECLARE_HINT = "declare a new one under parts: in the cell config, docs/quickstart.md#adding-a-part"
# A part's name names its state folder (``state/<name>/``) and is typed after ``--part``.
PART_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")
RESERVED_NAMES = ("all",)  # ``finepos evaluate --part all``: every part

Material = Literal["wood", "plastic", "metal"]
_UNIT_RANGE = {"min": 0.0, "max": 1.0}


@dataclass(frozen=True)
class Part:
    """One kind of part.

    Attributes:
        kind: the part's name (``cube``, ``nut``, ``ledge``, ``screw`` or a declared one).
        kappa: rotational symmetry about the vertical (see the module docstring); None: not
            declared, found at teach-in.
        grasp_width_mm: finger width when the part is held (across the jaws).
        grip_below_top_mm: how far below the part's top the fingertips go to grip it.
        jaw_opening_mm: how wide the jaws open before the descent: a little wider than the
            part, which sets the grasp's tolerance.
        mass_g: the part's mass (the weight the wrist sensor feels while it is held, which
            the grasp check measures; the simulated part's dynamic mass).
        material: what the part is made of (the simulated part's friction).
        color: the part's usual colour (RGB, 0..1).
        mesh_file: the part's mesh file for the simulated cell (an absolute path), or None:
            a built-in part's mesh is built by the simulator.
        mesh_scale: the mesh file's coordinates times this are millimetres.
    """

    kind: str
    kappa: int | None
    grasp_width_mm: float
    grip_below_top_mm: float
    jaw_opening_mm: float
    mass_g: float
    material: str
    color: tuple[float, float, float]
    mesh_file: str | None = None
    mesh_scale: float = 1.0

    @property
    def weight_n(self) -> float:
        """The part's weight (N): what the wrist sensor feels while it is held."""
        return self.mass_g * 9.81e-3

    @property
    def grasp_depth_mm(self) -> float:
        """How far the grasp descends along the approach axis from the pre-grasp pose."""
        return APPROACH_HEIGHT_MM + self.grip_below_top_mm


@dataclass(frozen=True)
class PartDeclaration:
    """One entry of the ``parts:`` section: a part declared under its name.

    grasp_width_mm: finger width when the part is held (across the jaws; required);
    mesh: the part's mesh for the simulated cell, an STL, OBJ or PLY file in millimetres,
    z up, lying as on the table (a relative path is taken from the config file's folder;
    null: none, the part runs on a real cell only); scale: the mesh file's coordinates times
    this are millimetres (0.001 for a file in metres, 25.4 for inches);
    grip_below_top_mm: how far below the part's top the fingertips go to grip it;
    jaw_opening_mm: how wide the jaws open before the descent, at most the gripper's 40 mm
    and above the grasp width (null: the grasp width plus 1.5 mm either side);
    mass_g: the part's mass (what the grasp's weight check expects); material: what it is
    made of (the simulated part's friction); color: its colour (RGB 0..1), as the simulated
    cell paints it unless ``scene.object.color`` is set; kappa: its rotational symmetry
    about the vertical as the hand camera sees it (null: teach-in finds it from the part's
    images).
    """

    grasp_width_mm: float = field(metadata={"min": 0.0, "exclusive_min": True})
    mesh: str | None = None
    scale: float = field(default=1.0, metadata={"min": 0.0, "exclusive_min": True})
    grip_below_top_mm: float = field(default=5.0, metadata={"min": 0.0, "max": 200.0})
    jaw_opening_mm: float | None = field(default=None, metadata={"min": 0.0})
    mass_g: float = field(default=10.0, metadata={"min": 0.0, "exclusive_min": True,
                                                   "max": 2000.0})
    material: Material = "wood"
    color: tuple[float, float, float] = field(default=(0.8, 0.3, 0.2), metadata=_UNIT_RANGE)
    kappa: int | None = field(default=None, metadata={"min": 1, "max": MAX_KAPPA})


def check_grasp(part: Part, path: str) -> Part:
    """``part`` if the gripper can hold it.

    Raises:
        ConfigError: one line naming the value and the limit: a jaw opening over the
            gripper's opening, or a grasp width not below the jaw opening.
    """
    if part.jaw_opening_mm > GRIPPER_MAX_OPENING_MM:
        raise ConfigError(f"{path}.jaw_opening_mm: {part.jaw_opening_mm:g} mm is over the "
                          f"gripper's {GRIPPER_MAX_OPENING_MM:g} mm opening")
    if part.grasp_width_mm >= part.jaw_opening_mm:
        raise ConfigError(f"{path}.grasp_width_mm: {part.grasp_width_mm:g} mm is not below the "
                          f"jaw opening, {part.jaw_opening_mm:g} mm: the jaws would not pass it")
    return part


def part_from_declaration(name: str, decl: PartDeclaration, base_dir: Path | None,
                          path: str) -> Part:
    """The catalogue entry a declaration makes, its mesh path made absolute (relative to
    ``base_dir``, the config file's folder; the working folder without one).

    Raises:
        ConfigError: geometry the gripper cannot grasp (``check_grasp``).
    """
    jaw = (decl.jaw_opening_mm if decl.jaw_opening_mm is not None
           else decl.grasp_width_mm + 2.0 * JAW_CLEARANCE_MM)
    mesh = None
    if decl.mesh is not None:
        mesh_path = Path(decl.mesh).expanduser()
        if not mesh_path.is_absolute():
            mesh_path = (base_dir or Path.cwd()) / mesh_path
        mesh = str(mesh_path.absolute())
    part = Part(name, decl.kappa, decl.grasp_width_mm, decl.grip_below_top_mm, jaw,
                decl.mass_g, decl.material, decl.color, mesh, decl.scale)
    return check_grasp(part, path)


def declare(data: Any, base_dir: Path | None = None, *, path: str = "parts",
            taken: Mapping[str, Part] | None = None) -> dict[str, Part]:
    """The parts a ``parts:`` section declares, in its order.

    Args:
        data: the section (a mapping of part names to declarations; None: no parts).
        base_dir: the folder relative mesh paths are taken from (the config file's).
        path: the section's key path, for messages.
        taken: parts already known, whose names a declaration may not take.

    Raises:
        ConfigError: one line naming the key: a bad name, a name already taken, an unknown
            key, a missing grasp width, a value out of range or ungraspable geometry.
    """
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of part names to parts, got "
                          f"{type(data).__name__}")
    declared: dict[str, Part] = {}
    for name, entry in data.items():
        key = f"{path}.{name}"
        if not isinstance(name, str) or not PART_NAME.fullmatch(name) or name in RESERVED_NAMES:
            raise ConfigError(f"{key}: a part's name is 1-32 lower-case letters, digits or _, "
                              f"starting with a letter, and not {' or '.join(RESERVED_NAMES)}")
        if taken is not None and name in taken:
            raise ConfigError(f"{key}: the name of a built-in part; choose another")
        if isinstance(entry, dict) and "grasp_width_mm" not in entry:
            raise ConfigError(f"{key}.grasp_width_mm: required (the finger width when held)")
        decl = from_mapping(PartDeclaration, entry, key)
        declared[name] = part_from_declaration(name, decl, base_dir, key)
    return declared


class Catalogue(Mapping[str, Part]):
    """The parts a cell knows, by name: the built-in ones, then the config's, in order."""

    def __init__(self, parts: Mapping[str, Part]) -> None:
        self._parts = dict(parts)

    def __getitem__(self, kind: str) -> Part:
        return self._parts[kind]

    def __iter__(self) -> Iterator[str]:
        return iter(self._parts)

    def __len__(self) -> int:
        return len(self._parts)

    def __hash__(self) -> int:
        return hash(tuple(self._parts.items()))

    def __repr__(self) -> str:
        return f"Catalogue({', '.join(self._parts)})"

    def unknown(self, kind: str) -> ConfigError:
        """The one-line error for a part this catalogue does not know."""
        return ConfigError(f"unknown part {kind[:40]!r} (known parts: {', '.join(self)}; "
                           f"{DECLARE_HINT})")

    def check(self, kind: str) -> str:
        """``kind`` if the catalogue knows it.

        Raises:
            ConfigError: an unknown part (the message lists the known ones and where to
                declare a new one).
        """
        if kind not in self._parts:
            raise self.unknown(kind)
        return kind

    def part(self, kind: str) -> Part:
        """The entry of ``kind``.

        Raises:
            ConfigError: an unknown part (as ``check``).
        """
        return self._parts[self.check(kind)]

    def with_declared(self, declared: Mapping[str, Part]) -> Catalogue:
        """This catalogue and the ``declared`` parts after it."""
        return Catalogue({**self._parts, **declared}) if declared else self


def _builtin() -> Catalogue:
    data = load_yaml_file(BUILTIN_FILE)
    return Catalogue(declare(data, path=f"{BUILTIN_FILE.name}"))


PARTS: Catalogue = _builtin()
