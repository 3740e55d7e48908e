"""The fine-positioning loop of the paper (Fig. 4): half loops while far, then full loops.

grab -> estimate translation -> if |(dx, dy)| > r_fine: move (dx, dy) and look again (a half
loop, counts 0.5) -> else estimate rotation (with a translation refined by it, where the
system has one) and move (dx, dy, dphi) (a full loop, counts 1) ->
repeat until a full look finds a step below the convergence thresholds (no move, the pose is
reached) or the loop budget is spent. "No object" / "ambiguous" stop without moving. Every
step passes the arm's safety layer; a rejected step stops the loop. A turn larger than the
arm's ``max_step_deg`` (a part without symmetry may need up to 180 deg) is sent as several
commands within it (``turn_in_commands``; or taken in part, and the next look measures the
rest). A full look whose turn contradicts the last full loop's (the reading should have
dropped by the turn taken, and it did not) stops the loop without moving (``inconsistent``):
the rotation reading no longer follows the arm, so the next step cannot be trusted either. A
look before the first full loop that finds no part, or little of it (something lies over the
end nearer the camera, which looks at the part from an angle), moves over the part where it
was found and turns the camera to the other side of it, and looks again
(``look_around_deg``). Each such check is one object in ``controller.loop.checks``, with
``Outcome``, how a run ends.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

import cv2
import numpy as np

from controller.loop.checks import (
    LoopChecks,
    Outcome,
    Stop,
    mean_scatter,
)
from controller.loop.iteration_log import IterationLog
from controller.loop.record import IterationRecord, LoopKind
from controller.systems.estimator import (
    Estimator,
    TranslationEstimate,
    corrective_step,
    full_step,
)
from drivers.camera.settle import settled_frame
from drivers.core.errors import MotionRejectedError
from drivers.core.pose import ToolStep
from drivers.interfaces import Arm, Camera, Frame
from drivers.safety import split_step

logger = logging.getLogger(__name__)

GroundTruth = Callable[[], tuple[float, float, float]]
# A converged look's step smaller than both is not made (``LoopConfig.final_step``): finer
# than the arm resolves (VAL takes a pose to 0.01 mm and 0.001 deg).
FINAL_STEP_MIN_MM = 1e-3
FINAL_STEP_MIN_DEG = 1e-3
# How a converged run's reason ends while its step waits for the grasp (``PositioningResult``).
CARRIED = ", carried to the grasp"


class LookRecorder(Protocol):
    """Sees every look as it is logged (``controller.recording.RunRecorder`` is one)."""

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """One look: its complete record, the frame, the translation estimate (whose percept
        holds the localisation), the estimator and the true error when the frame was taken."""
        ...


@dataclass(frozen=True)
class LoopConfig:
    """Config section ``controller.loop``.

    r_fine_mm: above this translation only half (translation) loops are made (paper: 4 mm);
    converge_mm / converge_deg: a full look whose step is below both ends the loop;
    final_step: that look still moves by its step (a full loop: its look and a move, within
    the loop budget) and the loop ends without another look; false: it ends where it is.
    The thresholds say the pose is reached, not that what is left is zero: without the move
    up to a threshold's size stays uncorrected (the cube in good light ended 0.15 deg RMS off
    where the settled readings at the pose scatter by under 0.05 deg);
    max_loops: loop budget (half = 0.5, full = 1);
    reach_factor: a correction read beyond this many times the training range (the NN1
    grid's largest displacement) is not taken: the blob is not the taught part, or the part
    is not where it was taught, and the loop stops (``out_of_range``) without moving;
    settle_frames: a full look whose first frame reads a step within ``settle_mm`` and
    ``settle_deg`` (the loop is settling at the taught pose) reads this many frames (1: every
    look reads one frame, the paper's loop): near the pose the readings' frame-to-frame noise
    is as large as what is left to correct, in a dim frame more so;
    settle_mm / settle_deg: the step a full look's first frame reads within which the look is
    a settling look;
    settle_max_frames / settle_sem_mm / settle_sem_deg: after its ``settle_frames`` such a
    look reads more frames, up to ``settle_max_frames`` in all, while the standard error of
    the mean step (each axis' frame-to-frame standard deviation over the root of the frames
    read) is above ``settle_sem_mm`` in x or y or ``settle_sem_deg`` in the turn: a noisy
    camera (a high gain in a dim cell) gets the frames it needs, a quiet one is not slowed
    (default 0.025 mm and 0.1 deg, docs/decisions/0008-settling-looks.md; None: that axis sets
    no bound; both None: ``settle_frames`` frames, always);
    settle_average: how those frames make one step: ``frames``, the step read from their
    mean frame (the camera's noise averaged out before the part's edge is read: in a dim
    frame's shadows some noisy pixels join the part's blob, which moves its centre one way
    in every frame, so that the mean of the frames' steps keeps it); ``steps``, the mean of
    their steps. Either way a frame without the part or reading outside that window is left
    out;
    turn_check_deg / turn_check_share: after a full loop that turned by t on a reading of
    r, the next full look should read about r - t (zero, unless the turn was cut to the
    arm's ``max_step_deg``); a reading further off than the larger of ``turn_check_deg`` and
    ``turn_check_share`` * |t| stops the loop without moving (``inconsistent``). None: no
    check;
    hidden_check_share: where the loop would end near the taught pose (converged, or the
    budget spent with a translation read within ``r_fine_mm``), a part seen smaller than at
    the taught pose by more than this share of its area is partly hidden (a card, another
    part lying on it), and the pose read from what is seen is off: the loop ends as
    ``occluded`` (no grasp follows). None: no check (nor for a system or model file that
    does not know the taught area);
    look_around_deg / look_around_below: where a look before the first full loop finds no part,
    or sees less than ``look_around_below`` of the part's area at the taught pose, the tool
    moves by the translation read (where the part was found within the training range: a half
    loop's step) and turns about its axis by ``look_around_deg`` (in equal commands within the
    arm's ``max_step_deg``; the look and the move count as a full loop) and the run goes on from
    the next look (stopping as ``no_object`` where that finds none). The camera looks at the
    part from an angle, so something lying over the end nearer the camera hides most of it, and
    a pose read from the rest is off (a screw with half of it hidden: 12 mm); from the other
    side (180 deg) it lies over the far end and hides less. Once a run, and only before the
    first full loop: once the camera has turned to the part's heading a part lost is not
    searched for. ``look_around_deg`` None or 0: no look-around (the paper's loop);
    ``look_around_below`` None: only where no part is found;
    turn_in_commands: a full loop's turn beyond the arm's ``max_step_deg`` (a part without
    symmetry needs up to 180 deg) is sent as equal commands within it, in the same loop, as
    the look-around's is; false: it is cut to ``max_step_deg`` and the next look measures
    the rest (such a part then takes two full loops);
    save_images: save each grabbed image as PNG next to the iteration log.
    """

    r_fine_mm: float = field(default=4.0, metadata={"min": 0.0})
    converge_mm: float = field(default=0.05, metadata={"min": 0.0})
    converge_deg: float = field(default=0.3, metadata={"min": 0.0})
    final_step: bool = True
    max_loops: float = field(default=6.0, metadata={"min": 0.5})
    reach_factor: float = field(default=1.25, metadata={"min": 1.0})
    settle_frames: int = field(default=3, metadata={"min": 1, "max": 32})
    settle_mm: float = field(default=0.5, metadata={"min": 0.0})
    settle_deg: float = field(default=2.0, metadata={"min": 0.0})
    settle_max_frames: int = field(default=16, metadata={"min": 1, "max": 64})
    settle_sem_mm: float | None = field(default=0.025, metadata={"min": 0.0,
                                                                 "exclusive_min": True})
    settle_sem_deg: float | None = field(default=0.1, metadata={"min": 0.0,
                                                                "exclusive_min": True})
    settle_average: Literal["frames", "steps"] = "frames"
    turn_check_deg: float | None = field(default=10.0, metadata={"min": 0.0})
    turn_check_share: float = field(default=0.4, metadata={"min": 0.0, "max": 1.0})
    hidden_check_share: float | None = field(default=0.1, metadata={"min": 0.0, "max": 1.0})
    look_around_deg: float | None = field(default=180.0, metadata={"min": 0.0, "max": 360.0})
    look_around_below: float | None = field(default=0.6, metadata={"min": 0.0, "max": 1.0})
    turn_in_commands: bool = True
    save_images: bool = False

    def settle_known(self, sem: tuple[float, float, float] | None) -> bool:
        """Whether a mean step whose standard errors are ``sem`` (mm, mm, deg; None: below
        two frames) is known to ``settle_sem_mm`` in x and y and ``settle_sem_deg`` in the
        turn: a bound that is None holds; without bounds every mean is known."""
        if self.settle_sem_mm is None and self.settle_sem_deg is None:
            return True
        if sem is None:
            return False
        return (self.settle_sem_mm is None or max(sem[0], sem[1]) <= self.settle_sem_mm) \
            and (self.settle_sem_deg is None or sem[2] <= self.settle_sem_deg)

    def settle_count(self, scatter: tuple[float, float, float] | None) -> int:
        """The frames a settling look reads where single frames' steps scatter by
        ``scatter`` (standard deviations: mm, mm, deg): the fewest from ``settle_frames`` on
        whose mean is ``settle_known``, at most ``settle_max_frames`` (None: not known,
        ``settle_frames``)."""
        if scatter is None:
            return self.settle_frames
        for n in range(self.settle_frames, self.settle_max_frames):
            if self.settle_known(mean_scatter(scatter, n)):
                return n
        return self.settle_max_frames

    def __post_init__(self) -> None:
        if self.settle_max_frames < self.settle_frames:
            raise ValueError(f"settle_max_frames: {self.settle_max_frames} is below "
                             f"settle_frames ({self.settle_frames})")


@dataclass(frozen=True)
class LoopState:
    """The state after a move (or at the start): cumulative loops and, when known, the error."""

    loops: float
    error: tuple[float, float, float] | None


@dataclass
class PositioningResult:
    """outcome: converged | budget | no_object | ambiguous | out_of_range | inconsistent |
    occluded | rejected; reason
    in words;
    loops: cumulative loop count spent; states: LoopState at the start and after every move;
    seconds_per_iteration: wall time of each look-and-move iteration;
    carried: the converged look's step, left for the grasp's first descent move to make
    (``run``'s ``carry_final_step``; None: made, or none to make). The grasp that makes it
    adds its full loop and the state after it (``FinePositioner.grasp``)."""

    run_id: str
    outcome: Outcome
    reason: str
    loops: float
    iterations: int
    states: list[LoopState]
    seconds_per_iteration: list[float]
    carried: ToolStep | None = None

    @property
    def ok(self) -> bool:
        """The loop ran to convergence or spent its budget (no lost part, no rejection)."""
        return self.outcome in ("converged", "budget")

    def carried_made(self, error: tuple[float, float, float] | None) -> None:
        """The grasp's first move made the ``carried`` step: count it as the full loop the
        loop would have made, with ``error`` the state after it."""
        self.loops += 1.0
        self.iterations += 1
        self.states.append(LoopState(self.loops, error))
        self.reason = self.reason.replace(CARRIED, ", and made by the grasp's first move")

    def carried_dropped(self) -> None:
        """The ``carried`` step was not made (the arm moved before the grasp)."""
        self.reason = self.reason.replace(CARRIED, ", not made (the arm moved before the grasp)")


def _less(step: ToolStep, zero: ToolStep | None) -> ToolStep:
    """``step`` with a zero (the step read at the taught pose at the tool's heading) taken
    off."""
    if zero is None:
        return step
    return dataclasses.replace(step, dx_mm=step.dx_mm - zero.dx_mm,
                               dy_mm=step.dy_mm - zero.dy_mm,
                               dphi_deg=step.dphi_deg - zero.dphi_deg)


def _turn_within_limits(step: ToolStep, arm: Arm) -> ToolStep:
    """The step with its rotation cut to the arm's ``max_step_deg``: a part without symmetry
    (kappa 1) may need a turn of up to 180 deg, which the safety layer rejects as one command;
    the loop turns as far as allowed and the next look measures the rest."""
    limits = getattr(arm, "limits", None)
    if limits is None or abs(step.dphi_deg) <= limits.max_step_deg:
        return step
    logger.debug("turn of %.1f deg taken in part (max_step_deg %g)", step.dphi_deg,
                 limits.max_step_deg)
    return dataclasses.replace(step, dphi_deg=math.copysign(limits.max_step_deg, step.dphi_deg))


@dataclass
class _Look:
    """One look: the frame, the translation read, its record and its clock (start, grabbed[,
    perceived])."""

    frame: Frame
    tr: TranslationEstimate
    record: IterationRecord
    clock: tuple[float, ...]


@dataclass
class _Run:
    """What a run has spent so far."""

    run_id: str
    budget: float
    states: list[LoopState]
    loops: float = 0.0
    iteration: int = 0
    per_iteration: list[float] = field(default_factory=list)

    def affords(self, cost: float) -> bool:
        """Whether the budget has ``cost`` loops left."""
        return self.loops + cost <= self.budget + 1e-9

    def moved(self, cost: float, error: tuple[float, float, float] | None,
              seconds: float) -> None:
        self.loops += cost
        self.iteration += 1
        self.states.append(LoopState(self.loops, error))
        self.per_iteration.append(seconds)

    def finish(self, outcome: Outcome, reason: str,
               carried: ToolStep | None = None) -> PositioningResult:
        logger.debug("positioning %s: %s after %.1f loops (%s)", self.run_id, outcome,
                     self.loops, reason)
        return PositioningResult(self.run_id, outcome, reason, self.loops, self.iteration,
                                 self.states, self.per_iteration, carried)


class PositioningLoop:
    """Runs the half/full loop with one estimator on one arm and camera."""

    def __init__(self, arm: Arm, camera: Camera, config: LoopConfig,
                 log: IterationLog | None = None, ground_truth: GroundTruth | None = None,
                 image_dir: str | Path | None = None,
                 recorder: LookRecorder | None = None, reach_mm: float | None = None) -> None:
        self.arm = arm
        self.reach_mm = reach_mm  # the training range (None: not checked)
        self.camera = camera
        self.config = config
        self.log = log
        self.ground_truth = ground_truth
        self.image_dir = Path(image_dir) if image_dir else (log.path.parent if log else None)
        self.recorder = recorder
        self._abort = False
        self._look: tuple[Frame, TranslationEstimate, Estimator, tuple | None] | None = None

    def abort(self) -> None:
        """Ask a running loop to stop before its next move (thread-safe flag)."""
        self._abort = True

    def _error(self) -> tuple[float, float, float] | None:
        return tuple(self.ground_truth()) if self.ground_truth else None

    def run(self, estimator: Estimator, max_loops: float | None = None,
            run_id: str | None = None, carry_final_step: bool = False) -> PositioningResult:
        """Position from wherever the arm is, one look per iteration, until converged.

        Args:
            estimator: the vision system (``controller.systems``).
            max_loops: the loop budget (default ``config.max_loops``).
            run_id: names the run in the iteration log (default: a fresh random id).
            carry_final_step: a grasp follows: the converged look's step
                (``LoopConfig.final_step``) is not made here but returned as the result's
                ``carried``, for the grasp's first descent move to make (the same move, no
                extra one). The look is logged as ``check`` with ``final_step: carried``.

        Returns:
            The outcome, the loops spent and the state after every move (see
            PositioningResult). A lost part, a rejected step and an abort end the run
            without an exception.
        """
        self._abort = False
        run = _Run(run_id or uuid.uuid4().hex[:12],
                   self.config.max_loops if max_loops is None else max_loops,
                   [LoopState(0.0, self._error())])
        checks = LoopChecks.for_run(self.config, self.reach_mm)
        first = True
        while True:
            if self._abort:
                return run.finish(Outcome.REJECTED, "aborted")
            look = self._look_once(estimator, run, settle=first)
            first = False
            around = checks.look_around.step(look.tr, checks.reach, look.record,
                                             affordable=run.affords(1.0))
            if around is not None:
                look.record.commanded = around
                refused = self._make(run, look, "around", 1.0)
                if refused is not None:
                    return refused
                continue
            if look.tr.status != "ok":
                return self._stop(run, look, Stop(Outcome(look.tr.status),
                                                  look.tr.reason or look.tr.status))
            stop = checks.reach.check(look.tr)
            if stop is not None:
                return self._stop(run, look, stop)
            kind, cost, read = self._read_step(estimator, look, checks)
            if isinstance(read, Stop):
                return self._stop(run, look, read)
            step = read if kind == "half" or self.config.turn_in_commands else \
                _turn_within_limits(read, self.arm)
            look.record.commanded = step
            ended = self._end(run, look, kind, cost, step, checks, carry_final_step)
            if ended is not None:
                return ended
            refused = self._make(run, look, kind, cost)
            if refused is not None:
                return refused
            if kind == "full":
                checks.look_around.full_made = True
                checks.turn.turned(read, look.record.executed)

    def _look_once(self, estimator: Estimator, run: _Run, settle: bool = False) -> _Look:
        """Grab a frame (``settle``: once the camera's exposure holds, as for a run's first
        look) and read the translation; the look's record."""
        t0 = time.perf_counter()
        frame = settled_frame(self.camera) if settle else self.camera.grab()
        t1 = time.perf_counter()
        tr = estimator.estimate_translation(frame.image)
        error = run.states[-1].error
        self._look = (frame, tr, estimator, error)
        record = IterationRecord(time.time(), run.run_id, estimator.name, run.iteration + 1,
                                 tr.u_px, tr.v_px, tr.status, dict(tr.record),
                                 loops=run.loops, error=error)
        if tr.status != "ok":
            record.estimates["reason"] = tr.reason  # why the part was not found
        return _Look(frame, tr, record, (t0, t1))

    def _read_step(self, estimator: Estimator, look: _Look, checks: LoopChecks
                   ) -> tuple[LoopKind, float, ToolStep | Stop]:
        """The look's kind, cost and step: a half loop's translation while far, else a full
        loop's step (the rotation read, the zero at the tool's heading taken off, the turn
        checked, and settled near the pose); a ``Stop`` where the turn check fails (the step
        read is then the record's ``commanded``)."""
        tr = look.tr
        if math.hypot(tr.dx_mm, tr.dy_mm) > self.config.r_fine_mm:
            return "half", 0.5, corrective_step(tr)
        rot = estimator.estimate_rotation(tr)
        look.record.estimates.update(rot.record)
        zero = self._heading_zero(estimator, look.record)
        read = _less(corrective_step(tr, rot), zero)
        stop = checks.turn.check(read, look.record)
        if stop is not None:
            look.record.commanded = read
            return "full", 1.0, stop
        if checks.settling.wanted(read):
            read = checks.settling.read(
                read, look.frame.image, look.record, lambda: self.camera.grab().image,
                lambda image: self._full_step(estimator, image, zero))
        return "full", 1.0, read

    def _end(self, run: _Run, look: _Look, kind: LoopKind, cost: float, step: ToolStep,
             checks: LoopChecks, carry_final_step: bool) -> PositioningResult | None:
        """The result where this look ends the run (converged, the budget spent, or the part
        partly hidden there), else None. A converged look still makes its step
        (``final_step``), or leaves it to the grasp (``carry_final_step``)."""
        cfg, tr = self.config, look.tr
        shift = math.hypot(step.dx_mm, step.dy_mm)
        look.clock = (*look.clock[:2], time.perf_counter())
        converged = kind == "full" and shift <= cfg.converge_mm and \
            abs(step.dphi_deg) <= cfg.converge_deg
        spent = not converged and not run.affords(cost)
        if converged or spent:
            hidden = checks.hidden.check(tr, math.hypot(tr.dx_mm, tr.dy_mm))
            if hidden is not None:
                return self._stop(run, look, hidden)
        if spent:
            return self._stop(run, look, Stop(Outcome.BUDGET,
                                              f"loop budget {run.budget:g} spent"))
        if not converged:
            return None
        reason = f"step {shift:.3f} mm / {step.dphi_deg:.2f} deg below the convergence " \
                 "thresholds"
        if cfg.final_step and run.affords(cost) and \
                (shift >= FINAL_STEP_MIN_MM or abs(step.dphi_deg) >= FINAL_STEP_MIN_DEG):
            if carry_final_step:
                look.record.estimates["final_step"] = "carried"
                self._write(look.record, "check", look.clock, look.frame.image)
                return run.finish(Outcome.CONVERGED, reason + CARRIED, step)
            refused = self._make(run, look, "check", cost)
            return refused if refused is not None else \
                run.finish(Outcome.CONVERGED, reason + ", and made")
        self._write(look.record, "check", look.clock, look.frame.image)
        return run.finish(Outcome.CONVERGED, reason)

    def _stop(self, run: _Run, look: _Look, stop: Stop) -> PositioningResult:
        """End the run at this look without a move, logged as a stop."""
        clock = look.clock if len(look.clock) > 2 else (*look.clock, time.perf_counter())
        self._write(look.record, "stop", clock, look.frame.image)
        return run.finish(stop.outcome, stop.reason)

    def _make(self, run: _Run, look: _Look, kind: LoopKind,
              cost: float) -> PositioningResult | None:
        """Make the look's move and count it; the result where the arm refused it."""
        outcome = self._move(look.record, kind, cost, look.clock, look.frame.image)
        if isinstance(outcome, str):
            return run.finish(Outcome.REJECTED, outcome)
        run.moved(cost, look.record.error, outcome)
        return None

    def _move(self, record: IterationRecord, kind: LoopKind, cost: float,
              clock: tuple[float, ...], image) -> float | str:
        """Send the look's commanded step to the arm (split within the arm's step limits,
        ``drivers.safety.split_step``: a turn beyond ``max_step_deg`` in equal commands, the
        translation with the first) and log
        the look as ``kind``, its loops and error those after the move. Returns the
        look-and-move's wall time (s), or why the safety layer rejected a command (the look
        is then logged as a stop)."""
        t2 = clock[2] if len(clock) > 2 else time.perf_counter()
        commands = split_step(record.commanded, getattr(self.arm, "limits", None),
                              turn_only=True)
        sent = []
        try:
            for command in commands:
                motion = self.arm.move_tool(command)
                sent.append(motion)
        except MotionRejectedError as exc:
            record.rejected = exc.reason
            self._write(record, "stop", (*clock[:2], t2, time.perf_counter()), image)
            return f"safety layer rejected the step: {exc.reason}"
        t3 = time.perf_counter()
        record.loops += cost
        record.error = self._error()
        record.executed = ToolStep(*(sum(getattr(m.sent, f) for m in sent)
                                     for f in ("dx_mm", "dy_mm", "dz_mm", "dphi_deg")))
        record.clipped = any(m.clipped for m in sent)
        record.pose_after = sent[-1].pose
        self._write(record, kind, (*clock[:2], t2, t3), image)
        return t3 - clock[0]

    @staticmethod
    def _full_step(estimator: Estimator, image: np.ndarray,
                   zero: ToolStep | None) -> ToolStep | None:
        """The full step read on ``image`` less ``zero``, None where the part is not found."""
        step = full_step(estimator, image)
        return None if step is None else _less(step, zero)

    def _heading_zero(self, estimator: Estimator, record: IterationRecord) -> ToolStep | None:
        """The estimator's zero at the tool's heading (``calibration_free.heading_zero``; the
        pose the last move reached, no exchange where the arm keeps it): its turn logged as
        ``heading_zero`` (deg) and its translation as ``heading_zero_mm`` ([dx, dy]), with the
        heading (null: beyond the headings it was read at, or the translation not read);
        None where the model has no zero by heading or none at this heading."""
        table = estimator.heading_zero
        if table is None:
            return None
        heading = self.arm.pose(fresh=False).approach_rotation_deg
        turn, shift = table.at(heading), table.shift_at(heading)
        record.estimates["heading_deg"] = heading
        record.estimates["heading_zero"] = turn
        record.estimates["heading_zero_mm"] = None if shift is None else list(shift)
        if turn is None:
            return None
        dx, dy = shift or (0.0, 0.0)
        return ToolStep(dx, dy, 0.0, turn)

    def _write(self, record: IterationRecord, kind: LoopKind, clock: tuple[float, ...],
               image) -> None:
        """Log one look: ``clock`` is (start, grabbed, perceived[, moved]) from perf_counter;
        without a move the move took no time. The ``recorder`` (if any) sees the record after
        the log has it."""
        if self.log is None and self.recorder is None:
            return
        t0, t1, t2 = clock[:3]
        t3 = clock[3] if len(clock) > 3 else t2
        record.loop_kind = kind
        record.timings_ms = {"grab": (t1 - t0) * 1e3, "perceive": (t2 - t1) * 1e3,
                             "move": (t3 - t2) * 1e3}
        if self.log is not None and self.config.save_images and self.image_dir is not None:
            name = f"{record.run_id}-{record.iteration:03d}-{kind}.png"
            self.image_dir.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(self.image_dir / name), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
            record.image = name
        if self.log is not None:
            self.log.write(record.as_dict())
        if self.recorder is not None and self._look is not None:
            frame, estimate, estimator, error_at_look = self._look
            self.recorder.look(record, frame, estimate, estimator, error_at_look)
