"""The positioning loop's checks, one small object each, and how a run ends (``Outcome``).

The loop (``controller.loop.positioning``) is the paper's: look, a half or a full step, move.
Around it sit the checks a real cell needs, each switched off in the recipe by its own key:

- ``LookAround``: a look before the first full loop that finds no part, or little of it, moves
  over the part where it was found and turns the camera to look from another side
  (``look_around_deg`` null: off).
- ``ReachCheck``: a correction read beyond the training range is not taken (``out_of_range``;
  the training range unknown: off).
- ``TurnCheck``: after a full loop the next full look must read about what the turn left
  (``inconsistent``; ``turn_check_deg`` null: off).
- ``Settling``: near the pose a full look reads several frames and steps by their mean
  (``settle_frames`` 1: off).
- ``HiddenCheck``: where the loop would end, a part seen smaller than at the taught pose is
  partly hidden (``occluded``; ``hidden_check_share`` null: off).

Each is built for one run (``LoopChecks.for_run``) and keeps that run's state.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration_free.preprocess import mean_frame
from controller.loop.record import IterationRecord
from controller.systems.estimator import TranslationEstimate
from drivers.core.pose import ToolStep


class Outcome(enum.StrEnum):
    """How a positioning run ended.

    ``converged``: a full look's step is below the convergence thresholds; ``budget``: the
    loop budget is spent; ``no_object`` / ``ambiguous``: the look found no part, or several
    blobs it cannot tell apart; ``out_of_range``: the correction read is beyond the training
    range (``ReachCheck``); ``inconsistent``: the turn read contradicts the last loop's
    (``TurnCheck``); ``occluded``: the part is partly hidden where the loop would end
    (``HiddenCheck``); ``rejected``: the safety layer refused a move, or the run was aborted.
    """

    CONVERGED = "converged"
    BUDGET = "budget"
    NO_OBJECT = "no_object"
    AMBIGUOUS = "ambiguous"
    OUT_OF_RANGE = "out_of_range"
    INCONSISTENT = "inconsistent"
    OCCLUDED = "occluded"
    REJECTED = "rejected"


# Outcomes that end a run early, before convergence or the loop budget: the arm is left where
# the last accepted move put it.
STOPPED: tuple[Outcome, ...] = (Outcome.NO_OBJECT, Outcome.AMBIGUOUS, Outcome.OUT_OF_RANGE,
                                Outcome.INCONSISTENT, Outcome.OCCLUDED, Outcome.REJECTED)


@dataclass(frozen=True)
class Stop:
    """A check's verdict that the run ends here, without a move."""

    outcome: Outcome
    reason: str


class ReachCheck:
    """A correction read beyond ``factor`` times the training range (``reach_mm``, the NN1
    grid's largest displacement; None: not known, no check) is not taken: the blob is not the
    taught part, or the part is not where it was taught."""

    def __init__(self, factor: float, reach_mm: float | None) -> None:
        self.factor, self.reach_mm = factor, reach_mm

    def beyond(self, tr: TranslationEstimate) -> bool:
        """Whether an ``ok`` look's translation lies beyond the reach."""
        return self.reach_mm is not None and \
            math.hypot(tr.dx_mm, tr.dy_mm) > self.factor * self.reach_mm

    def check(self, tr: TranslationEstimate) -> Stop | None:
        if not self.beyond(tr):
            return None
        return Stop(Outcome.OUT_OF_RANGE,
                    f"the correction read, {math.hypot(tr.dx_mm, tr.dy_mm):.1f} mm, is beyond "
                    f"the training range ({self.reach_mm:.1f} mm): not the taught part, or not "
                    "where it was taught")


