"""finepos model files (every system's): safetensors files whose loading cannot execute code.

Arrays are stored as safetensors tensors; everything else is one JSON document in the header
metadata (``finepos_model``), together with ``sha256``, a digest of that JSON and of every
array that catches corruption safetensors' own size checks miss. The JSON names the format,
the system (``kind``: ``gabor``, ``pca`` or ``hough``) and that system's format version, so a
file of another system or version is refused with a message saying so. Writes are atomic.

``TaughtModel`` is the save/load every system's model shares: the JSON says what was taught
(``object_kind``, ``kappa``, ``nominal_pose``), the front end (``FrontEnd.to_info``), the
system's own settings and the training metadata; the system adds its arrays.
"""

from __future__ import annotations

import hashlib
import json
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import safetensors.numpy
from safetensors import SafetensorError

from calibration_free.errors import BundleError
from calibration_free.front_end import FrontEnd
from drivers.core.errors import FineposError
from drivers.core.files import atomic_write_bytes, read_regular_file

# Models are a few MB; a larger file is not one (and must not fill the memory).
MAX_MODEL_BYTES = 512 * 1024 * 1024

FORMAT = "finepos-model"
_INFO_KEY = "finepos_model"


def _digest(info_json: str, arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256(info_json.encode("utf-8"))
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\0{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def pack_model(kind: str, version: int, info: dict[str, Any],
               arrays: dict[str, np.ndarray]) -> bytes:
    """The bytes of a model file (see ``write_model``).

    Raises:
        BundleError: the metadata is not JSON-serialisable (or not finite).
    """
    header = {"format": FORMAT, "kind": kind, "format_version": version, **info}
    try:
        info_json = json.dumps(header, allow_nan=False, sort_keys=True)
    except (TypeError, ValueError) as exc:
        raise BundleError(f"cannot serialise the {kind} model's metadata: {exc}") from exc
    tensors = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
    return safetensors.numpy.save(
        tensors, metadata={_INFO_KEY: info_json, "sha256": _digest(info_json, tensors)})


def write_model(path: str | Path, kind: str, version: int, info: dict[str, Any],
                arrays: dict[str, np.ndarray]) -> None:
    """Write a model file atomically.

    Args:
        path: destination.
        kind: the system, e.g. "gabor" or "pca".
        version: that system's model format version.
        info: JSON-able metadata (no keys "format", "kind", "format_version").
        arrays: named numeric arrays.

    Raises:
        BundleError: the metadata is not JSON-serialisable (or not finite).
    """
    try:
        data = pack_model(kind, version, info, arrays)
    except BundleError as exc:
        raise BundleError(f"{path}: {exc}") from exc
    atomic_write_bytes(path, data)


def read_model(path: str | Path, kind: str, version: int, older: tuple[int, ...] = ()) \
        -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read and check a model file written by ``write_model``: of format ``version``, or of
    one of the ``older`` versions the caller still reads.

    Returns:
        The JSON metadata (with "format", "kind", "format_version") and the arrays.

    Raises:
        BundleError: the file is missing, unreadable, truncated, corrupt (checksum), of
            another format or system, or of another version.
    """
    try:
        data = read_regular_file(path, MAX_MODEL_BYTES)
    except OSError as exc:
        raise BundleError(f"{path}: cannot read {kind} model: {exc.strerror or exc}") from exc
    if len(data) < 8:
        raise BundleError(f"{path}: not a {kind} model file (only {len(data)} bytes)")
    header_len = int.from_bytes(data[:8], "little")
    if data[8:9] != b"{":  # a safetensors header is a JSON object right after its length
        raise BundleError(f"{path}: not a {kind} model file (no model header at its start)")
    if header_len > len(data) - 8:
        raise BundleError(f"{path}: truncated {kind} model file (header claims {header_len} "
                          f"bytes, {len(data) - 8} present)")
    try:
        meta = json.loads(data[8:8 + header_len].decode("utf-8"))["__metadata__"]
        info_json, digest = meta[_INFO_KEY], meta["sha256"]
        info = json.loads(info_json)
    except (UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise BundleError(f"{path}: not a finepos model file, or a corrupt header "
                          f"({_header_problem(exc)})") from exc
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise BundleError(f"{path}: not a finepos model file")
    if info.get("kind") != kind:
        raise BundleError(f"{path}: a {info.get('kind')!r} model, not a {kind!r} model")
    if info.get("format_version") != version and info.get("format_version") not in older:
        raise BundleError(f"{path}: {kind} model format version "
                          f"{info.get('format_version')!r} is not supported (this finepos "
                          f"reads version {version}); retrain the model")
    try:
        arrays = safetensors.numpy.load(data)
    except (SafetensorError, ValueError, TypeError) as exc:
        raise BundleError(f"{path}: corrupt or truncated {kind} model: "
                          f"{_short(str(exc))}") from exc
    if _digest(info_json, arrays) != digest:
        raise BundleError(f"{path}: corrupt {kind} model (checksum mismatch)")
    return info, arrays


def _short(text: str, limit: int = 160) -> str:
    """``text`` on one line, cut to ``limit`` characters (never a whole header)."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _header_problem(exc: Exception) -> str:
    """What is wrong with a header, in a few words (the exception's repr would carry it)."""
    if isinstance(exc, UnicodeDecodeError):
        return f"byte {exc.object[exc.start]:#04x} at header offset {exc.start} is not UTF-8"
    if isinstance(exc, json.JSONDecodeError):
        return f"not JSON: {exc.msg} at header offset {exc.pos}"
    if isinstance(exc, KeyError):
        return f"no {_short(str(exc.args[0]), 40)!r} entry"
    return f"{type(exc).__name__}: {_short(str(exc), 80)}"


def nominal_pose_of(info: dict[str, Any]) -> dict[str, float]:
    """The taught pose stored in a model's JSON, as floats.

    Raises:
        KeyError, TypeError, ValueError: missing, not numeric, or not finite (callers turn
            these into a BundleError naming the file).
    """
    pose = {k: float(v) for k, v in info["nominal_pose"].items()}
    if not all(math.isfinite(v) for v in pose.values()):
        raise ValueError(f"nominal_pose is not finite: {pose}")
    return pose


def check_taught_object(path: str | Path, kind: str, taught: str, expected: str | None) -> None:
    """Refuse a model of ``kind`` taught on ``taught`` when ``expected`` (if given) differs."""
    if expected is not None and taught != expected:
        raise BundleError(f"{path}: this {kind} model was taught on object {taught!r}, "
                          f"not {expected!r}")


@dataclass(frozen=True, eq=False)
class TaughtModel(ABC):
    """A system's trained model of one part, saved to and loaded from one model file.

    Subclasses are frozen dataclasses that add their system's fields, set ``file_kind`` and
    ``file_version``, and implement ``system_info``, ``arrays`` and ``from_file``.

    Attributes:
        file_kind: (class) the system's name in the file (``gabor``, ``pca``, ``hough``).
        file_version: (class) that system's model format version (it writes).
        older_versions: (class) earlier versions it still reads (others are refused).
        object_kind: what was taught, e.g. "cube"; checked by ``load(expect_object=...)``.
        kappa: rotational symmetry count of the object (4 for the cube).
        nominal_pose: the taught pose, {x_mm, y_mm, z_mm, o_deg, a_deg, t_deg}.
        front: the preprocessing and localisation as trained.
        training: JSON-able training metadata (keyword-only).
    """

    file_kind: ClassVar[str]
    file_version: ClassVar[int]
    older_versions: ClassVar[tuple[int, ...]] = ()
    object_kind: str
    kappa: int
    nominal_pose: dict[str, float]
    front: FrontEnd
    training: dict[str, Any] = field(default_factory=dict, kw_only=True)

    @abstractmethod
    def system_info(self) -> dict[str, Any]:
        """The system's own JSON metadata (settings; no keys of ``to_info``'s shared part).

        Returns:
            A JSON-able dict merged into the file's JSON.
        """

    @abstractmethod
    def arrays(self) -> dict[str, np.ndarray]:
        """The model's numeric arrays, by the names the file stores them under.

        Returns:
            Named arrays (the file's safetensors tensors).
        """

    @classmethod
    @abstractmethod
    def from_file(cls, info: dict[str, Any], arrays: dict[str, np.ndarray],
                  taught: dict[str, Any]) -> Self:
        """Build the model from what ``read_model`` returned.

        Args:
            info: the file's JSON.
            arrays: the file's arrays.
            taught: constructor arguments read from the shared part of ``info``:
                ``object_kind``, ``kappa``, ``nominal_pose``, ``front``, ``training``.

        Raises:
            KeyError, TypeError, ValueError, AttributeError, FineposError: missing or
                inconsistent contents (``load`` turns them into a BundleError).
        """

    def to_info(self) -> dict[str, Any]:
        """The file's JSON: what was taught, the front end, ``system_info``, the training.

        Returns:
            A JSON-able dict (without "format", "kind", "format_version": ``write_model``
            adds them).
        """
        return {"object_kind": self.object_kind, "kappa": self.kappa,
                "nominal_pose": self.nominal_pose, **self.front.to_info(),
                **self.system_info(), "training": self.training}

    def save(self, path: str | Path) -> None:
        """Write the model to ``path`` atomically (a reader sees the old or the new file).

        Args:
            path: destination.

        Raises:
            BundleError: the metadata (e.g. the training's) is not JSON-serialisable.
        """
        write_model(path, self.file_kind, self.file_version, self.to_info(), self.arrays())

    @classmethod
    def load(cls, path: str | Path, expect_object: str | None = None) -> Self:
        """Read a model written by ``save``; never modifies anything.

        Args:
            path: the model file.
            expect_object: if given, the object kind the model must have been taught on.

        Raises:
            BundleError: the file is missing, corrupt, truncated, of another system or
                format version, inconsistent, or taught on another object than
                ``expect_object``.
        """
        info, arrays = read_model(path, cls.file_kind, cls.file_version, cls.older_versions)
        try:
            taught = {"object_kind": str(info["object_kind"]), "kappa": info["kappa"],
                      "nominal_pose": nominal_pose_of(info), "front": FrontEnd.from_info(info),
                      "training": info.get("training", {})}
            model = cls.from_file(info, arrays, taught)
        except (KeyError, TypeError, ValueError, AttributeError, FineposError) as exc:
            raise BundleError(f"{path}: inconsistent {cls.file_kind} model: {exc}") from exc
        check_taught_object(path, cls.file_kind, model.object_kind, expect_object)
        return model
