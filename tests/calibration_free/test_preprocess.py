"""Preprocessing: max channel, intensity normalisation, invariance of features to gain/offset."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.errors import ImageError
from calibration_free.gabor import GaborBank
from calibration_free.preprocess import (
    IntensityStats,
    image_stats,
    max_channel,
    max_channel_u8,
    normalise,
)
from calibration_free.roi import extract_roi
from calibration_free.synthetic import render_at

STATS = IntensityStats(mean=110.0, std=35.0)


def test_max_channel_takes_the_brightest_channel():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    gray = max_channel(image)
    assert gray.dtype == np.float32 and gray.shape == (7, 9)
    np.testing.assert_array_equal(gray, image.max(axis=2).astype(np.float32))
    np.testing.assert_array_equal(max_channel_u8(image), image.max(axis=2))


@pytest.mark.parametrize("bad", [np.zeros((4, 4), np.uint8), np.zeros((4, 4, 4), np.uint8),
                                 np.zeros((4, 4, 3), np.float32), np.zeros((0, 4, 3), np.uint8),
                                 [[1, 2, 3]]])
def test_max_channel_refuses_what_is_not_an_rgb_image(bad):
    with pytest.raises(ImageError, match="image"):
        max_channel(bad)


def test_normalise_reaches_the_training_mean_and_std():
    rng = np.random.default_rng(1)
    gray = rng.integers(20, 200, (30, 40), dtype=np.uint8)
    for source in (gray, gray.astype(np.float32)):
        out = normalise(source, STATS)
        assert out.dtype == np.float32 and out.shape == gray.shape
        assert float(out.mean()) == pytest.approx(STATS.mean, abs=1e-3)
        assert float(out.std()) == pytest.approx(STATS.std, rel=1e-4)


def test_flat_image_becomes_the_training_mean():
    out = normalise(np.full((5, 6), 77, np.uint8), STATS)
    np.testing.assert_array_equal(out, np.full((5, 6), STATS.mean, np.float32))
    assert image_stats(np.full((5, 6), 77, np.uint8)) is None


def test_normalise_refuses_bad_input():
    with pytest.raises(ImageError, match="grey image"):
        normalise(np.zeros((4, 4, 3), np.uint8), STATS)
    with pytest.raises(ImageError, match="grey image"):
        normalise(np.zeros((4, 4), np.int32), STATS)
    nan = np.zeros((4, 4), np.float32)
    nan[1, 1] = np.nan
    with pytest.raises(ImageError, match="NaN"):
        normalise(nan, STATS)
    with pytest.raises(ImageError, match="std > 0"):
        IntensityStats(100.0, 0.0)


@pytest.mark.parametrize(("gain", "offset"), [(2, 10), (1, -30), (1, 45), (2, -40)])
def test_features_unchanged_under_gain_and_offset_before_normalisation(cell, gain, offset):
    """a * I + b (a > 0), applied to the camera image, changes no feature. The scene is drawn
    dim enough that a * I + b stays exactly representable in uint8."""
    dim = render_at(cell, 93.3, 74.6, 23.0, np.random.default_rng(2), gain=0.3, bias=40.0)
    assert int(dim.max()) * gain + offset <= 255 and int(dim.min()) + offset >= 0
    bright = (dim.astype(np.int32) * gain + offset).astype(np.uint8)
    bank = GaborBank()

    def features(image):
        return bank.features(extract_roi(normalise(max_channel(image), STATS), 93.3, 74.6))

    reference = features(dim)
    np.testing.assert_allclose(features(bright), reference, rtol=0,
                               atol=1e-4 * np.abs(reference).max())
