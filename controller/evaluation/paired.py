"""Two runs on the same trials, compared trial by trial (``finepos compare``).

``finepos evaluate --states FILE`` writes every trial's error trace; two runs with the same
``--seed`` and ``--trials`` (and part and light) met the same placements and start offsets,
whatever system or model each ran. The difference of their RMS errors is then paired: the
trials are resampled (the same indices for both runs) and the 2.5 and 97.5 percentiles of
the resampled differences give a 95% interval. An interval that holds zero says the two are
level on those trials; one wholly below zero says the first run is ahead.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from controller.evaluation.metrics import state_at
from controller.loop.positioning import LoopState
from drivers.core.errors import FineposError

FIGURES = ("x_mm", "y_mm", "distance_mm", "phi_deg")
DEFAULT_BUDGETS = (1.5, 2.5, 3.5)
DEFAULT_RESAMPLES = 5000
# the same trial starts at the same offset in both runs, up to the arm's repeatability
SAME_START_MM = 0.5
SAME_START_DEG = 0.5


def load_states(path: str | Path) -> list[list[LoopState]]:
    """The trials of an ``evaluate --states`` file.

    Raises:
        FineposError: unreadable, not that file's shape, or a state without its error (one line
            naming the file and what is wrong).
    """
    try:
        data = json.loads(Path(path).read_text())
    except OSError as exc:
        raise FineposError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise FineposError(f"{path}: not JSON ({exc})") from None
    if not isinstance(data, list) or not data:
        raise FineposError(f"{path}: expected a list of trials (finepos evaluate --states)")
    trials = []
    for i, trial in enumerate(data):
        if not isinstance(trial, list) or not trial:
            raise FineposError(f"{path}: trial {i} is not a list of [loops, [x, y, phi]] states")
        states = []
        for state in trial:
            if not (isinstance(state, list) and len(state) == 2 and _number(state[0])
                    and isinstance(state[1], list) and len(state[1]) == 3
                    and all(_number(v) for v in state[1])):
                raise FineposError(f"{path}: trial {i} has a state that is not [loops, [x mm, "
                                   f"y mm, phi deg]] with finite numbers: {state!r:.60}")
            states.append(LoopState(float(state[0]), tuple(float(v) for v in state[1])))
        trials.append(states)
    return trials


def _number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def rms_figures(errors: np.ndarray) -> np.ndarray:
    """RMS x, y, distance from the pose (x and y together) and phi of N x 3 errors."""
    sq = errors**2
    return np.sqrt(np.array([sq[:, 0].mean(), sq[:, 1].mean(), (sq[:, 0] + sq[:, 1]).mean(),
                             sq[:, 2].mean()]))


def compare(first: Sequence[Sequence[LoopState]], second: Sequence[Sequence[LoopState]], *,
            budgets: Sequence[float] = DEFAULT_BUDGETS, resamples: int = DEFAULT_RESAMPLES,
            seed: int = 0) -> dict:
    """Per loop budget: each run's RMS figures after that many loops (``FIGURES``), and the
    first's less the second's with its paired 95% interval (trials resampled together).

    Raises:
        FineposError: the runs hold different numbers of trials, or a trial starts elsewhere
            in one run than in the other (more than ``SAME_START_MM`` / ``SAME_START_DEG``):
            not the same trials.
    """
    if len(first) != len(second):
        raise FineposError(f"the runs hold {len(first)} and {len(second)} trials: not the same "
                           "trials (run both with the same --trials and --seed)")
    for i, (a, b) in enumerate(zip(first, second, strict=True)):
        gap = np.abs(np.subtract(a[0].error, b[0].error))
        if gap[0] > SAME_START_MM or gap[1] > SAME_START_MM or gap[2] > SAME_START_DEG:
            raise FineposError(f"trial {i} starts {gap[0]:.2f} / {gap[1]:.2f} mm, "
                               f"{gap[2]:.2f} deg apart in the two runs: not the same trials "
                               "(run both with the same --part, --trials and --seed)")
    rng = np.random.default_rng(seed)
    n = len(first)
    picks = rng.integers(0, n, (resamples, n))
    out: dict = {"trials": n, "resamples": resamples, "budgets": {}}
    for budget in budgets:
        a = np.array([state_at(t, budget).error for t in first])
        b = np.array([state_at(t, budget).error for t in second])
        diffs = np.array([rms_figures(a[i]) - rms_figures(b[i]) for i in picks])
        low, high = np.percentile(diffs, [2.5, 97.5], axis=0)
        ra, rb = rms_figures(a), rms_figures(b)
        out["budgets"][f"{budget:g}"] = {
            "first": _named(ra),
            "second": _named(rb),
            "first_less_second": {
                name: {"difference": float(ra[k] - rb[k]), "low": float(low[k]),
                       "high": float(high[k]), "verdict": _verdict(low[k], high[k])}
                for k, name in enumerate(FIGURES)},
        }
    return out


def _named(values: np.ndarray) -> dict[str, float]:
    return {name: float(v) for name, v in zip(FIGURES, values, strict=True)}


def _verdict(low: float, high: float) -> str:
    """The first run against the second, from the difference's interval (smaller is better)."""
    if high < 0.0:
        return "ahead"
    if low > 0.0:
        return "behind"
    return "level"
