"""B-spline neuro-fuzzy controller (the PCA system's mapping, paper section 4.2, ref. [9]).

Each input has ``n_sets`` fuzzy sets whose membership functions are B-splines of ``order`` on
clamped uniform knots over the input's training range (they form a fuzzy partition). Every
combination of one set per input is a rule; its firing strength is the product of the
memberships (tensor-product B-spline), and the output is the firing-strength-weighted sum of
the rules' consequents. Because the memberships sum to one, no normalisation is needed and the
controller is linear in its consequents, which are fitted by least squares.

The rule base grows as n_sets ** m. Rules that no training sample fires are filled in by a
smoothness penalty on the consequents (squared second differences of neighbouring rules along
every input axis, as in P-splines), so the controller interpolates across them instead of
dropping to zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration_free.baselines.pca.bspline import bspline_basis, check_basis
from calibration_free.errors import TrainingError
from calibration_free.mlp import training_pairs
from drivers.core.errors import ConfigError

# The least-squares system is dense: rules ** 2 float64 (4096 rules: 134 MB).
MAX_RULES = 4096
# Each input's fuzzy sets span its training range grown by this fraction on both sides.
RANGE_MARGIN = 0.05
# Keeps the normal equations positive definite when a direction is neither seen nor penalised.
_JITTER = 1e-10


@dataclass(frozen=True, eq=False)
class BSplineFuzzyController:
    """A trained controller.

    Attributes:
        lo, hi: (m,) interval each input's fuzzy sets cover (inputs are clamped to it).
        n_sets: fuzzy sets (B-spline basis functions) per input.
        order: B-spline order (2: triangular memberships, 3: quadratic).
        consequents: (n_sets ** m, n_out) rule consequents; rule index is row-major over the
            inputs' set indices (input 0 slowest).
    """

    lo: np.ndarray
    hi: np.ndarray
    n_sets: int
    order: int
    consequents: np.ndarray

    def __post_init__(self) -> None:
        check_basis(self.n_sets, self.order)
        lo = np.asarray(self.lo, dtype=np.float64)
        hi = np.asarray(self.hi, dtype=np.float64)
        w = np.asarray(self.consequents, dtype=np.float64)
        if lo.ndim != 1 or lo.shape != hi.shape or not (np.isfinite(lo).all()
                                                        and np.isfinite(hi).all()
                                                        and (lo < hi).all()):
            raise ConfigError("fuzzy controller: lo and hi must be finite (m,) arrays, lo < hi")
        if w.ndim != 2 or w.shape[0] != self.n_sets ** lo.size or not np.isfinite(w).all():
            raise ConfigError(f"fuzzy controller: consequents must be finite "
                              f"({self.n_sets ** lo.size}, n_out), got {w.shape}")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)
        object.__setattr__(self, "consequents", w)

    @property
    def n_inputs(self) -> int:
        return self.lo.size

    @property
    def n_rules(self) -> int:
        return self.consequents.shape[0]

    def memberships(self, x: np.ndarray) -> list[np.ndarray]:
        """Per input, the (N, n_sets) membership degrees of the inputs ``x`` (N, m)."""
        x = _as_inputs(x, self.n_inputs)
        return [bspline_basis(x[:, j], self.lo[j], self.hi[j], self.n_sets, self.order)
                for j in range(self.n_inputs)]

    def firing(self, x: np.ndarray) -> np.ndarray:
        """(N, n_rules) firing strengths (product of the memberships); rows sum to 1."""
        return _tensor_product(self.memberships(x))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs for one input (m,) -> (n_out,) or a batch (N, m) -> (N, n_out).

        Raises:
            ConfigError: the inputs do not have m finite columns.
        """
        out = self.firing(x) @ self.consequents
        return out[0] if np.ndim(x) == 1 else out


def _as_inputs(x: np.ndarray, m: int) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    x = x[None, :] if x.ndim == 1 else x
    if x.ndim != 2 or x.shape[1] != m or not np.isfinite(x).all():
        raise ConfigError(f"fuzzy controller: expected finite inputs with {m} columns, got "
                          f"shape {np.shape(x)}")
    return x


def _tensor_product(parts: list[np.ndarray]) -> np.ndarray:
    out = parts[0]
    for part in parts[1:]:
        out = (out[:, :, None] * part[:, None, :]).reshape(out.shape[0], -1)
    return out


def _difference_penalty(n_sets: int, m: int) -> np.ndarray:
    """Sum over the input axes of D^T D, D the second (or first, for 2 sets) difference of
    neighbouring rules along that axis."""
    k = min(2, n_sets - 1)
    d = np.diff(np.eye(n_sets), n=k, axis=0)
    total = np.zeros((n_sets ** m, n_sets ** m))
    for axis in range(m):
        op = np.ones((1, 1))
        for j in range(m):
            op = np.kron(op, d if j == axis else np.eye(n_sets))
        total += op.T @ op
    return total


def fit_fuzzy_controller(x: np.ndarray, y: np.ndarray, *, n_sets: int = 5, order: int = 3,
                         smoothing: float = 1e-3) -> BSplineFuzzyController:
    """Fit the rule consequents to (x, y) by penalised least squares.

    Minimises mean((firing(x) @ W - y) ** 2) + smoothing * |differences of W| ** 2.

    Args:
        x: (N, m) inputs.
        y: (N, n_out) targets.
        n_sets: fuzzy sets per input.
        order: B-spline order of the membership functions.
        smoothing: weight of the smoothness penalty (>= 0).

    Raises:
        TrainingError: shapes do not match, fewer than two samples, non-finite values, an
            input that does not vary, or more than MAX_RULES rules.
        ConfigError: an invalid (n_sets, order) pair or a negative smoothing.
    """
    check_basis(n_sets, order)
    if not (np.isfinite(smoothing) and smoothing >= 0):
        raise ConfigError(f"smoothing: must be a finite number >= 0, got {smoothing!r}")
    x, y = training_pairs(x, y, "fuzzy controller")
    rules = n_sets ** x.shape[1]
    if rules > MAX_RULES:
        raise TrainingError(f"fuzzy controller: {n_sets} sets on {x.shape[1]} inputs make "
                            f"{rules} rules (at most {MAX_RULES}); use fewer sets or inputs")
    lo, hi = x.min(axis=0), x.max(axis=0)
    if (hi <= lo).any():
        raise TrainingError(f"fuzzy controller: input(s) {np.flatnonzero(hi <= lo).tolist()} "
                            f"do not vary in the training data")
    margin = RANGE_MARGIN * (hi - lo)
    lo, hi = lo - margin, hi + margin
    firing = _tensor_product([bspline_basis(x[:, j], lo[j], hi[j], n_sets, order)
                              for j in range(x.shape[1])])
    n = x.shape[0]
    normal = firing.T @ firing / n + smoothing * _difference_penalty(n_sets, x.shape[1])
    normal[np.diag_indices_from(normal)] += _JITTER
    consequents = np.linalg.solve(normal, firing.T @ y / n)
    return BSplineFuzzyController(lo, hi, n_sets, order, consequents)
