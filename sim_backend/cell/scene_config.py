"""The ``scene:`` section of the root config (the simulated cell) and the simulated arm's options.

Frozen dataclasses loaded with ``drivers.core.typed_config.from_mapping``: unknown keys, wrong types
and out-of-range values fail at load with the key's full path (``scene.lighting.preset: ...``).
Defaults reproduce the paper's standard conditions: the yellow cube on a grey table, good light.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from drivers.core import parts as catalogue
from drivers.core.errors import ConfigError
from drivers.core.timing import TimingMode
from drivers.core.typed_config import from_mapping, load_yaml_file

TableTexture = Literal["none", "wood", "checker", "noise"]
LightPreset = Literal["good", "poor", "dim", "side"]

_UNIT_RANGE = {"min": 0.0, "max": 1.0}
MAX_EXTRA_LAMPS = 4  # each further lamp costs a render and a shadow map per frame


@dataclass(frozen=True)
class ObjectConfig:
    """The part to grasp: its kind, colour (RGB 0..1) and where it lies on the table.

    kind: a built-in part (cube | nut | ledge | screw) or one the cell config declares under
    ``parts``; color: the colour the part is painted in (unset: the part's own ``color``).

    x_mm, y_mm: position in the robot's base frame; phi_deg: rotation about the vertical.
    The ranges keep the pre-grasp pose, 30 mm around it at any rotation and the grasp itself
    within the arm's reach.
    """

    kind: str = "cube"
    color: tuple[float, float, float] | None = field(default=None, metadata=_UNIT_RANGE)
    x_mm: float = field(default=300.0, metadata={"min": 220.0, "max": 340.0})
    y_mm: float = field(default=0.0, metadata={"min": -100.0, "max": 100.0})
    phi_deg: float = field(default=0.0, metadata={"min": -360.0, "max": 360.0})


@dataclass(frozen=True)
class TableConfig:
    """The table top: colour (RGB 0..1) and surface pattern."""

    color: tuple[float, float, float] = field(default=(0.5, 0.5, 0.5), metadata=_UNIT_RANGE)
    texture: TableTexture = "none"


@dataclass(frozen=True)
class LampConfig:
    """A further lamp beside the preset's: it adds its own diffuse light and casts its own
    shadows (no ambient light of its own).

    direction: towards the lamp (world frame, any length, must point up); diffuse: the
    renderer's diffuse coefficient; color: the lamp's RGB colour; shadow_strength: how much of
    this lamp's light a shadow takes away (1 = hard, black).
    """

    direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    diffuse: float = field(default=0.5, metadata={"min": 0.0, "max": 2.0})
    color: tuple[float, float, float] = field(default=(1.0, 1.0, 1.0),
                                              metadata={"min": 0.0, "max": 2.0})
    shadow_strength: float = field(default=0.5, metadata=_UNIT_RANGE)

    def __post_init__(self) -> None:
        _check_direction(self.direction)


def _check_direction(direction: tuple[float, float, float]) -> None:
    if math.hypot(*direction) < 1e-9:
        raise ValueError(f"direction: must not be zero, got {list(direction)}")
    if direction[2] <= 0.0:
        raise ValueError("direction: points from the table towards the lamp and must "
                         f"point upwards (z > 0), got {list(direction)}")


@dataclass(frozen=True)
class LightingConfig:
    """Light: a preset, with any of the explicit values overriding it.

    preset: good (bright, from above), dim (the same, dimmed), side (one sideward lamp, hard
    cast shadows), poor (dimmed light plus one sideward lamp with hard cast shadows);
    ambient / diffuse / specular: the renderer's coefficients; direction: towards the lamp
    (world frame, any length, must point up); shadows: cast shadows on/off;
    shadow_strength: how much of the lamp's light a shadow takes away (1 = hard, black);
    color: the lamp's RGB colour; lamps: further lamps, each with its own direction, light,
    colour and shadows (``LampConfig``).
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
    lamps: tuple[LampConfig, ...] = ()

    def __post_init__(self) -> None:
        if self.direction is not None:
            _check_direction(self.direction)
        if len(self.lamps) > MAX_EXTRA_LAMPS:
            raise ValueError(f"lamps: at most {MAX_EXTRA_LAMPS} further lamps, got "
                             f"{len(self.lamps)}")


@dataclass(frozen=True)
class OccluderConfig:
    """A card (120 mm long) lying over one end of the part (the seed picks which), leaning from
    the part to the table; its inner end lies where it hides ``coverage`` (0..1) of the
    part's length as the hand camera sees it from the pre-grasp pose. Over the end nearer
    the camera it also hides that end's side faces, so more."""

    enabled: bool = False
    coverage: float = field(default=0.0, metadata={"min": 0.0, "max": 0.9})


CameraPreset = Literal["realistic", "ideal"]


@dataclass(frozen=True)
class LensConfig:
    """The lens (None: the camera preset's value; ``sim_backend.cell.optics`` resolves them).

    fov_deg: vertical field of view of the undistorted (pinhole) image; k1, k2 (radial) and
    p1, p2 (tangential): distortion coefficients exactly as OpenCV's camera model defines them,
    on normalised image coordinates; vignetting: the fraction of light lost in the image
    corners (0: none; falls off with the squared distance from the centre); blur_px: defocus,
    the standard deviation of a Gaussian blur in pixels.
    """

    fov_deg: float | None = field(default=None, metadata={"min": 20.0, "max": 100.0})
    k1: float | None = field(default=None, metadata={"min": -1.0, "max": 1.0})
    k2: float | None = field(default=None, metadata={"min": -1.0, "max": 1.0})
    p1: float | None = field(default=None, metadata={"min": -0.05, "max": 0.05})
    p2: float | None = field(default=None, metadata={"min": -0.05, "max": 0.05})
    vignetting: float | None = field(default=None, metadata={"min": 0.0, "max": 0.9})
    blur_px: float | None = field(default=None, metadata={"min": 0.0, "max": 5.0})


@dataclass(frozen=True)
class MountConfig:
    """How the camera sits on the gripper, as a change from the standard mount (zeros).

    tilt_deg: about the image's x axis (positive: looks further forward, away from the
    fingers); roll_deg: about the optical axis; pan_deg: about the image's y axis; offset_mm:
    the lens moved along the tool frame's x, y, z.
    """

    tilt_deg: float = field(default=0.0, metadata={"min": -30.0, "max": 30.0})
    roll_deg: float = field(default=0.0, metadata={"min": -30.0, "max": 30.0})
    pan_deg: float = field(default=0.0, metadata={"min": -30.0, "max": 30.0})
    offset_mm: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0),
                                                  metadata={"min": -30.0, "max": 30.0})


