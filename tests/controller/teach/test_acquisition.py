"""Acquisition around the nominal pose: grid order, step-limited transfer, exact labels."""

import numpy as np
import pytest

from calibration_free.dataset import grid_offsets
from controller.config import GridConfig
from controller.teach.acquisition import acquire, grid_for, serpentine, transfer
from drivers.core.pose import Pose, ToolStep
from drivers.safety import SafetyLimits
from tests.mocks.fakes import FakeArm, FakeCamera

NOMINAL = Pose(300.0, 0.0, 150.0, -90.0, 90.0, 10.0)


def active(device):
    device.connect()
    device.activate()
    return device


def test_serpentine_keeps_every_point_and_short_moves():
    grid = grid_offsets(25.0, 45.0)
    order = serpentine(grid)
    assert sorted(map(tuple, order)) == sorted(map(tuple, grid))
    jumps = np.abs(np.diff(order[:, :2], axis=0)).max(axis=1)
    assert jumps.max() <= 25.0 + 1e-9  # never jumps across the whole grid


def test_transfer_splits_long_moves_within_limits():
    limits = SafetyLimits(max_step_mm=10.0, max_step_deg=20.0)
    arm = active(FakeArm(limits, start=NOMINAL))
    target = NOMINAL.moved_in_tool_frame(ToolStep(35.0, -12.0, 0.0, 70.0))
    transfer(arm, target, limits)
    assert len(arm.moves) == 4
    s = arm.pose().tool_step_to(target)
    assert abs(s.dx_mm) < 1e-6 and abs(s.dy_mm) < 1e-6 and abs(s.dphi_deg) < 1e-6


def test_labels_are_the_exact_step_back_to_nominal_even_with_tracking_error():
    arm = active(FakeArm(start=NOMINAL))
    arm.tracking_offset = ToolStep(0.3, -0.2, 0.0, 0.5)  # the arm misses every target a bit
    cam = active(FakeCamera())
    offsets = np.array([[5.0, -5.0, 10.0], [-5.0, 0.0, -20.0]])
    data = acquire(arm, cam, NOMINAL, offsets, name="t", progress=False,
                   ground_truth=lambda: (0.0, 0.0, 0.0))
    assert data.images.shape == (2, 144, 192, 3) and len(data.samples) == 2
    for (_, _, dphi), label, reached in zip(offsets, data.labels, arm.moves, strict=False):
        back = reached.moved_in_tool_frame(ToolStep(*label[:2], 0.0, label[2]))
        assert back.tool_step_to(NOMINAL).translation_mm == pytest.approx(0.0, abs=1e-9)
        assert label[2] == pytest.approx(dphi - 0.5, abs=1e-9)
    assert arm.moves[-1].tool_step_to(NOMINAL).translation_mm < 0.5  # back at nominal


@pytest.mark.parametrize("kappa", [1, 2, 4, 6])
def test_grid_for_staggers_the_nn2_grid_and_keeps_the_nn1_grid(kappa):
    period = 360.0 / kappa
    nn1 = grid_for(GridConfig(a_mm=25.0), kappa)
    nn2 = grid_for(GridConfig(a_mm=5.0, staggered=True), kappa)
    assert nn1.shape == nn2.shape == (63, 3)
    assert len(np.unique(nn1[:, 2])) == 7            # the paper's grid (the PSOM needs it)
    assert len(np.unique(nn2[:, 2].round(6))) == 63
    assert np.abs(nn2[:, 2]).max() < period / 2 and np.abs(nn2[:, :2]).max() == 5.0
    # serpentine order: consecutive moves stay short
    assert np.abs(np.diff(nn2[:, :2], axis=0)).max() <= 5.0 + 1e-9
    b = grid_for(GridConfig(a_mm=5.0, b_deg=10.0, staggered=True), kappa)
    assert np.abs(b[:, 2]).max() < 10.0


def test_frames_at_the_taught_pose_come_first_and_are_counted():
    arm = active(FakeArm(start=NOMINAL.moved_in_tool_frame(ToolStep(3.0, 0.0, 0.0, 5.0))))
    cam = active(FakeCamera())
    offsets = np.array([[5.0, -5.0, 10.0], [-5.0, 0.0, -20.0]])
    data = acquire(arm, cam, NOMINAL, offsets, name="t", progress=False, taught_frames=3)
    assert len(data) == 5 and data.metadata["taught_frames"] == 3
    np.testing.assert_allclose(data.labels[:3], 0.0, atol=1e-9)   # moved to nominal first
    np.testing.assert_allclose(data.labels[3:, 2], offsets[:, 2], atol=1e-9)
    assert acquire(arm, cam, NOMINAL, offsets, name="t",
                   progress=False).metadata["taught_frames"] == 0


def test_each_frame_at_the_taught_pose_follows_its_own_approach_from_another_side():
    """The arm's repeatability error is drawn at every move: frames after one approach
    share one, so each taught-pose frame is taken after leaving the pose and coming back."""
    arm = active(FakeArm(start=NOMINAL))
    grabbed_after: list[int] = []
    cam = active(FakeCamera())
    grab = cam.grab

    def counting_grab():
        grabbed_after.append(len(arm.moves))
        return grab()

    cam.grab = counting_grab
    acquire(arm, cam, NOMINAL, np.array([[5.0, -5.0, 10.0]]), name="t", progress=False,
            taught_frames=4)
    settling = [n for n in grabbed_after if n == 0]  # the exposure settles before any move
    assert len(settling) >= 2
    taught = grabbed_after[len(settling):len(settling) + 4]
    sides = []
    for n in taught:
        away, back = arm.moves[n - 2], arm.moves[n - 1]
        assert back.tool_step_to(NOMINAL).translation_mm == pytest.approx(0.0, abs=1e-9)
        step = NOMINAL.tool_step_to(away)
        assert step.translation_mm == pytest.approx(1.0, abs=1e-9)
        sides.append((round(step.dx_mm, 6), round(step.dy_mm, 6)))
    assert len(set(sides)) == 4 and np.diff(taught).min() == 2
