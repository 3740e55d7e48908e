"""One look of the positioning loop, as the iteration log stores it (one JSON line)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from drivers.core.pose import Pose, ToolStep

LoopKind = Literal["half", "full", "around", "check", "stop"]


@dataclass
class IterationRecord:
    """What the loop saw, decided and did in one look.

    Attributes:
        time: wall clock at the look (s since the epoch).
        run_id: the positioning run this look belongs to.
        system: the vision system's name.
        iteration: 1 for the first look of a run.
        u_px, v_px: the part's centre in the image (NaN when not found).
        status: ``ok``, ``no_object`` or ``ambiguous``.
        estimates: the estimators' values for the log (network outputs, timings...).
        loop_kind: ``half`` or ``full`` (a move was made), ``around`` (the look-around's
            turn, ``LoopConfig.look_around_deg``), ``check`` (a full look found its
            step below the convergence thresholds: the loop ends, after moving by that step
            where ``LoopConfig.final_step``), ``stop`` (no move: lost part, budget spent,
            rejected step).
        loops: cumulative loop count after this look (half = 0.5, full = 1).
        commanded: the step the loop asked for (None when it computed none).
        executed: the step the arm was sent after the safety layer (None without a move).
        clipped: the safety layer clipped the step.
        pose_after: the arm's pose after the move (None without a move).
        timings_ms: wall time of ``grab``, ``perceive`` and ``move``.
        error: the true (x_mm, y_mm, phi_deg) error after this look, where the cell knows it.
        rejected: why the safety layer rejected the step, if it did.
        image: the saved image's file name (``controller.loop.save_images``), if saved.
    """

    time: float
    run_id: str
    system: str
    iteration: int
    u_px: float
    v_px: float
    status: str
    estimates: dict[str, Any] = field(default_factory=dict)
    loop_kind: LoopKind = "stop"
    loops: float = 0.0
    commanded: ToolStep | None = None
    executed: ToolStep | None = None
    clipped: bool = False
    pose_after: Pose | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    error: tuple[float, float, float] | None = None
    rejected: str | None = None
    image: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The log's JSON record (field order as read by people: who, what was seen, what was
        done, how long, how far off)."""
        record: dict[str, Any] = {
            "time": self.time, "run_id": self.run_id, "system": self.system,
            "iteration": self.iteration, "u_px": self.u_px, "v_px": self.v_px,
            "status": self.status, **self.estimates,
        }
        if self.rejected is not None:
            record["rejected"] = self.rejected
        record.update({
            "loop_kind": self.loop_kind, "loops": self.loops,
            "commanded": self.commanded.as_dict() if self.commanded else None,
            "executed": self.executed.as_dict() if self.executed else None,
            "clipped": self.clipped,
            "pose_after": self.pose_after.as_dict() if self.pose_after else None,
            "timings_ms": self.timings_ms,
            "error": ({"x_mm": self.error[0], "y_mm": self.error[1],
                       "phi_deg": self.error[2]} if self.error is not None else None),
        })
        if self.image is not None:
            record["image"] = self.image
        return record
