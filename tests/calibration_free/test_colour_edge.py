"""The part's centre read from the colour along its edge (``localise.colour_centre``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration_free.axis import axis_of
from calibration_free.front_end import FrontEnd
from calibration_free.kernels import colour_coverage_moments, saturation_image
from calibration_free.localise import (
    LOCAL_COLOUR_CONTRAST,
    MIN_COLOUR_CONTRAST,
    ColourEdge,
    colour_centre,
    localise,
    subpixel_centre,
)
from calibration_free.preprocess import IntensityStats
from drivers.core.errors import ConfigError

SAMPLES = 16  # renderer samples per pixel side
HEIGHT, WIDTH = 96, 128  # the frames' size
YELLOW = (0.9, 0.7, 0.05)  # the part's colour, linear light
THRESHOLD = 110.0  # saturation level the blob is cut at


def square_frame(u0: float, v0: float, *, lit: float = 1.6, dark: float = 0.15,
                 table: float = 0.2, part=YELLOW, noise: float = 0.0,
                 gamma: float = 2.2) -> np.ndarray:
    """A 128x96 frame of a 30 px square part centred on (u0, v0) on a grey table, shaded as a
    low lamp from the left shades a part with rounded edges: its left edge lit ``lit`` times
    its colour, its right edge ``dark`` times, the change steepest at the edges. Each pixel
    integrates the light over its area (linear light), then the camera's gamma and noise."""
    half = 15.0
    x, y = _samples()
    inside = (np.abs(x - u0) <= half) & (np.abs(y - v0) <= half)
    t = np.clip((x - (u0 - half)) / (2 * half), 0.0, 1.0)
    shade = dark + (lit - dark) * (1 - t) ** 3 + 0.3 * (1 - np.abs(2 * t - 1))
    return _camera(np.stack([np.where(inside, c * shade, table) for c in part], axis=-1),
                   gamma, noise)


def shadowed_frame(u0: float, v0: float, *, shadow_px: float = 4.0, noise: float = 0.0
                   ) -> np.ndarray:
    """``square_frame``'s part evenly lit, with a black cast shadow ``shadow_px`` wide along
    its right edge (a low lamp from the left on a part taller than it is wide)."""
    half = 15.0
    x, y = _samples()
    inside = (np.abs(x - u0) <= half) & (np.abs(y - v0) <= half)
    shadow = (x > u0 + half) & (x <= u0 + half + shadow_px) & (np.abs(y - v0) <= half + 2)
    table = np.where(shadow, 0.0, 0.2)
    return _camera(np.stack([np.where(inside, c, table) for c in YELLOW], axis=-1), 2.2, noise)


def _samples() -> tuple[np.ndarray, np.ndarray]:
    """The frame coordinates (x, y) of the renderer's samples, SAMPLES per pixel side."""
    rows, cols = np.mgrid[0:HEIGHT * SAMPLES, 0:WIDTH * SAMPLES]
    return (cols + 0.5) / SAMPLES - 0.5, (rows + 0.5) / SAMPLES - 0.5


def _camera(linear: np.ndarray, gamma: float = 2.2, noise: float = 0.0) -> np.ndarray:
    """The frame a camera delivers of the samples' linear light: each pixel their mean, then
    the output gamma and noise, as uint8."""
    frame = cv2.resize(linear, (WIDTH, HEIGHT), interpolation=cv2.INTER_AREA)
    out = np.clip(frame, 0.0, 1.0) ** (1.0 / gamma) * 255.0
    if noise:
        out = out + np.random.default_rng(7).normal(0.0, noise, out.shape)
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _centres(image: np.ndarray):
    saturation = saturation_image(np.ascontiguousarray(image))
    loc = localise(saturation, THRESHOLD)
    assert loc.ok
    grey = subpixel_centre(saturation, "bright", loc.u_px, loc.v_px, loc.area_px,
                           loc.part_mask)
    colour = colour_centre(image, ColourEdge(2.2), loc.u_px, loc.v_px, loc.area_px,
                           loc.part_mask)
    return loc, grey, colour


@pytest.mark.parametrize(("u0", "v0"), [(60.3, 45.7), (63.62, 48.15)])
@pytest.mark.parametrize("noise", [0.0, 2.0])
def test_a_part_lit_from_one_side_is_centred_where_it_lies(u0, v0, noise):
    _, grey, colour = _centres(square_frame(u0, v0, noise=noise))
    # the grey levels of the lit edge read as more part, of the dark edge as less
    assert grey[0] - u0 < -0.1
    assert colour is not None
    assert abs(colour[0] - u0) < 0.05 and abs(colour[1] - v0) < 0.05


