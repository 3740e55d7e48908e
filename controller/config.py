"""The root configuration file (``finepos.yaml``): every section, strictly typed.

Sections: ``arm``, ``camera``, ``wrench`` (backend ``type`` plus that backend's options, see
``controller.devices``), ``scene`` (the simulated cell), ``safety``, ``perception``,
``controller``, ``service`` (``finepos serve``), ``timing`` (the realistic cell's durations,
``drivers.core.timing``). Unknown keys, wrong types and out-of-range
values fail at load with the full key path. With no file, every default applies: the simulated
cell, good light, the cube.

The ``scene`` section is the simulator's: it is read (into
``sim_backend.cell.scene_config.SceneConfig``, through ``controller.simulated``) only when a
device is simulated; on a real cell it stays as written (``controller.simulated.UnreadScene``),
for the emulators that read it from the file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from calibration_free.baselines.align.model import AlignConfig
from calibration_free.baselines.hough.model import HoughConfig
from calibration_free.baselines.pca.model import PcaConfig
from calibration_free.gabor import GaborConfig
from calibration_free.localise import DEFAULT_CAMERA_GAMMA
from calibration_free.training import NN2_HIDDEN
from controller import simulated
from controller.devices import DeviceSection, parse_device_section
from controller.loop.grasp import GraspConfig
from controller.loop.positioning import LoopConfig
from controller.service.config import ServiceConfig
from controller.teach.spacenav import TeachConfig
from controller.teach.state_folder import check_part
from drivers.core.errors import ConfigError
from drivers.core.parts import PartKind
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

    part: the part this cell grasps, from the parts catalogue (``drivers.core.parts``: cube |
    nut | ledge | screw); teach-in on a real cell takes its symmetry and grasp geometry from
    there. On the simulated cell the part on the table (``scene.object.kind``) is taught. The
    commands' ``--part`` (and a service job's ``part``) overrides both (``with_part``).
    """

    part: PartKind = "cube"
    loop: LoopConfig = LoopConfig()
    grasp: GraspConfig = GraspConfig()
    acquisition: AcquisitionConfig = AcquisitionConfig()
    paths: PathsConfig = PathsConfig()
    teach: TeachConfig = TeachConfig()


@dataclass(frozen=True)
class PerceptionConfig:
    """Config section ``perception``: the Gabor filter bank and the networks.

    nn2_hidden: hidden layer sizes of NN2, 1 to 8 layers of 1 to 4096 units (NN1 is the paper's
    2-3-2); nn2_weight_decay: L2
    penalty on NN2's weights, so it interpolates between the grid's angles (unset: 1e-2, and
    1e-3 for a part without symmetry, ``calibration_free.training.default_nn2_weight_decay``);
    nn2_widen_px: NN2 also learns from four copies of each ROI widened on one side by up to
    this many pixels, as a lamp-lit flank widens the outline (0: none; unset: 1 px for a part
    of kappa 6 or more, the nut, and none for the others,
    ``calibration_free.training.default_nn2_widen_px``);
    localisation_channel: the image the part is localised in (``max``: normalised max(R,G,B),
    the paper's; ``saturation``: unchanged by light and shadow for a coloured part; ``auto``:
    whichever separates part and table better in the training images); pca / hough: the
    baseline systems' settings (``finepos evaluate --system pca|hough``); align: the
    image-alignment servo's (``--system align``); seed: training seed;
    nn1_uses_nn2_set: also train NN1 on the NN2 grid's images (they cost no extra motion and
    make NN1 precise near the nominal pose, where the loop's fixed point is);
    axis: for an elongated part (screw, ledge) the turn near the taught pose is read from the
    silhouette's long axis (``calibration_free.axis``; with ``edge_coverage: colour`` the
    silhouette of the part's share of each pixel, ``FrontEnd.coverage_roi``; false: NN2
    alone);
    edge_coverage: how the part's centre reads the pixels along its outline: ``colour``, by
    the table's share of each pixel's colour (unchanged by how a lamp lights the part's
    edges, ``calibration_free.localise.colour_centre``), or ``grey``, by the localisation
    channel's grey level; camera_gamma: the camera's output gamma (``colour`` reads in linear
    light: a delivered grey level g is (g / 255) ** camera_gamma; 2.2 for an sRGB-like
    camera, 1 for a linear one).
    """

    gabor: GaborConfig = GaborConfig()
    nn2_hidden: tuple[int, ...] = field(default=NN2_HIDDEN, metadata={"min": 1, "max": 4096})
    nn2_weight_decay: float | None = field(default=None, metadata={"min": 0.0})
    nn2_widen_px: float | None = field(default=None, metadata={"min": 0.0, "max": 5.0})
    localisation_channel: Literal["max", "saturation", "auto"] = "auto"
    pca: PcaConfig = PcaConfig()
    hough: HoughConfig = HoughConfig()
    align: AlignConfig = AlignConfig()
    seed: int = 0
    nn1_uses_nn2_set: bool = True
    axis: bool = True
    edge_coverage: Literal["colour", "grey"] = "colour"
    camera_gamma: float = field(default=DEFAULT_CAMERA_GAMMA, metadata={"min": 1.0, "max": 3.0})

    def __post_init__(self) -> None:
        if not 1 <= len(self.nn2_hidden) <= 8:  # with <= 4096 units each: fits in memory
            raise ValueError(f"nn2_hidden: 1 to 8 hidden layers, got {len(self.nn2_hidden)}")

    @property
    def edge_gamma(self) -> float:
        """The gamma the part's edge is read with (``FrontEnd.edge_gamma``): 0 for ``grey``."""
        return float(self.camera_gamma) if self.edge_coverage == "colour" else 0.0


