"""The constellation model: accepts a part's outline, rejects other line sets, says why."""

from __future__ import annotations

import numpy as np
import pytest

from calibration_free.baselines.hough.angle_map import fit_angle_map
from calibration_free.baselines.hough.constellation import (
    ConstellationModel,
    find_constellation,
    learn_model,
    pair_count,
    prior_model,
)
from calibration_free.baselines.hough.transform import HoughLine
from drivers.core.errors import ConfigError

MODEL = ConstellationModel(kappa=4, width_min_px=25.0, width_max_px=35.0,
                           parallel_tol_deg=5.0, gap_min_deg=84.0, gap_max_deg=96.0)


def square(angle_deg: float, half: float = 15.0, offset=(0.0, 0.0), votes=30.0):
    """The four lines of a square turned by angle_deg around offset (origin at 0, 0)."""
    lines = []
    for theta in (angle_deg % 180.0, (angle_deg + 90.0) % 180.0):
        n = np.array([np.cos(np.radians(theta)), np.sin(np.radians(theta))])
        mid = float(np.asarray(offset) @ n)
        lines += [HoughLine(theta, mid - half, votes), HoughLine(theta, mid + half, votes)]
    return lines


@pytest.mark.parametrize("angle_deg", [-44.0, -10.0, 0.0, 12.5, 40.0, 44.9])
def test_accepts_a_square_and_reads_its_angle_and_centre(angle_deg):
    noise = [HoughLine(33.0, 7.0, 12.0), HoughLine(150.0, -20.0, 9.0)]
    found, reason = find_constellation(noise + square(angle_deg, offset=(2.0, -1.5)), MODEL,
                                       (100.0, 50.0))
    assert reason == "" and found is not None
    assert abs(found.angle_deg - angle_deg) < 1e-9
    np.testing.assert_allclose(found.centre_px, (102.0, 48.5), atol=1e-9)
    np.testing.assert_allclose(found.widths_px, (30.0, 30.0), atol=1e-9)
    assert found.votes == 120.0


def test_rejects_random_line_sets():
    rng = np.random.default_rng(0)
    for _ in range(200):
        lines = [HoughLine(float(t), float(d), 20.0) for t, d in
                 zip(rng.uniform(0, 180, 6), rng.uniform(-40, 40, 6), strict=True)]
        found, reason = find_constellation(lines, MODEL, (0.0, 0.0))
        assert found is None and reason


def test_says_why_it_rejects():
    lines = square(10.0)
    assert "4" in find_constellation(lines[:3], MODEL, (0, 0))[1]
    wide = square(10.0, half=25.0)
    assert "pairs of parallel lines" in find_constellation(wide, MODEL, (0, 0))[1]
    skewed = square(10.0)[:2] + [HoughLine(70.0, -15.0, 30.0), HoughLine(70.0, 15.0, 30.0)]
    assert "deg apart" in find_constellation(skewed, MODEL, (0, 0))[1]
    # both lines of a pair on one side of the object: not its outline
    beside = square(10.0)[:2] + [HoughLine(100.0, 10.0, 30.0), HoughLine(100.0, 40.0, 30.0)]
    assert find_constellation(beside, MODEL, (0, 0))[0] is None


def test_learned_model_spans_the_training_outlines():
    prior = prior_model(4, 30.0)
    found = [find_constellation(square(a, half=h), prior, (0, 0))[0]
             for a, h in ((0.0, 13.0), (20.0, 15.0), (-30.0, 16.0))]
    model = learn_model(found, 4, width_margin=0.1, angle_margin_deg=3.0, vote_fraction=0.5)
    assert model.width_min_px == pytest.approx(26.0 * 0.9)
    assert model.width_max_px == pytest.approx(32.0 * 1.1)
    assert model.parallel_tol_deg == pytest.approx(3.0)
    assert model.gap_min_deg == pytest.approx(87.0) and model.gap_max_deg == pytest.approx(93.0)
    assert model.min_votes == 15.0  # half the 30 points of every training line
    short = [HoughLine(line.theta_deg, line.d_px, 10.0) for line in square(0.0)]
    assert "edge points or more" in find_constellation(short, model, (0, 0))[1]


def test_only_even_kappa_outlines_are_modelled():
    assert pair_count(4) == 2 and pair_count(6) == 3
    for kappa in (1, 2, 3, 5):
        with pytest.raises(ConfigError, match="even kappa"):
            pair_count(kappa)


def test_angle_map_learns_offset_and_direction_and_wraps():
    dphi = np.linspace(-45.0, 45.0, 13)
    psi = ((-dphi + 10.0) + 45.0) % 90.0 - 45.0  # the image turns the other way, offset 10
    amap = fit_angle_map(psi, dphi, 4, harmonics=1)
    for true in (-44.0, -20.0, 0.0, 33.0, 44.5):
        measured = ((-true + 10.0) + 45.0) % 90.0 - 45.0
        error = (amap(measured) - true + 45.0) % 90.0 - 45.0
        assert abs(error) < 1e-6