@dataclass(frozen=True)
class ExposureConfig:
    """Exposure and gain (None: the preset's value).

    auto: auto-exposure on (it follows a change of light over a few frames, as real ones do);
    target_grey: the mean grey level it aims for; speed: the fraction of the (logarithmic)
    brightness error it corrects per frame (1: at once); gain: the fixed exposure x gain
    factor when auto is off, the starting one when on; max_gain: the most the gain may reach
    (the exposure time first grows to 3 times the nominal one, ``optics.MAX_EXPOSURE``; the
    gain amplifies the noise with the signal).
    """

    auto: bool | None = None
    target_grey: float | None = field(default=None, metadata={"min": 10.0, "max": 240.0})
    speed: float | None = field(default=None, metadata={"min": 0.0, "max": 1.0,
                                                        "exclusive_min": True})
    gain: float | None = field(default=None, metadata={"min": 0.05, "max": 32.0})
    max_gain: float | None = field(default=None, metadata={"min": 1.0, "max": 32.0})


@dataclass(frozen=True)
class CameraConfig:
    """The hand camera: its optics and sensor, and how it is mounted (part of the cell).

    preset: ``realistic`` (a small industrial colour camera, see ``optics.REALISTIC``) or
    ``ideal`` (the distortion-free pinhole camera with only Gaussian noise: with all other
    values unset, the same image as before these options existed); any value given
    overrides the preset's. noise_std: read noise, grey levels at unit gain (in
    ``realistic`` shot noise comes on top); full_well_e: electrons a pixel holds (sets the
    shot noise; 0: none); gamma: the camera's output gamma (2.2: the renderer's tone curve
    kept; 1: linear output); bayer: a Bayer colour mosaic demosaiced into RGB; jpeg_quality:
    JPEG compression quality (0: none); pixel_samples: renderer samples per pixel side, their
    light averaged (a sensor pixel integrates the light over its area; 1: one point sample a
    pixel, every edge snapped to the pixel grid); sample_roll_deg: those samples' grid turned
    by this against the sensor's pixel rows (``realistic``: 7; 0: on the pixel grid, where an
    edge parallel to the rows moves in steps of 1 / pixel_samples px; see
    ``optics.LensGeometry``). mount: the change from the
    standard mount the cell is taught and trained with; test_mount: a different mount the
    cell is tested with (``finepos evaluate``: the camera knocked after training; None: the
    same).
    """

    preset: CameraPreset = "realistic"
    noise_std: float = field(default=2.0, metadata={"min": 0.0, "max": 50.0})
    lens: LensConfig = LensConfig()
    mount: MountConfig = MountConfig()
    test_mount: MountConfig | None = None
    exposure: ExposureConfig = ExposureConfig()
    bayer: bool | None = None
    jpeg_quality: int | None = field(default=None, metadata={"min": 0, "max": 100})
    gamma: float | None = field(default=None, metadata={"min": 1.0, "max": 3.0})
    full_well_e: float | None = field(default=None, metadata={"min": 0.0, "max": 1e6})
    pixel_samples: int | None = field(default=None, metadata={"min": 1, "max": 4})
    sample_roll_deg: float | None = field(default=None, metadata={"min": 0.0, "max": 45.0})

    def __post_init__(self) -> None:
        from sim_backend.cell.optics import resolve_camera  # the presets live with the optics

        resolve_camera(self)  # a lens that folds the image fails here, at load

    def at_test(self) -> CameraConfig:
        """The camera the cell is tested with: ``test_mount`` (if set) as its mount."""
        if self.test_mount is None:
            return self
        return dataclasses.replace(self, mount=self.test_mount, test_mount=None)


