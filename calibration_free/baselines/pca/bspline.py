"""B-spline basis functions (Cox-de Boor) on clamped uniform knots, evaluated for many inputs.

With ``order`` k the basis functions are piecewise polynomials of degree k - 1: order 2 gives
the triangular membership functions of classical fuzzy control, order 3 smooth quadratic ones.
On clamped knots the n basis functions are non-negative and sum to one everywhere in [lo, hi]
(a fuzzy partition); inputs outside the interval are clamped to its ends.
"""

from __future__ import annotations

import numpy as np

from drivers.core.errors import ConfigError


def check_basis(n_basis: int, order: int) -> None:
    """Raise ConfigError unless ``order`` >= 1 and ``n_basis`` >= ``order``."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise ConfigError(f"order: must be a whole number >= 1, got {order!r}")
    if isinstance(n_basis, bool) or not isinstance(n_basis, (int, np.integer)) \
            or n_basis < order:
        raise ConfigError(f"n_basis: must be a whole number >= order ({order}), got "
                          f"{n_basis!r}")


def clamped_knots(lo: float, hi: float, n_basis: int, order: int) -> np.ndarray:
    """Knot vector (n_basis + order values) with ``order`` knots at each end and uniform inner
    knots, for ``n_basis`` basis functions on [lo, hi].

    Raises:
        ConfigError: an invalid (n_basis, order) pair, or not lo < hi.
    """
    check_basis(n_basis, order)
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise ConfigError(f"B-spline interval: need finite lo < hi, got [{lo!r}, {hi!r}]")
    inner = np.linspace(lo, hi, n_basis - order + 2)
    return np.concatenate([np.full(order - 1, lo), inner, np.full(order - 1, hi)])


def bspline_basis(x: np.ndarray, lo: float, hi: float, n_basis: int, order: int) -> np.ndarray:
    """Values of the ``n_basis`` B-splines of ``order`` on [lo, hi] at the points ``x``.

    Args:
        x: (N,) inputs; values outside [lo, hi] are clamped.
        lo, hi: the interval the basis covers.
        n_basis: number of basis functions (fuzzy sets).
        order: spline order (degree + 1).

    Returns:
        (N, n_basis) float64; every row is non-negative and sums to 1.

    Raises:
        ConfigError: an invalid basis or interval.
    """
    t = clamped_knots(lo, hi, n_basis, order)
    x = np.clip(np.asarray(x, dtype=np.float64).ravel(), lo, hi)
    # order 1: the indicator of the knot interval holding x (the last interval holds hi)
    span = np.clip(np.searchsorted(t, x, side="right") - 1, order - 1, n_basis - 1)
    b = np.zeros((x.size, t.size - 1))
    b[np.arange(x.size), span] = 1.0
    for k in range(2, order + 1):
        nxt = np.zeros((x.size, t.size - k))
        for i in range(t.size - k):
            left, right = t[i + k - 1] - t[i], t[i + k] - t[i + 1]
            if left > 0:
                nxt[:, i] += (x - t[i]) / left * b[:, i]
            if right > 0:
                nxt[:, i] += (t[i + k] - x) / right * b[:, i + 1]
        b = nxt
    return b
