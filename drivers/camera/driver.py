"""Camera driver over OpenCV's VideoCapture: device index, file, or stream URL (MJPEG over HTTP).

``grab()`` returns the first frame that arrives at least ``config.settle_s`` after the call, so
a frame taken after the arm stopped (never one buffered before, nor one still on its way through
the stream's encoding, transfer and decoding), converted to 192 x 144 RGB (resized if the source
differs), stamped with its arrival time. No frame within ``config.timeout_s`` (after the settle
time) raises DeviceTimeoutError and puts the camera into FAULT until ``reset()`` reopens the
source. A live source whose reads fail is opened again by the reader by itself
(``frame_reader``), so a stream that ends and comes back within the timeout gives a late
frame. ``stats`` counts frames received, failed reads, frames estimated dropped and reopens.

OpenCV's FFmpeg backend (in opencv-python-headless) opens ``multipart/x-mixed-replace`` MJPEG
streams over HTTP directly, so stream URLs need no separate code path.
"""

from __future__ import annotations

import logging
import time

from drivers.camera.config import OpenCvCameraConfig
from drivers.camera.frame_reader import FrameReader, FrameStats
from drivers.core.errors import DeviceTimeoutError
from drivers.interfaces import Camera, Frame

logger = logging.getLogger(__name__)


class OpenCvCamera(Camera):
    """A camera read through ``cv2.VideoCapture`` on a reader thread."""

    def __init__(self, config: OpenCvCameraConfig) -> None:
        super().__init__()
        self.config = config
        self._reader: FrameReader | None = None

    @property
    def stats(self) -> FrameStats:
        """Counters of the current connection (all zero when never opened)."""
        return self._reader.stats if self._reader is not None else FrameStats(0, 0, 0)

    def _open(self) -> None:
        reader = FrameReader(self.config, self.width_px, self.height_px)
        reader.start()
        self._reader = reader

    def _close(self) -> None:
        if self._reader is not None:
            self._reader.stop()

    def _grab(self) -> Frame:
        assert self._reader is not None
        settle_s = 0.0 if self._reader.on_demand else self.config.settle_s
        frame = self._reader.next_frame(time.monotonic() + settle_s,
                                        self.config.timeout_s + settle_s)
        if frame is None:
            message = (f"camera {self.config.source!r}: no frame within "
                       f"{self.config.timeout_s} s ({self._reader.stats})")
            self.mark_fault(message)
            raise DeviceTimeoutError(message)
        return frame
