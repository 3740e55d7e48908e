"""Accuracy figures of a set of positioning runs, as the paper's Table 1 reports them.

At loop budget b, a trial's state is the one after its last move whose cumulative loop count
is <= b. Safe = position error <= 2 mm and |ephi| <= 5 deg (the cube's grasp tolerance).

Every rate comes with its 95% Wilson score interval in a parallel ``<name>_ci`` entry:
``{"rate", "low", "high"}`` (``wilson``). Times are cell seconds (the simulated cell's clock:
virtual when ``scene.timing`` is realistic) from the start of positioning: ``time_to_safe_s``
to the first state within the safe tolerance, ``time_to_grasp_s`` to the part held after the
lift; each as ``{"median", "p95", "never"}`` over the trials (``never``: trials that did not
get there, counted as infinitely slow in the percentiles, which are None when they fall on
such a trial), plus ``per_trial`` lists.

``by_heading`` splits the trials by where the part lay: its turn on the table from its taught
heading, within one symmetry period, in equal bins. A lamp at the side lights the part from
another side at each heading, and what it does to the reading shows there as a bin whose mean
error is not zero.
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
HEADING_BUDGET = 2.5
HEADING_BINS = 12


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


WILSON_Z_95 = 1.959963984540054


def wilson(successes: int, trials: int, z: float = WILSON_Z_95) -> dict[str, float]:
    """The rate ``successes / trials`` with its Wilson score interval (95% by default):
    ``{"rate", "low", "high"}``. Raises ValueError for no trials or counts out of range."""
    if trials <= 0 or not 0 <= successes <= trials:
        raise ValueError(f"wilson: need 0 <= successes <= trials and trials >= 1, "
                         f"got {successes} / {trials}")
    p = successes / trials
    z2 = z * z
    centre = (p + z2 / (2 * trials)) / (1 + z2 / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / (1 + z2 / trials)
    return {"rate": p, "low": max(0.0, centre - half), "high": min(1.0, centre + half)}


def time_to_safe_s(states: Sequence[LoopState], times: Sequence[float]) -> float:
    """Cell seconds (``times``, one per state) to the first safe state (inf if never safe)."""
    for s, t in zip(states, times, strict=True):
        if s.error is not None and is_safe(s.error):
            return t
    return math.inf


def _percentiles(values: Sequence[float]) -> dict:
    arr = np.array([math.inf if v is None else v for v in values], dtype=float)

    def pct(q: float):
        v = float(np.percentile(arr, q, method="inverted_cdf"))
        return v if math.isfinite(v) else None

    return {"median": pct(50), "p95": pct(95), "never": int((~np.isfinite(arr)).sum()),
            "per_trial": [float(v) if math.isfinite(v) else None for v in arr]}


def _key(b: float) -> str:
    return f"{b:.1f}"


def summarise(trials: Sequence[Sequence[LoopState]],
              state_times: Sequence[Sequence[float] | None] | None = None,
              grasp_times: Sequence[float | None] | None = None) -> dict:
    """rms per budget, safe_rate (and safe_rate_ci) per budget, loops_to_safe median/p95 over
    trials; with ``state_times`` (cell seconds of every state, per trial) time_to_safe_s, with
    ``grasp_times`` (cell seconds to the part held, None when not held) time_to_grasp_s."""
    out: dict = {"rms": {}, "safe_rate": {}, "safe_rate_ci": {}}
    for b in RMS_BUDGETS:
        errs = np.array([state_at(t, b).error for t in trials], dtype=float)
        rms = np.sqrt(np.mean(errs**2, axis=0))
        out["rms"][_key(b)] = {"x_mm": float(rms[0]), "y_mm": float(rms[1]),
                               "phi_deg": float(rms[2])}
    for b in SAFE_BUDGETS:
        safe = [is_safe(state_at(t, b).error) for t in trials]
        out["safe_rate"][_key(b)] = float(np.mean(safe))
        out["safe_rate_ci"][_key(b)] = wilson(sum(safe), len(safe))
    lts = np.array([loops_to_safe(t) for t in trials])
    finite = np.isfinite(lts)

    def pct(q: float):
        v = float(np.percentile(lts, q, method="inverted_cdf"))
        return v if math.isfinite(v) else None

    out["loops_to_safe"] = {"median": pct(50), "p95": pct(95),
                            "never_safe": int((~finite).sum())}
    if state_times is not None and all(t is not None for t in state_times):
        out["time_to_safe_s"] = _percentiles(
            [time_to_safe_s(s, t) for s, t in zip(trials, state_times, strict=True)])
    if grasp_times:
        out["time_to_grasp_s"] = _percentiles(grasp_times)
    return out


def by_heading(trials: Sequence[Sequence[LoopState]], turns_deg: Sequence[float],
               period_deg: float, budget: float = HEADING_BUDGET,
               bins: int = HEADING_BINS) -> dict:
    """The error at ``budget`` loops by the part's turn from its taught heading
    (``turns_deg``, one per trial, taken within ``0..period_deg``): ``{"budget", "bins":
    [{"from_deg", "to_deg", "trials", "mean", "rms"}, ...]}``, ``mean`` and ``rms`` as
    ``{"x_mm", "y_mm", "phi_deg"}`` (None in a bin without trials).

    Raises:
        ValueError: not one turn per trial, or a period or bin count that is not positive.
    """
    if len(turns_deg) != len(trials):
        raise ValueError(f"by_heading: needs one turn per trial, got {len(turns_deg)} for "
                         f"{len(trials)}")
    if not period_deg > 0 or bins < 1:
        raise ValueError(f"by_heading: needs a positive period and bin count, got "
                         f"{period_deg!r} and {bins!r}")
    width = period_deg / bins
    errs = np.array([state_at(t, budget).error for t in trials], dtype=float).reshape(-1, 3)
    index = np.minimum((np.mod(np.asarray(turns_deg, dtype=float), period_deg) // width)
                       .astype(int), bins - 1)
    rows = []
    for k in range(bins):
        e = errs[index == k]
        row = {"from_deg": k * width, "to_deg": (k + 1) * width, "trials": len(e),
               "mean": None, "rms": None}
        if len(e):
            for name, values in (("mean", e.mean(axis=0)), ("rms", np.sqrt((e ** 2).mean(axis=0)))):
                row[name] = {"x_mm": float(values[0]), "y_mm": float(values[1]),
                             "phi_deg": float(values[2])}
        rows.append(row)
    return {"budget": budget, "bins": rows}
