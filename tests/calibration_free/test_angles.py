"""Angle codec: round trip across the wrap for several symmetry counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from calibration_free.angles import decode, encode
from drivers.core.errors import ConfigError
from drivers.core.pose import wrap_deg


@pytest.mark.parametrize("kappa", [1, 2, 4, 6])
def test_round_trip_across_the_wrap(kappa):
    half = 180.0 / kappa
    for dphi in (0.0, 1e-9, half - 1e-6, -half + 1e-6, half, half * 0.5, -half * 0.99):
        got = decode(*encode(dphi, kappa), kappa)
        assert isinstance(got, float)
        assert got == pytest.approx(dphi, abs=1e-6)
    # the wrap point itself decodes to +180/kappa, and just past it comes back negative
    assert decode(*encode(-half, kappa), kappa) == pytest.approx(half, abs=1e-9)
    assert decode(*encode(half + 1.0, kappa), kappa) == pytest.approx(-half + 1.0, abs=1e-9)


@pytest.mark.parametrize("kappa", [1, 2, 4, 6])
@given(dphi=st.floats(-720.0, 720.0, allow_nan=False))
def test_decode_gives_the_shortest_equivalent_rotation(kappa, dphi):
    half = 180.0 / kappa
    got = decode(*encode(dphi, kappa), kappa)
    assert -half < got <= half
    # same appearance: equal modulo 360/kappa (compare on the circle)
    assert abs(wrap_deg(kappa * (got - dphi))) < 1e-6


def test_arrays_and_unnormalised_codes():
    dphi = np.linspace(-44.0, 44.0, 9)
    s, c = encode(dphi, 4)
    assert isinstance(s, np.ndarray) and s.shape == (9,)
    np.testing.assert_allclose(decode(3.0 * s, 3.0 * c, 4), dphi, atol=1e-9)
    assert decode(0.0, -1.0, 1) == 180.0
    assert decode(-0.0, -1.0, 1) == 180.0
    assert decode(math.sin(math.radians(-90)), 0.0, 2) == pytest.approx(-45.0)


@pytest.mark.parametrize("kappa", [0, -1, 1.5, True])
def test_bad_kappa_is_refused(kappa):
    with pytest.raises(ConfigError, match="kappa"):
        encode(10.0, kappa)
    with pytest.raises(ConfigError, match="kappa"):
        decode(0.0, 1.0, kappa)
