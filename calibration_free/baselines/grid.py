"""Recovering the acquisition grid behind a training set (the PSOM needs its nodes' topology).

A training set is a grid of displacements (dx, dy, dphi) (``dataset.grid_offsets``) but stores
labels, the corrective steps measured from the reached poses. On the arm a displacement is a
translation followed by a turn about the approach axis, so a label's (dx, dy) is the grid's
(dx, dy) turned by dphi; synthetic sets label the grid values directly. ``grid_indices`` tries
both readings, clusters each axis into levels and returns every sample's grid index.
"""

from __future__ import annotations

import numpy as np

from calibration_free.errors import TrainingError

# Values on one axis belong to one level when they are closer than this fraction of the
# axis's span (grid spacings are far larger; repeatability errors far smaller).
LEVEL_GAP = 0.1


def _levels(values: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(level index per value, level means), or None if the levels are not equally full."""
    order = np.argsort(values, kind="stable")
    span = float(values.max() - values.min())
    breaks = np.diff(values[order]) > LEVEL_GAP * span if span > 0 else \
        np.zeros(values.size - 1, dtype=bool)
    level_sorted = np.concatenate([[0], np.cumsum(breaks)])
    index = np.empty(values.size, dtype=np.int64)
    index[order] = level_sorted
    counts = np.bincount(index)
    if (counts != counts[0]).any():
        return None
    return index, np.bincount(index, weights=values) / counts


def grid_indices(labels: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Grid index of every sample and the grid's levels along dx, dy and dphi.

    Args:
        labels: (N, 3) [dx_mm, dy_mm, dphi_deg] of a grid-sampled training set.

    Returns:
        (N, 3) int indices into the levels, and the three level arrays (increasing).

    Raises:
        TrainingError: the labels do not form a complete grid in either reading.
    """
    labels = np.asarray(labels, dtype=np.float64)
    if labels.ndim != 2 or labels.shape[1] != 3 or labels.shape[0] < 2:
        raise TrainingError(f"grid: expected (N, 3) labels, got {labels.shape}")
    phi = _levels(labels[:, 2])
    for turned in (False, True):
        xy = labels[:, :2]
        if turned:
            a = np.radians(labels[:, 2])
            c, s = np.cos(a), np.sin(a)
            xy = np.stack([c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]], axis=1)
        x, y = _levels(xy[:, 0]), _levels(xy[:, 1])
        if phi is None or x is None or y is None:
            continue
        idx = np.stack([x[0], y[0], phi[0]], axis=1)
        shape = (x[1].size, y[1].size, phi[1].size)
        if len({tuple(r) for r in idx}) == labels.shape[0] == int(np.prod(shape)):
            return idx, (x[1], y[1], phi[1])
    raise TrainingError(f"the {labels.shape[0]} training labels do not form a complete "
                        f"dx x dy x dphi grid; the PSOM needs a grid-sampled set")
