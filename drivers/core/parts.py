"""The parts catalogue: what the cell knows of each part of the toy construction set.

The real cell reads it (teach-in takes a part's symmetry and grasp geometry from here) and so
does the simulated cell (which adds each part's mesh, ``sim_backend.cell.objects``), so both
agree on every figure. kappa is the part's rotational symmetry about the vertical as the hand
camera sees it (the image repeats every 360/kappa deg), which is also the period of its grasp:
  cube 4: a cube (same from above after a quarter turn);
  nut 6: hexagonal;
  ledge 2: a bar with three holes (same after a half turn);
  screw 1: a round-headed screw lying on its side: the head is at one end, so its top view only
  repeats after a full turn (the shank alone would allow a half turn, the image does not).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from drivers.core.errors import ConfigError

# The parallel-jaw gripper's full opening (mm); before a grasp the jaws open to the part's
# ``jaw_opening_mm``.
GRIPPER_MAX_OPENING_MM = 40.0
# Where the pre-grasp (taught) pose holds the fingertips above the part's top (mm): the grasp
# descends this plus the part's grip depth.
APPROACH_HEIGHT_MM = 35.0


@dataclass(frozen=True)
class Part:
    """One kind of part.

    Attributes:
        kind: the part's name (``cube``, ``nut``, ``ledge``, ``screw``).
        kappa: rotational symmetry about the vertical (see the module docstring).
        grasp_width_mm: finger width when the part is held (across the jaws).
        grip_below_top_mm: how far below the part's top the fingertips go to grip it.
        jaw_opening_mm: how wide the jaws open before the descent: a little wider than the
            part (1.5 mm either side), which sets the grasp's tolerance (the paper's cube is
            "little smaller than the open gripper"; 33 mm for our 30 mm cube, whose 6 mm
            rounded edges would let 34 mm jaws pass it turned by 14.6 deg: ``finepos
            grasp-sweep`` measures it).
        mass_g: the part's mass (the weight the wrist sensor feels while it is held, which
            the grasp check measures; the simulated part's dynamic mass).
        material: what the part is made of (the simulated part's friction).
        color: the part's usual colour (RGB, 0..1).
    """

    kind: str
    kappa: int
    grasp_width_mm: float
    grip_below_top_mm: float
    jaw_opening_mm: float
    mass_g: float
    material: str
    color: tuple[float, float, float]

    @property
    def weight_n(self) -> float:
        """The part's weight (N): what the wrist sensor feels while it is held."""
        return self.mass_g * 9.81e-3

    @property
    def grasp_depth_mm(self) -> float:
        """How far the grasp descends along the approach axis from the pre-grasp pose."""
        return APPROACH_HEIGHT_MM + self.grip_below_top_mm


CUBE_EDGE_MM = 30.0
SCREW_SHANK_RADIUS_MM = 5.5

# A part's name as a config key takes it (``controller.part``, ``scene.object.kind``); keep in
# step with PARTS (tests/sim_backend/cell/test_scene_config.py checks it).
PartKind = Literal["cube", "nut", "ledge", "screw"]

PARTS: dict[str, Part] = {
    "cube": Part("cube", kappa=4, grasp_width_mm=CUBE_EDGE_MM, grip_below_top_mm=15.0,
                 jaw_opening_mm=33.0, mass_g=15.0, material="wood", color=(1.0, 0.85, 0.1)),
    "nut": Part("nut", kappa=6, grasp_width_mm=24.0, grip_below_top_mm=7.0,
                jaw_opening_mm=27.0, mass_g=5.0, material="wood", color=(0.85, 0.2, 0.15)),
    "ledge": Part("ledge", kappa=2, grasp_width_mm=22.0, grip_below_top_mm=5.0,
                  jaw_opening_mm=25.0, mass_g=8.0, material="wood", color=(0.2, 0.55, 0.25)),
    "screw": Part("screw", kappa=1, grasp_width_mm=2.0 * SCREW_SHANK_RADIUS_MM,
                  grip_below_top_mm=16.5, jaw_opening_mm=14.0, mass_g=4.0, material="wood",
                  color=(0.95, 0.45, 0.1)),
}


def part(kind: str) -> Part:
    """The catalogue's entry for ``kind``.

    Raises:
        ConfigError: no such part.
    """
    try:
        return PARTS[kind]
    except KeyError:
        raise ConfigError(f"part: must be one of {' | '.join(PARTS)}, got {kind!r}") from None
