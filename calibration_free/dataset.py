"""Training and test sets: images (or features), corrective-step labels and metadata, one file.

Labels are ``[dx_mm, dy_mm, dphi_deg]``: the tool step (in the tool frame, ``drivers.core.pose.
ToolStep`` convention) that brings the arm back to the nominal pose from where the image was
taken. The arm is displaced by the negative of the label before the image is grabbed (paper:
"after displacing the robot by -(dx, dy, dphi)").

File format: a numpy ``.npz`` archive (read with ``allow_pickle=False``, so loading cannot run
code) holding ``labels``, optionally ``images`` and ``features``, and ``metadata_json``, the
UTF-8 JSON of ``{"format", "version", "metadata", "samples"}`` as a uint8 array. Written
atomically.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration_free.errors import DatasetError
from drivers.core.files import atomic_write_bytes, read_regular_file

FORMAT = "finepos-dataset"
VERSION = 1
LABEL_COLUMNS = ("dx_mm", "dy_mm", "dphi_deg")
LABEL_LIMITS = (1000.0, 1000.0, 360.0)  # |label| bounds per column: a damaged file beyond
MAX_DATASET_BYTES = 4 << 30  # a set of a few hundred compressed images is far smaller
# The arrays of one set once decoded; a header claiming more is refused before allocation.
MAX_DATASET_ARRAY_BYTES = 4 << 30


@dataclass(frozen=True)
class Dataset:
    """Samples for training or testing one network.

    Attributes:
        labels: (N, 3) float64 corrective steps [dx_mm, dy_mm, dphi_deg].
        images: (N, H, W, 3) uint8 RGB hand-camera images, or None.
        features: (N, F) float32 precomputed features, or None.
        samples: per-sample JSON-able metadata (N dicts), or None.
        metadata: JSON-able metadata of the whole set (object, nominal pose, a_mm, ...).
    """

    labels: np.ndarray
    images: np.ndarray | None = None
    features: np.ndarray | None = None
    samples: list[dict[str, Any]] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        labels = np.asarray(self.labels, dtype=np.float64)
        if labels.ndim != 2 or labels.shape[1] != 3:
            raise DatasetError(f"labels: expected (N, 3) [dx_mm, dy_mm, dphi_deg], got "
                               f"{labels.shape}")
        if not np.isfinite(labels).all():
            raise DatasetError("labels: must be finite")
        worst = np.abs(labels).max(axis=0) if labels.shape[0] else np.zeros(3)
        for column, value, limit in zip(LABEL_COLUMNS, worst, LABEL_LIMITS, strict=True):
            if value > limit:
                raise DatasetError(f"labels: {column} reaches {value:.6g}, beyond +-{limit:g} "
                                   "(no fine-positioning grid spans that)")
        object.__setattr__(self, "labels", labels)
        n = labels.shape[0]
        if self.images is not None:
            im = self.images
            if not isinstance(im, np.ndarray) or im.dtype != np.uint8 or im.ndim != 4 \
                    or im.shape[0] != n or im.shape[3] != 3:
                raise DatasetError(f"images: expected ({n}, H, W, 3) uint8, got "
                                   f"{getattr(im, 'shape', None)} "
                                   f"{getattr(im, 'dtype', type(im))}")
        if self.features is not None:
            f = np.asarray(self.features, dtype=np.float32)
            if f.ndim != 2 or f.shape[0] != n or not np.isfinite(f).all():
                raise DatasetError(f"features: expected ({n}, F) finite values, got {f.shape}")
            object.__setattr__(self, "features", f)
        if self.samples is not None and len(self.samples) != n:
            raise DatasetError(f"samples: expected {n} metadata entries, got "
                               f"{len(self.samples)}")

    def __len__(self) -> int:
        return self.labels.shape[0]

    def save(self, path: str | Path) -> None:
        """Write the set to ``path`` (npz) atomically.

        Raises:
            DatasetError: the metadata is not JSON-serialisable.
        """
        try:
            meta = json.dumps({"format": FORMAT, "version": VERSION,
                               "metadata": self.metadata, "samples": self.samples},
                              allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise DatasetError(f"{path}: metadata is not JSON-serialisable: {exc}") from exc
        arrays = {"labels": self.labels,
                  "metadata_json": np.frombuffer(meta.encode("utf-8"), dtype=np.uint8)}
        if self.images is not None:
            arrays["images"] = self.images
        if self.features is not None:
            arrays["features"] = self.features
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **arrays)
        atomic_write_bytes(path, buffer.getvalue())

    @classmethod
    def load(cls, path: str | Path) -> Dataset:
        """Read a set written by ``save``.

        Raises:
            DatasetError: the file is missing, not a dataset, corrupt, truncated or of another
                version.
        """
        try:
            raw = read_regular_file(path, MAX_DATASET_BYTES)  # never blocks on a FIFO
            _check_array_headers(raw)
            with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile,
                zlib.error) as exc:
            raise DatasetError(f"{path}: cannot read dataset: {exc}") from exc
        if "labels" not in arrays or "metadata_json" not in arrays:
            raise DatasetError(f"{path}: not a finepos dataset (labels or metadata missing)")
        try:
            meta = json.loads(arrays["metadata_json"].tobytes().decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise DatasetError(f"{path}: metadata is not valid JSON: {exc}") from exc
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            raise DatasetError(f"{path}: not a finepos dataset")
        if meta.get("version") != VERSION:
            raise DatasetError(f"{path}: dataset version {meta.get('version')!r} is not "
                               f"supported (this finepos reads version {VERSION})")
        try:
            return cls(arrays["labels"], arrays.get("images"), arrays.get("features"),
                       meta.get("samples"), meta.get("metadata") or {})
        except DatasetError as exc:
            raise DatasetError(f"{path}: {exc}") from exc


def _check_array_headers(raw: bytes) -> None:
    """Raise ValueError when an array header of the archive ``raw`` claims more bytes than
    its member holds or all of them more than MAX_DATASET_ARRAY_BYTES (read before numpy
    allocates what a header claims)."""
    total = 0
    with zipfile.ZipFile(io.BytesIO(raw)) as archive:
        for info in archive.infolist():
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                    np.lib.format.read_array_header_2_0
                shape, _, dtype = read_header(member)
                claimed = math.prod(shape) * dtype.itemsize
                if claimed > info.file_size - member.tell():
                    raise ValueError(f"{info.filename}: its header claims {claimed} bytes, "
                                     f"the archive holds {info.file_size}")
            total += claimed
            if total > MAX_DATASET_ARRAY_BYTES:
                raise ValueError(f"{info.filename}: the arrays exceed "
                                 f"{MAX_DATASET_ARRAY_BYTES} bytes")


def grid_offsets(a_mm: float, b_deg: float, shape: tuple[int, int, int] = (3, 3, 7)) \
        -> np.ndarray:
    """Labels of the training grid: every combination of evenly spaced dx, dy, dphi.

    Args:
        a_mm: translations span [-a_mm, a_mm] on both axes.
        b_deg: rotations span [-b_deg, b_deg].
        shape: number of values along (dx, dy, dphi); an axis with 1 value sits at 0.

    Returns:
        (nx * ny * nphi, 3) float64 labels, dx slowest and dphi fastest.

    Raises:
        DatasetError: a negative span or an axis with fewer than one value.
    """
    if a_mm < 0 or b_deg < 0 or len(shape) != 3 or any(n < 1 for n in shape):
        raise DatasetError(f"grid: need a_mm, b_deg >= 0 and three counts >= 1, got "
                           f"a_mm={a_mm}, b_deg={b_deg}, shape={shape}")
    axes = [np.linspace(-span, span, n) if n > 1 else np.zeros(1)
            for span, n in zip((a_mm, a_mm, b_deg), shape, strict=True)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1)


def staggered_grid_offsets(a_mm: float, b_deg: float,
                           shape: tuple[int, int, int] = (3, 3, 7)) -> np.ndarray:
    """A grid whose rotation levels are staggered over its positions: every (dx, dy) of the
    grid has ``shape[2]`` rotations spaced 2 b / shape[2] apart, each position's set shifted
    by another fraction of that spacing, so the nx * ny * nphi images show as many distinct
    rotations, evenly spread over [-b_deg, b_deg] and never both ends (for b = 180/kappa the
    ends are one and the same view of the part).

    The plain grid (``grid_offsets``) repeats the same nphi rotations at every position; over
    a whole symmetry period its two end levels show the same view, so a 3x3x7 grid holds six
    distinct views: 60 deg apart for a part with no symmetry (kappa 1), too far apart for NN2
    to interpolate. The staggered grid of the same 63 images holds 63 views, 360/63 deg
    apart. Neighbouring positions get shifts far apart (rank m * s mod nx*ny, s near 0.618
    of the count and coprime to it), so position and rotation stay uncorrelated.

    Args:
        a_mm: translations span [-a_mm, a_mm] on both axes (as ``grid_offsets``).
        b_deg: rotations span [-b_deg, b_deg).
        shape: number of values along (dx, dy, dphi); with one rotation value (or b = 0) the
            grid is ``grid_offsets``'s.

    Returns:
        (nx * ny * nphi, 3) float64 labels, dx slowest and dphi fastest.

    Raises:
        DatasetError: a negative span or an axis with fewer than one value.
    """
    grid = grid_offsets(a_mm, b_deg, shape)
    n_pos, n_phi = shape[0] * shape[1], shape[2]
    if n_phi < 2 or b_deg == 0:
        return grid
    stride = _coprime_stride(n_pos)
    rank = (np.arange(n_pos) * stride) % n_pos
    shift = (rank + 0.5) / n_pos                                  # in (0, 1), one per position
    level = np.arange(n_phi)
    phi = -b_deg + 2.0 * b_deg * (level[None, :] + shift[:, None]) / n_phi
    grid[:, 2] = phi.ravel()
    return grid


def _coprime_stride(n: int) -> int:
    """The whole number nearest 0.618 n that is coprime to n (1 for n <= 2)."""
    if n <= 2:
        return 1
    target = 0.618 * n
    candidates = [s for s in range(1, n) if np.gcd(s, n) == 1]
    return min(candidates, key=lambda s: abs(s - target))


def random_offsets(rng: np.random.Generator, n: int, a_mm: float, b_deg: float) -> np.ndarray:
    """n labels drawn uniformly from [-a, a] x [-a, a] x [-b, b] (the paper's test sets).

    Raises:
        DatasetError: n < 1 or a negative span.
    """
    if n < 1 or a_mm < 0 or b_deg < 0:
        raise DatasetError(f"random offsets: need n >= 1 and spans >= 0, got n={n}, "
                           f"a_mm={a_mm}, b_deg={b_deg}")
    return rng.uniform((-a_mm, -a_mm, -b_deg), (a_mm, a_mm, b_deg), size=(n, 3))
