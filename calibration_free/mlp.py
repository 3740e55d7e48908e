"""Small multilayer perceptrons: trained in torch with Rprop, run from a numpy copy.

Networks are tanh hidden layers and a linear output layer. Inputs and outputs are standardised
(zero mean, unit variance per column, from the training set) so Rprop's step sizes suit every
task. Training is full batch, float64 and seeded (weights are drawn from numpy's generator, not
torch's global one), so the same data and seed give the same network.

Inference runs through ``NumpyMLP``, a numpy copy with the standardisation folded into the first
and last layers: a torch call costs ~20 us of overhead, a whole numpy pass a few microseconds.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from calibration_free.errors import TrainingError
from calibration_free.kernels import mlp_forward

# Columns whose training spread is below this are left unscaled (a constant input or output).
_MIN_SPREAD = 1e-12


class NumpyMLP:
    """Inference copy of a trained network.

    Attributes:
        weights: per layer, (n_out, n_in) float64 matrices as trained (standardised units).
        biases: per layer, (n_out,) float64 vectors as trained.
        x_mean, x_std: input standardisation (x - x_mean) / x_std.
        y_mean, y_std: output de-standardisation y * y_std + y_mean.
    """

    def __init__(self, weights: list[np.ndarray], biases: list[np.ndarray],
                 x_mean: np.ndarray, x_std: np.ndarray, y_mean: np.ndarray,
                 y_std: np.ndarray):
        self.weights = [np.asarray(w, dtype=np.float64) for w in weights]
        self.biases = [np.asarray(b, dtype=np.float64) for b in biases]
        self.x_mean, self.x_std = np.asarray(x_mean, np.float64), np.asarray(x_std, np.float64)
        self.y_mean, self.y_std = np.asarray(y_mean, np.float64), np.asarray(y_std, np.float64)
        self._check()
        folded_w = list(self.weights)
        folded_b = list(self.biases)
        folded_w[0] = folded_w[0] / self.x_std[None, :]
        folded_b[0] = folded_b[0] - folded_w[0] @ self.x_mean
        folded_w[-1] = self.y_std[:, None] * folded_w[-1]
        folded_b[-1] = self.y_std * folded_b[-1] + self.y_mean
        self._hidden = [(np.ascontiguousarray(w), np.ascontiguousarray(b))
                        for w, b in zip(folded_w[:-1], folded_b[:-1], strict=True)]
        self._out_w = np.ascontiguousarray(folded_w[-1])
        self._out_b = np.ascontiguousarray(folded_b[-1])
        # one hidden layer (every network of the default pipeline): one compiled call a look
        self._one_layer = ((*self._hidden[0], self._out_w, self._out_b)
                           if len(self._hidden) == 1 else None)

    def _check(self) -> None:
        if not self.weights or len(self.weights) != len(self.biases):
            raise ValueError("an MLP needs one bias per weight matrix and at least one layer")
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            if w.ndim != 2 or b.shape != (w.shape[0],):
                raise ValueError(f"layer {i}: weight {w.shape} and bias {b.shape} do not fit")
            if i and w.shape[1] != self.weights[i - 1].shape[0]:
                raise ValueError(f"layer {i}: takes {w.shape[1]} inputs, the layer before "
                                 f"gives {self.weights[i - 1].shape[0]}")
        if self.x_mean.shape != (self.n_inputs,) or self.x_std.shape != (self.n_inputs,):
            raise ValueError(f"input standardisation must have {self.n_inputs} values")
        if self.y_mean.shape != (self.n_outputs,) or self.y_std.shape != (self.n_outputs,):
            raise ValueError(f"output standardisation must have {self.n_outputs} values")
        arrays = [*self.weights, *self.biases, self.x_mean, self.x_std, self.y_mean, self.y_std]
        if not all(np.isfinite(a).all() for a in arrays):
            raise ValueError("weights and standardisation must be finite")
        if (self.x_std <= 0).any() or (self.y_std <= 0).any():
            raise ValueError("standardisation spreads must be > 0")

    def shifted(self, offset: np.ndarray) -> NumpyMLP:
        """The same network with ``offset`` subtracted from every output."""
        return NumpyMLP(self.weights, self.biases, self.x_mean, self.x_std,
                        self.y_mean - np.asarray(offset, dtype=np.float64), self.y_std)

    def turned(self, angle_rad: float) -> NumpyMLP:
        """The same network, for a net whose two outputs are (sin a, cos a) of an angle a,
        reading (sin, cos) of a - ``angle_rad`` instead: its output layer turned (exactly,
        through the output standardisation).

        Raises:
            ValueError: the network does not have two outputs.
        """
        if self.n_outputs != 2:
            raise ValueError(f"turned: needs a network with 2 outputs, has {self.n_outputs}")
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        turn = np.array([[c, -s], [s, c]])  # (sin a, cos a) -> (sin(a - d), cos(a - d))
        mix = turn * self.y_std[None, :] / self.y_std[:, None]
        weights = [*self.weights[:-1], mix @ self.weights[-1]]
        biases = [*self.biases[:-1], mix @ self.biases[-1]
                  + (turn @ self.y_mean - self.y_mean) / self.y_std]
        return NumpyMLP(weights, biases, self.x_mean, self.x_std, self.y_mean, self.y_std)

    @property
    def n_inputs(self) -> int:
        return self.weights[0].shape[1]

    @property
    def n_outputs(self) -> int:
        return self.weights[-1].shape[0]

    @property
    def layer_sizes(self) -> tuple[int, ...]:
        """(inputs, hidden..., outputs), e.g. (2, 3, 2) for NN1."""
        return (self.n_inputs, *(w.shape[0] for w in self.weights))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs for one input vector (n_in,) or a batch (N, n_in), in output units."""
        h = x
        if h.ndim == 1:
            if self._one_layer is not None:
                try:
                    return mlp_forward(h, *self._one_layer)
                except TypeError:  # not a contiguous float32 or float64 vector
                    pass
            for w, b in self._hidden:
                h = np.tanh(w @ h + b)
            return self._out_w @ h + self._out_b
        for w, b in self._hidden:
            h = np.tanh(h @ w.T + b)
        return h @ self._out_w.T + self._out_b

    def to_arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """Named arrays for storage: ``{prefix}.w0``, ``{prefix}.b0``, ..., ``{prefix}.x_mean``."""
        out = {f"{prefix}.x_mean": self.x_mean, f"{prefix}.x_std": self.x_std,
               f"{prefix}.y_mean": self.y_mean, f"{prefix}.y_std": self.y_std}
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            out[f"{prefix}.w{i}"] = w
            out[f"{prefix}.b{i}"] = b
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], prefix: str) -> NumpyMLP:
        """Inverse of ``to_arrays``.

        Raises:
            KeyError: an array is missing.
            ValueError: the arrays do not form a valid network.
        """
        n_layers = sum(1 for k in arrays if k.startswith(f"{prefix}.w"))
        return cls([arrays[f"{prefix}.w{i}"] for i in range(n_layers)],
                   [arrays[f"{prefix}.b{i}"] for i in range(n_layers)],
                   arrays[f"{prefix}.x_mean"], arrays[f"{prefix}.x_std"],
                   arrays[f"{prefix}.y_mean"], arrays[f"{prefix}.y_std"])