@dataclass(frozen=True)
class ClutterConfig:
    """Other parts lying around the target (not touching it, clear of the gripper)."""

    count: int = field(default=0, metadata={"min": 0, "max": 8})


@dataclass(frozen=True)
class SceneConfig:
    """Config section ``scene``: everything the simulated cell shows.

    timing: ``realistic`` (every action takes its modelled time from the root ``timing``
    section on the cell clock; see ``drivers.core.timing``) or ``ideal`` (instant).
    """

    timing: TimingMode = "realistic"
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
    of the contact model behind the wrist sensor; max_penetration_mm: a move into the table
    or a part collides and the arm stalls where the gripper is pushed this deep into it
    (pressing with stiffness x depth: 40 N by default; the force guards must stop it);
    wrench_noise_n: standard deviation of the sensor's force noise (torque noise is a tenth
    of it in N*m); grip_force_n: the force limit of the jaws' closing (each finger; a small
    pneumatic parallel gripper, a judgement); programs: the arm runs the grasp's guarded
    descent as one controller program stopped by the wrist sensor's monitor output, timed as
    the VAL driver's program path (``arm.programs`` of a VAL arm); false: every move is one
    command.
    """

    repeatability_mm: float = field(default=0.02, metadata={"min": 0.0, "max": 5.0})
    repeatability_deg: float = field(default=0.02, metadata={"min": 0.0, "max": 5.0})
    contact_stiffness_n_per_mm: float = field(default=8.0, metadata={"min": 0.0,
                                                                     "exclusive_min": True})
    max_penetration_mm: float = field(default=5.0, metadata={"min": 0.0, "exclusive_min": True})
    wrench_noise_n: float = field(default=0.02, metadata={"min": 0.0, "max": 1.0})
    grip_force_n: float = field(default=10.0, metadata={"min": 0.5, "max": 200.0})
    programs: bool = False


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


def load_parts(path: str | Path) -> catalogue.Catalogue:
    """The parts the root config file ``path`` knows: the built-in ones and those its
    ``parts`` section declares (relative mesh paths from the file's folder).

    Raises:
        ConfigError: naming the file and the key's full path.
    """
    data = load_yaml_file(path)
    try:
        declared = catalogue.declare(data.get("parts"), Path(path).parent,
                                     taken=catalogue.PARTS)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    return catalogue.PARTS.with_declared(declared)


def load_cell(path: str | Path | None) -> tuple[SceneConfig, catalogue.Catalogue]:
    """The scene and the parts of the root config file ``path`` (``load_scene``,
    ``load_parts``); without a file, the default scene and the built-in parts."""
    if not path:
        return SceneConfig(), catalogue.PARTS
    return load_scene(path), load_parts(path)
