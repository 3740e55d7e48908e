"""Localisation: sub-pixel centre, no object, ambiguity, picking the object in clutter."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration_free.errors import ImageError
from calibration_free.localise import binarise, localise, otsu_threshold
from calibration_free.preprocess import IntensityStats, max_channel, normalise
from calibration_free.synthetic import SyntheticCell, render_at
from drivers.core.errors import ConfigError

STATS = IntensityStats(mean=110.0, std=35.0)


def normalised(image: np.ndarray) -> np.ndarray:
    return normalise(max_channel(image), STATS)


def threshold_for(image: np.ndarray) -> float:
    return otsu_threshold(normalised(image))


def add_disc(image: np.ndarray, u: float, v: float, radius: float,
             rgb=(225, 195, 40)) -> np.ndarray:
    out = image.copy()
    cv2.circle(out, (int(round(u * 16)), int(round(v * 16))), int(round(radius * 16)), rgb, -1,
               cv2.LINE_AA, 4)
    return out


@pytest.mark.parametrize(("u", "v", "angle"), [(96.0, 72.0, 0.0), (101.37, 66.81, 17.0),
                                               (60.55, 100.2, -38.0), (140.9, 40.3, 44.0)])
def test_recovers_a_known_sub_pixel_centre(cell, u, v, angle):
    image = render_at(cell, u, v, angle, np.random.default_rng(3))
    n = normalised(image)
    loc = localise(n, otsu_threshold(n))
    assert loc.status == "ok" and loc.method == "histogram"
    assert abs(loc.u_px - u) < 0.2 and abs(loc.v_px - v) < 0.2


def test_holes_placed_symmetrically_do_not_move_the_centre():
    cell = SyntheticCell(holes_mm=((0.0, 0.0), (-5.0, -5.0), (5.0, 5.0)), hole_radius_mm=2.0)
    image = render_at(cell, 88.4, 77.7, 31.0, np.random.default_rng(4))
    n = normalised(image)
    loc = localise(n, otsu_threshold(n))
    assert loc.ok and abs(loc.u_px - 88.4) < 0.2 and abs(loc.v_px - 77.7) < 0.2


def test_histogram_and_components_agree(cell):
    image = render_at(cell, 101.37, 66.81, 17.0, np.random.default_rng(5))
    n = normalised(image)
    thr = otsu_threshold(n)
    fast = localise(n, thr)
    speck = n.copy()
    speck[5:9, 5:9] = n.max()  # a 16 px speck far away forces the components path
    slow = localise(speck, thr, fast.area_px)
    assert fast.method == "histogram" and slow.method == "components"
    assert slow.ok and slow.area_px == fast.area_px
    assert slow.u_px == pytest.approx(fast.u_px, abs=1e-9)
    assert slow.v_px == pytest.approx(fast.v_px, abs=1e-9)
    # both keep the part's blob, and only it: the speck is not the part
    np.testing.assert_array_equal(fast.part_mask > 0, binarise(n, thr) > 0)
    np.testing.assert_array_equal(slow.part_mask, fast.part_mask)


def test_empty_image_is_no_object(cell):
    image = render_at(cell, 96.0, 72.0, 0.0, np.random.default_rng(6))
    empty = np.empty_like(image)
    empty[:] = cell.table_rgb
    empty = np.clip(empty + np.random.default_rng(7).normal(0, 1.5, empty.shape), 0, 255) \
        .astype(np.uint8)
    loc = localise(normalised(empty), threshold_for(image), 820.0)
    assert loc.status == "no_object"
    assert loc.u_px is None and loc.v_px is None and loc.area_px is None
    assert loc.reason


def test_two_equal_blobs_are_ambiguous(cell):
    image = render_at(cell, 96.0, 72.0, 0.0, np.random.default_rng(8))
    thr = threshold_for(image)
    area = localise(normalised(image), thr).area_px
    twins = render_at(cell, 50.0, 72.0, 0.0, np.random.default_rng(9))
    twins = np.maximum(twins, render_at(cell, 140.0, 72.0, 20.0, np.random.default_rng(10)))
    for expected in (area, None):
        loc = localise(normalised(twins), thr, expected)
        assert loc.status == "ambiguous", loc
        assert loc.u_px is None and loc.method == "components" and loc.reason


def test_picks_the_object_in_clutter(cell):
    image = render_at(cell, 101.37, 66.81, 17.0, np.random.default_rng(11))
    thr = threshold_for(image)
    area = localise(normalised(image), thr).area_px
    cluttered = add_disc(image, 30.0, 30.0, 4.0)          # small bright speck
    cluttered = add_disc(cluttered, 160.0, 110.0, 24.0)   # bright patch, 2.2x the area
    cluttered = add_disc(cluttered, 40.0, 120.0, 2.0)     # noise
    loc = localise(normalised(cluttered), thr, area)
    assert loc.status == "ok" and loc.method == "components"
    assert abs(loc.u_px - 101.37) < 0.2 and abs(loc.v_px - 66.81) < 0.2
    assert cv2.countNonZero(loc.part_mask) == loc.area_px  # the part's blob alone
    m = cv2.moments(loc.part_mask, True)
    assert abs(m["m10"] / m["m00"] - 101.37) < 0.5 and abs(m["m01"] / m["m00"] - 66.81) < 0.5
    # the only blob is the wrong size: no object, never a guess
    patch_only = add_disc(np.full_like(image, cell.table_rgb), 160.0, 110.0, 24.0)
    assert localise(normalised(patch_only), thr, area).status == "no_object"


def test_dark_polarity_finds_a_dark_object():
    cell = SyntheticCell(object_rgb=(40, 40, 45), hole_rgb=(200, 200, 200),
                         table_rgb=(180, 180, 170))
    image = render_at(cell, 77.2, 81.9, 12.0, np.random.default_rng(12))
    n = normalised(image)
    loc = localise(n, otsu_threshold(n), polarity="dark")
    assert loc.ok and abs(loc.u_px - 77.2) < 0.2 and abs(loc.v_px - 81.9) < 0.2


def test_binarise_refuses_bad_input():
    with pytest.raises(ImageError, match="float32"):
        binarise(np.zeros((4, 4), np.uint8), 0.5)
    with pytest.raises(ImageError, match="polarity"):
        binarise(np.zeros((4, 4), np.float32), 0.5, "grey")


def test_otsu_separates_two_modes():
    values = np.concatenate([np.full(900, 10.0), np.full(100, 200.0)])
    assert 10.0 < otsu_threshold(values) <= 200.0
    rng = np.random.default_rng(13)
    table, cube, holes = rng.normal(100, 5, 9000), rng.normal(220, 5, 900), rng.normal(30, 5, 60)
    t = otsu_threshold(np.concatenate([table, cube, holes]))
    assert (table > t).mean() < 0.01 and (cube < t).mean() < 0.01 and (holes < t).all()
    with pytest.raises(ImageError, match="single grey level"):
        otsu_threshold(np.full(10, 3.0))
    with pytest.raises(ImageError, match="NaN"):
        otsu_threshold(np.array([1.0, np.nan]))


def test_bad_expected_area_is_refused():
    with pytest.raises(ConfigError, match="expected_area_px"):
        localise(np.zeros((4, 4), np.float32), 0.5, 0.0)


def _shapes(*blobs):
    """A normalised-looking image (0 background, 1 inside) with filled rectangles."""
    img = np.zeros((144, 192), np.float32)
    for x0, y0, x1, y1 in blobs:
        img[y0:y1, x0:x1] = 1.0
    return img


def test_elongation_of_square_and_bar():
    from calibration_free.localise import elongation

    square = np.zeros((30, 30), np.uint8)
    square[5:25, 5:25] = 1
    bar = np.zeros((30, 90), np.uint8)
    bar[10:20, 5:85] = 1
    assert elongation(square) == pytest.approx(1.0, abs=1e-6)
    assert elongation(bar) == pytest.approx(8.0, rel=0.05)


def test_a_bar_of_the_right_area_is_not_the_part():
    bar = _shapes((40, 60, 140, 68))  # 100 x 8 = 800 px, elongation ~12
    loc = localise(bar, 0.5, 800.0, max_elongation=1.5)
    assert loc.status == "no_object" and "shape" in loc.reason


def test_the_part_is_picked_beside_a_bar_of_the_same_area():
    img = _shapes((20, 20, 48, 48), (60, 100, 158, 108))  # square 784 px; bar 784 px
    assert localise(img, 0.5, 784.0).status == "ambiguous"
    loc = localise(img, 0.5, 784.0, max_elongation=1.5)
    assert loc.ok and loc.u_px == pytest.approx(33.5) and loc.v_px == pytest.approx(33.5)


def _covered_square(cx: float, cy: float, side: float = 30.0, size: int = 80) -> np.ndarray:
    """A bright square on a dark background, each pixel the share of its area the square
    covers (what an area-integrating sensor sees), as normalised float32 (0.2 .. 1.0)."""
    def cover(lo: float, hi: float, n: int) -> np.ndarray:
        edges = np.arange(n + 1) - 0.5
        return np.clip(np.minimum(edges[1:], hi) - np.maximum(edges[:-1], lo), 0.0, 1.0)
    area = np.outer(cover(cy - side / 2, cy + side / 2, size),
                    cover(cx - side / 2, cx + side / 2, size))
    return (0.2 + 0.8 * area).astype(np.float32)


@pytest.mark.parametrize("shift", [0.0, 0.1, 0.25, 0.4])
def test_the_centre_follows_an_edge_within_its_pixels(shift):
    """A square moved by a fraction of a pixel: the binary mask's centre stays put (or jumps
    by half a pixel), the refined centre follows within a hundredth of a pixel."""
    cx, cy = 40.0 + shift, 39.0 - 0.5 * shift
    loc = localise(_covered_square(cx, cy), 0.6, 900.0)
    assert loc.status == "ok"
    assert loc.u_px == pytest.approx(cx, abs=0.01) and loc.v_px == pytest.approx(cy, abs=0.01)
    ys, xs = np.nonzero(binarise(_covered_square(cx, cy), 0.6))
    assert abs(xs.mean() - cx) > 0.05 or shift == 0.0   # the mask's rows and columns flip whole
