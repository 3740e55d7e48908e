"""Parsing ``where`` by its labelled lines: with and without joints, odd spacing, garbage."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.core.errors import ProtocolError
from drivers.core.pose import Pose
from drivers.val.where import parse_where

CARTESIAN = ["     X         Y         Z         O         A         T",
             "   300.00     -0.50    150.25   -90.000    90.000     6.000"]
JOINTS = ["    JT1       JT2       JT3       JT4       JT5       JT6",
          "  -25.045    20.059  -176.592     0.000   -23.467    64.955"]
POSE = Pose(300.0, -0.5, 150.25, -90.0, 90.0, 6.0)


def test_cartesian_only():
    reading = parse_where(CARTESIAN)
    assert reading.pose == POSE and reading.joints_deg is None


def test_with_joint_block_and_blank_lines():
    reading = parse_where(["", *CARTESIAN, "", *JOINTS, ""])
    assert reading.pose == POSE
    assert reading.joints_deg == (-25.045, 20.059, -176.592, 0.0, -23.467, 64.955)


def test_extra_whitespace_tabs_and_lowercase_labels():
    lines = ["\t x  y   z o a t  ", "300   -0.5\t150.25 -90 90 6.0   "]
    assert parse_where(lines).pose == POSE


def test_unrelated_lines_around_the_table_are_ignored():
    assert parse_where(["Robot at rest", *CARTESIAN, "3 programs loaded"]).pose == POSE


def test_combined_v_plus_header():
    lines = ["  X/JT1  Y/JT2  Z/JT3  O/JT4  A/JT5  T/JT6", CARTESIAN[1], JOINTS[1]]
    reading = parse_where(lines)
    assert reading.pose == POSE and reading.joints_deg[2] == -176.592


def test_order_of_blocks_does_not_matter():
    assert parse_where([*JOINTS, *CARTESIAN]).pose == POSE


@pytest.mark.parametrize("lines", [
    [],
    ["garbage", "1 2 3 4 5 6"],                              # no header
    [CARTESIAN[0]],                                          # header without values
    [CARTESIAN[0], "1 2 3 4 5"],                             # five values
    [CARTESIAN[0], "1 2 3 4 5 6 7"],                         # seven values
    [CARTESIAN[0], "1 2 3 4 5 *****"],                       # overflow field
    [CARTESIAN[0], "1 2 3 nan 5 6"],
    [CARTESIAN[0], "1 2 3 1e999 5 6"],
    [*CARTESIAN, *CARTESIAN],                                # two tables
    [*CARTESIAN, JOINTS[0], "1 2 3"],                        # broken joint block
])
def test_garbage_raises_protocol_error(lines):
    with pytest.raises(ProtocolError):
        parse_where(lines)


finite = st.floats(min_value=-9999, max_value=9999, allow_nan=False)


@given(st.lists(finite, min_size=6, max_size=6), st.text(max_size=40))
def test_printed_values_round_trip(values, noise):
    line = " ".join(f"{v:.3f}" for v in values)
    noise_lines = [n for n in noise.splitlines() if "x" not in n.lower()]
    reading = parse_where([*noise_lines, CARTESIAN[0], line])
    assert reading.pose.as_dict() == pytest.approx(
        dict(zip(reading.pose.as_dict(), (round(v, 3) for v in values), strict=True)))


@given(st.lists(st.text(max_size=60), max_size=8))
def test_arbitrary_text_gives_a_reading_or_protocol_error(lines):
    try:
        parse_where(lines)
    except ProtocolError:
        pass
