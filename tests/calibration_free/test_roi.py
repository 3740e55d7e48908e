"""ROI: bilinear sub-pixel window, replicated border, continuity of the features."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration_free.errors import ImageError
from calibration_free.gabor import GaborBank
from calibration_free.roi import above, extract_roi


def image() -> np.ndarray:
    rng = np.random.default_rng(0)
    return cv2.GaussianBlur(rng.normal(100, 40, (144, 192)).astype(np.float32), (0, 0), 2.0)


def bilinear(img: np.ndarray, x: float, y: float) -> float:
    x0, y0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - x0, y - y0
    return ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1])
            + fy * ((1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]))


def test_integer_centre_cuts_the_pixels_out():
    img = image()
    np.testing.assert_array_equal(extract_roi(img, 50.5, 40.5), img[16:66, 26:76])


def test_sub_pixel_centre_is_sampled_bilinearly():
    img = image()
    u, v = 101.37, 66.81
    roi = extract_roi(img, u, v)
    assert roi.shape == (50, 50) and roi.dtype == np.float32
    for i, j in [(0, 0), (24, 25), (49, 49), (10, 37)]:
        expected = bilinear(img.astype(np.float64), u - 24.5 + j, v - 24.5 + i)
        assert roi[i, j] == pytest.approx(expected, abs=1e-3)


@pytest.mark.parametrize(("u", "v"), [(0.0, 0.0), (191.0, 143.0), (3.3, 100.6), (-0.5, 143.5)])
def test_border_repeats_the_nearest_edge_pixel(u, v):
    img = image()
    pad = 40
    padded = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    roi = extract_roi(img, u, v)
    for i, j in [(0, 0), (49, 49), (25, 25), (0, 49), (49, 0), (12, 40)]:
        expected = bilinear(padded.astype(np.float64), u - 24.5 + j + pad, v - 24.5 + i + pad)
        assert roi[i, j] == pytest.approx(expected, abs=1e-3)


def test_features_vary_continuously_with_the_centre():
    img = image()
    bank = GaborBank()
    base = bank.features(extract_roi(img, 80.0, 60.0))
    steps = [np.abs(bank.features(extract_roi(img, 80.0 + d, 60.0 + d / 2)) - base).max()
             for d in (0.01, 0.1)]
    assert 0 < steps[0] < steps[1]
    assert steps[0] < 0.02 * np.abs(base).max()


@pytest.mark.parametrize(("u", "v"), [(-0.6, 10.0), (10.0, 143.6), (float("nan"), 3.0)])
def test_centre_outside_the_image_is_refused(u, v):
    with pytest.raises(ImageError, match="not inside"):
        extract_roi(image(), u, v)


def test_wrong_image_type_is_refused():
    with pytest.raises(ImageError, match="float32"):
        extract_roi(np.zeros((144, 192), np.uint8), 10.0, 10.0)


def test_above_takes_off_the_level_and_cuts_at_the_top_in_place():
    roi = np.array([[10.0, 50.0], [100.0, 200.0]], np.float32)
    assert above(roi, 40.0) is roi
    np.testing.assert_array_equal(roi, [[0.0, 10.0], [60.0, 160.0]])
    roi = np.array([[10.0, 50.0], [100.0, 200.0]], np.float32)
    assert above(roi, 40.0, 150.0) is roi
    np.testing.assert_array_equal(roi, [[0.0, 10.0], [60.0, 110.0]])
