"""The cell configuration file (``finepos.yaml``): every section, strictly typed.

Sections: ``arm``, ``camera``, ``wrench`` (backend ``type`` plus that backend's options, see
``controller.devices``), ``scene`` (the simulated cell), ``safety``, ``controller``,
``service`` (``finepos serve``), ``timing`` (the realistic cell's durations,
``drivers.core.timing``), ``parts`` (parts declared beside the built-in ones,
``drivers.core.parts``; a relative mesh path is taken from the file's folder). Unknown keys,
wrong types and out-of-range values fail at load with the full key path. With no file, every
default applies: the simulated cell, good light, the cube.

The perception settings and the loop's tuned keys are not in this file: they are the recipe
(``controller.recipe``), kept in the model file. A file that sets one is refused with a line
naming the key's home. ``FineposConfig.perception`` and the recipe keys of
``controller.loop`` hold the recipe a command runs with (``with_recipe``).

The ``scene`` section is the simulator's: it is read (into
``sim_backend.cell.scene_config.SceneConfig``, through ``controller.simulated``) only when a
device is simulated; on a real cell it stays as written (``controller.simulated.UnreadScene``),
for the emulators that read it from the file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from controller import simulated
from controller.devices import DeviceSection, parse_device_section
from controller.loop.grasp import GraspConfig
from controller.loop.positioning import LoopConfig
from controller.recipe import PerceptionConfig, Recipe, refuse_recipe_keys
from controller.service.config import ServiceConfig
from controller.teach.spacenav import TeachConfig
from drivers.core import parts as catalogue
from drivers.core.errors import ConfigError
from drivers.core.timing import TimingConfig
from drivers.core.typed_config import from_mapping, load_yaml_file
from drivers.safety import SafetyLimits

if TYPE_CHECKING:
    from sim_backend.cell.scene_config import SceneConfig


@dataclass(frozen=True)
class GridConfig:
    """One acquisition grid: displacements in [-a, a] x [-a, a] x [-b, b] on ``shape`` points.

    a_mm: the largest displacement along the tool's x and y; b_deg: the largest turn (None:
    180/kappa, the part's whole symmetry period); shape: grid points along x, y and the turn;
    staggered: each position takes its rotations shifted by another fraction of their
    spacing, so the grid shows nx * ny * nphi distinct rotations instead of nphi
    (``dataset.staggered_grid_offsets``).
    """

    a_mm: float = field(default=25.0, metadata={"min": 0.0})
    b_deg: float | None = field(default=None, metadata={"min": 0.0})
    shape: tuple[int, int, int] = field(default=(3, 3, 7), metadata={"min": 1})
    staggered: bool = False


@dataclass(frozen=True)
class Nn2GridConfig(GridConfig):
    """NN2's grid: as ``GridConfig``, with NN2's defaults (a = 5 mm, staggered), so a config
    that sets only some of its keys keeps the others."""

    a_mm: float = field(default=5.0, metadata={"min": 0.0})
    staggered: bool = True


@dataclass(frozen=True)
class AcquisitionConfig:
    """Config section ``controller.acquisition``.

    nn1 / nn2: the NN1 and NN2 training grids (the paper's, NN2's staggered); test_count: images
    in the random test set (``finepos acquire --set test``); taught_pose_frames: frames each
    grid set first takes at the taught pose itself, each after its own approach (the
    translation nets are pinned on them and both networks train on them,
    ``controller.teach.acquisition.acquire``).
    """

    nn1: GridConfig = GridConfig()
    nn2: Nn2GridConfig = Nn2GridConfig()
    test_count: int = field(default=50, metadata={"min": 1})
    taught_pose_frames: int = field(default=4, metadata={"min": 0})


@dataclass(frozen=True)
class PathsConfig:
    """Config section ``controller.paths``: where state, datasets, models and logs go.

    state_dir: one folder per taught part (``<part>/cell.json``, ``<part>/datasets/``,
    ``<part>/model-<system>.<suffix>``; ``controller.teach.state_folder``); log_dir: the
    iteration logs (one JSON record per look; the service's ``iterations.jsonl``).
    """

    state_dir: str = "state"
    log_dir: str = "runs"


@dataclass(frozen=True)
class ControllerConfig:
    """Config section ``controller``.

    part: the part this cell grasps: a built-in part (cube | nut | ledge | screw) or one
    declared under ``parts``; teach-in on a real cell takes its symmetry and grasp geometry
    from there. On the simulated cell the part on the table (``scene.object.kind``) is taught. The
    commands' ``--part`` (and a service job's ``part``) overrides both (``with_part``).
    """

    part: str = "cube"
    loop: LoopConfig = LoopConfig()
    grasp: GraspConfig = GraspConfig()
    acquisition: AcquisitionConfig = AcquisitionConfig()
    paths: PathsConfig = PathsConfig()
    teach: TeachConfig = TeachConfig()


@dataclass(frozen=True)
class FineposConfig:
    """The whole configuration: one field per section, the recipe in use (``perception`` and
    the recipe keys of ``controller.loop``), the parts it knows and the file it came from.

    scene: the simulated cell, a ``SceneConfig`` when a device is simulated (else the section
    unread, ``controller.simulated.UnreadScene``); parts: the built-in parts and those the
    ``parts`` section declares (``drivers.core.parts.Catalogue``).
    """

    arm: DeviceSection
    camera: DeviceSection
    wrench: DeviceSection
    scene: SceneConfig | simulated.UnreadScene = simulated.UnreadScene()
    safety: SafetyLimits = SafetyLimits()
    perception: PerceptionConfig = PerceptionConfig()
    controller: ControllerConfig = ControllerConfig()
    service: ServiceConfig = ServiceConfig()
    timing: TimingConfig = TimingConfig()
    parts: catalogue.Catalogue = field(default_factory=lambda: catalogue.PARTS)
    source: str = "<defaults>"


SECTIONS = ("arm", "camera", "wrench", "scene", "safety", "controller", "service", "timing",
            "parts")


def config_from_mapping(data: dict[str, Any], source: str = "<mapping>",
                        base_dir: Path | None = None) -> FineposConfig:
    """Validate a whole root mapping (e.g. parsed YAML) into a FineposConfig, with the default
    recipe. ``base_dir``: where a declared part's relative mesh path starts (the config file's
    folder; the working folder without one).

    Raises:
        ConfigError: one line naming the key: unknown, mistyped or out of range, a recipe
            key (its home named), a part the gripper cannot grasp, or ``controller.part``
            naming no known part.
    """
    refuse_recipe_keys(data)
    unknown = sorted(str(k) for k in data if k not in SECTIONS)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown section (allowed: {', '.join(SECTIONS)})")
    devices = {kind: parse_device_section(kind, data.get(kind))
               for kind in ("arm", "camera", "wrench")}
    known = catalogue.PARTS.with_declared(
        catalogue.declare(data.get("parts"), base_dir, taken=catalogue.PARTS))
    controller = from_mapping(ControllerConfig, data.get("controller"), "controller")
    try:
        known.check(controller.part)
    except ConfigError as exc:
        raise ConfigError(f"controller.part: {exc}") from None
    scene = simulated.scene_section(data.get("scene"),
                                    any(d.type == "sim" for d in devices.values()))
    if not isinstance(scene, simulated.UnreadScene) and scene.object.kind not in known:
        raise ConfigError(f"scene.object.kind: {known.unknown(scene.object.kind)}")
    return FineposConfig(
        **devices,
        scene=scene,
        safety=from_mapping(SafetyLimits, data.get("safety"), "safety"),
        controller=controller,
        service=from_mapping(ServiceConfig, data.get("service"), "service"),
        timing=from_mapping(TimingConfig, data.get("timing"), "timing"),
        parts=known,
        source=source,
    )


def load_config(path: str | Path | None) -> FineposConfig:
    """Load ``path`` (None: all defaults). Raises ConfigError naming the bad key."""
    if path is None:
        return config_from_mapping({}, "<defaults>")
    try:
        return config_from_mapping(load_yaml_file(path), str(path), Path(path).parent)
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from exc


def with_recipe(config: FineposConfig, recipe: Recipe) -> FineposConfig:
    """``config`` running ``recipe``: its perception settings and loop keys."""
    controller = dataclasses.replace(config.controller,
                                     loop=recipe.apply_loop(config.controller.loop))
    return dataclasses.replace(config, perception=recipe.perception, controller=controller)


def recipe_of(config: FineposConfig) -> Recipe:
    """The recipe ``config`` runs (what training writes into the model file)."""
    return Recipe(perception=config.perception, loop=config.controller.loop)


def is_simulated(config: FineposConfig) -> bool:
    """Whether any device is simulated, so the simulated cell (and its part) is built."""
    return any(getattr(config, kind).type == "sim" for kind in ("arm", "camera", "wrench"))


def cell_part(config: FineposConfig) -> str:
    """The part the cell is set up for: on the simulated cell the part on its table
    (``scene.object.kind``), on a real cell ``controller.part``."""
    return config.scene.object.kind if is_simulated(config) else config.controller.part


def with_part(config: FineposConfig, kind: str) -> FineposConfig:
    """``config`` set up for part ``kind``: ``controller.part``, and the simulated table's part
    (``scene.object.kind``; its placement and colour stay the scene's; an unread scene, on a
    real cell, stays as written).

    Raises:
        ConfigError: ``kind`` is not in the config's parts (the message lists them and says
            where to declare a new one).
    """
    config.parts.check(kind)
    scene = config.scene
    if not isinstance(scene, simulated.UnreadScene) and scene.object.kind != kind:
        scene = dataclasses.replace(scene, object=dataclasses.replace(scene.object, kind=kind))
    return dataclasses.replace(
        config, controller=dataclasses.replace(config.controller, part=kind), scene=scene)
