"""The headings a re-zero by heading visits, and the ranges it refuses before the arm moves
(the procedure itself on the simulated cell: ``tests/controller/test_end_to_end.py``)."""

from __future__ import annotations

import math

import pytest

from calibration_free.errors import TrainingError
from controller.teach.heading_zero import MAX_HEADINGS, centres, default_range, headings


def test_a_range_in_even_steps_of_at_most_the_step_both_ends_included():
    assert headings(5.0, (-45.0, 45.0)) == pytest.approx([-45.0 + 5.0 * i for i in range(19)])
    assert 0.0 in headings(5.0, (-45.0, 45.0))
    assert headings(40.0, (-45.0, 45.0)) == pytest.approx([-45.0, -15.0, 15.0, 45.0])
    assert headings(500.0, (0.0, 10.0)) == pytest.approx([0.0, 10.0])


def test_only_a_part_with_faces_at_right_angles_is_centred_and_its_translation_read():
    assert centres(4) and centres(8)
    assert not any(centres(k) for k in (1, 2, 3, 6))


def test_the_default_range_is_one_symmetry_period_and_a_whole_turn_less_a_step():
    assert default_range(4, 5.0) == (-45.0, 45.0)
    assert default_range(2, 5.0) == (-90.0, 90.0)
    turn = headings(10.0, default_range(1, 10.0))
    assert turn[0] == -180.0 and turn[-1] == pytest.approx(170.0) and len(turn) == 36
    assert headings(500.0, default_range(1, 500.0)) == pytest.approx([-180.0, 0.0])


@pytest.mark.parametrize("step, span, match", [
    (0.0, (-45.0, 45.0), "step must be > 0"),
    (math.nan, (-45.0, 45.0), "step must be > 0"),
    (5.0, (10.0, 0.0), "lower to a higher"),
    (5.0, (0.0, 0.0), "lower to a higher"),
    (5.0, (-180.0, 180.0), "less than a turn"),
    (5.0, (0.0, math.inf), "lower to a higher"),
    (0.5, (-179.0, 179.0), f"at most {MAX_HEADINGS}"),
])
def test_ranges_that_are_no_turns_are_refused_in_one_line(step, span, match):
    with pytest.raises(TrainingError, match=match) as err:
        headings(step, span)
    assert "\n" not in str(err.value)
