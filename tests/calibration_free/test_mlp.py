"""MLPs: NN1 and NN2 shapes learn known smooth mappings; training is reproducible."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.angles import decode, encode
from calibration_free.errors import TrainingError
from calibration_free.mlp import NumpyMLP, Rprop, train_mlp


def camera_map(uv: np.ndarray) -> np.ndarray:
    """A smooth, mildly nonlinear (u, v) -> (dx_mm, dy_mm), like a tilted camera's."""
    du, dv = (uv[:, 0] - 96.0) / 40.0, (uv[:, 1] - 72.0) / 40.0
    return np.stack([25.0 * np.tanh(0.9 * du + 0.1 * dv), 22.0 * dv + 2.0 * du * dv], axis=1)


def test_nn1_learns_a_smooth_camera_map():
    """NN1's shape (2-3-2) on a 7 x 9 grid of centres; tolerance: 0.5 mm RMS, 1.5 mm max on
    random centres inside the grid (the map spans +-25 mm)."""
    u, v = np.meshgrid(np.linspace(56, 136, 7), np.linspace(32, 112, 9))
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    result = train_mlp(uv, camera_map(uv), (3,), seed=0, epochs=2000)
    test = np.random.default_rng(1).uniform((56, 32), (136, 112), (200, 2))
    err = result.model(test) - camera_map(test)
    assert np.sqrt((err**2).mean()) < 0.5 and np.abs(err).max() < 1.5
    assert result.loss_curve[-1] < result.loss_curve[0] / 100


def rotation_features(phi_deg: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """36 smooth features of a kappa = 4 object's rotation plus a little noise."""
    a = np.radians(4.0 * phi_deg)[:, None]
    basis = np.concatenate([np.cos(m * a) for m in (1, 2, 3)]
                           + [np.sin(m * a) for m in (1, 2, 3)], axis=1)
    mix = np.random.default_rng(7).normal(size=(6, 36))
    return 50.0 * basis @ mix + rng.normal(0.0, 0.5, (len(phi_deg), 36))


def test_nn2_learns_rotation_from_features():
    """NN2's shape (36-12-2) on 63 angles across +-45 deg; tolerance: decoded angle within
    0.5 deg RMS and 1.5 deg max on random angles over the whole range, across the wrap."""
    rng = np.random.default_rng(2)
    phi = np.linspace(-45.0, 45.0, 63)
    s, c = encode(phi, 4)
    result = train_mlp(rotation_features(phi, rng), np.stack([s, c], axis=1), (12,), seed=1,
                       epochs=400)
    test_phi = rng.uniform(-45.0, 45.0, 300)
    out = result.model(rotation_features(test_phi, rng))
    err = decode(*encode(decode(out[:, 0], out[:, 1], 4) - test_phi, 4), 4)
    assert np.sqrt((err**2).mean()) < 0.5 and np.abs(err).max() < 1.5


def test_training_is_seeded_and_reproducible():
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=(30, 4)), rng.normal(size=(30, 2))
    a = train_mlp(x, y, (5,), seed=11, epochs=50)
    b = train_mlp(x, y, (5,), seed=11, epochs=50)
    c = train_mlp(x, y, (5,), seed=12, epochs=50)
    assert a.loss_curve == b.loss_curve
    for wa, wb in zip(a.model.weights, b.model.weights, strict=True):
        np.testing.assert_array_equal(wa, wb)
    assert not np.array_equal(a.model.weights[0], c.model.weights[0])
    assert len(a.loss_curve) == 50 and a.seconds > 0


def test_rprop_takes_the_library_optimisers_steps():
    """The written-out Rprop gives torch.optim.Rprop's numbers, step for step, over sign
    changes and the step limits."""
    import torch

    rng = np.random.default_rng(3)
    start = [rng.normal(size=(4, 3)), rng.normal(size=4)]
    mine = [torch.tensor(a, requires_grad=True) for a in start]
    theirs = [torch.tensor(a, requires_grad=True) for a in start]
    ours, library = Rprop(mine), torch.optim.Rprop(theirs)
    target = torch.from_numpy(rng.normal(size=(5, 4)))
    xs = torch.from_numpy(rng.normal(size=(5, 3)))

    def loss(p):
        return ((torch.tanh(torch.nn.functional.linear(xs, p[0], p[1])) - target) ** 2).sum()

    for _ in range(60):
        ours.step(list(torch.autograd.grad(loss(mine), mine)))
        library.zero_grad()
        loss(theirs).backward()
        library.step()
    for a, b in zip(mine, theirs, strict=True):
        assert torch.equal(a, b)