class LookAround:
    """Once a run, before its first full loop: a look that finds no part, or sees less than
    ``below`` of its area at the taught pose (None: only where none is found), moves over the
    part where it was found within reach and turns the tool by ``turn_deg`` (None or 0: off)."""

    def __init__(self, turn_deg: float | None, below: float | None) -> None:
        self.turn_deg, self.below = turn_deg, below
        self.done = False  # made this run
        self.full_made = False  # a full loop was made this run: too late to look around

    def wanted(self, tr: TranslationEstimate) -> bool:
        """Whether this look calls for the look-around (ignoring whether one was made)."""
        if not self.turn_deg:
            return False
        if tr.status != "ok":
            return tr.status == "no_object"
        return self.below is not None and tr.seen_share is not None \
            and tr.seen_share < self.below

    def step(self, tr: TranslationEstimate, reach: ReachCheck, record: IterationRecord, *,
             affordable: bool) -> ToolStep | None:
        """The look-around's step where this look calls for it (logged in the record's
        ``look_around``), else None. ``affordable``: the budget has a full loop left."""
        if self.full_made or self.done or not self.wanted(tr) or not affordable:
            return None
        self.done = True
        # where the part was found within reach the tool first moves over it (a half loop's
        # step), so the turn does not swing the camera round a far part
        found = tr.status == "ok" and not reach.beyond(tr)
        shift = (tr.dx_mm, tr.dy_mm) if found else (0.0, 0.0)
        seen = "the part not found" if tr.status != "ok" else \
            f"{tr.seen_share:.0%} of the part seen"
        how = f"moving by the {math.hypot(*shift):.1f} mm read and turning" if found \
            else "turning"
        record.estimates["look_around"] = \
            f"{seen}: {how} the tool by {self.turn_deg:g} deg to look from another side"
        return ToolStep(*shift, 0.0, self.turn_deg)


class TurnCheck:
    """After a full loop that turned by t on a reading of r, the next full look should read
    about r - t; further off than the larger of ``min_deg`` and ``share`` * |t| is
    ``inconsistent`` (``min_deg`` None: off)."""

    def __init__(self, min_deg: float | None, share: float) -> None:
        self.min_deg, self.share = min_deg, share
        self.expected: tuple[float, float] | None = None  # (turn, tolerance), once a full loop

    def check(self, read: ToolStep, record: IterationRecord) -> Stop | None:
        """The verdict on a full look's turn (the expectation logged as
        ``turn_expected_deg``)."""
        if self.expected is None:
            return None
        expected, tolerance = self.expected
        record.estimates["turn_expected_deg"] = expected
        if abs(read.dphi_deg - expected) <= tolerance:
            return None
        return Stop(Outcome.INCONSISTENT,
                    f"the turn read, {read.dphi_deg:.1f} deg, contradicts the last loop's "
                    f"(about {expected:.1f} deg expected): the rotation reading does not "
                    "follow the arm")

    def turned(self, read: ToolStep, executed: ToolStep) -> None:
        """A full loop read ``read`` and made ``executed``."""
        if self.min_deg is not None:
            turned = executed.dphi_deg
            self.expected = (read.dphi_deg - turned,
                             max(self.min_deg, self.share * abs(turned)))


class HiddenCheck:
    """Where the loop would end near the taught pose (the translation read within
    ``r_fine_mm``), a part seen smaller than there by more than ``share`` of its area is
    partly hidden, and the pose read from what is seen is off (``share`` None: off)."""

    def __init__(self, share: float | None, r_fine_mm: float) -> None:
        self.share, self.r_fine_mm = share, r_fine_mm

    def check(self, tr: TranslationEstimate, read_mm: float) -> Stop | None:
        if self.share is None or tr.seen_share is None or read_mm > self.r_fine_mm \
                or tr.seen_share >= 1.0 - self.share:
            return None
        return Stop(Outcome.OCCLUDED,
                    f"the part shows {tr.seen_share:.0%} of its area at the taught pose: "
                    "something hides part of it, so the pose read from what is seen is off")


