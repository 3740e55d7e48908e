"""What the positioning loop needs from a vision system: the estimator protocol.

The Gabor system (``calibration_free``) and the PCA and Hough baselines each provide an
estimator; the loop in ``controller.loop.positioning`` does not know which one it runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

Status = Literal["ok", "no_object", "ambiguous"]


@dataclass(frozen=True)
class TranslationEstimate:
    """The corrective translation seen in one image (tool frame, mm).

    status: ``ok``, or ``no_object`` / ``ambiguous`` (then dx/dy are NaN and reason says why);
    u_px, v_px: the object centre in the image; record: extra values for the iteration log
    (network outputs, areas...).
    """

    status: Status
    dx_mm: float = float("nan")
    dy_mm: float = float("nan")
    u_px: float = float("nan")
    v_px: float = float("nan")
    reason: str = ""
    record: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RotationEstimate:
    """The corrective rotation about the approach axis (deg), with log values.

    dx_mm, dy_mm: a translation refined with the rotation estimate, where the system has one
    (the full loop then moves by it instead of the translation estimate); None otherwise.
    """

    dphi_deg: float
    record: dict[str, Any] = field(default_factory=dict)
    dx_mm: float | None = None
    dy_mm: float | None = None


class Estimator(Protocol):
    """A vision system usable by the positioning loop."""

    name: str

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """NN1 path: localise the object and map it to (dx, dy). Cheap: used by half loops."""
        ...

    def estimate_rotation(self, image: np.ndarray,
                          translation: TranslationEstimate) -> RotationEstimate:
        """NN2 path: the rotation, from the same image and its (ok) translation estimate."""
        ...
