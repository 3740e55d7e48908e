"""Gabor bank: closed-form kernel values, DC-freeness, rotation, configuration, features."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration_free.errors import ImageError
from calibration_free.gabor import GaborBank, GaborConfig, gabor_kernel
from drivers.core.errors import ConfigError
from drivers.core.typed_config import from_mapping


def closed_form(i: int, j: int, p: float, q: float, theta_deg: float, lam: float, sigma: float,
                alpha: float, odd: bool) -> float:
    """Eq. (1)-(2) at ROI pixel (row i, column j) before the DC term, written out by hand."""
    x, y = j + 0.5 - p, i + 0.5 - q
    t = math.radians(theta_deg)
    xr = x * math.cos(t) + y * math.sin(t)
    yr = -x * math.sin(t) + y * math.cos(t)
    g = math.exp(-(xr * xr + alpha * alpha * yr * yr) / (2 * sigma * sigma))
    return g * (-math.sin(2 * math.pi * xr / lam) if odd else math.cos(2 * math.pi * xr / lam))


def envelope(i: int, j: int, p: float, q: float, theta_deg: float, sigma: float,
             alpha: float) -> float:
    x, y = j + 0.5 - p, i + 0.5 - q
    t = math.radians(theta_deg)
    xr = x * math.cos(t) + y * math.sin(t)
    yr = -x * math.sin(t) + y * math.cos(t)
    return math.exp(-(xr * xr + alpha * alpha * yr * yr) / (2 * sigma * sigma))


@pytest.mark.parametrize("phase", ["even", "odd"])
@pytest.mark.parametrize(("p", "q", "theta", "alpha"),
                         [(25.0, 25.0, 0.0, 1.0), (13.0, 37.0, 45.0, 1.0),
                          (37.0, 13.0, 135.0, 1.7)])
def test_kernel_values_match_closed_form(phase, p, q, theta, alpha):
    cfg = GaborConfig(alpha=alpha)
    kernel = gabor_kernel(p, q, theta, cfg, phase)
    n = cfg.roi_px
    wave = np.array([[closed_form(i, j, p, q, theta, 30.0, 12.5, alpha, phase == "odd")
                      for j in range(n)] for i in range(n)])
    env = np.array([[envelope(i, j, p, q, theta, 12.5, alpha) for j in range(n)]
                    for i in range(n)])
    dc = wave.sum() / env.sum()
    np.testing.assert_allclose(kernel, wave - dc * env, rtol=0, atol=1e-12)
    # the middle pixel of the centre filter, by hand: dx = dy = 0.5
    if (p, q, theta, phase) == (25.0, 25.0, 0.0, "even"):
        g = math.exp(-0.5 / (2 * 12.5**2))
        assert kernel[25, 25] == pytest.approx(g * (math.cos(math.pi / 30) - dc), abs=1e-12)


def test_unclipped_even_dc_term_tends_to_the_analytic_one():
    """Reading note 2: on a window far larger than the envelope, the DC constant is
    exp(-2 pi^2 sigma^2 / lambda^2)."""
    cfg = GaborConfig(roi_px=200, centres_px=(100.0,), orientations_deg=(0.0,))
    kernel = gabor_kernel(100.0, 100.0, 0.0, cfg, "even")
    x = np.arange(200) + 0.5 - 100.0
    g = np.exp(-(x[None, :] ** 2 + x[:, None] ** 2) / (2 * 12.5**2))
    dc = (g * np.cos(2 * np.pi * x[None, :] / 30.0) - kernel).sum() / g.sum()
    assert dc == pytest.approx(math.exp(-2 * math.pi**2 * 12.5**2 / 30.0**2), rel=1e-6)


@pytest.mark.parametrize("kind", ["even", "odd", "magnitude"])
def test_constant_image_gives_zero_for_every_filter(kind):
    bank = GaborBank(GaborConfig(kind=kind))
    for level in (0.0, 1.0, 173.25, -40.0):
        roi = np.full((50, 50), level, dtype=np.float32)
        features = bank.features(roi)
        assert features.shape == (36,)
        scale = max(abs(level), 1.0) * np.abs(bank.kernels).sum(axis=(1, 2)).max()
        assert np.abs(features).max() <= 1e-6 * scale


def test_default_bank_is_the_papers_36_even_filters():
    bank = GaborBank()
    assert bank.config.centres_px == (13.0, 25.0, 37.0)
    assert bank.config.orientations_deg == (0.0, 45.0, 90.0, 135.0)
    assert (bank.config.lambda_px, bank.config.sigma_px, bank.config.alpha) == (30.0, 12.5, 1.0)
    assert bank.kernels.shape == (36, 50, 50)
    assert bank.n_features == 36
    assert np.abs(bank.kernels.sum(axis=(1, 2))).max() < 1e-12
    # order: q outer, p inner, orientation innermost
    k = 1 * 12 + 2 * 4 + 3  # q = 25, p = 37, theta = 135
    np.testing.assert_array_equal(bank.kernels[k],
                                  gabor_kernel(37.0, 25.0, 135.0, bank.config, "even"))


@pytest.mark.parametrize("phase", ["even", "odd"])
def test_90_degree_kernel_is_the_0_degree_kernel_rotated(phase):
    """Turning the image by +90 deg (x -> y; clockwise on screen, y pointing down) maps the
    0-deg filter at offset (dx, dy) from the ROI centre onto the 90-deg filter at (-dy, dx)."""
    cfg = GaborConfig()
    for p in cfg.centres_px:
        for q in cfg.centres_px:
            k0 = gabor_kernel(p, q, 0.0, cfg, phase)
            k90 = gabor_kernel(25.0 - (q - 25.0), p, 90.0, cfg, phase)
            np.testing.assert_allclose(np.rot90(k0, k=-1), k90, rtol=0, atol=1e-12)


def test_features_are_one_matrix_vector_product():
    rng = np.random.default_rng(0)
    roi = rng.normal(100.0, 30.0, (50, 50)).astype(np.float32)
    for kind in ("even", "odd"):
        bank = GaborBank(GaborConfig(kind=kind))
        expected = np.einsum("kij,ij->k", bank.kernels, roi.astype(np.float64))
        np.testing.assert_allclose(bank.features(roi), expected, rtol=1e-4, atol=1e-2)
    bank = GaborBank(GaborConfig(kind="magnitude"))
    assert np.iscomplexobj(bank.kernels)
    expected = np.abs(np.einsum("kij,ij->k", bank.kernels, roi.astype(np.float64)))
    np.testing.assert_allclose(bank.features(roi), expected, rtol=1e-4, atol=1e-2)


def test_features_refuse_a_wrong_roi():
    bank = GaborBank()
    with pytest.raises(ImageError, match="ROI"):
        bank.features(np.zeros((49, 50), np.float32))
    with pytest.raises(ImageError, match="float32"):
        bank.features(np.zeros((50, 50), np.float64))


def test_config_loads_from_a_mapping_and_rejects_bad_values():
    cfg = from_mapping(GaborConfig, {"centres_px": [10, 25, 40], "kind": "magnitude",
                                     "orientations_deg": [0, 60, 120]}, "gabor")
    assert cfg.centres_px == (10.0, 25.0, 40.0) and cfg.n_filters == 27
    with pytest.raises(ConfigError, match=r"^gabor\.lambda_px: must be > 0"):
        from_mapping(GaborConfig, {"lambda_px": 0}, "gabor")
    with pytest.raises(ConfigError, match=r"^gabor\.kind: must be one of"):
        from_mapping(GaborConfig, {"kind": "complex"}, "gabor")
    with pytest.raises(ConfigError, match=r"^gabor\.sigma: unknown key"):
        from_mapping(GaborConfig, {"sigma": 3}, "gabor")
    with pytest.raises(ConfigError, match="centres_px"):
        GaborConfig(centres_px=(13.0, 60.0))
