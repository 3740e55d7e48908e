"""The compiled localisation kernels give what the OpenCV formulas they replace give."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration_free.kernels import (
    coverage_moments,
    cut_levels,
    filled_blob,
    object_mask,
    saturation_image,
)
from calibration_free.localise import binarise, elongation
from calibration_free.preprocess import max_and_saturation_u8


def test_saturation_matches_opencvs_division_for_every_grey_pair():
    top = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 256, axis=1)
    low = np.repeat(np.arange(256, dtype=np.uint8)[None, :], 256, axis=0)
    keep = low <= top
    # every (max, min) pair, each in a different channel order
    pairs = np.stack([top[keep], low[keep], low[keep]], axis=-1)
    for order in ((0, 1, 2), (1, 0, 2), (2, 1, 0)):
        image = np.ascontiguousarray(pairs[:, order].reshape(-1, 1, 3))
        expected = max_and_saturation_u8(image)[1].astype(np.float32)
        np.testing.assert_array_equal(saturation_image(image), expected)


def test_saturation_of_a_camera_frame():
    image = np.random.default_rng(4).integers(0, 256, (144, 192, 3), dtype=np.uint8)
    np.testing.assert_array_equal(saturation_image(image),
                                  max_and_saturation_u8(image)[1].astype(np.float32))


def _blob_image(rng: np.random.Generator, two: bool = False) -> np.ndarray:
    image = rng.normal(40.0, 6.0, (120, 160)).astype(np.float32)
    cv2.rectangle(image, (50, 30), (85, 70), 200.0, -1)
    if two:
        cv2.circle(image, (130, 95), 12, 180.0, -1)
    return cv2.GaussianBlur(image, (5, 5), 1.2)


@pytest.mark.parametrize("polarity", ["bright", "dark"])
@pytest.mark.parametrize("two", [False, True])
def test_object_mask_moments_and_box(polarity, two):
    image = _blob_image(np.random.default_rng(1), two)
    if polarity == "dark":
        image = 255.0 - image
    threshold = 120.0
    mask, moments, box = object_mask(image, np.float32(threshold), polarity == "bright")
    expected = binarise(image, threshold, polarity)
    np.testing.assert_array_equal(mask, (expected * 255).astype(np.uint8))
    ref = cv2.moments(expected, binaryImage=True)
    n = ref["m00"]
    assert moments[0] == n
    assert moments[1] == pytest.approx(ref["m10"]) and moments[2] == pytest.approx(ref["m01"])
    u, v = moments[1] / n, moments[2] / n
    assert moments[3] / n - u * u == pytest.approx(ref["mu20"] / n)
    assert moments[4] / n - v * v == pytest.approx(ref["mu02"] / n)
    assert moments[5] / n - u * v == pytest.approx(ref["mu11"] / n)
    x, y, w, h = cv2.boundingRect(mask)
    if two:
        # the circle's rows overlap the square's, its columns do not: two runs of columns
        assert box[1] == 0
    else:
        assert list(box) == [x, w, y, h]
        assert elongation(mask[y:y + h, x:x + w]) == pytest.approx(
            elongation(expected[y:y + h, x:x + w].astype(np.uint8)))


def _reference_coverage(window, core, band, ring, bright):
    """The coverage-weighted moments with numpy, as the centre was computed before."""
    inside, outside = window[core > 0].mean(), window[ring > 0].mean()
    if not (inside > outside if bright else inside < outside):
        return 0.0, 0.0, 0.0
    weight = np.clip((window - outside) / (inside - outside), 0.0, 1.0)
    weight[band == 0] = 0.0
    weight[core > 0] = 1.0
    rows, cols = np.mgrid[0:window.shape[0], 0:window.shape[1]]
    return weight.sum(), (weight * cols).sum(), (weight * rows).sum()


@pytest.mark.parametrize("bright", [True, False])
def test_coverage_moments_match_the_numpy_formula(bright):
    image = _blob_image(np.random.default_rng(2))
    if not bright:
        image = 255.0 - image
    window = image[20:80, 40:100]
    blob = cv2.compare(window, 120.0, cv2.CMP_GT if bright else cv2.CMP_LE)
    core = cv2.erode(blob, np.ones((3, 3), np.uint8))
    band = cv2.dilate(blob, np.ones((5, 5), np.uint8))
    ring = cv2.subtract(cv2.dilate(blob, np.ones((7, 7), np.uint8)), band)
    got = coverage_moments(window, core, band, ring, bright)
    np.testing.assert_allclose(got, _reference_coverage(window, core, band, ring, bright),
                               rtol=1e-6)  # the reference sums in float32
    # a part that is not beyond its background (polarity swapped) gives nothing
    assert coverage_moments(window, core, band, ring, not bright) == (0.0, 0.0, 0.0)
    empty = np.zeros_like(core)
    assert coverage_moments(window, empty, band, ring, bright) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize(("x0", "y0"), [(40, 30), (-7, -5), (150, 110)])
def test_cut_levels_keeps_what_stands_between_the_levels_near_the_part(x0, y0):
    rng = np.random.default_rng(9)
    part = np.zeros((144, 192), np.uint8)
    cv2.circle(part, (x0 + 25, y0 + 25), 12, 255, -1)
    cv2.circle(part, (5, 140), 6, 255, -1)  # a second blob, in some windows only
    roi = rng.uniform(0.0, 250.0, (50, 50)).astype(np.float32)
    # the reference: the part (none beyond the frame) grown by 2 px (5x5 square), the window
    # under the ROI
    grown = cv2.dilate(np.pad(part, 60), np.ones((5, 5), np.uint8))
    keep = grown[y0 + 60:y0 + 110, x0 + 60:x0 + 110]
    expected = np.where(keep > 0, np.clip(roi - 80.0, 0.0, 100.0), 0.0)
    cut_levels(roi, np.float32(80.0), np.float32(180.0), part, x0, y0, 2)
    np.testing.assert_array_equal(roi, expected.astype(np.float32))


def _flood_filled(blob: np.ndarray) -> np.ndarray:
    """The blob with its holes filled by OpenCV's flood fill of the background from outside."""
    padded = cv2.copyMakeBorder(blob, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    cv2.floodFill(padded, None, (0, 0), 1)
    return np.where(padded[1:-1, 1:-1] == 1, np.uint8(0), np.uint8(255))


@pytest.mark.parametrize("seed", range(24))
def test_filled_blob_fills_what_the_background_does_not_reach(seed):
    rng = np.random.default_rng(seed)
    specks = 0.02 + 0.3 * seed / 24
    blob = np.zeros((40, 52), np.uint8)
    cv2.rectangle(blob, (3, 4), (45, 33), 255, -1)
    # holes (one open to the border through a 1 px channel), specks, a diagonal-only gap
    cv2.circle(blob, (15, 18), 5, 0, -1)
    cv2.line(blob, (30, 0), (30, 20), 0, 1)
    blob[rng.random(blob.shape) < specks] = 0
    blob[0, :] = 0
    blob[-1, :] = 255  # a blob reaching the window's edge
    window = np.ascontiguousarray(blob[:, 1:])  # and a non-contiguous view of it below
    np.testing.assert_array_equal(filled_blob(blob[:, 1:]), _flood_filled(window))
    out = filled_blob(blob)
    np.testing.assert_array_equal(out, _flood_filled(blob))
    assert out.dtype == np.uint8 and out.flags.c_contiguous
    assert (out[blob > 0] == 255).all() and out[18, 15] == 255  # the round hole is filled