def test_evenly_lit_part_reads_the_same_either_way():
    u0, v0 = 61.4, 47.3
    _, grey, colour = _centres(square_frame(u0, v0, lit=1.0, dark=1.0))
    assert abs(colour[0] - u0) < 0.05 and abs(colour[1] - v0) < 0.05
    assert abs(grey[0] - u0) < 0.07 and abs(grey[1] - v0) < 0.07


def test_with_localise_and_the_frame_the_colour_centre_is_taken():
    image = square_frame(60.3, 45.7)
    saturation = saturation_image(np.ascontiguousarray(image))
    _, _, colour = _centres(image)
    loc = localise(saturation, THRESHOLD, image=image, edge=ColourEdge(2.2))
    assert (loc.u_px, loc.v_px) == pytest.approx(colour[:2], abs=1e-9)
    # the part's share of each pixel is kept with the centre: its centroid is the centre
    x0, y0, weights = loc.coverage
    assert weights.dtype == np.float32 and (x0, y0) == colour[2][:2]
    np.testing.assert_array_equal(weights, colour[2][2])
    rows, cols = np.mgrid[0:weights.shape[0], 0:weights.shape[1]]
    centroid = ((weights * cols).sum() / weights.sum() + x0,
                (weights * rows).sum() / weights.sum() + y0)
    assert centroid == pytest.approx((loc.u_px, loc.v_px), abs=1e-4)


@pytest.mark.parametrize(("u0", "v0"), [(60.3, 45.7), (63.62, 48.15)])
def test_a_black_cast_shadow_beside_the_part_keeps_the_colour_edge(u0, v0):
    # the table around the shadow's pixels is too dark for its colour to be told from the
    # part's: those pixels read the part's own share, and the rest of the edge its colour
    _, grey, colour = _centres(shadowed_frame(u0, v0))
    assert colour is not None
    assert abs(colour[0] - u0) < 0.1 and abs(colour[1] - v0) < 0.05
    # the grey levels read the dark shadow's noise-free saturation ramp as more part
    # on one of the two places; the colour edge does not
    assert abs(colour[0] - u0) <= abs(grey[0] - u0) + 0.01


def test_a_part_of_the_tables_colour_falls_back_to_grey_levels():
    # a grey part brighter than a grey table: no colour tells them apart
    image = square_frame(60.3, 45.7, part=(0.5, 0.5, 0.5), lit=1.0, dark=1.0)
    grey_levels = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    loc = localise(grey_levels, 150.0)
    assert loc.ok
    assert colour_centre(image, ColourEdge(2.2), loc.u_px, loc.v_px, loc.area_px,
                         loc.part_mask) is None
    fallback = localise(grey_levels, 150.0, image=image, edge=ColourEdge(2.2))
    assert (fallback.u_px, fallback.v_px) == pytest.approx((loc.u_px, loc.v_px), abs=1e-9)


def _reference_colour_moments(rgb, blob, core, band, ring, linear, min_contrast,
                              local_contrast):
    """The kernel's formula in numpy, one pixel at a time: its moments and weights."""
    lin = linear[rgb]
    fg0, bg0 = lin[core > 0].mean(axis=0), lin[ring > 0].mean(axis=0)
    c0 = fg0 / np.linalg.norm(fg0)
    if bg0 @ bg0 - (c0 @ bg0) ** 2 < min_contrast ** 2:
        return (0.0, 0.0, 0.0), np.zeros(core.shape)
    height, width = core.shape
    m = np.zeros(3)
    weights = np.zeros(core.shape)
    for i in range(height):
        for j in range(width):
            if core[i, j]:
                w = 1.0
            elif band[i, j]:
                ys, xs = slice(max(i - 2, 0), i + 3), slice(max(j - 2, 0), j + 3)
                near_core = core[ys, xs] > 0
                near_ring = (ring[ys, xs] > 0) & ~near_core
                fg = lin[ys, xs][near_core].mean(axis=0) if near_core.any() else fg0
                bg = lin[ys, xs][near_ring].mean(axis=0) if near_ring.any() else bg0
                c = fg / np.linalg.norm(fg)
                across = bg @ bg - (c @ bg) ** 2
                p = lin[i, j]
                if across < local_contrast ** 2:  # a black shadow around: the part's share
                    w = float(np.clip(p @ c / np.linalg.norm(fg), -1.0, 2.0))
                else:
                    beta = (p @ bg - (c @ bg) * (p @ c)) / across
                    w = 1.0 - beta
                    if not blob[i, j]:
                        w = 0.5 * (w + (p @ c - beta * (c @ bg)) / np.linalg.norm(fg))
                    w = float(np.clip(w, -1.0, 2.0))
            else:
                continue
            weights[i, j] = w
            m += (w, w * j, w * i)
    return tuple(m), weights


