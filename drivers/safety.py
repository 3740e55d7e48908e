"""The safety layer: pure checks of a motion command against the workspace box and step limits.

Applied in one place (``drivers.interfaces.Arm``) to every backend. A command beyond a limit is
either rejected (MotionRejectedError, nothing moves) or clipped onto the limit, as configured;
either way it is logged. A motion longer than the step limits is split into commands within
them here, and only here (``split_step``, ``split_target``): the loop, acquisition and the
calibrations call these.
"""

from __future__ import annotations

import dataclasses
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


def pieces(step: ToolStep, limits: SafetyLimits | None) -> int:
    """How many equal commands ``step`` takes within ``limits`` (None: one)."""
    if limits is None:
        return 1
    return max(1, math.ceil(max(step.translation_mm / limits.max_step_mm,
                                abs(step.dphi_deg) / limits.max_step_deg) - 1e-9))


def split_step(step: ToolStep, limits: SafetyLimits | None, *,
               turn_only: bool = False) -> list[ToolStep]:
    """``step`` as consecutive tool steps within ``limits``: the translation first, in equal
    parts, then the turn in equal parts, the last translation part and the first turn part in
    one command. A tool step translates in the tool frame before it turns, so the commands end
    where the whole step would; within the limits, it is ``[step]``. ``turn_only``: only the
    turn is split, a translation beyond ``max_step_mm`` is sent whole, for the safety check to
    reject or clip (the positioning loop: so long a correction is no fine step)."""
    if limits is None:
        return [step]
    moves = 1 if turn_only else \
        max(1, math.ceil(step.translation_mm / limits.max_step_mm - 1e-9))
    turns = max(1, math.ceil(abs(step.dphi_deg) / limits.max_step_deg - 1e-9))
    if moves == turns == 1:
        return [step]
    part = ToolStep(step.dx_mm / moves, step.dy_mm / moves, step.dz_mm / moves, 0.0)
    turn = step.dphi_deg / turns
    return [part] * (moves - 1) + [dataclasses.replace(part, dphi_deg=turn)] + \
        [ToolStep(0.0, 0.0, 0.0, turn)] * (turns - 1)


def split_target(here: Pose, target: Pose, limits: SafetyLimits | None) -> list[Pose]:
    """The absolute targets of a move from ``here`` to ``target`` within ``limits``: equal
    fractions of the tool step between them, each reached from the one before."""
    step = here.tool_step_to(target)
    n = pieces(step, limits)
    fractions = [i / n for i in range(1, n + 1)]
    return [here.moved_in_tool_frame(ToolStep(step.dx_mm * f, step.dy_mm * f, step.dz_mm * f,
                                              step.dphi_deg * f)) for f in fractions]


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
