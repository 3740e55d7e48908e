"""Frames taken once the camera's exposure holds (drivers.camera.settle)."""

from __future__ import annotations

import numpy as np

from drivers.camera.settle import SETTLE_MAX_FRAMES, settled_frame
from drivers.interfaces import Frame


class _Camera:
    """Frames whose brightness follows ``levels``, then holds at the last one."""

    def __init__(self, levels):
        self.levels = list(levels)
        self.grabbed = 0

    def grab(self) -> Frame:
        level = self.levels[min(self.grabbed, len(self.levels) - 1)]
        self.grabbed += 1
        return Frame(np.full((4, 6, 3), level, np.uint8), float(self.grabbed))


def test_an_auto_exposure_still_moving_is_waited_for():
    camera = _Camera([10, 40, 70, 90, 100, 104, 105, 105])
    frame = settled_frame(camera)
    assert camera.grabbed == 7 and frame.image.mean() == 105


def test_a_steady_camera_costs_one_frame_more():
    camera = _Camera([120])
    settled_frame(camera)
    assert camera.grabbed == 2


def test_a_camera_that_never_holds_is_taken_as_it_is_after_the_limit():
    camera = _Camera([(17 * i) % 250 for i in range(100)])
    settled_frame(camera)
    assert camera.grabbed == SETTLE_MAX_FRAMES
