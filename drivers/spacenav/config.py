"""The 3D mouse's jog mapping (config ``controller.teach.jog``, see controller.teach.spacenav).

Example (YAML)::

    controller:
      teach:
        jog:
          deadband: 15             # counts
          full_scale: 350          # counts at full deflection
          max_speed_mm_s: 10.0
          max_speed_deg_s: 10.0
          max_period_ms: 200
          dx_mm: x                 # tool x  <- mouse x (cap pushed right)
          dy_mm: -z                # tool y  <- mouse -z (cap pulled towards the user)
          dz_mm: -y                # tool z (approach, towards the object) <- cap pushed down
          dphi_deg: -ry            # about the approach axis <- twist, see drivers.spacenav.jog
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

AXIS_NAMES = ("x", "y", "z", "rx", "ry", "rz")
_AXIS_SPEC = re.compile(r"(-?)(x|y|z|rx|ry|rz)|none")
_POSITIVE = {"min": 0.0, "exclusive_min": True}


@dataclass(frozen=True)
class JogConfig:
    """How mouse deflection becomes tool-frame jog speed (see ``drivers.spacenav.jog``).

    deadband: counts; a smaller |value| counts as zero, larger ones are measured from it;
    full_scale: counts of a full deflection (maps to the maximum speed; more is clipped);
    max_speed_mm_s / max_speed_deg_s: jog speed at full deflection;
    max_period_ms: longest time one event's deflection is applied for (a stale event after a
    pause must not become a long jump);
    dx_mm, dy_mm, dz_mm, dphi_deg: the mouse axis driving each tool-step component: one of
    x, y, z, rx, ry, rz, optionally negated with ``-``, or ``none``.
    """

    deadband: int = field(default=15, metadata={"min": 0})
    full_scale: float = field(default=350.0, metadata=_POSITIVE)
    max_speed_mm_s: float = field(default=10.0, metadata={"min": 0.0})
    max_speed_deg_s: float = field(default=10.0, metadata={"min": 0.0})
    max_period_ms: float = field(default=200.0, metadata=_POSITIVE)
    dx_mm: str = "x"
    dy_mm: str = "-z"
    dz_mm: str = "-y"
    dphi_deg: str = "-ry"

    def __post_init__(self) -> None:
        if self.full_scale <= self.deadband:
            raise ValueError(f"full_scale ({self.full_scale}) must exceed deadband "
                             f"({self.deadband})")
        for name in ("dx_mm", "dy_mm", "dz_mm", "dphi_deg"):
            spec = getattr(self, name)
            if not _AXIS_SPEC.fullmatch(spec):
                raise ValueError(f"{name}: {spec!r} is not an axis (one of "
                                 f"{', '.join(AXIS_NAMES)}, optionally with '-', or none)")

    def axis_source(self, component: str) -> tuple[str, float] | None:
        """(mouse axis, sign) driving ``component`` (``dx_mm``...), or None if unmapped."""
        spec = getattr(self, component)
        if spec == "none":
            return None
        return spec.lstrip("-"), (-1.0 if spec.startswith("-") else 1.0)
