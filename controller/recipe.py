"""The recipe: the perception and loop settings tuned by experiment, kept in the model file.

A cell's configuration (``controller.config``) holds what an operator sets: devices, limits,
the part, paths, the service. The recipe holds what the method's experiments settled: the
Gabor bank, the networks, the localisation channel, the baselines' settings (``perception``)
and the loop's settling, checks and look-around (``loop``, ``RECIPE_LOOP_KEYS`` of
``controller.loop``). Training writes it into the model file (``training.recipe``), and a
run reads it back from there, so a model always runs with the settings it was trained with.

A recipe file is YAML with a ``perception`` and a ``loop`` section, both optional; a key left
out takes its default. ``finepos train --recipe FILE`` trains with it; ``finepos train``
without it keeps the recipe of the part's current model file (the defaults where there is
none). A model file written without a recipe runs with the defaults.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from calibration_free.baselines.align.model import AlignConfig
from calibration_free.baselines.hough.model import HoughConfig
from calibration_free.baselines.pca.model import PcaConfig
from calibration_free.gabor import GaborConfig
from calibration_free.localise import DEFAULT_CAMERA_GAMMA
from calibration_free.stages import StageName
from calibration_free.training import NN2_HIDDEN
from controller.loop.positioning import LoopConfig
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping, load_yaml_file, to_mapping

# ``controller.loop`` keys that belong to the recipe; the others (the convergence thresholds,
# the loop budget, image saving) stay in the cell's configuration.
RECIPE_LOOP_KEYS = (
    "r_fine_mm", "final_step", "reach_factor", "settle_frames", "settle_mm", "settle_deg",
    "settle_max_frames", "settle_sem_mm", "settle_sem_deg", "settle_average",
    "turn_check_deg", "turn_check_share", "hidden_check_share", "look_around_deg",
    "look_around_below", "turn_in_commands",
)
RECIPE_SECTIONS = ("perception", "loop")
USE_RECIPE = "set it in a recipe file given to `finepos train --recipe FILE`"


@dataclass(frozen=True)
class PerceptionConfig:
    """Recipe section ``perception``: the Gabor filter bank and the networks.

    nn2_hidden: hidden layer sizes of NN2, 1 to 8 layers of 1 to 4096 units (NN1 is the paper's
    2-3-2); nn2_weight_decay: L2
    penalty on NN2's weights, so it interpolates between the grid's angles (unset: 1e-2, and
    1e-3 for a part without symmetry, ``calibration_free.training.default_nn2_weight_decay``);
    nn2_widen_px: NN2 also learns from four copies of each ROI widened on one side by up to
    this many pixels, as a lamp-lit flank widens the outline (0: none; unset: 1 px for a part
    of kappa 6 or more, the nut, and none for the others,
    ``calibration_free.training.default_nn2_widen_px``);
    localisation_channel: the image the part is localised in (``max``: normalised max(R,G,B),
    the paper's; ``saturation``: unchanged by light and shadow for a coloured part;
    ``colour``: the part's colour against the table's, learned at the taught pose,
    ``calibration_free.part_colour``; ``auto``: of max and saturation the one that separates
    part and table better in the training images, the part's colour where neither shows the
    part); pca / hough: the
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
    camera, 1 for a linear one);
    stages: the optional perception stages the part's model runs
    (``calibration_free.stages``): ``ends`` (a bar with one end hidden is centred where the end
    it shows puts it), ``outline`` (a part partly hidden is centred on the outline it shows)
    and ``axis`` (an elongated part's turn from its long axis); each named is fitted and run,
    and one the part cannot have (``axis`` for a part that is not elongated, ``ends`` for one
    that is not a bar) fails training in one line; one left out is skipped. Unset: every one
    the part's training fits (``axis``, and ``ends`` for a bar, where ``axis`` is true), and
    every one whose data the model has runs.
    """

    gabor: GaborConfig = GaborConfig()
    nn2_hidden: tuple[int, ...] = field(default=NN2_HIDDEN, metadata={"min": 1, "max": 4096})
    nn2_weight_decay: float | None = field(default=None, metadata={"min": 0.0})
    nn2_widen_px: float | None = field(default=None, metadata={"min": 0.0, "max": 5.0})
    localisation_channel: Literal["max", "saturation", "colour", "auto"] = "auto"
    pca: PcaConfig = PcaConfig()
    hough: HoughConfig = HoughConfig()
    align: AlignConfig = AlignConfig()
    seed: int = 0
    nn1_uses_nn2_set: bool = True
    axis: bool = True
    edge_coverage: Literal["colour", "grey"] = "colour"
    camera_gamma: float = field(default=DEFAULT_CAMERA_GAMMA, metadata={"min": 1.0, "max": 3.0})
    stages: tuple[StageName, ...] | None = None

    def __post_init__(self) -> None:
        if not 1 <= len(self.nn2_hidden) <= 8:  # with <= 4096 units each: fits in memory
            raise ValueError(f"nn2_hidden: 1 to 8 hidden layers, got {len(self.nn2_hidden)}")
        if self.stages is not None:
            if len(set(self.stages)) != len(self.stages):
                raise ValueError(f"stages: each stage once, got {list(self.stages)}")
            needs_axis = [s for s in self.stages if s in ("axis", "ends")]
            if needs_axis and not self.axis:
                raise ValueError(f"stages: {needs_axis[0]} needs the long axis, but axis is "
                                 f"false")

    @property
    def edge_gamma(self) -> float:
        """The gamma the part's edge is read with (``FrontEnd.edge_gamma``): 0 for ``grey``."""
        return float(self.camera_gamma) if self.edge_coverage == "colour" else 0.0


@dataclass(frozen=True)
class Recipe:
    """A whole recipe: the perception settings and the loop's (only its ``RECIPE_LOOP_KEYS``
    are read from ``loop``; the others keep the cell configuration's values)."""

    perception: PerceptionConfig = PerceptionConfig()
    loop: LoopConfig = LoopConfig()

    def to_mapping(self) -> dict[str, Any]:
        """The recipe as the model file stores it (plain JSON)."""
        return {"perception": to_mapping(self.perception),
                "loop": {key: to_mapping(getattr(self.loop, key)) for key in RECIPE_LOOP_KEYS}}

    def apply_loop(self, loop: LoopConfig) -> LoopConfig:
        """The cell's ``loop`` with this recipe's loop keys."""
        return dataclasses.replace(
            loop, **{key: getattr(self.loop, key) for key in RECIPE_LOOP_KEYS})


DEFAULT_RECIPE = Recipe()


def recipe_from_mapping(data: Any, source: str = "<recipe>") -> Recipe:
    """Validate a recipe mapping (a recipe file's, or a model file's ``training.recipe``).

    Raises:
        ConfigError: one line naming the source and the key: an unknown section or key, a cell
            key in the ``loop`` section, a wrong type or a value out of range.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a recipe must be a mapping, got {type(data).__name__}")
    unknown = sorted(str(k) for k in data if k not in RECIPE_SECTIONS)
    if unknown:
        raise ConfigError(f"{source}: {unknown[0]}: unknown recipe section (allowed: "
                          f"{', '.join(RECIPE_SECTIONS)}; the cell's keys go in its config)")
    loop = data.get("loop")
    if isinstance(loop, dict):
        cell = sorted(str(k) for k in loop if k not in RECIPE_LOOP_KEYS
                      and k in {f.name for f in dataclasses.fields(LoopConfig)})
        if cell:
            raise ConfigError(f"{source}: loop.{cell[0]}: a cell key, not a recipe key: set "
                              f"controller.loop.{cell[0]} in the cell config")
    try:
        return Recipe(perception=from_mapping(PerceptionConfig, data.get("perception"),
                                              "perception"),
                      loop=from_mapping(LoopConfig, loop, "loop"))
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from exc


def load_recipe(path: str | Path) -> Recipe:
    """Read a recipe file (an empty file: the defaults).

    Raises:
        ConfigError: one line naming the file and what is wrong with it.
    """
    return recipe_from_mapping(load_yaml_file(path), str(path))


def recipe_of_model(model: Any) -> Recipe:
    """The recipe a model object was trained with (its ``training.recipe``; the defaults for a
    model file written without one).

    Raises:
        ConfigError: the model file's recipe is damaged (names the key).
    """
    stored = getattr(model, "training", {}).get("recipe")
    return DEFAULT_RECIPE if stored is None else recipe_from_mapping(stored, "model recipe")


def with_recipe_stored(model: Any, recipe: Recipe) -> Any:
    """``model`` (a model object with ``training`` metadata) with ``recipe`` written into it."""
    return dataclasses.replace(model, training={**model.training,
                                                "recipe": recipe.to_mapping()})


def refuse_recipe_keys(data: dict[str, Any]) -> None:
    """Refuse a cell configuration that sets a recipe key: one line naming the key and its
    home.

    Raises:
        ConfigError: the mapping sets ``perception`` or a ``controller.loop`` recipe key.
    """
    perception = data.get("perception")
    if "perception" in data:
        first = next(iter(perception), None) if isinstance(perception, dict) and perception \
            else None
        key = f"perception.{first}" if first is not None else "perception"
        raise ConfigError(f"{key}: a recipe key, kept in the model file: {USE_RECIPE} "
                          f"(as {key})")
    controller = data.get("controller")
    loop = controller.get("loop") if isinstance(controller, dict) else None
    if isinstance(loop, dict):
        for key in loop:
            if key in RECIPE_LOOP_KEYS:
                raise ConfigError(f"controller.loop.{key}: a recipe key, kept in the model "
                                  f"file: {USE_RECIPE} (as loop.{key})")