def test_numpy_inference_matches_the_unfolded_network():
    rng = np.random.default_rng(4)
    x, y = rng.normal(5.0, 3.0, size=(40, 3)), rng.normal(-2.0, 10.0, size=(40, 2))
    model = train_mlp(x, y, (6, 4), seed=0, epochs=30).model
    h = (x - model.x_mean) / model.x_std
    for w, b in zip(model.weights[:-1], model.biases[:-1], strict=True):
        h = np.tanh(h @ w.T + b)
    expected = (h @ model.weights[-1].T + model.biases[-1]) * model.y_std + model.y_mean
    np.testing.assert_allclose(model(x), expected, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(model(x[7]), expected[7], rtol=1e-10, atol=1e-10)
    assert model.layer_sizes == (3, 6, 4, 2)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_one_hidden_layer_takes_the_compiled_path_with_the_same_outputs(dtype):
    rng = np.random.default_rng(6)
    x, y = rng.normal(0.0, 2.0, size=(40, 36)), rng.normal(size=(40, 2))
    model = train_mlp(x, y, (12,), seed=0, epochs=30).model
    h = np.tanh((x - model.x_mean) / model.x_std @ model.weights[0].T + model.biases[0])
    expected = (h @ model.weights[1].T + model.biases[1]) * model.y_std + model.y_mean
    batch = x.astype(dtype)
    for i in (0, 17, 39):
        one = model(batch[i])  # a vector: the compiled kernel
        np.testing.assert_allclose(one, model(batch[i:i + 1])[0], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(one, expected[i], rtol=1e-5, atol=1e-5)
    # a strided vector (a column of a batch) or whole numbers still read through numpy
    column = np.ascontiguousarray(batch.T).T[3]
    assert not column.flags.c_contiguous
    np.testing.assert_allclose(model(column), model(batch[3]), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(model(np.round(x[5]).astype(int)),
                               model(np.round(x[5])), rtol=1e-12, atol=1e-12)


def test_arrays_round_trip_and_validation():
    rng = np.random.default_rng(5)
    model = train_mlp(rng.normal(size=(10, 2)), rng.normal(size=(10, 2)), (3,), epochs=5).model
    again = NumpyMLP.from_arrays(model.to_arrays("nn1"), "nn1")
    x = rng.normal(size=(4, 2))
    np.testing.assert_array_equal(again(x), model(x))
    arrays = model.to_arrays("nn1")
    arrays["nn1.b0"] = np.zeros(4)
    with pytest.raises(ValueError, match="layer 0"):
        NumpyMLP.from_arrays(arrays, "nn1")


@pytest.mark.parametrize(("x", "y", "hidden"), [
    (np.zeros((10, 2)), np.zeros((9, 2)), (3,)),
    (np.zeros((1, 2)), np.zeros((1, 2)), (3,)),
    (np.full((10, 2), np.nan), np.zeros((10, 2)), (3,)),
    (np.zeros((10, 2)), np.zeros((10, 2)), (0,)),
])
def test_bad_training_data_is_refused(x, y, hidden):
    with pytest.raises(TrainingError):
        train_mlp(x, y, hidden)


def test_a_turned_network_reads_the_angle_less_the_turn_at_the_same_length():
    rng = np.random.default_rng(3)
    net = NumpyMLP([rng.normal(size=(6, 4)), rng.normal(size=(2, 6))],
                   [rng.normal(size=6), rng.normal(size=2)], rng.normal(size=4),
                   np.full(4, 0.7), np.array([0.2, -0.4]), np.array([0.3, 2.0]))
    x = rng.normal(size=(20, 4))
    kappa = 6
    for turn_deg in (1.3, -20.0):
        y, t = net(x), net.turned(np.radians(kappa * turn_deg))(x)
        diff = (decode(y[:, 0], y[:, 1], kappa) - decode(t[:, 0], t[:, 1], kappa) + 30.0) \
            % 60.0 - 30.0
        assert np.allclose(diff, turn_deg)
        assert np.allclose(np.hypot(*y.T), np.hypot(*t.T))
    with pytest.raises(ValueError, match="2 outputs"):
        NumpyMLP([np.ones((3, 4))], [np.zeros(3)], np.zeros(4), np.ones(4), np.zeros(3),
                 np.ones(3)).turned(0.1)
