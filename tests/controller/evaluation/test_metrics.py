"""Table-1 figures: state at a loop budget, safe rate, loops to safe."""

import math

import pytest

from controller.evaluation.metrics import by_heading, is_safe, loops_to_safe, state_at, summarise
from controller.loop.positioning import LoopState as S


def trial(*pairs):
    return [S(loops, err) for loops, err in pairs]


T1 = trial((0.0, (20.0, 0.0, 30.0)), (0.5, (3.0, 0.0, 30.0)), (1.5, (0.3, 0.1, 2.0)),
           (2.5, (0.1, 0.0, 0.4)))
T2 = trial((0.0, (1.0, 1.0, 10.0)), (1.0, (0.2, 0.2, 1.0)))


def test_state_at_uses_the_last_move_within_the_budget():
    assert state_at(T1, 0.0).loops == 0.0
    assert state_at(T1, 1.0).loops == 0.5
    assert state_at(T1, 1.5).loops == 1.5
    assert state_at(T1, 6.5).loops == 2.5


def test_safe_tolerance():
    assert is_safe((1.2, 1.5, 4.9)) and not is_safe((1.5, 1.5, 0.0))
    assert not is_safe((0.0, 0.0, -5.1))


def test_loops_to_safe():
    assert loops_to_safe(T1) == 1.5 and loops_to_safe(T2) == 1.0
    assert loops_to_safe(trial((0.0, (9.0, 0.0, 0.0)))) == math.inf


def test_summary():
    s = summarise([T1, T2])
    assert s["rms"]["1.5"]["x_mm"] == pytest.approx(math.sqrt((0.3**2 + 0.2**2) / 2))
    assert s["rms"]["0.5"]["phi_deg"] == pytest.approx(math.sqrt((30.0**2 + 10.0**2) / 2))
    assert s["safe_rate"]["1.0"] == 0.5 and s["safe_rate"]["1.5"] == 1.0
    assert s["loops_to_safe"] == {"median": 1.0, "p95": 1.5, "never_safe": 0}
    never = summarise([trial((0.0, (9.0, 0.0, 0.0)))])
    assert never["loops_to_safe"]["median"] is None and never["loops_to_safe"]["never_safe"] == 1


def test_by_heading_splits_the_trials_by_the_parts_turn():
    # a screw (360 deg) in 12 bins of 30 deg: two trials in the first, one in the ninth,
    # and a turn of exactly the period back in the first
    trials = [T1, T2, trial((0.0, (1.0, 0.0, 0.0)), (2.5, (-0.5, 0.2, 1.0))), T1]
    out = by_heading(trials, [10.0, 29.9, 250.0, 360.0], 360.0)
    assert out["budget"] == 2.5 and len(out["bins"]) == 12
    first, ninth = out["bins"][0], out["bins"][8]
    assert (first["from_deg"], first["to_deg"], first["trials"]) == (0.0, 30.0, 3)
    assert first["mean"]["x_mm"] == pytest.approx((0.1 + 0.2 + 0.1) / 3)
    assert first["rms"]["phi_deg"] == pytest.approx(math.sqrt((0.4**2 * 2 + 1.0) / 3))
    assert (ninth["from_deg"], ninth["trials"]) == (240.0, 1)
    assert ninth["mean"] == {"x_mm": -0.5, "y_mm": 0.2, "phi_deg": 1.0}
    assert ninth["rms"]["x_mm"] == pytest.approx(0.5)
    empty = out["bins"][1]
    assert empty["trials"] == 0 and empty["mean"] is None and empty["rms"] is None
    assert sum(b["trials"] for b in out["bins"]) == len(trials)


def test_by_heading_over_a_shorter_period_and_its_errors():
    out = by_heading([T1, T2], [5.0, 95.0], 90.0, budget=1.5, bins=3)
    assert [b["trials"] for b in out["bins"]] == [2, 0, 0]  # 95 is 5 deg into the next period
    assert out["bins"][0]["rms"]["x_mm"] == pytest.approx(math.sqrt((0.3**2 + 0.2**2) / 2))
    with pytest.raises(ValueError, match="one turn per trial"):
        by_heading([T1], [1.0, 2.0], 360.0)
    with pytest.raises(ValueError, match="positive period"):
        by_heading([T1], [1.0], 0.0)
