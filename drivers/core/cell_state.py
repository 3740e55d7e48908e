"""The cell's state file: what teach-in recorded (nominal grasp pose, object, grasp geometry).

Written atomically as JSON; loading a missing or malformed file raises a clear StateError.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from drivers.core.errors import FineposError
from drivers.core.files import atomic_write_text, read_regular_file
from drivers.core.pose import Pose

STATE_VERSION = 1
MAX_STATE_BYTES = 64 * 1024  # a state file is a few hundred bytes
# Where a taught value may lie (beyond is a damaged file, not a cell): far outside any PUMA 260
# reach, and small enough that nothing computed from it overflows.
_POSE_KEYS = ("x_mm", "y_mm", "z_mm", "o_deg", "a_deg", "t_deg")
_LIMITS = {"mm": 10_000.0, "deg": 3600.0, "grasp_depth_mm": 1000.0, "object_width_mm": 1000.0,
           "kappa": 360}


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not a number")


def _finite(name: str, value, limit: float, low: float | None = None) -> float:
    """``value`` as a float within [low (default -limit), limit] (raises ValueError)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name}: expected a number, got {type(value).__name__}")
    number = float(value)
    low = -limit if low is None else low
    if not math.isfinite(number) or not low <= number <= limit:
        raise ValueError(f"{name}: {value!r} is outside [{low:g}, {limit:g}]")
    return number


class StateError(FineposError):
    """The cell state file is missing, unreadable or malformed."""


@dataclass(frozen=True)
class CellState:
    """Teach-in result.

    nominal_pose: the pre-grasp pose shown once (tool above the part, mm/deg);
    object_kind / kappa: the part and its rotational symmetry;
    grasp_depth_mm: how far to descend along the approach axis from the nominal pose to grip;
    object_width_mm: finger width expected when the part is held;
    source: how the pose was taught (``auto``, ``spacenav``, ``current``);
    taught_at: UNIX time of the teach-in;
    kappa_found: for a part declared without kappa, what its images showed
    (``controller.teach.symmetry.SymmetryEvidence.as_dict``: kappa, sure, confidence, the
    scores); None where kappa was declared or confirmed (and in files written before).
    """

    nominal_pose: Pose
    object_kind: str
    kappa: int
    grasp_depth_mm: float
    object_width_mm: float
    source: str
    taught_at: float
    kappa_found: dict | None = None

    def save(self, path: str | Path) -> None:
        """Write the state to ``path`` atomically as JSON, with the format version."""
        data = asdict(self)
        data["nominal_pose"] = self.nominal_pose.as_dict()
        data["version"] = STATE_VERSION
        atomic_write_text(path, json.dumps(data, indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> CellState:
        """Read a state file written by ``save``.

        Raises:
            StateError: the file is missing, unreadable, of another version or malformed.
        """
        path = Path(path)
        try:
            raw = read_regular_file(path, MAX_STATE_BYTES)
        except FileNotFoundError as exc:
            raise StateError(f"{path}: no cell state yet; run `finepos teach` first") from exc
        except OSError as exc:
            raise StateError(f"{path}: unreadable cell state: {exc.strerror or exc}") from exc
        try:
            data = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant)
        except (ValueError, RecursionError) as exc:  # JSON, UTF-8, NaN/Infinity
            raise StateError(f"{path}: unreadable cell state: {' '.join(str(exc).split())[:200]}"
                             ) from exc
        if not isinstance(data, dict) or data.get("version") != STATE_VERSION:
            raise StateError(f"{path}: unsupported cell state version "
                             f"{data.get('version') if isinstance(data, dict) else None!r}")
        try:
            pose_data = data["nominal_pose"]
            if not isinstance(pose_data, dict) or sorted(pose_data) != sorted(_POSE_KEYS):
                raise ValueError(f"nominal_pose: expected an object with {', '.join(_POSE_KEYS)}")
            pose = Pose(**{k: _finite(f"nominal_pose.{k}", pose_data[k],
                                      _LIMITS["mm" if k.endswith("_mm") else "deg"])
                           for k in _POSE_KEYS})
            kappa = data["kappa"]
            if isinstance(kappa, bool) or not isinstance(kappa, int) or \
                    not 1 <= kappa <= _LIMITS["kappa"]:
                raise ValueError(f"kappa: expected an integer in [1, {_LIMITS['kappa']}], "
                                 f"got {kappa!r}")
            if not isinstance(data["object_kind"], str) or not isinstance(data["source"], str):
                raise ValueError("object_kind and source: expected strings")
            found = data.get("kappa_found")
            if found is not None and not isinstance(found, dict):
                raise ValueError("kappa_found: expected an object or null")
            return cls(pose, data["object_kind"], kappa,
                       _finite("grasp_depth_mm", data["grasp_depth_mm"],
                               _LIMITS["grasp_depth_mm"], 0.0),
                       _finite("object_width_mm", data["object_width_mm"],
                               _LIMITS["object_width_mm"], 0.0),
                       data["source"], _finite("taught_at", data["taught_at"], 1e11, 0.0),
                       found)
        except KeyError as exc:
            raise StateError(f"{path}: malformed cell state: {exc.args[0]!r} is missing") \
                from exc
        except (TypeError, ValueError) as exc:
            raise StateError(f"{path}: malformed cell state: {exc}") from exc

    @staticmethod
    def now() -> float:
        """The current UNIX time (``taught_at`` of a new teach-in)."""
        return time.time()
