"""Model bundle: everything needed to run perception for one taught object, in one file.

Format: a safetensors file (loading parses a JSON header and raw little-endian arrays, so it
cannot execute code). Arrays: the two networks (``nn1.*``, ``nn2.*``, see
``NumpyMLP.to_arrays``). Header metadata: ``finepos_bundle``, the JSON of everything else
(format name and version, object kind, kappa, nominal pose, intensity statistics, localisation
parameters, Gabor configuration, training metadata), and ``sha256``, a digest of that JSON and
of every array, which catches corruption that safetensors' own checks (sizes and offsets) miss.

Saving is atomic. Loading returns a new bundle or raises BundleError; it never modifies
anything, so a failed load leaves the caller's current bundle in place.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import safetensors.numpy
from safetensors import SafetensorError

from calibration_free.errors import BundleError
from calibration_free.gabor import GaborConfig
from calibration_free.localise import Polarity
from calibration_free.mlp import NumpyMLP
from calibration_free.preprocess import IntensityStats
from drivers.errors import FineposError
from drivers.files import atomic_write_bytes
from drivers.pose import Pose
from drivers.typed_config import from_mapping, to_mapping

FORMAT = "finepos-model-bundle"
FORMAT_VERSION = 2  # 2: localisation.max_elongation
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
        gabor: the filter-bank configuration NN2's inputs come from.
        nn1: (u_px, v_px) -> (dx_mm, dy_mm).
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
    gabor: GaborConfig
    nn1: NumpyMLP
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
        if self.nn2.n_inputs != self.gabor.n_filters or self.nn2.n_outputs != 2:
            raise BundleError(f"nn2: must map {self.gabor.n_filters} features to 2 outputs, "
                              f"has layers {self.nn2.layer_sizes}")

    @property
    def pose(self) -> Pose:
        """The nominal pose as a ``drivers.pose.Pose``."""
        return Pose(**self.nominal_pose)

    def _info(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "format_version": self.format_version,
            "object_kind": self.object_kind,
            "kappa": self.kappa,
            "nominal_pose": self.nominal_pose,
            "frame_px": {"height": self.frame_height_px, "width": self.frame_width_px},
            "intensity": {"mean": self.intensity.mean, "std": self.intensity.std},
            "localisation": {"threshold": self.threshold, "polarity": self.polarity,
                             "expected_area_px": self.expected_area_px,
                             "area_tolerance": self.area_tolerance,
                             "max_elongation": self.max_elongation},
            "gabor": to_mapping(self.gabor),
            "training": self.training,
        }

    def save(self, path: str | Path) -> None:
        """Write the bundle to ``path`` atomically (a reader sees the old or the new file).

        Raises:
            BundleError: the training metadata is not JSON-serialisable.
        """
        tensors = {**self.nn1.to_arrays("nn1"), **self.nn2.to_arrays("nn2")}
        try:
            data = _pack(self._info(), tensors)
        except (TypeError, ValueError) as exc:
            raise BundleError(f"{path}: cannot serialise bundle metadata: {exc}") from exc
        atomic_write_bytes(path, data)

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
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise BundleError(f"{path}: cannot read model bundle: {exc.strerror or exc}") \
                from exc
        info, tensors = _unpack(data, path)
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
                gabor=from_mapping(GaborConfig, info["gabor"], "gabor"),
                nn1=NumpyMLP.from_arrays(tensors, "nn1"),
                nn2=NumpyMLP.from_arrays(tensors, "nn2"),
                training=info.get("training", {}),
                format_version=info["format_version"],
            )
        except (KeyError, TypeError, ValueError, AttributeError, FineposError) as exc:
            raise BundleError(f"{path}: inconsistent model bundle: {exc}") from exc
        if expect_object is not None and bundle.object_kind != expect_object:
            raise BundleError(f"{path}: this bundle was taught on object "
                              f"{bundle.object_kind!r}, not {expect_object!r}")
        return bundle


def _digest(info_json: str, tensors: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256(info_json.encode("utf-8"))
    for name in sorted(tensors):
        a = np.ascontiguousarray(tensors[name])
        h.update(f"\0{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _pack(info: dict[str, Any], tensors: dict[str, np.ndarray]) -> bytes:
    """Bytes of a bundle file holding ``info`` (JSON) and ``tensors``."""
    info_json = json.dumps(info, allow_nan=False, sort_keys=True)
    tensors = {k: np.ascontiguousarray(v) for k, v in tensors.items()}
    return safetensors.numpy.save(
        tensors, metadata={"finepos_bundle": info_json, "sha256": _digest(info_json, tensors)})


def _unpack(data: bytes, path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Check and split the bytes of a bundle file into its JSON info and its arrays."""
    if len(data) < 8:
        raise BundleError(f"{path}: not a model bundle (only {len(data)} bytes)")
    header_len = int.from_bytes(data[:8], "little")
    if header_len > len(data) - 8:
        raise BundleError(f"{path}: truncated model bundle (header claims {header_len} bytes, "
                          f"{len(data) - 8} present)")
    try:
        header = json.loads(data[8:8 + header_len].decode("utf-8"))
        meta = header["__metadata__"]
        info_json, digest = meta["finepos_bundle"], meta["sha256"]
        info = json.loads(info_json)
    except (UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise BundleError(f"{path}: not a finepos model bundle or corrupt header ({exc})") \
            from exc
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise BundleError(f"{path}: not a finepos model bundle")
    if info.get("format_version") != FORMAT_VERSION:
        raise BundleError(f"{path}: model bundle format version {info.get('format_version')!r}"
                          f" is not supported (this finepos reads version {FORMAT_VERSION});"
                          f" retrain or convert the bundle")
    try:
        tensors = safetensors.numpy.load(data)
    except SafetensorError as exc:
        raise BundleError(f"{path}: corrupt or truncated model bundle: {exc}") from exc
    if _digest(info_json, tensors) != digest:
        raise BundleError(f"{path}: corrupt model bundle (checksum mismatch)")
    return info, tensors
