"""The long axis' reading of an elongated part's turn (``calibration_free.axis``).

A synthetic screw (a shank with a head at one end) is drawn as a tilted camera sees it: its
image direction is not the tool's turn (``image_angle``: steeper near the taught pose, as the
cell's camera sees the screw), and its position in the image moves. The map fitted on a
staggered NN2 grid must read unseen turns over the whole circle with NN2 choosing the head's
side, and never take a reading NN2 disagrees with.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from calibration_free.axis import (
    AGREE_DEG,
    WHOLE_MAX_RMS_DEG,
    AxisMap,
    axis_of,
    fit_axis,
)
from calibration_free.dataset import staggered_grid_offsets
from calibration_free.errors import BundleError
from calibration_free.roi import extract_roi

SIZE_PX = 120
SUPERSAMPLE = 4


def image_angle(turn_deg: float, kappa: int) -> float:
    """The part's image direction for a tool turn: the turn scaled up near zero and back
    down further out (a view from an angle), plus the camera's roll."""
    t = math.radians(turn_deg * kappa / 2.0)
    return 2.0 / kappa * math.degrees(math.atan2(1.4 * math.sin(t), math.cos(t))) + 90.0


def part_roi(turn_deg: float, shift_px: tuple[float, float], kappa: int = 1,
             rng: np.random.Generator | None = None, round_part: bool = False) -> np.ndarray:
    """The 50x50 ROI centred on the part's centroid: a 44x10 px bar, with a head at one end
    (kappa 1) or none (kappa 2), or a disc (``round_part``)."""
    s = SUPERSAMPLE
    big = np.zeros((SIZE_PX * s, SIZE_PX * s), np.uint8)
    cx, cy = (SIZE_PX / 2.0 + shift_px[0]) * s, (SIZE_PX / 2.0 + shift_px[1]) * s
    if round_part:
        cv2.circle(big, (round(cx), round(cy)), 14 * s, 255, -1)
    else:
        a = math.radians(image_angle(turn_deg, kappa))
        d = np.array([math.cos(a), math.sin(a)])
        n = np.array([-d[1], d[0]])
        c = np.array([cx, cy])
        corners = [c + (sx * 22 * d + sy * 5 * n) * s for sx, sy in
                   ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        cv2.fillPoly(big, [np.round(np.array(corners)).astype(np.int32)], 255)
        if kappa == 1:
            head = c + 20 * d * s
            cv2.circle(big, (round(head[0]), round(head[1])), 9 * s, 255, -1)
    img = cv2.resize(big, (SIZE_PX, SIZE_PX), interpolation=cv2.INTER_AREA).astype(np.float32)
    if rng is not None:
        img += rng.normal(0.0, 2.0, img.shape).astype(np.float32) * (img > 0)
    m = cv2.moments((img > 127).astype(np.uint8), binaryImage=True)
    u, v = m["m10"] / m["m00"], m["m01"] / m["m00"]
    return extract_roi(img, u, v, 50), np.array([u, v])


def grid(kappa: int):
    """The staggered NN2 grid's ROIs (shifts of +/-2 px) with four frames at the taught pose
    first, as acquisition takes them."""
    rng = np.random.default_rng(0)
    offsets = np.concatenate([np.zeros((4, 3)), staggered_grid_offsets(2.0, 180.0 / kappa)])
    rois, uv = zip(*(part_roi(o[2], (o[0], o[1]), kappa, rng) for o in offsets), strict=True)
    taught = np.zeros(len(offsets), bool)
    taught[:4] = True
    return list(rois), np.array(uv), offsets[:, 2], taught


def wrapped(deg, period):
    return (np.asarray(deg) + period / 2.0) % period - period / 2.0


def test_axis_of_reads_direction_and_elongation():
    roi, _ = part_roi(0.0, (0.0, 0.0), kappa=2)
    angle, elongation = axis_of(roi)
    assert abs(wrapped(angle - 90.0, 180.0)) < 0.5 and elongation > 2.5
    disc, _ = part_roi(0.0, (0.0, 0.0), round_part=True)
    assert axis_of(disc)[1] < 1.05
    assert axis_of(np.zeros((50, 50), np.float32)) == (0.0, 1.0)


@pytest.mark.parametrize("kappa", [1, 2])
def test_the_axis_reads_every_turn_of_the_period(kappa):
    rois, uv, dphi, taught = grid(kappa)
    axis = fit_axis(rois, uv, dphi, taught, kappa)
    assert axis is not None and axis.kappa == kappa
    period = 360.0 / kappa
    rng = np.random.default_rng(3)
    errors, near_errors = [], []
    for turn in rng.uniform(-period / 2.0, period / 2.0, 80):
        shift = tuple(rng.uniform(-1.5, 1.5, 2))
        roi, (u, v) = part_roi(turn, shift, kappa, rng)
        # NN2's reading: right to within 12 deg; the axis says which side the head is on
        nn2 = float(wrapped(turn + rng.uniform(-12.0, 12.0), period))
        read = axis.reading(roi, u, v, nn2)
        assert read is not None, turn
        err = float(wrapped(read - turn, period))
        (near_errors if abs(turn) < 10.0 else errors).append(err)
    assert np.sqrt(np.mean(np.square(errors))) < 1.0, np.round(errors, 2)
    assert np.abs(near_errors).max() < 0.5, np.round(near_errors, 2)


@pytest.mark.parametrize("turn", [0.0, 5.0, -12.0, 28.0])
@pytest.mark.parametrize("nn2_off", [-21.0, 21.0])
def test_the_axis_reads_where_nn2_is_off_by_what_poor_light_does(turn, nn2_off):
    """Near the taught pose in poor light NN2 read the screw up to 21 deg off; the axis, which
    the lamp barely moves, must still be taken (it reads within 1 deg here)."""
    rois, uv, dphi, taught = grid(1)
    axis = fit_axis(rois, uv, dphi, taught, 1)
    roi, (u, v) = part_roi(turn, (0.5, -0.5), 1)
    read = axis.reading(roi, u, v, turn + nn2_off)
    assert read is not None and abs(read - turn) < 1.0, read


def test_a_reading_nn2_disagrees_with_is_not_taken():
    rois, uv, dphi, taught = grid(1)
    axis = fit_axis(rois, uv, dphi, taught, 1)
    roi, (u, v) = part_roi(40.0, (0.0, 0.0), 1)
    u0, v0 = uv[taught].mean(axis=0)
    assert abs(axis.reading(roi, u, v, 40.0) - 40.0) < 1.0
    assert axis.reading(roi, u, v, 40.0 + AGREE_DEG + 5.0) is None
    # NN2 pointing the other way: the head is on the other side, the axis cannot say which,
    # so it never reads the turn NN2 points away from
    other = axis.reading(roi, u, v, -140.0)
    assert other is None or abs(wrapped(other - 40.0, 360.0)) > 90.0
    # a frame without a clear axis (a card hiding most of the shank) gives none
    disc, (ud, vd) = part_roi(0.0, (0.0, 0.0), round_part=True)
    assert axis.reading(disc, ud, vd, 0.0) is None
    assert (u0, v0) == pytest.approx(axis.uv0_px)


def test_a_whole_circle_map_that_fits_badly_reads_only_near_the_taught_pose():
    rois, uv, dphi, taught = grid(2)
    axis = fit_axis(rois, uv, dphi, taught, 2)
    assert axis.whole_reads and axis.whole_rms_deg < WHOLE_MAX_RMS_DEG
    near_only = dataclasses.replace(axis, whole_reads=False)
    roi, (u, v) = part_roi(40.0, (0.0, 0.0), 2)
    assert axis.reading(roi, u, v, 42.0) is not None
    assert near_only.reading(roi, u, v, 42.0) is None  # NN2's reading stands there
    roi, (u, v) = part_roi(6.0, (0.0, 0.0), 2)
    assert near_only.reading(roi, u, v, 8.0) == pytest.approx(6.0, abs=0.3)
    assert near_only.reading(roi, u, v, 8.0) == axis.reading(roi, u, v, 8.0)


def test_no_axis_for_a_round_part_or_a_symmetric_one(caplog):
    rois, uv, dphi, taught = grid(1)
    # a small NN2 grid (a 3x3x3 one: 120 deg apart for the screw) cannot fit the near map
    sparse = (np.abs(dphi) > 30.0) | taught
    with caplog.at_level("WARNING", logger="calibration_free.axis"):
        assert fit_axis([r for r, k in zip(rois, sparse, strict=True) if k], uv[sparse],
                        dphi[sparse], taught[sparse], 1) is None
    assert "no axis map: only 4 NN2 images" in caplog.text
    assert fit_axis(rois, uv, dphi, taught, 4) is None
    discs = [part_roi(p, (0.0, 0.0), round_part=True)[0] for p in dphi]
    assert fit_axis(discs, uv, dphi, taught, 1) is None
    assert fit_axis(rois, uv, dphi, np.zeros(len(rois), bool), 1) is None


def test_the_map_round_trips_and_bad_files_are_refused():
    rois, uv, dphi, taught = grid(1)
    axis = fit_axis(rois, uv, dphi, taught, 1)
    assert AxisMap.from_info(axis.to_info()) == axis
    info = axis.to_info()
    for bad, match in (({**info, "whole": info["whole"][:-1]}, "whole needs"),
                       ({**info, "axis0_deg": float("nan")}, "finite"),
                       ({**info, "kappa": 4}, "kappa must be 1 or 2"),
                       ({k: v for k, v in info.items() if k != "near"}, "needs the keys"),
                       ({**info, "near": "x"}, "finite"),
                       ({**info, "whole_reads": "yes"}, "whole_reads must be true or false"),
                       ({**info, "silhouette": "saturation"},
                        "silhouette must be coverage or features"),
                       ([1, 2], "needs the keys")):
        with pytest.raises(BundleError, match=match):
            AxisMap.from_info(bad)


def test_the_silhouette_a_map_reads_is_kept_and_older_files_read_the_features():
    rois, uv, dphi, taught = grid(1)
    axis = fit_axis(rois, uv, dphi, taught, 1, "coverage")
    assert axis.silhouette == "coverage"
    assert AxisMap.from_info(axis.to_info()).silhouette == "coverage"
    older = {k: v for k, v in axis.to_info().items() if k != "silhouette"}
    assert AxisMap.from_info(older).silhouette == "features"
    assert fit_axis(rois, uv, dphi, taught, 1).silhouette == "features"
