"""The preprocessing and localisation the baselines share with the Gabor system (paper sec. 3).

max(R, G, B) -> normalisation to the training statistics -> binarisation at the training
threshold -> the object's centroid (``calibration_free.preprocess`` and ``localise``). Training
runs the Gabor pipeline's own preparation (``calibration_free.pipeline``), so all three systems
see the object in the same place; ``FrontEnd`` keeps what it learned in a baseline model.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration_free.dataset import Dataset
from calibration_free.errors import ImageError, TrainingError
from calibration_free.localise import (
    AREA_TOLERANCE,
    NO_ELONGATION_LIMIT,
    Localisation,
    Polarity,
    localise,
)
from calibration_free.pipeline import _check_sets, _pose, _prepare
from calibration_free.preprocess import IntensityStats, max_channel_u8, normalise
from drivers.core.errors import ConfigError
from drivers.core.pose import Pose


@dataclass(frozen=True)
class FrontEnd:
    """What preprocessing and localisation learned from the training images.

    Attributes:
        frame_height_px, frame_width_px: the training frames' size (other sizes are refused).
        intensity: target statistics of the intensity normalisation.
        threshold: binarisation level (normalised grey units).
        polarity: "bright" or "dark": which side of the threshold the object is on.
        expected_area_px: the middle of the object's blob areas in the training images.
        area_tolerance: a blob matches when |area / expected - 1| <= this (spans the
            training images' areas).
        max_elongation: a blob matches only up to this elongation (the part's shape).
    """

    frame_height_px: int
    frame_width_px: int
    intensity: IntensityStats
    threshold: float
    polarity: Polarity
    expected_area_px: float
    area_tolerance: float = AREA_TOLERANCE
    max_elongation: float = NO_ELONGATION_LIMIT

    def __post_init__(self) -> None:
        if self.frame_height_px < 1 or self.frame_width_px < 1:
            raise ConfigError(f"front end: frame size must be positive, got "
                              f"{self.frame_width_px}x{self.frame_height_px}")
        if self.polarity not in ("bright", "dark"):
            raise ConfigError(f"front end: polarity must be bright or dark, got "
                              f"{self.polarity!r}")
        if not (math.isfinite(self.threshold) and math.isfinite(self.expected_area_px)
                and self.expected_area_px > 0 and 0 < self.area_tolerance <= 1):
            raise ConfigError(f"front end: need a finite threshold, expected_area_px > 0 and "
                              f"0 < area_tolerance <= 1, got {self.threshold!r}, "
                              f"{self.expected_area_px!r}, {self.area_tolerance!r}")

    def normalise(self, image: np.ndarray) -> np.ndarray:
        """The max-channel image normalised to the training statistics (HxW float32).

        Raises:
            ImageError: not HxWx3 uint8 of the training frames' size.
        """
        gray = max_channel_u8(image)
        if gray.shape != (self.frame_height_px, self.frame_width_px):
            raise ImageError(f"image: the model was trained on {self.frame_width_px}x"
                             f"{self.frame_height_px} frames, got {gray.shape[1]}x"
                             f"{gray.shape[0]}")
        return normalise(gray, self.intensity)

    def localise(self, normalised: np.ndarray) -> Localisation:
        """The object's centroid in a normalised image."""
        return localise(normalised, self.threshold, self.expected_area_px,
                        polarity=self.polarity, area_tolerance=self.area_tolerance,
                        max_elongation=self.max_elongation)

    def to_info(self) -> dict[str, Any]:
        return {"frame_px": {"height": self.frame_height_px, "width": self.frame_width_px},
                "intensity": {"mean": self.intensity.mean, "std": self.intensity.std},
                "localisation": {"threshold": self.threshold, "polarity": self.polarity,
                                 "expected_area_px": self.expected_area_px,
                                 "area_tolerance": self.area_tolerance,
                                 "max_elongation": self.max_elongation}}

    @classmethod
    def from_info(cls, info: Mapping[str, Any]) -> FrontEnd:
        """Inverse of ``to_info``; raises KeyError/TypeError/ValueError on bad input."""
        loc = info["localisation"]
        return cls(int(info["frame_px"]["height"]), int(info["frame_px"]["width"]),
                   IntensityStats(**info["intensity"]), float(loc["threshold"]),
                   loc["polarity"], float(loc["expected_area_px"]),
                   float(loc["area_tolerance"]), float(loc["max_elongation"]))


@dataclass(frozen=True)
class PreparedSets:
    """Training images after the shared preprocessing and localisation.

    Attributes:
        front: what was learned (normalisation, threshold, expected area).
        normalised: per set name, the normalised images.
        found: per set name, every image's localisation.
        usable: per set name, the indices of images where the object was found.
        seconds: time spent.
    """

    front: FrontEnd
    normalised: dict[str, list[np.ndarray]]
    found: dict[str, list[Localisation]]
    usable: dict[str, np.ndarray]
    seconds: float

    def centres(self, name: str) -> np.ndarray:
        """(n_usable, 2) object centroids (u_px, v_px) of set ``name``."""
        return np.array([(self.found[name][i].u_px, self.found[name][i].v_px)
                         for i in self.usable[name]]).reshape(-1, 2)


def prepare_training(sets: dict[str, Dataset], polarity: Polarity = "bright") -> PreparedSets:
    """Run the Gabor pipeline's training preparation on the sets (one of them named "nn2").

    Raises:
        TrainingError: a set has no images, the image sizes differ, an image is flat, the
            object is not found in at least half of a set's images, or the "object" is the
            table (wrong polarity).
    """
    start = time.perf_counter()
    height, width = _check_sets(sets)
    prep = _prepare(sets, polarity, height * width)
    front = FrontEnd(height, width, prep.intensity, prep.threshold, polarity,
                     prep.expected_area_px, prep.area_tolerance, prep.max_elongation)
    return PreparedSets(front, prep.normalised, prep.found, prep.usable,
                        time.perf_counter() - start)


def check_part(object_kind: str, kappa: int, nominal_pose: Pose | Mapping[str, float]) \
        -> dict[str, float]:
    """Validate what the model is taught on; returns the nominal pose as a dict.

    Raises:
        TrainingError: an empty object kind, kappa not a whole number >= 1, or a bad pose.
    """
    if not isinstance(object_kind, str) or not object_kind:
        raise TrainingError(f"object_kind: must be a non-empty string, got {object_kind!r}")
    if isinstance(kappa, bool) or not isinstance(kappa, int) or kappa < 1:
        raise TrainingError(f"kappa: must be a whole number >= 1, got {kappa!r}")
    return _pose(nominal_pose).as_dict()
