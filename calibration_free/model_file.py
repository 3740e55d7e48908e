"""finepos model files (every system's): safetensors files whose loading cannot execute code.

Arrays are stored as safetensors tensors; everything else is one JSON document in the header
metadata (``finepos_model``), together with ``sha256``, a digest of that JSON and of every
array that catches corruption safetensors' own size checks miss. The JSON names the format,
the system (``kind``: ``gabor``, ``pca`` or ``hough``) and that system's format version, so a
file of another system or version is refused with a message saying so. Writes are atomic.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import safetensors.numpy
from safetensors import SafetensorError

from calibration_free.errors import BundleError
from drivers.core.files import atomic_write_bytes

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


def read_model(path: str | Path, kind: str, version: int) \
        -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read and check a model file written by ``write_model``.

    Returns:
        The JSON metadata (with "format", "kind", "format_version") and the arrays.

    Raises:
        BundleError: the file is missing, unreadable, truncated, corrupt (checksum), of
            another format or system, or of another version.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise BundleError(f"{path}: cannot read {kind} model: {exc.strerror or exc}") from exc
    if len(data) < 8:
        raise BundleError(f"{path}: not a {kind} model file (only {len(data)} bytes)")
    header_len = int.from_bytes(data[:8], "little")
    if header_len > len(data) - 8:
        raise BundleError(f"{path}: truncated {kind} model file (header claims {header_len} "
                          f"bytes, {len(data) - 8} present)")
    try:
        meta = json.loads(data[8:8 + header_len].decode("utf-8"))["__metadata__"]
        info_json, digest = meta[_INFO_KEY], meta["sha256"]
        info = json.loads(info_json)
    except (UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise BundleError(f"{path}: not a finepos model file, or a corrupt header "
                          f"({exc!r})") from exc
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise BundleError(f"{path}: not a finepos model file")
    if info.get("kind") != kind:
        raise BundleError(f"{path}: a {info.get('kind')!r} model, not a {kind!r} model")
    if info.get("format_version") != version:
        raise BundleError(f"{path}: {kind} model format version "
                          f"{info.get('format_version')!r} is not supported (this finepos "
                          f"reads version {version}); retrain the model")
    try:
        arrays = safetensors.numpy.load(data)
    except SafetensorError as exc:
        raise BundleError(f"{path}: corrupt or truncated {kind} model: {exc}") from exc
    if _digest(info_json, arrays) != digest:
        raise BundleError(f"{path}: corrupt {kind} model (checksum mismatch)")
    return info, arrays


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
