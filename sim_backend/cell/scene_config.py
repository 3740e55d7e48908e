"""The ``scene:`` section of the root config (the simulated cell) and the simulated arm's options.

Frozen dataclasses loaded with ``drivers.core.typed_config.from_mapping``: unknown keys, wrong types
and out-of-range values fail at load with the key's full path (``scene.lighting.preset: ...``).
Defaults reproduce the paper's standard conditions: the yellow cube on a grey table, good light.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, load_yaml_file

# Keep in step with the parts catalogue, drivers.core.parts.PARTS (a test checks it).
PartKind = Literal["cube", "nut", "ledge", "screw"]
TableTexture = Literal["none", "wood", "checker", "noise"]
LightPreset = Literal["good", "poor", "dim", "side"]

_UNIT_RANGE = {"min": 0.0, "max": 1.0}


@dataclass(frozen=True)
class ObjectConfig:
    """The part to grasp: its kind, colour (RGB 0..1) and where it lies on the table.

    x_mm, y_mm: position in the robot's base frame; phi_deg: rotation about the vertical.
    The ranges keep the pre-grasp pose, 30 mm around it at any rotation and the grasp itself
    within the arm's reach.
    """

    kind: PartKind = "cube"
    color: tuple[float, float, float] = field(default=(1.0, 0.85, 0.1), metadata=_UNIT_RANGE)
    x_mm: float = field(default=300.0, metadata={"min": 220.0, "max": 340.0})
    y_mm: float = field(default=0.0, metadata={"min": -100.0, "max": 100.0})
    phi_deg: float = field(default=0.0, metadata={"min": -360.0, "max": 360.0})


@dataclass(frozen=True)
class TableConfig:
    """The table top: colour (RGB 0..1) and surface pattern."""

    color: tuple[float, float, float] = field(default=(0.5, 0.5, 0.5), metadata=_UNIT_RANGE)
    texture: TableTexture = "none"


@dataclass(frozen=True)
class LightingConfig:
    """Light: a preset, with any of the explicit values overriding it.

    preset: good (bright, from above), dim (the same, dimmed), side (one sideward lamp, hard
    cast shadows), poor (dimmed light plus one sideward lamp with hard cast shadows);
    ambient / diffuse / specular: the renderer's coefficients; direction: towards the lamp
    (world frame, any length, must point up); shadows: cast shadows on/off;
    shadow_strength: how much of the lamp's light a shadow takes away (1 = hard, black);
    color: the lamp's RGB colour.
    """

    preset: LightPreset = "good"
    ambient: float | None = field(default=None, metadata={"min": 0.0, "max": 2.0})
    diffuse: float | None = field(default=None, metadata={"min": 0.0, "max": 2.0})
    specular: float | None = field(default=None, metadata={"min": 0.0, "max": 2.0})
    direction: tuple[float, float, float] | None = None
    shadows: bool | None = None
    shadow_strength: float | None = field(default=None, metadata=_UNIT_RANGE)
    color: tuple[float, float, float] | None = field(default=None,
                                                     metadata={"min": 0.0, "max": 2.0})

    def __post_init__(self) -> None:
        if self.direction is not None:
            if math.hypot(*self.direction) < 1e-9:
                raise ValueError(f"direction: must not be zero, got {list(self.direction)}")
            if self.direction[2] <= 0.0:
                raise ValueError("direction: points from the table towards the lamp and must "
                                 f"point upwards (z > 0), got {list(self.direction)}")


@dataclass(frozen=True)
class OccluderConfig:
    """A flat piece lying on the part, hiding ``coverage`` (0..1) of it from above."""

    enabled: bool = False
    coverage: float = field(default=0.0, metadata={"min": 0.0, "max": 0.9})


@dataclass(frozen=True)
class CameraConfig:
    """The hand camera: noise_std is the standard deviation of pixel noise in grey levels."""

    noise_std: float = field(default=2.0, metadata={"min": 0.0, "max": 50.0})


@dataclass(frozen=True)
class ClutterConfig:
    """Other parts lying around the target (not touching it, clear of the gripper)."""

    count: int = field(default=0, metadata={"min": 0, "max": 8})


@dataclass(frozen=True)
class SceneConfig:
    """Config section ``scene``: everything the simulated cell shows."""

    object: ObjectConfig = ObjectConfig()
    table: TableConfig = TableConfig()
    lighting: LightingConfig = LightingConfig()
    occluder: OccluderConfig = OccluderConfig()
    camera: CameraConfig = CameraConfig()
    clutter: ClutterConfig = ClutterConfig()


@dataclass(frozen=True)
class SimArmConfig:
    """Options of the simulated arm (``arm: {type: sim, ...}``).

    repeatability_mm / repeatability_deg: bound of the random error of every executed pose
    (position, and rotation about a random axis); contact_stiffness_n_per_mm: spring constant
    of the contact model behind the wrist sensor; max_penetration_mm: a move that would push
    the gripper deeper than this into the table or a part is refused (the real arm would stall
    or break something); wrench_noise_n: standard deviation of the sensor's force noise (torque
    noise is a tenth of it in N*m).
    """

    repeatability_mm: float = field(default=0.02, metadata={"min": 0.0, "max": 5.0})
    repeatability_deg: float = field(default=0.02, metadata={"min": 0.0, "max": 5.0})
    contact_stiffness_n_per_mm: float = field(default=8.0, metadata={"min": 0.0,
                                                                     "exclusive_min": True})
    max_penetration_mm: float = field(default=5.0, metadata={"min": 0.0, "exclusive_min": True})
    wrench_noise_n: float = field(default=0.02, metadata={"min": 0.0, "max": 1.0})


def load_scene(path: str | Path) -> SceneConfig:
    """The ``scene`` section of the root config file ``path`` (defaults where absent).

    Other top-level sections are not looked at here. Raises ConfigError naming the file and
    the key's full path.
    """
    data = load_yaml_file(path)
    try:
        return from_mapping(SceneConfig, data.get("scene"), "scene")
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc
