"""Model bundle: everything needed to run perception for one taught object, in one file.

Format: a finepos model file (``calibration_free.model_file``: safetensors, so loading cannot
execute code; a JSON header; a sha256 over both) of kind ``gabor``. Arrays: the networks
(``nn1.*``, ``nn1_rot.*``, ``nn2.*``, see ``NumpyMLP.to_arrays``). JSON: object kind, kappa,
nominal pose, frame size, intensity statistics, localisation parameters, Gabor
configuration, training metadata.

Saving is atomic. Loading returns a new bundle or raises BundleError; it never modifies
anything, so a failed load leaves the caller's current bundle in place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration_free.errors import BundleError
from calibration_free.gabor import GaborConfig
from calibration_free.localise import Polarity
from calibration_free.mlp import NumpyMLP
from calibration_free.model_file import check_taught_object, read_model, write_model
from calibration_free.preprocess import Channel, IntensityStats
from drivers.core.errors import FineposError
from drivers.core.pose import Pose
from drivers.core.typed_config import from_mapping, to_mapping

KIND = "gabor"
FORMAT_VERSION = 4  # 2: max_elongation; 3: channel, nominal_uv_px; 4: nn1_rot
POSE_KEYS = ("x_mm", "y_mm", "z_mm", "o_deg", "a_deg", "t_deg")


@dataclass(frozen=True, eq=False)
class ModelBundle:
    """A trained perception model for one object.

    Attributes:
        object_kind: what was taught, e.g. "cube"; checked by ``load(expect_object=...)``.
        kappa: rotational symmetry count of the object (4 for the cube).
        nominal_pose: the taught grasp pose, {x_mm, y_mm, z_mm, o_deg, a_deg, t_deg}.
        frame_height_px, frame_width_px: size of the camera frames it was trained on (NN1
            maps pixel positions, so other sizes are refused).
        intensity: target statistics of the intensity normalisation.
        threshold: binarisation level in normalised grey units.
        polarity: "bright" or "dark": which side of the threshold the object is on.
        expected_area_px: the object's blob area in training images.
        area_tolerance: a blob matches when |area / expected - 1| <= this.
        max_elongation: a blob matches only up to this elongation (the part's shape).
        channel: the image localisation binarises: "max" or "saturation".
        nominal_uv_px: where the part appeared at the taught pose (u, v); of several blobs
            that match the part, one clearly nearest this point is taken.
        gabor: the filter-bank configuration NN2's inputs come from.
        nn1: (u_px, v_px) -> (dx_mm, dy_mm) (half loops).
        nn1_rot: (u_px, v_px, sin(kappa dphi), cos(kappa dphi)) -> (dx_mm, dy_mm) (full
            loops, which know the rotation from NN2).
        nn2: Gabor features -> (sin(kappa dphi), cos(kappa dphi)).
        training: JSON-able training metadata (loss curves, seconds, sample counts, seed).
        format_version: file format version this bundle follows.
    """

    object_kind: str
    kappa: int
    nominal_pose: dict[str, float]
    frame_height_px: int
    frame_width_px: int
    intensity: IntensityStats
    threshold: float
    polarity: Polarity
    expected_area_px: float
    area_tolerance: float
    max_elongation: float
    channel: Channel
    nominal_uv_px: tuple[float, float]
    gabor: GaborConfig
    nn1: NumpyMLP
    nn1_rot: NumpyMLP
    nn2: NumpyMLP
    training: dict[str, Any] = field(default_factory=dict)
    format_version: int = FORMAT_VERSION

    def __post_init__(self) -> None:
        if not isinstance(self.object_kind, str) or not self.object_kind:
            raise BundleError(f"object_kind: must be a non-empty string, got "
                              f"{self.object_kind!r}")
        if isinstance(self.kappa, bool) or not isinstance(self.kappa, int) or self.kappa < 1:
            raise BundleError(f"kappa: must be a whole number >= 1, got {self.kappa!r}")
        pose = dict(self.nominal_pose)
        if sorted(pose) != sorted(POSE_KEYS) or not all(
                isinstance(v, (int, float)) and math.isfinite(v) for v in pose.values()):
            raise BundleError(f"nominal_pose: needs finite {', '.join(POSE_KEYS)}, got {pose}")
        object.__setattr__(self, "nominal_pose", {k: float(pose[k]) for k in POSE_KEYS})
        for name in ("frame_height_px", "frame_width_px"):
            size = getattr(self, name)
            if isinstance(size, bool) or not isinstance(size, int) or size < 1:
                raise BundleError(f"{name}: must be a whole number >= 1, got {size!r}")
        if self.channel not in ("max", "saturation"):
            raise BundleError(f"channel: must be max or saturation, got {self.channel!r}")
        if self.polarity not in ("bright", "dark"):
            raise BundleError(f"polarity: must be bright or dark, got {self.polarity!r}")
        if not (math.isfinite(self.threshold) and math.isfinite(self.expected_area_px)
                and self.expected_area_px > 0 and 0 < self.area_tolerance <= 1
                and self.max_elongation >= 1.0):
            raise BundleError(f"localisation: need a finite threshold, expected_area_px > 0 "
                              f"and 0 < area_tolerance <= 1, got {self.threshold!r}, "
                              f"{self.expected_area_px!r}, {self.area_tolerance!r}")
        if self.nn1.layer_sizes[0] != 2 or self.nn1.n_outputs != 2:
            raise BundleError(f"nn1: must map 2 inputs to 2 outputs, has layers "
                              f"{self.nn1.layer_sizes}")
        if self.nn1_rot.layer_sizes[0] != 4 or self.nn1_rot.n_outputs != 2:
            raise BundleError(f"nn1_rot: must map 4 inputs to 2 outputs, has layers "
                              f"{self.nn1_rot.layer_sizes}")
        if self.nn2.n_inputs != self.gabor.n_filters or self.nn2.n_outputs != 2:
            raise BundleError(f"nn2: must map {self.gabor.n_filters} features to 2 outputs, "
                              f"has layers {self.nn2.layer_sizes}")

    @property
    def pose(self) -> Pose:
        """The nominal pose as a ``drivers.core.pose.Pose``."""
        return Pose(**self.nominal_pose)

    def _info(self) -> dict[str, Any]:
        return {
            "object_kind": self.object_kind,
            "kappa": self.kappa,
            "nominal_pose": self.nominal_pose,
            "frame_px": {"height": self.frame_height_px, "width": self.frame_width_px},
            "intensity": {"mean": self.intensity.mean, "std": self.intensity.std},
            "localisation": {"threshold": self.threshold, "polarity": self.polarity,
                             "expected_area_px": self.expected_area_px,
                             "area_tolerance": self.area_tolerance,
                             "max_elongation": self.max_elongation,
                             "channel": self.channel,
                             "nominal_uv_px": list(self.nominal_uv_px)},
            "gabor": to_mapping(self.gabor),
            "training": self.training,
        }

    def save(self, path: str | Path) -> None:
        """Write the bundle to ``path`` atomically (a reader sees the old or the new file).

        Raises:
            BundleError: the training metadata is not JSON-serialisable.
        """
        write_model(path, KIND, FORMAT_VERSION, self._info(), self.arrays())

    def arrays(self) -> dict[str, np.ndarray]:
        """The networks' weights as named arrays (what the file stores besides the JSON)."""
        return {**self.nn1.to_arrays("nn1"), **self.nn1_rot.to_arrays("nn1_rot"),
                **self.nn2.to_arrays("nn2")}

    @classmethod
    def load(cls, path: str | Path, expect_object: str | None = None) -> ModelBundle:
        """Read a bundle written by ``save``.

        Args:
            path: the bundle file.
            expect_object: if given, the object kind the bundle must have been taught on.

        Raises:
            BundleError: the file is missing, corrupt, truncated, of another format version,
                inconsistent, or taught on another object than ``expect_object``.
        """
        info, tensors = read_model(path, KIND, FORMAT_VERSION)
        try:
            bundle = cls(
                object_kind=info["object_kind"],
                kappa=info["kappa"],
                nominal_pose=info["nominal_pose"],
                frame_height_px=info["frame_px"]["height"],
                frame_width_px=info["frame_px"]["width"],
                intensity=IntensityStats(**info["intensity"]),
                threshold=info["localisation"]["threshold"],
                polarity=info["localisation"]["polarity"],
                expected_area_px=info["localisation"]["expected_area_px"],
                area_tolerance=info["localisation"]["area_tolerance"],
                max_elongation=info["localisation"]["max_elongation"],
                channel=info["localisation"]["channel"],
                nominal_uv_px=tuple(float(v) for v in info["localisation"]["nominal_uv_px"]),
                gabor=from_mapping(GaborConfig, info["gabor"], "gabor"),
                nn1=NumpyMLP.from_arrays(tensors, "nn1"),
                nn1_rot=NumpyMLP.from_arrays(tensors, "nn1_rot"),
                nn2=NumpyMLP.from_arrays(tensors, "nn2"),
                training=info.get("training", {}),
                format_version=info["format_version"],
            )
        except (KeyError, TypeError, ValueError, AttributeError, FineposError) as exc:
            raise BundleError(f"{path}: inconsistent model bundle: {exc}") from exc
        check_taught_object(path, KIND, bundle.object_kind, expect_object)
        return bundle
