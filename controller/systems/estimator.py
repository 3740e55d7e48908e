"""What the positioning loop needs from a vision system: the estimator contract.

A frame is perceived once. ``estimate_translation(image)`` localises the part and maps it to a
translation (the cheap path, all that a half loop needs); the estimate keeps that pass's
percept, and ``estimate_rotation(translation)`` goes on from it to the rotation (a full loop),
without looking at the image again. ``corrective_step`` is the one place where the two become
the step the arm is sent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from calibration_free.heading_zero import HeadingZero
from drivers.core.pose import ToolStep

Status = Literal["ok", "no_object", "ambiguous"]


@dataclass(frozen=True)
class TranslationEstimate:
    """The corrective translation seen in one frame (tool frame).

    Attributes:
        status: ``ok``; or ``no_object`` / ``ambiguous``, when dx/dy are NaN and ``reason``
            says why.
        dx_mm, dy_mm: the corrective translation (mm).
        u_px, v_px: the part's centre in the image (px).
        reason: why the status is not ``ok`` (empty when it is).
        record: values for the iteration log (network outputs, blob area, timings...).
        percept: the system's own perception of the frame, for ``estimate_rotation`` (opaque
            to the loop).
        seen_share: the part's blob area over its area at the taught pose
            (``FrontEnd.seen_share``); None where the system does not know it, or has
            accounted for a hidden part itself (a bar read from the end it shows).
    """

    status: Status
    dx_mm: float = float("nan")
    dy_mm: float = float("nan")
    u_px: float = float("nan")
    v_px: float = float("nan")
    reason: str = ""
    record: dict[str, Any] = field(default_factory=dict)
    percept: Any = field(default=None, repr=False, compare=False)
    seen_share: float | None = None


@dataclass(frozen=True)
class RotationEstimate:
    """The corrective rotation about the approach axis, from the translation's percept.

    Attributes:
        dphi_deg: the corrective rotation (deg).
        record: values for the iteration log.
        dx_mm, dy_mm: a translation refined with the rotation known, where the system has one
            (a full loop then moves by it instead of the translation estimate); None otherwise.
    """

    dphi_deg: float
    record: dict[str, Any] = field(default_factory=dict)
    dx_mm: float | None = None
    dy_mm: float | None = None


class Estimator(Protocol):
    """A vision system usable by the positioning loop.

    ``heading_zero``: the model's zero by the tool's heading in the cell's light (the turn, and
    the translation where it was read: ``calibration_free.heading_zero``), which the loop takes
    off each full look's step; None:
    the system's readings are used as they are."""

    name: str
    heading_zero: HeadingZero | None

    def estimate_translation(self, image: np.ndarray) -> TranslationEstimate:
        """Perceive one frame (HxWx3 uint8 RGB) as far as the translation: localise the part
        and map it to (dx, dy). Cheap: all that a half loop needs."""
        ...

    def estimate_rotation(self, translation: TranslationEstimate) -> RotationEstimate:
        """Go on from an ``ok`` translation estimate's percept to the rotation (and, where the
        system has one, the rotation-aware translation), without a second pass on the frame.

        Raises:
            ValueError: the estimate is not ``ok`` or carries no percept of this system.
        """
        ...


def full_step(estimator: Estimator, image: np.ndarray) -> ToolStep | None:
    """The full loop's step read on ``image`` (translation, then rotation from the same
    percept), None where the part is not found."""
    tr = estimator.estimate_translation(image)
    if tr.status != "ok":
        return None
    return corrective_step(tr, estimator.estimate_rotation(tr))


def corrective_step(translation: TranslationEstimate,
                    rotation: RotationEstimate | None = None) -> ToolStep:
    """The step the loop sends: the translation alone (a half loop), or with the rotation and,
    where the system refined it, the rotation-aware translation (a full loop)."""
    if rotation is None:
        return ToolStep(translation.dx_mm, translation.dy_mm, 0.0, 0.0)
    if rotation.dx_mm is not None and rotation.dy_mm is not None:
        return ToolStep(rotation.dx_mm, rotation.dy_mm, 0.0, rotation.dphi_deg)
    return ToolStep(translation.dx_mm, translation.dy_mm, 0.0, rotation.dphi_deg)


def percept_of(translation: TranslationEstimate, kind: type) -> Any:
    """The percept an ``ok`` translation estimate carries, checked to be ``kind``.

    Raises:
        ValueError: the estimate is not ``ok`` or carries another system's percept.
    """
    if translation.status != "ok" or not isinstance(translation.percept, kind):
        raise ValueError(f"estimate_rotation: needs an ok translation estimate of this system, "
                         f"got status {translation.status!r} with "
                         f"{type(translation.percept).__name__}")
    return translation.percept