@dataclass(frozen=True)
class FineposConfig:
    """The whole configuration: one field per section, and the file it came from.

    scene: the simulated cell, a ``SceneConfig`` when a device is simulated (else the section
    unread, ``controller.simulated.UnreadScene``).
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
    source: str = "<defaults>"


SECTIONS = ("arm", "camera", "wrench", "scene", "safety", "perception", "controller", "service",
            "timing")


def config_from_mapping(data: dict[str, Any], source: str = "<mapping>") -> FineposConfig:
    """Validate a whole root mapping (e.g. parsed YAML) into a FineposConfig."""
    unknown = sorted(str(k) for k in data if k not in SECTIONS)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown section (allowed: {', '.join(SECTIONS)})")
    devices = {kind: parse_device_section(kind, data.get(kind))
               for kind in ("arm", "camera", "wrench")}
    return FineposConfig(
        **devices,
        scene=simulated.scene_section(
            data.get("scene"), any(d.type == "sim" for d in devices.values())),
        safety=from_mapping(SafetyLimits, data.get("safety"), "safety"),
        perception=from_mapping(PerceptionConfig, data.get("perception"), "perception"),
        controller=from_mapping(ControllerConfig, data.get("controller"), "controller"),
        service=from_mapping(ServiceConfig, data.get("service"), "service"),
        timing=from_mapping(TimingConfig, data.get("timing"), "timing"),
        source=source,
    )


def load_config(path: str | Path | None) -> FineposConfig:
    """Load ``path`` (None: all defaults). Raises ConfigError naming the bad key."""
    if path is None:
        return config_from_mapping({}, "<defaults>")
    try:
        return config_from_mapping(load_yaml_file(path), str(path))
    except ConfigError as exc:
        msg = str(exc)
        raise ConfigError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from exc


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
        ConfigError: ``kind`` is not in the parts catalogue (the message lists the parts).
    """
    check_part(kind)
    scene = config.scene
    if not isinstance(scene, simulated.UnreadScene) and scene.object.kind != kind:
        scene = dataclasses.replace(scene, object=dataclasses.replace(scene.object, kind=kind))
    return dataclasses.replace(
        config, controller=dataclasses.replace(config.controller, part=kind), scene=scene)
