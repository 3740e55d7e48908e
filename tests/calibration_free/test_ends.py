"""A bar with one end hidden (``calibration_free.ends``).

A synthetic bar, drawn with anti-aliased edges into a saturation-like channel (the bar at 200,
the table at 10, a slate card at 90), is seen by a camera looking at it from an angle: its
near half is drawn longer than its far half. The end map fitted on whole bars must put the
centre of a bar whose one end is under the card where the whole bar's centre is, and must
leave the centre alone where it cannot say which end is hidden.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from calibration_free.ends import READ_DEG, EndMap, blob_axis, fit_ends, hidden_end_shift
from calibration_free.errors import BundleError

SIZE = (144, 192)  # rows, columns
SUPERSAMPLE = 4
THRESHOLD = 117.0
TABLE, BAR, CARD = 10.0, 200.0, 90.0
HALF_NEAR, HALF_FAR, HALF_WIDTH = 40.0, 34.0, 16.0  # px: the view from an angle
TAUGHT = (96.0, 70.0)  # the bar's centre at the taught pose
DIRECTION = (0.0, 1.0)  # the bar's axis at the taught pose: down the image


def bar_frame(centre: tuple[float, float], turn_deg: float, card: int = 0
              ) -> tuple[np.ndarray, np.ndarray]:
    """The channel and the part's mask: the bar turned by ``turn_deg`` about ``centre``; a
    card over its far end (``card`` -1: the low end, up the image), its near end (+1), or
    none (0), covering 14 px of it and running on beyond it."""
    s = SUPERSAMPLE
    a = math.radians(turn_deg)
    d = np.array([-math.sin(a), math.cos(a)])  # turn 0: down the image
    n = np.array([d[1], -d[0]])
    c = np.array(centre)

    def poly(points):
        return [np.round(np.array(points) * s).astype(np.int32)]

    big = np.full((SIZE[0] * s, SIZE[1] * s), TABLE, np.float32)
    corners = [c - HALF_FAR * d - HALF_WIDTH * n, c - HALF_FAR * d + HALF_WIDTH * n,
               c + HALF_NEAR * d + HALF_WIDTH * n, c + HALF_NEAR * d - HALF_WIDTH * n]
    cv2.fillPoly(big, poly(corners), BAR)
    if card:
        inner = (HALF_NEAR - 14.0) if card > 0 else -(HALF_FAR - 14.0)
        outer = inner + card * 60.0
        strip = [c + inner * d - 17 * n, c + inner * d + 17 * n, c + outer * d + 17 * n,
                 c + outer * d - 17 * n]
        cv2.fillPoly(big, poly(strip), CARD)
    channel = cv2.resize(big, (SIZE[1], SIZE[0]), interpolation=cv2.INTER_AREA)
    mask = np.where(channel > THRESHOLD, 255, 0).astype(np.uint8)
    return channel, mask


def whole_centre(turn_deg: float, centre: tuple[float, float]) -> tuple[float, float]:
    """Where the localisation puts the whole bar: its blob's centroid."""
    _, mask = bar_frame(centre, turn_deg)
    return blob_axis(mask).centre


@pytest.fixture(scope="module")
def ends() -> EndMap:
    rng = np.random.default_rng(3)
    channels, masks, centres, taught = [], [], [], []
    for k in range(40):
        here = k < 4
        turn = 0.0 if here else rng.uniform(-45.0, 45.0)
        shift = (0.0, 0.0) if here else tuple(rng.uniform(-6.0, 6.0, 2))
        centre = (TAUGHT[0] + shift[0], TAUGHT[1] + shift[1])
        channel, mask = bar_frame(centre, turn)
        channels.append(channel)
        masks.append(mask)
        centres.append(whole_centre(turn, centre))
        taught.append(here)
    fitted = fit_ends(channels, masks, np.array(centres), np.array(taught), DIRECTION,
                      THRESHOLD)
    assert fitted is not None
    return fitted


def test_the_map_fits_the_whole_bar(ends):
    assert max(ends.rms_px) < 0.35  # psi and its square for the turn within FIT_DEG
    assert ends.length_px == pytest.approx(HALF_NEAR + HALF_FAR, abs=1.0)


@pytest.mark.parametrize("card", [-1, 1])
@pytest.mark.parametrize("turn", [0.0, -12.0, 15.0])
def test_a_bar_with_one_end_under_a_card_is_centred_on_the_end_seen(ends, card, turn):
    centre = (TAUGHT[0] + 2.5, TAUGHT[1] - 3.0)
    channel, mask = bar_frame(centre, turn, card)
    seen = blob_axis(mask).centre
    truth = whole_centre(turn, centre)
    assert math.dist(seen, truth) > 5.0  # the blob's own centre is off by half the card
    shift = hidden_end_shift(channel, mask, seen[0], seen[1], ends, THRESHOLD)
    assert shift is not None
    du, dv, hidden = shift
    assert math.dist((seen[0] + du, seen[1] + dv), truth) < 0.5
    assert hidden == pytest.approx(14.0, abs=1.5)


def test_nothing_moves_where_it_cannot_say_which_end_is_hidden(ends):
    # the whole bar: nothing beyond either end
    channel, mask = bar_frame(TAUGHT, 0.0)
    assert hidden_end_shift(channel, mask, *blob_axis(mask).centre, ends, THRESHOLD) is None
    # something beyond both ends
    channel, mask = bar_frame(TAUGHT, 0.0, 1)
    other, _ = bar_frame(TAUGHT, 0.0, -1)
    both = np.maximum(channel, np.where(other == CARD, CARD, TABLE).astype(np.float32))
    both_mask = np.where(both > THRESHOLD, 255, 0).astype(np.uint8)
    assert hidden_end_shift(both, both_mask, *blob_axis(both_mask).centre, ends,
                            THRESHOLD) is None
    # turned beyond the map's reach
    channel, mask = bar_frame(TAUGHT, READ_DEG + 10.0, 1)
    assert hidden_end_shift(channel, mask, *blob_axis(mask).centre, ends, THRESHOLD) is None
    # the end seen at the frame's edge may be the frame's, not the bar's
    channel, mask = bar_frame((TAUGHT[0], 36.0), 0.0, 1)
    assert hidden_end_shift(channel, mask, *blob_axis(mask).centre, ends, THRESHOLD) is None


def test_too_few_images_near_the_taught_heading_give_no_map():
    channel, mask = bar_frame(TAUGHT, 0.0)
    far, far_mask = bar_frame(TAUGHT, 60.0)
    assert fit_ends([channel] * 4 + [far] * 20, [mask] * 4 + [far_mask] * 20,
                    np.array([TAUGHT] * 24), np.array([True] * 4 + [False] * 20),
                    DIRECTION, THRESHOLD) is None


def test_a_bad_map_is_refused(ends):
    info = ends.to_info()
    assert EndMap.from_info(info) == ends
    for bad in ({**info, "low": info["low"][:3]}, {**info, "direction": [1.0, 1.0]},
                {**info, "length_px": float("nan")}, {k: info[k] for k in list(info)[:-1]},
                [1, 2]):
        with pytest.raises(BundleError, match="axis.ends"):
            EndMap.from_info(bad)
