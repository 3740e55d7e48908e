"""The headings a re-zero by heading visits, and the ranges it refuses before the arm moves
(the procedure itself on the simulated cell: ``tests/controller/test_end_to_end.py``)."""

from __future__ import annotations

import math

import pytest

from calibration_free.errors import TrainingError
from controller.calibration import heading_zero
from controller.calibration.heading_zero import MAX_HEADINGS, centres, default_range, headings
from drivers.core.pose import ToolStep


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


class _SlidingPart:
    """The arm's side of a re-zero (``heading_zero._Turner``) over a part the jaws cannot
    centre: each set-down slides it along the jaws (``slides``, mm, one per set-down, and a
    turn of a tenth of that in deg); at each heading the taught pose reads where it lies plus
    the lamp's offset there (``lamp``); the first look reads ``first_extra`` mm more in x
    (the camera's gain)."""

    def __init__(self, slides, lamp, first_extra=0.0):
        self.slides, self.lamp, self.extra = list(slides), lamp, first_extra
        self.turn, self.offset = 0.0, 0.0
        self.turns, self.set_downs = [], 0

    def heading(self) -> float:
        return 100.0 + self.turn

    def set_down_at(self, turn: float) -> bool:
        if turn == self.turn:
            return False
        self.offset += self.slides.pop(0)
        self.turn = turn
        self.turns.append(turn)
        self.set_downs += 1
        return True

    def read(self, turn) -> ToolStep:
        assert turn == self.turn
        dx, dy, dphi = self.lamp(turn)
        extra, self.extra = self.extra, 0.0
        return ToolStep(self.offset + dx + extra, dy, 0.0, 0.1 * self.offset + dphi)


def test_a_part_the_jaws_cannot_centre_is_read_between_two_looks_at_the_taught_heading():
    def lamp(turn):  # the plain zero nulls the translation at the taught heading, not the turn
        return 0.01 * turn, -0.002 * turn, 0.2 + 0.003 * turn

    # set-downs that slide the part unevenly, as the screw's do (0 to 0.06 mm)
    slides = [0.0, 0.06, 0.02, 0.02, 0.05, 0.0, 0.01, 0.03]
    # the first look at the taught heading reads 0.02 mm more than the part lies off (the
    # camera's gain): it is in the first heading's zero by half, in no other
    part = _SlidingPart(slides, lamp, first_extra=0.02)
    turns = [-90.0, -30.0, 0.0, 30.0, 90.0]
    table = heading_zero._bracketed(part, turns)
    # there and back for every heading but the taught one itself
    assert part.turns == [-90.0, 0.0, -30.0, 0.0, 30.0, 0.0, 90.0, 0.0]
    assert part.turn == 0.0 and part.set_downs == 8
    # the table holds the tool's headings, unwrapped within half a turn of the first read
    assert table.headings_deg == pytest.approx([-170.0, 10.0, 70.0, 100.0, 130.0])
    off = 0.5 * max(abs(a - b) for a, b in zip(slides[::2], slides[1::2], strict=True))
    worst = 0.0
    for i, heading in enumerate(table.headings_deg):
        dx, dy, dphi = lamp((heading - 100.0 + 180.0) % 360.0 - 180.0)
        worst = max(worst, abs(table.dx_mm[i] - dx))
        # off by half the difference of the slides there and back, at most (the first
        # heading: and by half the first look's extra)
        assert table.dx_mm[i] == pytest.approx(dx, abs=off + (0.01 if heading == 10.0 else 0)
                                               + 1e-9)
        assert table.dy_mm[i] == pytest.approx(dy, abs=1e-9)
        # the turn (a tenth of a degree a millimetre of slide here) closed out evenly over
        # the eight set-downs: within 0.004 deg of the lamp's
        assert table.dphi_deg[i] == pytest.approx(dphi, abs=0.004)
    assert table.dx_mm[3] == pytest.approx(0.0, abs=1e-9)  # the taught heading, no set-down
    # what is left is the slides' unevenness (and the first look's), never their sum (0.19 mm)
    assert 0.0 < worst <= off + 0.01 + 1e-9
