"""The safety layer: pure checks of a motion command against the workspace box and step limits.

Applied in one place (``drivers.interfaces.Arm``) to every backend. A command beyond a limit is
either rejected (MotionRejectedError, nothing moves) or clipped onto the limit, as configured;
either way it is logged.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from drivers.core.errors import MotionRejectedError
from drivers.core.pose import Pose, ToolStep

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SafetyLimits:
    """Limits every motion must respect (config section ``safety``).

    workspace_min_mm / workspace_max_mm: the box the tool centre point must stay in (world frame);
    max_step_mm: largest translation of one command; max_step_deg: largest rotation about the
    approach axis of one command; on_violation: ``reject`` or ``clip``.
    """

    workspace_min_mm: tuple[float, float, float] = field(
        default=(-450.0, -450.0, 0.0), metadata={"length": 3})
    workspace_max_mm: tuple[float, float, float] = field(
        default=(450.0, 450.0, 700.0), metadata={"length": 3})
    max_step_mm: float = field(default=60.0, metadata={"min": 0.0, "exclusive_min": True})
    max_step_deg: float = field(default=100.0, metadata={"min": 0.0, "exclusive_min": True})
    on_violation: Literal["reject", "clip"] = "reject"

    def __post_init__(self) -> None:
        for lo, hi in zip(self.workspace_min_mm, self.workspace_max_mm, strict=True):
            if not lo < hi:
                raise ValueError("safety.workspace_min_mm must be below workspace_max_mm on every "
                                 f"axis, got {self.workspace_min_mm} / {self.workspace_max_mm}")


@dataclass(frozen=True)
class StepDecision:
    step: ToolStep
    clipped: bool
    reason: str | None = None


@dataclass(frozen=True)
class TargetDecision:
    target: Pose
    clipped: bool
    reason: str | None = None


def _violation(limits: SafetyLimits, reason: str) -> None:
    if limits.on_violation == "reject":
        logger.warning("motion rejected: %s", reason)
        raise MotionRejectedError(reason)
    logger.warning("motion clipped: %s", reason)


def clip_step(step: ToolStep, limits: SafetyLimits) -> tuple[ToolStep, str | None]:
    """Scale the translation down to max_step_mm and clamp the rotation to max_step_deg."""
    reasons = []
    scale = 1.0
    if step.translation_mm > limits.max_step_mm:
        scale = limits.max_step_mm / step.translation_mm
        reasons.append(f"step of {step.translation_mm:.2f} mm exceeds max_step_mm "
                       f"{limits.max_step_mm:g}")
    dphi = step.dphi_deg
    if abs(dphi) > limits.max_step_deg:
        reasons.append(f"rotation of {dphi:.2f} deg exceeds max_step_deg {limits.max_step_deg:g}")
        dphi = math.copysign(limits.max_step_deg, dphi)
    clipped = ToolStep(step.dx_mm * scale, step.dy_mm * scale, step.dz_mm * scale, dphi)
    return clipped, ("; ".join(reasons) or None)


def workspace_violation(position_mm, limits: SafetyLimits) -> str | None:
    """Describe how ``position_mm`` leaves the workspace box, or None when inside."""
    lo, hi = np.asarray(limits.workspace_min_mm), np.asarray(limits.workspace_max_mm)
    p = np.asarray(position_mm, dtype=float)
    outside = [f"{axis}={v:.1f} not in [{a:g}, {b:g}]"
               for axis, v, a, b in zip("xyz", p, lo, hi, strict=True) if not a <= v <= b]
    return ("target outside workspace: " + ", ".join(outside)) if outside else None


def check_tool_step(step: ToolStep, current: Pose, limits: SafetyLimits) -> StepDecision:
    """Check a relative tool-frame step taken from ``current``; reject or clip it."""
    sent, reason = clip_step(step, limits)
    if reason:
        _violation(limits, reason)
    target = current.moved_in_tool_frame(sent)
    ws = workspace_violation(target.position_mm, limits)
    if ws:
        _violation(limits, ws)
        inside = np.clip(target.position_mm, limits.workspace_min_mm, limits.workspace_max_mm)
        target = Pose.from_matrix(inside, target.rotation())
        sent = current.tool_step_to(target)
    reasons = "; ".join(r for r in (reason, ws) if r) or None
    return StepDecision(sent, reasons is not None, reasons)


def check_target(target: Pose, current: Pose, limits: SafetyLimits) -> TargetDecision:
    """Check an absolute target reached from ``current``; reject or clip it."""
    if not target.is_finite():
        raise MotionRejectedError(f"target pose is not finite: {target}")
    step = current.tool_step_to(target)
    decision = check_tool_step(step, current, limits)
    if not decision.clipped:
        return TargetDecision(target, False)
    return TargetDecision(current.moved_in_tool_frame(decision.step), True, decision.reason)
