"""From 3D-mouse deflection to tool-frame jog steps: deadband, scaling, axis mapping, timing.

Sign conventions:

- Mouse axes are spacenavd's, as its clients receive them (for a serial Magellan the daemon
  has already negated Z and rZ). libspnav's examples read them as x right, y up, z away from
  the user, each rotation right-handed about its axis. That is not verified on a device here,
  so every mapping is configuration (``JogConfig``), and the Magellan emulator scripts are
  written in these client-side values.
- A tool step (``drivers.core.pose.ToolStep``): dx_mm / dy_mm along the tool's x / y axes, dz_mm
  along the approach axis (positive = towards the object), dphi_deg right-handed about the
  approach axis.
- The default mapping assumes the tool points down with its x axis to the user's right:
  then the tool's y axis points towards the user and its approach axis down, so dx = x,
  dy = -z, dz = -y (pushing the cap down moves towards the object) and dphi = -ry (a twist
  about "up" is the opposite twist about the downward approach axis).

Shaping: ``|v| <= deadband`` is zero; beyond it the deflection is measured from the deadband
and scaled linearly so that ``full_scale`` counts give the maximum speed (clipped there).

Timing: spacenavd sends a motion event only when the values change, and an event's
``period_ms`` is how long the *previous* deflection was held. ``JogIntegrator.on_motion``
therefore returns the previous deflection's speed times this event's period, then takes on
the new deflection. While no event comes (the cap held still), ``hold(elapsed_s)`` keeps
jogging at the current deflection; the next event's period is reduced by what ``hold``
already applied, so no time is counted twice. Each event's remaining period and each
``hold`` interval is clamped to ``max_period_ms``, so a stall never turns into a long jump.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from drivers.core.pose import ToolStep
from drivers.spacenav.config import JogConfig
from drivers.spacenav.events import MotionEvent


@dataclass(frozen=True)
class ToolRate:
    """A jog speed in the tool frame: mm/s along x, y, approach; deg/s about the approach."""

    dx_mm_s: float = 0.0
    dy_mm_s: float = 0.0
    dz_mm_s: float = 0.0
    dphi_deg_s: float = 0.0

    @property
    def is_zero(self) -> bool:
        return not (self.dx_mm_s or self.dy_mm_s or self.dz_mm_s or self.dphi_deg_s)

    def over(self, duration_s: float) -> ToolStep:
        """The step made by moving at this rate for ``duration_s``."""
        return ToolStep(self.dx_mm_s * duration_s, self.dy_mm_s * duration_s,
                        self.dz_mm_s * duration_s, self.dphi_deg_s * duration_s)


def shaped(value: int, config: JogConfig) -> float:
    """Deflection in [-1, 1] after the deadband (0 inside it)."""
    magnitude = abs(value) - config.deadband
    if magnitude <= 0:
        return 0.0
    fraction = min(1.0, magnitude / (config.full_scale - config.deadband))
    return math.copysign(fraction, value)


def tool_rate(event: MotionEvent, config: JogConfig) -> ToolRate:
    """The tool-frame speed one motion event asks for."""
    def component(name: str, max_speed: float) -> float:
        source = config.axis_source(name)
        if source is None:
            return 0.0
        axis, sign = source
        return sign * shaped(event.axis(axis), config) * max_speed

    return ToolRate(component("dx_mm", config.max_speed_mm_s),
                    component("dy_mm", config.max_speed_mm_s),
                    component("dz_mm", config.max_speed_mm_s),
                    component("dphi_deg", config.max_speed_deg_s))


class JogIntegrator:
    """Turns the stream of motion events into tool steps (see the module docstring)."""

    def __init__(self, config: JogConfig) -> None:
        self.config = config
        self.rate = ToolRate()
        self._held_s = 0.0

    @property
    def moving(self) -> bool:
        return not self.rate.is_zero

    def on_motion(self, event: MotionEvent) -> ToolStep:
        """The previous deflection over this event's period; then take on the new one."""
        remaining_s = max(0.0, event.period_ms / 1000.0 - self._held_s)
        step = self.rate.over(min(remaining_s, self.config.max_period_ms / 1000.0))
        self.rate = tool_rate(event, self.config)
        self._held_s = 0.0
        return step

    def hold(self, elapsed_s: float) -> ToolStep:
        """Keep the current deflection for ``elapsed_s`` more (no event came meanwhile)."""
        applied_s = min(max(0.0, elapsed_s), self.config.max_period_ms / 1000.0)
        self._held_s += applied_s
        return self.rate.over(applied_s)

    def stop(self) -> None:
        """Forget the deflection (e.g. after the arm refused a step); the next event resumes."""
        self.rate = ToolRate()
        self._held_s = 0.0