@pytest.mark.parametrize("shadow", [False, True])
def test_colour_coverage_moments_match_the_numpy_formula(shadow):
    image = (shadowed_frame(60.3, 45.7, noise=3.0) if shadow
             else square_frame(60.3, 45.7, noise=3.0))
    loc, _, _ = _centres(image)
    window = (slice(20, 75), slice(35, 90))
    blob = loc.part_mask[window]
    core = cv2.erode(blob, np.ones((3, 3), np.uint8))
    band = cv2.dilate(blob, np.ones((3, 3), np.uint8))
    ring = cv2.subtract(cv2.dilate(blob, np.ones((5, 5), np.uint8)), band)
    linear = ColourEdge(2.2).linear
    weights = np.full(blob.shape, np.nan, np.float32)
    got = colour_coverage_moments(image[window], blob, core, band, ring, linear,
                                  MIN_COLOUR_CONTRAST, LOCAL_COLOUR_CONTRAST, weights)
    want, want_weights = _reference_colour_moments(image[window], blob, core, band, ring,
                                                   linear, MIN_COLOUR_CONTRAST,
                                                   LOCAL_COLOUR_CONTRAST)
    np.testing.assert_allclose(got, want, rtol=1e-9)
    np.testing.assert_allclose(weights, want_weights, rtol=1e-6, atol=1e-6)
    empty = np.zeros_like(core)
    assert colour_coverage_moments(image[window], blob, empty, band, ring, linear,
                                   MIN_COLOUR_CONTRAST, LOCAL_COLOUR_CONTRAST,
                                   weights) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("gamma", [0.5, 3.5, True, "2.2"])
def test_a_bad_camera_gamma_is_refused(gamma):
    with pytest.raises(ConfigError, match="gamma"):
        ColourEdge(gamma)


def _front(area_px: float = 900.0, **kw) -> FrontEnd:
    return FrontEnd(96, 128, IntensityStats(110.0, 30.0), THRESHOLD, "bright", area_px,
                    channel="saturation", **kw)


def test_the_front_end_keeps_its_edge_gamma_in_the_model_file():
    front = _front(edge_gamma=2.2)
    assert front.edge == ColourEdge(2.2)
    again = FrontEnd.from_info(front.to_info())
    assert again.edge_gamma == 2.2 and again.edge == ColourEdge(2.2)
    info = front.to_info()
    del info["localisation"]["edge_gamma"]  # a model file written before it
    assert FrontEnd.from_info(info).edge is None
    with pytest.raises(ConfigError, match="edge_gamma"):
        _front(edge_gamma=0.7)


def test_the_front_end_keeps_whether_holes_are_filled():
    front = _front(edge_gamma=2.2, edge_fill_holes=True)
    assert front.edge == ColourEdge(2.2, fill_holes=True)
    assert FrontEnd.from_info(front.to_info()).edge.fill_holes
    info = front.to_info()
    del info["localisation"]["edge_fill_holes"]  # a model file written before it
    assert FrontEnd.from_info(info).edge == ColourEdge(2.2)
    with pytest.raises(ConfigError, match="edge_fill_holes must be true or false"):
        _front(edge_gamma=2.2, edge_fill_holes="yes")
    with pytest.raises(ConfigError, match="fill_holes must be true or false"):
        ColourEdge(2.2, fill_holes=1)


def holed_frame(u0: float, v0: float, hole_du: float, *, wall: float) -> np.ndarray:
    """A 30 px square part centred on (u0, v0), evenly lit, with a round through hole of
    radius 5 px ``hole_du`` px right of its centre. The hole shows its wall on its left (its
    part colour times ``wall``, as a lamp falling into it lights it) and the table beneath
    on its right."""
    half, radius = 15.0, 5.0
    x, y = _samples()
    inside = (np.abs(x - u0) <= half) & (np.abs(y - v0) <= half)
    dx, dy = x - (u0 + hole_du), y - v0
    hole = dx * dx + dy * dy <= radius * radius
    shade = np.where(hole & (dx < 0.0), wall, 1.0)
    table = 0.2
    return _camera(np.stack([np.where(inside & ~(hole & (dx >= 0.0)), c * shade, table)
                             for c in YELLOW], axis=-1))


