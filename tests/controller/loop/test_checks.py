"""The positioning loop's checks, each on its own."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controller.loop.checks import (
    STOPPED,
    HiddenCheck,
    LookAround,
    LoopChecks,
    Outcome,
    ReachCheck,
    Settling,
    TurnCheck,
)
from controller.loop.positioning import LoopConfig
from controller.loop.record import IterationRecord
from controller.systems.estimator import TranslationEstimate
from drivers.core.pose import ToolStep


def record() -> IterationRecord:
    return IterationRecord(0.0, "r", "test", 1, 0.0, 0.0, "ok", {})


def seen(dx: float = 0.0, dy: float = 0.0, share: float | None = 1.0) -> TranslationEstimate:
    return TranslationEstimate("ok", dx, dy, seen_share=share)


LOST = TranslationEstimate("no_object", reason="no blob")


def test_outcomes_are_strings_in_reports_and_stopped_ones_are_early_ends():
    assert Outcome.OUT_OF_RANGE == "out_of_range" and f"{Outcome.BUDGET}" == "budget"
    assert json.dumps({"outcome": Outcome.CONVERGED}) == '{"outcome": "converged"}'
    assert Outcome("no_object") is Outcome.NO_OBJECT
    assert Outcome.CONVERGED not in STOPPED and Outcome.BUDGET not in STOPPED
    assert set(STOPPED) | {Outcome.CONVERGED, Outcome.BUDGET} == set(Outcome)


def test_reach_stops_a_correction_beyond_the_training_range_and_is_off_without_one():
    reach = ReachCheck(1.25, 20.0)
    assert reach.check(seen(24.0, 7.0)) is None  # 25 mm: within 1.25 x 20
    stop = reach.check(seen(24.0, 8.0))
    assert stop.outcome == Outcome.OUT_OF_RANGE and "25.3 mm" in stop.reason
    assert ReachCheck(1.25, None).check(seen(500.0, 0.0)) is None


def test_look_around_once_before_the_first_full_loop_and_within_the_budget():
    reach = ReachCheck(1.25, 20.0)
    around = LookAround(180.0, 0.6)
    assert around.step(seen(share=0.9), reach, record(), affordable=True) is None
    assert around.step(LOST, reach, record(), affordable=False) is None  # no loop left
    r = record()
    assert around.step(seen(3.0, 4.0, share=0.3), reach, r, affordable=True) == \
        ToolStep(3.0, 4.0, 0.0, 180.0)
    assert r.estimates["look_around"].startswith("30% of the part seen: moving by the 5.0 mm")
    assert around.step(LOST, reach, record(), affordable=True) is None  # once a run
    fresh = LookAround(180.0, None)
    fresh.full_made = True
    assert fresh.step(LOST, reach, record(), affordable=True) is None
    far = LookAround(180.0, 0.6)
    assert far.step(seen(40.0, 0.0, share=0.3), reach, record(), affordable=True) == \
        ToolStep(0.0, 0.0, 0.0, 180.0)  # found beyond reach: turns where it is
    assert LookAround(None, 0.6).step(LOST, reach, record(), affordable=True) is None
    ambiguous = TranslationEstimate("ambiguous")
    assert LookAround(180.0, 0.6).step(ambiguous, reach, record(), affordable=True) is None


def test_turn_check_expects_what_the_last_turn_left():
    turn = TurnCheck(10.0, 0.4)
    assert turn.check(ToolStep(0, 0, 0, 50.0), record()) is None  # no full loop yet
    turn.turned(ToolStep(0, 0, 0, 50.0), ToolStep(0, 0, 0, 40.0))  # cut to 40: 10 left
    r = record()
    assert turn.check(ToolStep(0, 0, 0, 25.0), r) is None  # within max(10, 16) of 10
    assert r.estimates["turn_expected_deg"] == 10.0
    stop = turn.check(ToolStep(0, 0, 0, -7.0), record())
    assert stop.outcome == Outcome.INCONSISTENT and "-7.0 deg" in stop.reason
    off = TurnCheck(None, 0.4)
    off.turned(ToolStep(0, 0, 0, 50.0), ToolStep(0, 0, 0, 40.0))
    assert off.check(ToolStep(0, 0, 0, 170.0), record()) is None


@pytest.mark.parametrize("share, read_mm, hidden", [
    (0.85, 1.0, True), (0.95, 1.0, False), (0.85, 5.0, False), (None, 1.0, False)])
def test_hidden_check_near_the_pose_only(share, read_mm, hidden):
    stop = HiddenCheck(0.1, 4.0).check(seen(share=share), read_mm)
    assert (stop is not None) == hidden
    assert HiddenCheck(None, 4.0).check(seen(share=0.5), 1.0) is None
    if hidden:
        assert stop.outcome == Outcome.OCCLUDED and "85%" in stop.reason


def test_settling_reads_more_frames_until_the_mean_is_known():
    cfg = LoopConfig(settle_frames=3, settle_max_frames=8, settle_sem_mm=0.01,
                     settle_sem_deg=None, settle_average="steps")
    settling = Settling(cfg)
    assert settling.wanted(ToolStep(0.1, 0.1, 0.0, 0.5))
    assert not settling.wanted(ToolStep(1.0, 0.0, 0.0, 0.0))  # outside the window
    assert not Settling(LoopConfig(settle_frames=1)).wanted(ToolStep(0.1, 0.0, 0.0, 0.0))
    rng = np.random.default_rng(0)
    steps = iter([ToolStep(0.05 + rng.normal(0, 0.02), 0.0, 0.0, 0.0) for _ in range(10)])
    r = record()
    mean = settling.read(ToolStep(0.05, 0.0, 0.0, 0.0), np.zeros((2, 2, 3), np.uint8), r,
                         lambda: np.zeros((2, 2, 3), np.uint8), lambda image: next(steps))
    assert 3 <= len(r.estimates["settle"]) <= 8
    assert mean.dx_mm == pytest.approx(np.mean([s[0] for s in r.estimates["settle"]]))


def test_a_run_gets_fresh_checks():
    cfg = LoopConfig()
    one, two = LoopChecks.for_run(cfg, 35.0), LoopChecks.for_run(cfg, 35.0)
    one.look_around.done = True
    one.turn.turned(ToolStep(0, 0, 0, 10.0), ToolStep(0, 0, 0, 10.0))
    assert not two.look_around.done and two.turn.expected is None
    assert two.reach.reach_mm == 35.0 and two.hidden.r_fine_mm == cfg.r_fine_mm
