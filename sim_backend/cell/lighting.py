"""Light presets and the resolved light the renderer uses.

The renderer (PyBullet's TinyRenderer) shades a pixel as
``albedo * (ambient + diffuse * max(0, n . l) * color)`` (plus specular); cast shadows are
added by ``sim_backend.cell.shadows``, which removes ``shadow_strength`` of the lamp's share where
something stands between the lamp and the surface.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim_backend.cell.scene_config import LampConfig, LightingConfig


@dataclass(frozen=True)
class Light:
    """A fully specified light: coefficients, unit direction towards the lamp, colour, shadows.

    shadow_strength 0 means no cast shadows. lamps: further lamps, each a Light of its own
    with no ambient or specular share (the renderer shades each lamp in a pass of its own and
    the passes add up).
    """

    ambient: float
    diffuse: float
    specular: float
    direction: tuple[float, float, float]
    color: tuple[float, float, float]
    shadow_strength: float
    lamps: tuple[Light, ...] = ()

    @property
    def casts_shadows(self) -> bool:
        return self.shadow_strength > 0.0


def _unit(v: tuple[float, float, float]) -> tuple[float, float, float]:
    n = math.sqrt(sum(c * c for c in v))
    return (v[0] / n, v[1] / n, v[2] / n)


# Sideward lamp: low (about 25 deg above the table), from the robot's left.
_SIDE_DIRECTION = (0.25, 1.0, 0.5)
# Room light: ceiling lamps straight above the cell, as a well-lit cell has. Light from above
# shades the part the same way whatever its heading; a tilted key light lights one side face
# more than the others, which moves the binarised blob by pixels as the part turns.
_ROOM_DIRECTION = (0.0, 0.0, 1.0)

PRESETS: dict[str, Light] = {
    "good": Light(ambient=0.5, diffuse=0.5, specular=0.0, direction=_unit(_ROOM_DIRECTION),
                  color=(1.0, 1.0, 1.0), shadow_strength=0.3),
    "dim": Light(ambient=0.2, diffuse=0.25, specular=0.0, direction=_unit(_ROOM_DIRECTION),
                 color=(1.0, 1.0, 1.0), shadow_strength=0.3),
    "side": Light(ambient=0.3, diffuse=0.95, specular=0.0, direction=_unit(_SIDE_DIRECTION),
                  color=(1.0, 0.97, 0.9), shadow_strength=0.9),
    "poor": Light(ambient=0.1, diffuse=0.55, specular=0.0, direction=_unit(_SIDE_DIRECTION),
                  color=(1.0, 0.95, 0.85), shadow_strength=0.95),
}


def resolve_light(config: LightingConfig) -> Light:
    """The preset named in ``config`` with every explicitly given value put in its place."""
    base = PRESETS[config.preset]
    strength = base.shadow_strength if config.shadow_strength is None else config.shadow_strength
    if config.shadows is False:
        strength = 0.0
    return Light(
        ambient=base.ambient if config.ambient is None else config.ambient,
        diffuse=base.diffuse if config.diffuse is None else config.diffuse,
        specular=base.specular if config.specular is None else config.specular,
        direction=base.direction if config.direction is None else _unit(config.direction),
        color=base.color if config.color is None else config.color,
        shadow_strength=strength,
        lamps=tuple(_lamp(lamp, shadows=config.shadows is not False) for lamp in config.lamps),
    )


def _lamp(config: LampConfig, shadows: bool) -> Light:
    """A further lamp as a Light of its own: its diffuse light only."""
    return Light(ambient=0.0, diffuse=config.diffuse, specular=0.0,
                 direction=_unit(config.direction), color=config.color,
                 shadow_strength=config.shadow_strength if shadows else 0.0)


def kelvin_rgb(kelvin: float) -> tuple[float, float, float]:
    """The RGB colour (brightest channel 1) of a black body at ``kelvin`` (1,000-40,000 K), by
    Tanner Helland's fit to the CIE 1964 colour matching functions: 2,700 K is a warm
    incandescent lamp, 6,500 K daylight."""
    t = min(max(kelvin, 1000.0), 40000.0) / 100.0
    red = 255.0 if t <= 66 else 329.698727446 * (t - 60.0) ** -0.1332047592
    green = (99.4708025861 * math.log(t) - 161.1195681661 if t <= 66
             else 288.1221695283 * (t - 60.0) ** -0.0755148492)
    blue = (255.0 if t >= 66 else 0.0 if t <= 19
            else 138.5177312231 * math.log(t - 10.0) - 305.0447927307)
    rgb = [min(max(c, 0.0), 255.0) for c in (red, green, blue)]
    top = max(rgb)
    return (rgb[0] / top, rgb[1] / top, rgb[2] / top)
