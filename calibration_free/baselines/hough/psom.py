"""Parametrised self-organising map (PSOM, Walter and Ritter), the Hough system's translation map.

A PSOM is a grid of nodes (e.g. 3 x 3 x 3) in a d-dimensional parameter space s; node a holds
a reference vector w_a in the embedding space (here: image features followed by the robot
command). Lagrange polynomials on the grid turn the nodes into a continuous manifold

    w(s) = sum_a H(a, s) w_a,    H(a, s) = prod_k l_{a_k}(s_k),

with l_i the 1-D Lagrange polynomial of node i along an axis (1 at node i, 0 at the others),
so w(s) passes exactly through every training node. A mapping is a completion: given some
components of a vector (the features), find the s whose w(s) matches them best (least squares,
Levenberg-Marquardt from the best-matching node) and read the other components off w(s*).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration_free.errors import ImageError, TrainingError

# The best-match search may leave the grid by this many node spacings (mild extrapolation).
EXTRAPOLATION = 0.5
MAX_ITERATIONS = 50
STEP_TOLERANCE = 1e-10


def lagrange(s: float, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives at ``s`` of the Lagrange polynomials of 1-D ``nodes``."""
    n = nodes.size
    values = np.ones(n)
    derivs = np.zeros(n)
    for i in range(n):
        others = np.delete(nodes, i)
        denom = nodes[i] - others
        factors = (s - others) / denom
        values[i] = float(np.prod(factors))
        for k in range(n - 1):
            derivs[i] += float(np.prod(np.delete(factors, k))) / denom[k]
    return values, derivs


@dataclass(frozen=True, eq=False)
class PSOM:
    """A trained PSOM.

    Attributes:
        nodes: per parameter axis, the node coordinates (strictly increasing; 0, 1, 2, ...).
        weights: (n_1, ..., n_d, D) reference vectors of the nodes.
        inputs: indices of the embedding components that are given when mapping.
        scale: (len(inputs),) divisor of each input component's error in the best match.
    """

    nodes: tuple[np.ndarray, ...]
    weights: np.ndarray
    inputs: tuple[int, ...]
    scale: np.ndarray

    def __post_init__(self) -> None:
        nodes = tuple(np.asarray(n, dtype=np.float64) for n in self.nodes)
        w = np.asarray(self.weights, dtype=np.float64)
        scale = np.asarray(self.scale, dtype=np.float64)
        if not nodes or w.shape[:-1] != tuple(n.size for n in nodes) or w.ndim != len(nodes) + 1:
            raise TrainingError(f"PSOM: weights {w.shape} do not fit a grid of "
                                f"{tuple(n.size for n in nodes)} nodes")
        if any(n.size < 2 or (np.diff(n) <= 0).any() for n in nodes):
            raise TrainingError("PSOM: every axis needs >= 2 strictly increasing nodes")
        if not np.isfinite(w).all():
            raise TrainingError("PSOM: reference vectors must be finite")
        inputs = tuple(int(i) for i in self.inputs)
        if not inputs or len(set(inputs)) != len(inputs) \
                or not all(0 <= i < w.shape[-1] for i in inputs):
            raise TrainingError(f"PSOM: inputs must be distinct components of 0..{w.shape[-1]-1}"
                                f", got {list(self.inputs)}")
        if scale.shape != (len(inputs),) or not (np.isfinite(scale).all() and (scale > 0).all()):
            raise TrainingError(f"PSOM: need {len(inputs)} positive finite input scales")
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "inputs", inputs)
        object.__setattr__(self, "scale", scale)

    @property
    def dim(self) -> int:
        """Dimension d of the parameter space."""
        return len(self.nodes)

    def at(self, s: np.ndarray) -> np.ndarray:
        """The embedding vector w(s), (D,)."""
        return self._evaluate(s)[0]

    def jacobian(self, s: np.ndarray) -> np.ndarray:
        """dw/ds at s, (D, d)."""
        return self._evaluate(s)[1]

    def _evaluate(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(s, dtype=np.float64)
        basis = [lagrange(float(sk), nk) for sk, nk in zip(s, self.nodes, strict=True)]
        value = self.weights
        for values, _ in basis:
            value = np.tensordot(values, value, axes=(0, 0))
        jac = np.empty((self.weights.shape[-1], self.dim))
        for k in range(self.dim):
            g = self.weights
            for j, (values, derivs) in enumerate(basis):
                g = np.tensordot(derivs if j == k else values, g, axes=(0, 0))
            jac[:, k] = g
        return value, jac

    def complete(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Best-match parameters and the completed vector for the input components ``x``.

        Args:
            x: (len(inputs),) values of the input components.

        Returns:
            (s*, w(s*)): the parameters minimising sum(((w_in(s) - x) / scale) ** 2) (within
            the grid grown by EXTRAPOLATION spacings) and the whole embedding vector there.

        Raises:
            ImageError: ``x`` does not have one finite value per input component.
        """
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (len(self.inputs),) or not np.isfinite(x).all():
            raise ImageError(f"PSOM: expected {len(self.inputs)} finite inputs, got "
                                f"{x.shape}")
        idx = list(self.inputs)
        flat = self.weights.reshape(-1, self.weights.shape[-1])[:, idx]
        best = int(np.argmin((((flat - x) / self.scale) ** 2).sum(axis=1)))
        s = np.array([n[i] for n, i in zip(self.nodes, np.unravel_index(
            best, self.weights.shape[:-1]), strict=True)])
        lo = np.array([n[0] - EXTRAPOLATION * (n[1] - n[0]) for n in self.nodes])
        hi = np.array([n[-1] + EXTRAPOLATION * (n[-1] - n[-2]) for n in self.nodes])
        damping = 1e-3
        value, jac = self._evaluate(s)
        residual = (value[idx] - x) / self.scale
        cost = float(residual @ residual)
        for _ in range(MAX_ITERATIONS):
            j = jac[idx] / self.scale[:, None]
            normal = j.T @ j
            step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12),
                                   -j.T @ residual)
            trial = np.clip(s + step, lo, hi)
            t_value, t_jac = self._evaluate(trial)
            t_residual = (t_value[idx] - x) / self.scale
            t_cost = float(t_residual @ t_residual)
            if t_cost < cost:
                moved = float(np.abs(trial - s).max())
                s, value, jac, residual, cost = trial, t_value, t_jac, t_residual, t_cost
                damping = max(damping / 10.0, 1e-9)
                if moved < STEP_TOLERANCE:
                    break
            else:
                damping *= 10.0
                if damping > 1e8:
                    break
        return s, value
