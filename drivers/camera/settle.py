"""Frames taken once the camera's exposure holds.

A camera with auto-exposure needs a few frames to settle after it starts or after the light
changes; a frame taken earlier is darker or brighter than every later one. ``settled_frame``
grabs until two consecutive frames agree in mean brightness, so the first frame of a set or of
a run is exposed as the rest will be. A fixed-exposure camera (or one already settled) costs
one extra frame.
"""

from __future__ import annotations

from drivers.interfaces import Camera, Frame

# Two consecutive frames whose mean grey levels differ by at most this fraction of the mean
# (or by SETTLED_GREY grey levels, whichever is more) are exposed alike.
SETTLED_FRACTION = 0.01
SETTLED_GREY = 0.5
# The most frames grabbed to settle; a camera still drifting then is taken as it is.
SETTLE_MAX_FRAMES = 40


def settled_frame(camera: Camera, max_frames: int = SETTLE_MAX_FRAMES) -> Frame:
    """The first frame whose mean brightness matches the frame before it (at most
    ``max_frames`` grabbed; the last one if none does)."""
    frame = camera.grab()
    previous = float(frame.image.mean())
    for _ in range(max_frames - 1):
        frame = camera.grab()
        mean = float(frame.image.mean())
        if abs(mean - previous) <= max(SETTLED_GREY, SETTLED_FRACTION * previous):
            break
        previous = mean
    return frame
