"""NN2's zero by heading: interpolation, the table's ends, unwrapping, and bad tables refused
in one line."""

from __future__ import annotations

import math

import pytest

from calibration_free.errors import BundleError
from calibration_free.heading_zero import HeadingZero

TABLE = HeadingZero((0.0, 10.0, 20.0), (0.0, 0.5, -0.5))


def test_reads_its_rows_and_between_them_linearly():
    assert TABLE.at(10.0) == pytest.approx(0.5)
    assert TABLE.at(15.0) == pytest.approx(0.0)
    assert TABLE.at(2.5) == pytest.approx(0.125)


def test_a_heading_a_turn_away_is_the_same_heading():
    assert TABLE.at(17.0 + 360.0) == pytest.approx(TABLE.at(17.0))
    assert TABLE.at(17.0 - 720.0) == pytest.approx(TABLE.at(17.0))


def test_up_to_a_step_beyond_an_end_holds_that_end_and_further_out_nothing():
    assert TABLE.at(-9.0) == pytest.approx(0.0)
    assert TABLE.at(29.0) == pytest.approx(-0.5)
    assert TABLE.at(-11.0) is None
    assert TABLE.at(31.0) is None
    assert TABLE.at(180.0) is None
    assert TABLE.at(math.nan) is None


def test_readings_across_the_half_turn_are_unwrapped_and_sorted():
    table = HeadingZero.from_readings([(170.0, 0.1), (-175.0, 0.3), (-180.0, 0.2),
                                       (175.0, 0.15)])
    assert table.headings_deg == (170.0, 175.0, 180.0, 185.0)
    assert table.at(-177.5) == pytest.approx(0.25)
    assert table.step_deg == pytest.approx(5.0)


@pytest.mark.parametrize("headings, turns, match", [
    ((0.0,), (0.0,), "2 to"),
    ((0.0, 0.0), (0.0, 0.0), "increase"),
    ((10.0, 0.0), (0.0, 0.0), "increase"),
    ((0.0, 360.0), (0.0, 0.0), "less than 360"),
    ((0.0, 5.0), (0.0,), "one turn per heading"),
    ((0.0, math.inf), (0.0, 0.0), "finite"),
    ((0.0, 5.0), (0.0, "x"), "not numbers"),
    ((0.0, 5.0), (0.0, 9.0), "beyond"),
])
def test_a_table_that_is_no_zero_by_heading_is_refused_in_one_line(headings, turns, match):
    with pytest.raises(BundleError, match=match) as err:
        HeadingZero(headings, turns)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("info", [None, [], {"headings_deg": [0, 5]},
                                  {"headings_deg": [0, 5], "dphi_deg": [0, "x"]},
                                  {"headings_deg": "0,5", "dphi_deg": []}])
def test_bad_json_is_refused_in_one_line(info):
    with pytest.raises(BundleError, match="heading_zero") as err:
        HeadingZero.from_info(info)
    assert "\n" not in str(err.value)


def test_json_round_trip():
    assert HeadingZero.from_info(TABLE.to_info()) == TABLE


SHIFTED = HeadingZero((0.0, 10.0, 20.0), (0.0, 0.5, -0.5), (0.0, 0.04, -0.02),
                      (0.0, -0.01, 0.03))


def test_the_translation_reads_its_rows_and_between_them_as_the_turn_does():
    assert SHIFTED.has_translation and not TABLE.has_translation
    assert SHIFTED.shift_at(10.0) == pytest.approx((0.04, -0.01))
    assert SHIFTED.shift_at(15.0 + 360.0) == pytest.approx((0.01, 0.01))
    assert SHIFTED.shift_at(29.0) == pytest.approx((-0.02, 0.03))
    assert SHIFTED.shift_at(31.0) is None
    assert TABLE.shift_at(10.0) is None  # a table of the turn only
    assert SHIFTED.at(15.0) == pytest.approx(0.0)


def test_readings_with_the_translation_are_sorted_with_their_headings():
    table = HeadingZero.from_readings([(10.0, 0.5, 0.04, -0.01), (0.0, 0.0, 0.0, 0.0),
                                       (20.0, -0.5, -0.02, 0.03)])
    assert table == SHIFTED
    with pytest.raises(BundleError, match="all alike"):
        HeadingZero.from_readings([(0.0, 0.0), (10.0, 0.5, 0.04, -0.01)])


@pytest.mark.parametrize("dx, dy, match", [
    ((0.0, 0.1), None, "go together"),
    ((0.0,), (0.0,), "one translation per heading"),
    ((0.0, 1.6), (0.0, 0.0), "beyond 1.5 mm"),
    ((0.0, math.nan), (0.0, 0.0), "not finite"),
    ((0.0, "x"), (0.0, 0.0), "not numbers"),
])
def test_a_translation_that_is_no_light_offset_is_refused_in_one_line(dx, dy, match):
    with pytest.raises(BundleError, match=match) as err:
        HeadingZero((0.0, 5.0), (0.0, 0.1), dx, dy)
    assert "\n" not in str(err.value)


def test_json_round_trip_with_the_translation_and_bad_translation_json_refused():
    assert HeadingZero.from_info(SHIFTED.to_info()) == SHIFTED
    assert "dx_mm" not in TABLE.to_info()
    info = {**SHIFTED.to_info(), "dx_mm": "0,1"}
    with pytest.raises(BundleError, match="dx_mm"):
        HeadingZero.from_info(info)
