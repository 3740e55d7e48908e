"""The cell's state file: what teach-in recorded (nominal grasp pose, object, grasp geometry).

Written atomically as JSON; loading a missing or malformed file raises a clear StateError.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from drivers.core.errors import FineposError
from drivers.core.files import atomic_write_text
from drivers.core.pose import Pose

STATE_VERSION = 1


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
    taught_at: UNIX time of the teach-in.
    """

    nominal_pose: Pose
    object_kind: str
    kappa: int
    grasp_depth_mm: float
    object_width_mm: float
    source: str
    taught_at: float

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
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError as exc:
            raise StateError(f"{path}: no cell state yet; run `finepos teach` first") from exc
        except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise StateError(f"{path}: unreadable cell state: {exc}") from exc
        if not isinstance(data, dict) or data.get("version") != STATE_VERSION:
            raise StateError(f"{path}: unsupported cell state version "
                             f"{data.get('version') if isinstance(data, dict) else None!r}")
        try:
            pose = Pose(**{k: float(v) for k, v in data["nominal_pose"].items()})
            return cls(pose, str(data["object_kind"]), int(data["kappa"]),
                       float(data["grasp_depth_mm"]), float(data["object_width_mm"]),
                       str(data["source"]), float(data["taught_at"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise StateError(f"{path}: malformed cell state: {exc!r}") from exc

    @staticmethod
    def now() -> float:
        """The current UNIX time (``taught_at`` of a new teach-in)."""
        return time.time()
