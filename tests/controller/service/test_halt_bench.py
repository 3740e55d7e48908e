"""The halt measurement of ``finepos bench service``: motion bookkeeping from the VAL emulator's
listener and the pose sampler reading the cell."""

from __future__ import annotations

import threading
import time

from controller.service.halt_bench import MotionWatch, PoseSampler

WAIT_S = 5.0  # bounds only


def test_motion_watch_tracks_moves_and_when_the_arm_came_to_rest():
    watch = MotionWatch()
    watch.on_val("command", "where")  # not a motion
    watch.on_val("done", "where")
    assert watch.count() == 0
    watch.on_val("command", "do move trans(1,2,3,4,5,6)")
    start = watch.wait_running(0, WAIT_S)
    assert start is not None and watch.running_since(start)
    sent = time.monotonic()
    threading.Timer(0.05, watch.on_val, ("done", "do move trans(1,2,3,4,5,6)")).start()
    halted = watch.halted_at(sent, WAIT_S)  # waits for the running move to end
    assert halted is not None and halted > sent
    assert not watch.running_since(start)
    assert watch.started_after(sent) == 0
    watch.on_val("command", "do ready")
    assert watch.started_after(sent) == 1
    assert len(watch.durations_ms()) == 1


def test_motion_watch_at_rest_halts_at_once():
    watch = MotionWatch()
    watch.on_val("command", "do ready")
    watch.on_val("done", "do ready")
    sent = time.monotonic()
    assert watch.halted_at(sent, WAIT_S) == sent
    assert watch.wait_running(1, 0.01) is None  # no second motion


class MovingCell:
    """A cell whose arm pose changes until ``stop`` is set."""

    def __init__(self) -> None:
        self.stop = threading.Event()
        self.reads = 0

    def arm_pose(self):
        self.reads += 1
        return 0 if self.stop.is_set() else self.reads


def test_pose_sampler_remembers_the_last_change():
    cell = MovingCell()
    with PoseSampler(cell, period_s=0.002) as sampler:
        time.sleep(0.05)
        stopped = time.monotonic()
        cell.stop.set()
        time.sleep(0.05)
    assert sampler.last_change is not None
    assert stopped - 0.02 <= sampler.last_change <= stopped + 0.02
