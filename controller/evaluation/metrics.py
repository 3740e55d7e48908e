"""Accuracy figures of a set of positioning runs, as the paper's Table 1 reports them.

At loop budget b, a trial's state is the one after its last move whose cumulative loop count
is <= b. Safe = position error <= 2 mm and |ephi| <= 5 deg (the cube's grasp tolerance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from controller.loop.positioning import LoopState

SAFE_MM = 2.0
SAFE_DEG = 5.0
RMS_BUDGETS = (0.5, 1.0, 1.5, 2.5, 3.5, 6.5)
SAFE_BUDGETS = (1.0, 1.5, 2.5, 3.5)


def state_at(states: Sequence[LoopState], budget: float) -> LoopState:
    """The state after the last move with cumulative loops <= budget."""
    chosen = states[0]
    for s in states:
        if s.loops <= budget + 1e-9:
            chosen = s
    return chosen


def is_safe(error: tuple[float, float, float]) -> bool:
    """Whether an error (x mm, y mm, phi deg) is within SAFE_MM (x-y distance) and SAFE_DEG."""
    return math.hypot(error[0], error[1]) <= SAFE_MM and abs(error[2]) <= SAFE_DEG


def loops_to_safe(states: Sequence[LoopState]) -> float:
    """Cumulative loops at the first safe state (inf if never safe)."""
    for s in states:
        if s.error is not None and is_safe(s.error):
            return s.loops
    return math.inf


def _key(b: float) -> str:
    return f"{b:.1f}"


def summarise(trials: Sequence[Sequence[LoopState]]) -> dict:
    """rms per budget, safe_rate per budget, loops_to_safe median/p95 over trials."""
    out: dict = {"rms": {}, "safe_rate": {}}
    for b in RMS_BUDGETS:
        errs = np.array([state_at(t, b).error for t in trials], dtype=float)
        rms = np.sqrt(np.mean(errs**2, axis=0))
        out["rms"][_key(b)] = {"x_mm": float(rms[0]), "y_mm": float(rms[1]),
                               "phi_deg": float(rms[2])}
    for b in SAFE_BUDGETS:
        out["safe_rate"][_key(b)] = float(np.mean([is_safe(state_at(t, b).error)
                                                   for t in trials]))
    lts = np.array([loops_to_safe(t) for t in trials])
    finite = np.isfinite(lts)

    def pct(q: float):
        v = float(np.percentile(lts, q, method="inverted_cdf"))
        return v if math.isfinite(v) else None

    out["loops_to_safe"] = {"median": pct(50), "p95": pct(95),
                            "never_safe": int((~finite).sum())}
    return out
