"""Convergence plots: RMS error against loop count, one curve per run (PNG, matplotlib Agg)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from controller.evaluation.metrics import state_at
from controller.loop.positioning import LoopState

BUDGETS = np.arange(0.0, 6.51, 0.5)


def rms_curve(trials: Sequence[Sequence[LoopState]]) -> tuple[np.ndarray, np.ndarray]:
    """(position RMS mm, angle RMS deg) at each loop budget in BUDGETS."""
    pos, ang = [], []
    for b in BUDGETS:
        e = np.array([state_at(t, b).error for t in trials], dtype=float)
        pos.append(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2)))
        ang.append(np.sqrt(np.mean(e[:, 2] ** 2)))
    return np.array(pos), np.array(ang)


def plot_convergence(curves: Mapping[str, Sequence[Sequence[LoopState]]], path: str | Path,
                     title: str = "Fine positioning: error against loops") -> Path:
    """One line per named set of trials; position and angle RMS on log axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_p, ax_a) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for name, trials in curves.items():
        pos, ang = rms_curve(trials)
        ax_p.semilogy(BUDGETS, np.maximum(pos, 1e-3), marker="o", label=name)
        ax_a.semilogy(BUDGETS, np.maximum(ang, 1e-3), marker="o", label=name)
    for ax, unit, safe in ((ax_p, "position RMS [mm]", 2.0), (ax_a, "angle RMS [deg]", 5.0)):
        ax.axhline(safe, color="grey", linestyle="--", linewidth=1, label="safe grasp")
        ax.set_xlabel("loops (half = 0.5, full = 1)")
        ax.set_ylabel(unit)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