@pytest.mark.parametrize("wall", [0.05, 0.6])
def test_with_holes_filled_the_centre_is_the_outer_outlines(wall):
    u0, v0 = 60.4, 47.2
    image = holed_frame(u0, v0, 6.0, wall=wall)
    saturation = saturation_image(np.ascontiguousarray(image))
    loc = localise(saturation, THRESHOLD)
    assert loc.ok
    args = (image, loc.u_px, loc.v_px, loc.area_px, loc.part_mask)
    filled = colour_centre(args[0], ColourEdge(2.2, fill_holes=True), *args[1:])
    assert abs(filled[0] - u0) < 0.05 and abs(filled[1] - v0) < 0.05
    # the hole's coverage is the part's: 1 over the whole hole
    x0, y0, weights = filled[2]
    assert weights[int(v0) - y0, int(u0 + 6.0) - x0] == 1.0
    # read as edges, the hole's rim pulls the centre away from it, by how much of the hole
    # reads as table: what the lamp and the view show of its wall
    holed = colour_centre(args[0], ColourEdge(2.2), *args[1:])
    assert holed[0] - u0 < -0.2
    assert localise(saturation, THRESHOLD, image=image,
                    edge=ColourEdge(2.2, fill_holes=True)).u_px == pytest.approx(filled[0])


def test_the_front_end_reads_the_centre_from_colour_only_with_its_gamma():
    image = square_frame(60.3, 45.7)
    _, grey, colour = _centres(image)
    with_colour = _front(edge_gamma=2.2)
    without = _front()
    _, loc = with_colour.locate(image)
    assert (loc.u_px, loc.v_px) == pytest.approx(colour[:2], abs=1e-9)
    _, loc = without.locate(image)
    assert (loc.u_px, loc.v_px) == pytest.approx(grey, abs=1e-9)


def bar_frame(u0: float, v0: float, angle_deg: float, *, lit: float = 1.6,
              dark: float = 0.15) -> np.ndarray:
    """A 128x96 frame of a 44x12 px bar centred on (u0, v0), its long axis at ``angle_deg``
    from the u axis, shaded by a low lamp from the left as ``square_frame``'s part."""
    x, y = _samples()
    a = np.radians(angle_deg)
    along = (x - u0) * np.cos(a) + (y - v0) * np.sin(a)
    across = -(x - u0) * np.sin(a) + (y - v0) * np.cos(a)
    inside = (np.abs(along) <= 22.0) & (np.abs(across) <= 6.0)
    t = np.clip((x - (u0 - 22.0)) / 44.0, 0.0, 1.0)
    shade = dark + (lit - dark) * (1 - t) ** 3
    return _camera(np.stack([np.where(inside, c * shade, 0.2) for c in YELLOW], axis=-1))


@pytest.mark.parametrize("angle", [20.0, 65.0, 110.0])
def test_the_coverage_roi_is_the_parts_share_of_each_pixel_centred_on_it(angle):
    image = bar_frame(61.3, 47.6, angle)
    front = _front(edge_gamma=2.2, area_px=44.0 * 12.0)
    _, loc = front.locate(image)
    roi = front.coverage_roi(loc, 50)
    assert roi.shape == (50, 50) and roi.dtype == np.float32
    assert roi.min() >= 0.0 and roi.max() <= 1.0
    assert roi[24:26, 24:26].min() == 1.0
    corners = (roi[:4, :4], roi[:4, -4:], roi[-4:, :4], roi[-4:, -4:])
    assert max(c.max() for c in corners) == 0.0
    # its second moments give the bar's axis, whichever side the lamp lights
    direction, elongation = axis_of(roi)
    assert abs((direction - angle + 90.0) % 180.0 - 90.0) < 0.3
    assert elongation > 3.0
    # without the colour edge (or for a part drawn in where it is hidden) there is none
    _, grey_loc = _front(area_px=44.0 * 12.0).locate(image)
    assert grey_loc.coverage is None and front.coverage_roi(grey_loc, 50) is None
