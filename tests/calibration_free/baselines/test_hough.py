"""Hough transform, back-transform and outline edges on drawn squares at known poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration_free.baselines.hough import edges
from calibration_free.baselines.hough import transform as hough
from calibration_free.errors import ImageError
from calibration_free.preprocess import max_channel
from calibration_free.synthetic import SyntheticCell, render_at

SQUARE = SyntheticCell(corner_mm=0.0, holes_mm=(), noise_std=0.0)  # 30 px sharp square
HALF_SIDE_PX = SQUARE.side_mm / 2.0 * SQUARE.px_per_mm


def square_points(centre_xy, angle_deg: float, half: float, n: int = 41) -> np.ndarray:
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    t = np.linspace(-half, half, n)
    sides = [np.stack([t, np.full(n, s * half)], 1) for s in (-1, 1)] + \
            [np.stack([np.full(n, s * half), t], 1) for s in (-1, 1)]
    return np.asarray(centre_xy) + np.concatenate(sides) @ rot.T


def expected_lines(centre_xy, angle_deg, half, origin_xy) -> list[tuple[float, float]]:
    """(theta_deg in [0, 180), d_px) of a square's four sides."""
    out = []
    for theta in (angle_deg % 180.0, (angle_deg + 90.0) % 180.0):
        n = np.array([math.cos(math.radians(theta)), math.sin(math.radians(theta))])
        mid = float((np.asarray(centre_xy) - origin_xy) @ n)
        out += [(theta, mid - half), (theta, mid + half)]
    return out


def difference(line, theta: float, d: float) -> tuple[float, float]:
    """(|d theta|, |d d|) between a line and (theta, d), across the wrap (theta + 180, -d)."""
    dt = line.theta_deg - theta
    if abs(dt) > 90.0:
        return abs(abs(dt) - 180.0), abs(line.d_px + d)
    return abs(dt), abs(line.d_px - d)


def match(lines, expected, tol_deg: float, tol_px: float) -> None:
    for theta, d in expected:
        best = min(lines, key=lambda line: sum(difference(line, theta, d)))
        dt, dd = difference(best, theta, d)
        assert dt < tol_deg and dd < tol_px, (best, theta, d)


def lines_of(points, origin, reach=60.0):
    space = hough.accumulate(points, origin_px=origin, d_max_px=reach)
    sharp, owner = hough.back_transform(points, space)
    peaks = hough.find_peaks(sharp, max_peaks=6)
    return hough.fit_lines(points, owner, sharp, peaks, min_votes=5)


@pytest.mark.parametrize("angle_deg", [0.0, 17.3, 44.0, 71.5])
def test_lines_of_an_exact_square_are_exact(angle_deg):
    centre, origin = (80.6, 60.2), (80.0, 60.0)
    lines = lines_of(square_points(centre, angle_deg, 15.0), origin)
    assert len(lines) == 4
    match(lines, expected_lines(centre, angle_deg, 15.0, np.array(origin)), 1e-6, 1e-6)


@pytest.mark.parametrize("angle_deg, centre", [(0.0, (96.0, 72.0)), (23.0, (101.3, 69.6)),
                                               (-38.5, (90.7, 75.4)), (61.0, (99.5, 66.1))])
def test_hough_finds_a_drawn_square_within_1_deg_and_1_px(angle_deg, centre):
    image = max_channel(render_at(SQUARE, *centre, angle_deg))
    filled = edges.silhouette(image, 170.0, "bright", *centre)
    edge = edges.edge_map(image, 1.0, 20.0, 40.0)
    points = edges.outline_points(edge, filled, 3)
    origin = (95.0, 70.0)  # not the centre: offsets are tested too
    lines = lines_of(points, origin)
    assert len(lines) >= 4
    match(lines, expected_lines(centre, angle_deg, HALF_SIDE_PX, np.array(origin)), 1.0, 1.0)


def test_back_transform_sharpens_the_peaks():
    rng = np.random.default_rng(0)
    points = np.concatenate([square_points((60.0, 50.0), 25.0, 18.0),
                             rng.uniform(20.0, 100.0, (40, 2))])  # plus clutter
    space = hough.accumulate(points, origin_px=(60.0, 50.0), d_max_px=70.0)
    sharp, owner = hough.back_transform(points, space)
    raw_ratio = hough.peak_to_sidelobe(space, hough.find_peaks(space, max_peaks=4))
    sharp_ratio = hough.peak_to_sidelobe(sharp, hough.find_peaks(sharp, max_peaks=4))
    assert raw_ratio < 4.0
    assert sharp_ratio > 2.0 * raw_ratio
    assert sharp.votes.sum() == len(points) and owner.shape == (len(points), 2)


def test_inner_edges_are_masked():
    cell = SyntheticCell(noise_std=0.0)  # with its dark screw hole in the middle
    image = max_channel(render_at(cell, 96.0, 72.0, 10.0))
    filled = edges.silhouette(image, 170.0, "bright", 96.0, 72.0)
    edge = edges.edge_map(image, 1.0, 20.0, 40.0)
    points = edges.outline_points(edge, filled, 3)
    hole_px = cell.hole_radius_mm * cell.px_per_mm
    assert np.hypot(*(points - (96.0, 72.0)).T).min() > hole_px + 5.0  # no hole ring
    rows, cols = np.nonzero(edge.binary)
    assert (np.hypot(cols - 96.0, rows - 72.0) < hole_px + 2.0).any()  # it was an edge


def test_bad_arguments_are_refused():
    with pytest.raises(ImageError, match="whole multiple"):
        hough.accumulate(np.zeros((3, 2)), origin_px=(0, 0), d_max_px=5, theta_step_deg=7.0)
    with pytest.raises(ImageError, match="finite"):
        hough.accumulate(np.zeros((3, 3)), origin_px=(0, 0), d_max_px=5)
    with pytest.raises(ImageError, match="low <= high"):
        edges.edge_map(np.zeros((8, 8), np.float32), 1.0, 5.0, 2.0)
    with pytest.raises(ImageError, match="no blob"):
        edges.silhouette(np.zeros((8, 8), np.float32), 1.0, "bright", 4.0, 4.0)
