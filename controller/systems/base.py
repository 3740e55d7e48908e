"""What every vision system shares: the trained model record and its save, load and estimator.

A system trains from the acquired datasets into a model object that saves, loads and checks its
own file (``calibration_free.model_file``), and builds an Estimator
(``controller.systems.estimator``) from it. Each system is one subclass of ``VisionSystem``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from calibration_free.dataset import Dataset
from drivers.core.cell_state import CellState


@dataclass
class TrainedModel:
    """A trained system and what training it cost.

    Attributes:
        system: the registry name (``gabor``, ``pca``, ``hough``).
        model: the system's model object (ModelBundle, PcaModel, HoughModel).
        train_seconds: wall time of the training.
        train_images: images trained on (what acquiring them cost in robot moves).
        feature_count: features per frame (36 Gabor filters, m eigenimages...).
    """

    system: str
    model: Any
    train_seconds: float
    train_images: int
    feature_count: int


@dataclass
class Rezeroed:
    """A model object re-zeroed at the taught pose (``VisionSystem.rezero``).

    Attributes:
        model: the model object with its new zero.
        report: what moved (the system's own keys, e.g. ``shift_mm``, ``read_mm``).
        frames: the frames the zero was read on (a zero by heading reads as many at each
            heading).
        average: the frames a mean is read on.
    """

    model: Any
    report: dict[str, Any]
    frames: int
    average: int


class ModelEstimator:
    """An Estimator that runs one trained model object, ``self.model``."""

    name: ClassVar[str]
    heading_zero = None  # these systems keep one zero for every heading

    def __init__(self, model: Any) -> None:
        self.model = model


class VisionSystem:
    """One vision system: how it trains, saves, loads and perceives (class-level, stateless).

    Subclasses set ``name``, ``suffix`` (model file ending), ``model_cls`` (with ``save(path)``
    and ``load(path, expect_object=...)``) and ``estimator_cls`` (built on the model object),
    and implement ``train``. A system declares the calibrations it supports: ``rezeroes``
    (``rezero``: a new zero read at the taught pose in the cell's light) and
    ``zero_by_heading`` (the model keeps a zero for each heading of the tool,
    ``controller.calibration.heading_zero``).
    """

    name: ClassVar[str]
    suffix: ClassVar[str]
    model_cls: ClassVar[Any]
    estimator_cls: ClassVar[Any]
    rezeroes: ClassVar[bool] = False
    zero_by_heading: ClassVar[bool] = False

    @classmethod
    def train(cls, nn1: Dataset, nn2: Dataset, state: CellState,
              perception_cfg: Any) -> TrainedModel:
        """Train on the two acquired sets for the taught part.

        Args:
            nn1: the translation set (paper: 3x3x7 grid, a = 25 mm).
            nn2: the rotation set (paper: 3x3x7 grid, a = 5 mm, b = 180/kappa deg).
            state: what teach-in recorded (part, kappa, nominal pose).
            perception_cfg: the ``perception`` config section.

        Raises:
            TrainingError: the sets cannot train this system (see the system's trainer).
        """
        raise NotImplementedError

    @classmethod
    def rezero(cls, model: TrainedModel, images: list[np.ndarray], loop: Any,
               grab: Callable[[], np.ndarray]) -> Rezeroed:
        """Read the model's zero on ``images``, taken at the taught pose with the part where
        it was taught (a system with ``rezeroes`` implements it).

        Args:
            loop: the loop's settings the model runs with (``LoopConfig``).
            grab: takes one more frame there, where the system needs more.

        Raises:
            TrainingError: the part is not seen whole there, or not where it was taught.
        """
        raise NotImplementedError(f"the {cls.name} system does not re-zero")

    @classmethod
    def without_heading_zero(cls, model: Any) -> Any:
        """The model object without its zero by heading (for a system with
        ``zero_by_heading``)."""
        return model

    @classmethod
    def with_heading_zero(cls, model: Any, table: Any) -> Any:
        """The model object keeping ``table`` as its zero by heading."""
        raise NotImplementedError(f"the {cls.name} system keeps one zero")

    @classmethod
    def save(cls, model: TrainedModel, path: str | Path) -> None:
        """Write the model file atomically."""
        model.model.save(path)

    @classmethod
    def load(cls, path: str | Path, state: CellState | None = None) -> TrainedModel:
        """Read a model file; with ``state``, it must have been taught on that part.

        Raises:
            BundleError: the file is missing, corrupt, of another system or taught on another
                part.
        """
        return cls.trained(
            cls.model_cls.load(path, expect_object=state.object_kind if state else None))

    @classmethod
    def trained(cls, model: Any) -> TrainedModel:
        """A model object with its training cost, as its metadata records it."""
        seconds, images = cls.training_cost(model.training)
        return TrainedModel(cls.name, model, seconds, images, cls.feature_count(model))

    @classmethod
    def estimator(cls, model: TrainedModel) -> Any:
        """The Estimator that runs this trained model in the positioning loop."""
        return cls.estimator_cls(model.model)

    @staticmethod
    def training_cost(training: dict[str, Any]) -> tuple[float, int]:
        """(seconds, distinct images) from a model file's training metadata."""
        return float(training.get("seconds", 0.0)), int(training.get("images", 0))

    @staticmethod
    def feature_count(model: Any) -> int:
        """Features per frame of a loaded model."""
        return int(model.feature_count)
