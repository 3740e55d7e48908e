"""Scripted 3D-mouse input for the Magellan emulator: motions held for a time, button changes.

A script file is a YAML list under ``steps``; each step is one of::

    steps:
      - {axes: [120, 0, 0, 0, 0, 0], duration_s: 1.5}   # x, y, z, rx, ry, rz as clients see them
      - {button: 0, pressed: true}
      - {button: 0, pressed: false}

After the last step the cap springs back (all axes 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from drivers.core.typed_config import from_mapping, load_yaml_file
from sim_backend.emulators.magellan.protocol import AXIS_MAX, AXIS_MIN, BUTTON_COUNT


@dataclass(frozen=True)
class Motion:
    """Hold the cap at ``axes`` (client-side x, y, z, rx, ry, rz counts) for ``duration_s``."""

    axes: tuple[int, int, int, int, int, int] = field(
        metadata={"min": AXIS_MIN, "max": AXIS_MAX})
    duration_s: float = field(default=0.0, metadata={"min": 0.0})


@dataclass(frozen=True)
class Button:
    """Put ``button`` (0..11) down (``pressed``) or up."""

    button: int = field(metadata={"min": 0, "max": BUTTON_COUNT - 1})
    pressed: bool = True


Step = Motion | Button


@dataclass(frozen=True)
class Script:
    steps: tuple[Step, ...] = ()


def click(button: int) -> list[Step]:
    """Press and release ``button``."""
    return [Button(button, True), Button(button, False)]


def load_script(path: str | Path) -> list[Step]:
    """Read a script file (strictly: unknown keys and bad values fail with their path)."""
    return list(from_mapping(Script, load_yaml_file(path), str(path)).steps)