def training_pairs(x: np.ndarray, y: np.ndarray, learner: str) \
        -> tuple[np.ndarray, np.ndarray]:
    """Check a learner's training data (the MLPs', the PCA system's fuzzy controller's).

    Args:
        x: (N, n_in) inputs.
        y: (N, n_out) targets.
        learner: named in the error messages, e.g. "mlp" or "fuzzy controller".

    Returns:
        x and y as float64 arrays.

    Raises:
        TrainingError: not 2-D, different N, fewer than two samples, or not finite.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 2 or x.shape[0] != y.shape[0] or x.shape[0] < 2:
        raise TrainingError(f"{learner}: need (N, n_in) inputs and (N, n_out) targets with "
                            f"N >= 2, got {x.shape} and {y.shape}")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise TrainingError(f"{learner}: training inputs and targets must be finite")
    return x, y


@dataclass(frozen=True)
class TrainedMLP:
    """Result of ``train_mlp``.

    Attributes:
        model: the numpy inference copy.
        loss_curve: mean squared error (standardised outputs) before each Rprop step.
        seconds: wall-clock training time.
    """

    model: NumpyMLP
    loss_curve: list[float]
    seconds: float


class Rprop:
    """Rprop as ``torch.optim.Rprop`` does it with its defaults (initial step 0.01, step
    factors 0.5 / 1.2, steps within 1e-6 .. 50), step for step the same numbers.

    Written out because the library's optimisers bring in torch's compiler stack on their
    first step, about 3 s, which was half of the first training in a process.
    """

    def __init__(self, params: list[torch.Tensor], *, lr: float = 0.01,
                 etas: tuple[float, float] = (0.5, 1.2),
                 step_sizes: tuple[float, float] = (1e-6, 50.0)):
        self.params = params
        self.etaminus, self.etaplus = etas
        self.step_min, self.step_max = step_sizes
        self._prev = [torch.zeros_like(p) for p in params]
        self._step = [torch.full_like(p, lr) for p in params]

    @torch.no_grad()
    def step(self, grads: list[torch.Tensor]) -> None:
        """One update from the gradients of ``params`` (in the same order)."""
        for param, grad, prev, step in zip(self.params, grads, self._prev, self._step,
                                           strict=True):
            sign = grad.mul(prev).sign()
            sign[sign.gt(0)] = self.etaplus
            sign[sign.lt(0)] = self.etaminus
            sign[sign.eq(0)] = 1
            step.mul_(sign).clamp_(self.step_min, self.step_max)
            # After a sign change the step is skipped and the gradient forgotten.
            grad = grad.clone()
            grad[sign.eq(self.etaminus)] = 0
            param.addcmul_(grad.sign(), step, value=-1)
            prev.copy_(grad)


def _spread(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mean, std = a.mean(axis=0), a.std(axis=0)
    return mean, np.where(std < _MIN_SPREAD, 1.0, std)


def train_mlp(x: np.ndarray, y: np.ndarray, hidden: tuple[int, ...], *, seed: int = 0,
              epochs: int = 1500, target_loss: float = 1e-7,
              weight_decay: float = 0.0,
              sample_weight: np.ndarray | None = None) -> TrainedMLP:
    """Train a tanh MLP with full-batch Rprop on standardised data.

    Args:
        x: (N, n_in) inputs.
        y: (N, n_out) targets.
        hidden: sizes of the hidden layers, e.g. (3,) for NN1.
        seed: seed of the initial weights (Glorot uniform, zero biases).
        epochs: maximum number of Rprop steps.
        target_loss: stop early once the standardised MSE is below this.
        weight_decay: L2 penalty on the weights (not the biases), added to the loss that
            Rprop descends; the loss curve records the data term only. A few dozen images
            cannot pin down dozens of weights: the penalty makes the network interpolate
            smoothly between the grid's samples instead of memorising them.
        sample_weight: (N,) positive weights of the samples in the squared error (None:
            equal). The loss stays a weighted mean, so its scale does not change.

    Returns:
        The trained network, its loss curve and the training time.

    Raises:
        TrainingError: shapes do not match, fewer than two samples, non-finite values, a
            hidden size below 1, or a negative weight_decay.
    """
    start = time.perf_counter()
    x, y = training_pairs(x, y, "mlp")
    if sample_weight is not None:
        sample_weight = np.asarray(sample_weight, dtype=np.float64)
        if sample_weight.shape != (x.shape[0],) or not (np.isfinite(sample_weight).all()
                                                        and (sample_weight > 0).all()):
            raise TrainingError(f"sample_weight must be {x.shape[0]} positive finite values")
    if not weight_decay >= 0.0:
        raise TrainingError(f"weight_decay must be >= 0, got {weight_decay!r}")
    if not hidden or any(h < 1 for h in hidden):
        raise TrainingError(f"hidden layer sizes must be >= 1, got {hidden}")
    x_mean, x_std = _spread(x)
    y_mean, y_std = _spread(y)
    rng = np.random.default_rng(seed)
    sizes = [x.shape[1], *hidden, y.shape[1]]
    params = []
    for n_in, n_out in zip(sizes[:-1], sizes[1:], strict=True):
        limit = np.sqrt(6.0 / (n_in + n_out))
        params.append(torch.tensor(rng.uniform(-limit, limit, (n_out, n_in)),
                                   requires_grad=True))
        params.append(torch.zeros(n_out, dtype=torch.float64, requires_grad=True))
    xt = torch.from_numpy((x - x_mean) / x_std)
    yt = torch.from_numpy((y - y_mean) / y_std)
    wt = None if sample_weight is None else torch.from_numpy(sample_weight / sample_weight.sum())
    optimiser = Rprop(params)
    curve: list[float] = []
    threads = torch.get_num_threads()
    # Tensors this small gain nothing from threads; on a busy machine, spinning worker
    # threads make each step ~100x slower.
    torch.set_num_threads(1)
    try:
        for _ in range(epochs):
            h = xt
            for i in range(0, len(params) - 2, 2):
                h = torch.tanh(torch.nn.functional.linear(h, params[i], params[i + 1]))
            out = torch.nn.functional.linear(h, params[-2], params[-1])
            if wt is None:
                loss = torch.nn.functional.mse_loss(out, yt)
            else:
                loss = (wt * ((out - yt) ** 2).mean(dim=1)).sum()
            curve.append(loss.item())
            if curve[-1] < target_loss:
                break
            if weight_decay:
                loss = loss + weight_decay * sum((w * w).sum() for w in params[0::2])
            optimiser.step(list(torch.autograd.grad(loss, params)))
    finally:
        torch.set_num_threads(threads)
    arrays = [p.detach().numpy().copy() for p in params]
    model = NumpyMLP(arrays[0::2], arrays[1::2], x_mean, x_std, y_mean, y_std)
    return TrainedMLP(model, curve, time.perf_counter() - start)
