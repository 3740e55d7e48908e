"""Magellan emulator scripts that jog the tool by a known tool-frame step (teach-in tests)."""

from __future__ import annotations

import math

from drivers.core.pose import ToolStep
from drivers.spacenav import JogConfig
from sim_backend.emulators.magellan.script import Motion, Step

AXES = ("x", "y", "z", "rx", "ry", "rz")
REST = (0, 0, 0, 0, 0, 0)


def deflection_counts(fraction: float, jog: JogConfig) -> int:
    """Device counts whose shaped deflection is closest to ``fraction`` of full scale."""
    return int(round(jog.deadband + fraction * (jog.full_scale - jog.deadband)))


def shaped_fraction(counts: int, jog: JogConfig) -> float:
    """The fraction of full speed ``counts`` give (as ``drivers.spacenav.jog.shaped``)."""
    return (abs(counts) - jog.deadband) / (jog.full_scale - jog.deadband)


def jog_script(step: ToolStep, jog: JogConfig, fraction: float = 0.25,
               rest_s: float = 0.2) -> list[Step]:
    """Deflect one mapped mouse axis per component of ``step`` at ``fraction`` of full speed
    for as long as that component needs, letting the cap rest after each.

    Translations come first, the turn last: that is how a tool-frame step applies (translate
    in the start frame, then turn), so the jogs add up to ``step`` exactly.
    """
    counts = deflection_counts(fraction, jog)
    script: list[Step] = []
    for component, max_speed in (("dx_mm", jog.max_speed_mm_s), ("dy_mm", jog.max_speed_mm_s),
                                 ("dz_mm", jog.max_speed_mm_s),
                                 ("dphi_deg", jog.max_speed_deg_s)):
        value = getattr(step, component)
        source = jog.axis_source(component)
        if abs(value) < 1e-9 or source is None:
            continue
        axis, sign = source
        axes = list(REST)
        axes[AXES.index(axis)] = int(math.copysign(counts, value * sign))
        duration_s = abs(value) / (shaped_fraction(counts, jog) * max_speed)
        script += [Motion(tuple(axes), duration_s), Motion(REST, rest_s)]
    return script
