"""Table-1 figures: state at a loop budget, safe rate, loops to safe."""

import math

import pytest

from controller.evaluation.metrics import is_safe, loops_to_safe, state_at, summarise
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
