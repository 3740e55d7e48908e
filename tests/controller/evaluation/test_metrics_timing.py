"""Wilson intervals and the cell-seconds figures of the evaluation report."""

from __future__ import annotations

import math

import pytest

from controller.evaluation.metrics import summarise, time_to_safe_s, wilson
from controller.loop.positioning import LoopState


def test_wilson_interval_known_values():
    # 95% Wilson interval of 0/10 is [0, 0.2775], of 10/10 [0.7225, 1], of 50/100 ~[0.4038, 0.5962]
    assert wilson(0, 10) == pytest.approx({"rate": 0.0, "low": 0.0, "high": 0.27753}, abs=1e-4)
    assert wilson(10, 10) == pytest.approx({"rate": 1.0, "low": 0.72247, "high": 1.0}, abs=1e-4)
    assert wilson(50, 100) == pytest.approx({"rate": 0.5, "low": 0.40383, "high": 0.59617},
                                            abs=1e-4)
    assert wilson(200, 200)["low"] == pytest.approx(0.98116, abs=1e-4)


def test_wilson_refuses_bad_counts():
    for bad in ((1, 0), (-1, 5), (6, 5)):
        with pytest.raises(ValueError, match="wilson"):
            wilson(*bad)


def test_time_to_safe_is_the_first_safe_states_time():
    states = [LoopState(0.0, (10.0, 0.0, 0.0)), LoopState(0.5, (1.0, 0.5, 1.0)),
              LoopState(1.5, (0.1, 0.0, 0.2))]
    assert time_to_safe_s(states, [0.0, 1.2, 2.5]) == 1.2
    assert time_to_safe_s(states[:1], [0.0]) == math.inf


def test_summary_reports_times_and_intervals():
    safe = [LoopState(0.0, (10.0, 0.0, 0.0)), LoopState(0.5, (0.5, 0.0, 0.0))]
    never = [LoopState(0.0, (10.0, 0.0, 0.0)), LoopState(0.5, (9.0, 0.0, 0.0))]
    out = summarise([safe, safe, never], [[0.0, 1.0], [0.0, 2.0], [0.0, 1.0]],
                    [3.0, 4.0, None])
    assert out["safe_rate_ci"]["1.5"] == pytest.approx(wilson(2, 3))
    assert out["time_to_safe_s"]["median"] == 2.0
    assert out["time_to_safe_s"]["p95"] is None  # falls on the trial that never got safe
    assert out["time_to_safe_s"]["never"] == 1
    assert out["time_to_grasp_s"]["per_trial"] == [3.0, 4.0, None]
    assert out["time_to_grasp_s"]["median"] == 4.0
    assert "time_to_safe_s" not in summarise([safe])
