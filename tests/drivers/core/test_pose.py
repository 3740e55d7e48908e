"""VAL pose math: O/A/T round trips, the tool-down singularity, tool-frame steps."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.core.pose import Pose, ToolStep, wrap_deg

angles = st.floats(-179.0, 179.0)


@given(angles, st.floats(-85.0, 85.0), angles)
def test_matrix_round_trip_away_from_singularity(o, a, t):
    p = Pose(10.0, -20.0, 30.0, o, a, t)
    q = Pose.from_matrix(p.position_mm, p.rotation())
    assert np.allclose(q.rotation(), p.rotation(), atol=1e-9)
    assert (q.o_deg, q.a_deg, q.t_deg) == pytest.approx((o, a, t), abs=1e-6)


@given(angles)
def test_tool_down_reports_o_minus_90_and_keeps_the_rotation(t):
    p = Pose(0.0, 0.0, 0.0, -90.0, 90.0, t)
    r = p.rotation()
    assert r[:, 2] == pytest.approx([0.0, 0.0, -1.0], abs=1e-12)  # approach points down
    q = Pose.from_matrix(p.position_mm, r)
    assert q.o_deg == -90.0 and q.a_deg == pytest.approx(90.0)
    assert np.allclose(q.rotation(), r, atol=1e-9)


@given(st.floats(-30, 30), st.floats(-30, 30), st.floats(-10, 10), st.floats(-170, 170))
def test_tool_step_round_trip(dx, dy, dz, dphi):
    start = Pose(300.0, 20.0, 150.0, -90.0, 90.0, 17.0)
    end = start.moved_in_tool_frame(ToolStep(dx, dy, dz, dphi))
    back = start.tool_step_to(end)
    assert (back.dx_mm, back.dy_mm, back.dz_mm) == pytest.approx((dx, dy, dz), abs=1e-6)
    assert back.dphi_deg == pytest.approx(dphi, abs=1e-6)


def test_positive_dz_moves_along_the_approach_axis_down():
    start = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 0.0)
    assert start.moved_in_tool_frame(ToolStep(dz_mm=10.0)).z_mm == pytest.approx(140.0)


def test_approach_rotation_follows_tool_rotation():
    start = Pose(0.0, 0.0, 0.0, -90.0, 90.0, 0.0)
    turned = start.moved_in_tool_frame(ToolStep(dphi_deg=30.0))
    # The approach axis points down, so +30 deg about it is -30 deg about world z.
    assert wrap_deg(turned.approach_rotation_deg - start.approach_rotation_deg) == \
        pytest.approx(-30.0)


@pytest.mark.parametrize("angle,period,expected", [
    (180.0, 360.0, 180.0), (-180.0, 360.0, 180.0), (190.0, 360.0, -170.0),
    (45.0, 90.0, 45.0), (-45.0, 90.0, 45.0), (50.0, 90.0, -40.0), (725.0, 360.0, 5.0),
])
def test_wrap_deg(angle, period, expected):
    assert wrap_deg(angle, period) == pytest.approx(expected)


def test_is_finite():
    assert not Pose(math.nan, 0, 0, 0, 0, 0).is_finite()