class Settling:
    """Near the pose a full look reads several frames and steps by their mean
    (``LoopConfig``: ``settle_frames``, the window ``settle_mm`` / ``settle_deg``, the bounds
    ``settle_sem_*`` up to ``settle_max_frames``, ``settle_average``)."""

    def __init__(self, config: Any) -> None:
        self.config = config

    def within(self, step: ToolStep) -> bool:
        """Whether a step lies in the settle window."""
        return math.hypot(step.dx_mm, step.dy_mm) <= self.config.settle_mm and \
            abs(step.dphi_deg) <= self.config.settle_deg

    def wanted(self, read: ToolStep) -> bool:
        """Whether a full look reading ``read`` is a settling look."""
        return self.config.settle_frames > 1 and self.within(read)

    def read(self, first: ToolStep, image: np.ndarray, record: IterationRecord,
             grab: Callable[[], np.ndarray],
             step_of: Callable[[np.ndarray], ToolStep | None]) -> ToolStep:
        """One step from ``first`` (read on ``image``) and ``settle_frames - 1`` more frames
        (``grab``; ``step_of`` reads a frame's full step, None where the part is not found),
        and more while their mean step is not known to ``settle_sem_mm`` / ``settle_sem_deg``
        (``settle_max_frames`` in all; ``settle_average``). A frame where the part is not
        found, or whose step is outside the settle window (a misreading), is left out. The
        record keeps every frame's step (``settle``, the first one first; null where not
        found), the standard error of their mean step (``settle_sem``: mm, mm, deg; null below
        two frames) and the mean frame's step (``settle_mean_frame``). Where the mean frame
        reads no part or a step outside the window, the frames' mean step is taken."""
        cfg = self.config
        steps, images = [first], [image]
        read: list[list[float] | None] = [[first.dx_mm, first.dy_mm, first.dphi_deg]]
        while len(read) < cfg.settle_frames or (
                len(read) < cfg.settle_max_frames and not cfg.settle_known(
                    standard_errors(steps))):
            image = grab()
            step = step_of(image)
            if step is None:
                read.append(None)
                continue
            read.append([step.dx_mm, step.dy_mm, step.dphi_deg])
            if self.within(step):
                steps.append(step)
                images.append(image)
        record.estimates["settle"] = read
        sem = standard_errors(steps)
        record.estimates["settle_sem"] = None if sem is None else list(sem)
        if cfg.settle_average == "frames" and len(images) > 1:
            step = step_of(mean_frame(images))
            record.estimates["settle_mean_frame"] = None if step is None else \
                [step.dx_mm, step.dy_mm, step.dphi_deg]
            if step is not None and self.within(step):
                return ToolStep(step.dx_mm, step.dy_mm, 0.0, step.dphi_deg)
        n = len(steps)
        return ToolStep(sum(s.dx_mm for s in steps) / n, sum(s.dy_mm for s in steps) / n, 0.0,
                        sum(s.dphi_deg for s in steps) / n)


@dataclass
class LoopChecks:
    """One run's checks."""

    look_around: LookAround
    reach: ReachCheck
    turn: TurnCheck
    settling: Settling
    hidden: HiddenCheck

    @classmethod
    def for_run(cls, config: Any, reach_mm: float | None) -> LoopChecks:
        """Fresh checks for a run with the loop's ``config`` (``LoopConfig``)."""
        return cls(LookAround(config.look_around_deg, config.look_around_below),
                   ReachCheck(config.reach_factor, reach_mm),
                   TurnCheck(config.turn_check_deg, config.turn_check_share),
                   Settling(config), HiddenCheck(config.hidden_check_share, config.r_fine_mm))


def step_scatter(steps: list[ToolStep]) -> tuple[float, float, float] | None:
    """The sample standard deviation of ``steps`` in x, y (mm) and the turn (deg); None
    below two."""
    if len(steps) < 2:
        return None
    values = np.array([(s.dx_mm, s.dy_mm, s.dphi_deg) for s in steps])
    sd = values.std(axis=0, ddof=1)
    return float(sd[0]), float(sd[1]), float(sd[2])


def standard_errors(steps: list[ToolStep]) -> tuple[float, float, float] | None:
    """The standard error of the mean of ``steps`` in x, y (mm) and the turn (deg): each
    axis' sample standard deviation over the root of their number; None below two."""
    sd = step_scatter(steps)
    return None if sd is None else mean_scatter(sd, len(steps))


def mean_scatter(scatter: tuple[float, float, float], n: int) -> tuple[float, float, float]:
    """The standard errors (x, y mm, the turn deg) of a mean of ``n`` frames' steps whose
    single frames scatter by ``scatter`` (standard deviations)."""
    root = math.sqrt(n)
    return scatter[0] / root, scatter[1] / root, scatter[2] / root
