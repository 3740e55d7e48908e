"""A thread that owns one ``cv2.VideoCapture``: opens it, reads every frame, keeps the newest.

``VideoCapture.read()`` blocks (for a hung stream until FFmpeg's read timeout, for some devices
much longer), so no caller ever calls it: the reader thread does, and callers wait on a
condition with their own timeout. The capture is created, read and released on the reader
thread only.

A live source (device, stream) is read continuously, so its buffer never holds stale frames. A
video file is read one frame per request instead (reading ahead would race to its end; its
arrival times then follow the requests, so no drops are counted).

A live source whose reads have failed for ``REOPEN_AFTER_S`` since its last frame (a stream
whose server closed the connection or restarted, a device unplugged and plugged in again) is
released and opened again on the reader thread, at growing intervals up to ``REOPEN_MAX_S``
until it opens: a grab waiting meanwhile gets the first frame after it, late rather than
never.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import dataclass

import cv2
import numpy as np

from drivers.camera.config import OpenCvCameraConfig
from drivers.camera.drop_counter import DropCounter
from drivers.core.errors import DeviceNotConnectedError, DeviceTimeoutError
from drivers.interfaces import Frame

logger = logging.getLogger(__name__)

_RETRY_AFTER_FAILED_READ_S = 0.05  # end of file or broken stream: do not spin
_JOIN_MARGIN_S = 1.0
# A live source with no frame for this long, its last read failed, is opened again; the
# attempts start this far apart and double up to REOPEN_MAX_S.
REOPEN_AFTER_S = 0.25
REOPEN_FIRST_S = 0.05
REOPEN_MAX_S = 1.0


@dataclass(frozen=True)
class FrameStats:
    """received: frames read; failed_reads: reads that returned no image; dropped: frames
    estimated missing from gaps in the arrival times (see ``DropCounter``); reopened: times
    the live source was opened again after its reads failed."""

    received: int
    failed_reads: int
    dropped: int
    reopened: int = 0


def to_rgb(image: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """OpenCV's BGR (or grey, or BGRA) image as ``height x width x 3`` uint8 RGB."""
    if image.ndim == 2:
        rgb = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        rgb = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    else:
        rgb = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    if rgb.shape[:2] != (height_px, width_px):
        rgb = cv2.resize(rgb, (width_px, height_px), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(rgb, dtype=np.uint8)


class FrameReader:
    """Reads ``config.source`` on a thread; ``start()`` returns once it is open."""

    def __init__(self, config: OpenCvCameraConfig, width_px: int, height_px: int) -> None:
        self.config = config
        self.width_px = width_px
        self.height_px = height_px
        self._on_demand = isinstance(config.source, str) and os.path.isfile(config.source)
        self._requested = threading.Event()
        self._stop = threading.Event()
        self._opened = threading.Event()
        self._open_ok = False
        self._changed = threading.Condition()
        self._latest: Frame | None = None
        self._received = 0
        self._failed_reads = 0
        self._reopened = 0
        self._drops = DropCounter(config.gap_factor)
        self._thread = threading.Thread(target=self._run, name="camera-reader", daemon=True)

    @property
    def on_demand(self) -> bool:
        """A video file, read one frame per request (arrival times follow the requests)."""
        return self._on_demand

    @property
    def stats(self) -> FrameStats:
        with self._changed:
            return FrameStats(self._received, self._failed_reads, self._drops.dropped,
                              self._reopened)

    def start(self) -> None:
        """Open the source (raises DeviceNotConnectedError / DeviceTimeoutError on failure)."""
        self._thread.start()
        wait_s = self.config.open_timeout_s + _JOIN_MARGIN_S
        if not self._opened.wait(wait_s):
            self.stop()
            raise DeviceTimeoutError(f"camera {self.config.source!r} did not open in {wait_s} s")
        if not self._open_ok:
            self.stop()
            raise DeviceNotConnectedError(f"camera {self.config.source!r} cannot be opened")

    def next_frame(self, after_s: float, timeout_s: float) -> Frame | None:
        """The first frame that arrived after ``after_s`` (monotonic); None after ``timeout_s``."""
        self._requested.set()
        with self._changed:
            self._changed.wait_for(
                lambda: self._latest is not None and self._latest.timestamp_s > after_s,
                timeout_s)
            latest = self._latest
        return latest if latest is not None and latest.timestamp_s > after_s else None

    def stop(self) -> None:
        """Ask the thread to release the capture and wait for it (bounded by the timeouts)."""
        self._stop.set()
        self._requested.set()
        if not self._thread.is_alive():
            return
        self._thread.join(self.config.timeout_s + _JOIN_MARGIN_S)
        if self._thread.is_alive():
            logger.warning("camera %r: reader still blocked in read(); it releases the capture "
                           "when that returns", self.config.source)

    def _run(self) -> None:
        capture = self._capture(first=True)
        self._open_ok = capture is not None
        self._opened.set()
        while capture is not None:
            try:
                gone = self._read_loop(capture)
            finally:
                capture.release()
            if not gone:
                return
            logger.warning("camera %r: no frame for %.2f s, reads failing: opening it again",
                           self.config.source, REOPEN_AFTER_S)
            capture = self._reopen()

    def _capture(self, first: bool = False) -> cv2.VideoCapture | None:
        """The source opened (None where it does not open; logged as an error the first
        time, when ``start`` reports it)."""
        cfg = self.config
        params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, int(cfg.open_timeout_s * 1000),
                  cv2.CAP_PROP_READ_TIMEOUT_MSEC, int(cfg.timeout_s * 1000)]
        try:
            capture = cv2.VideoCapture(cfg.source, cv2.CAP_ANY, params)
        except cv2.error as exc:
            if first:
                logger.error("camera %r: OpenCV cannot open it: %s", cfg.source, exc)
            return None
        if not capture.isOpened():
            capture.release()
            return None
        logger.info("camera %r open (%s backend)", cfg.source, capture.getBackendName())
        return capture

    def _reopen(self) -> cv2.VideoCapture | None:
        """The live source opened again, trying at growing intervals; None once stopped."""
        wait_s = REOPEN_FIRST_S
        while not self._stop.wait(wait_s):
            capture = self._capture()
            if capture is not None:
                with self._changed:
                    self._reopened += 1
                return capture
            wait_s = min(2.0 * wait_s, REOPEN_MAX_S)
        return None

    def _read_loop(self, capture: cv2.VideoCapture) -> bool:
        """Read until stopped (False) or, for a live source, until its reads have failed
        for ``REOPEN_AFTER_S`` since its last frame (True: open it again)."""
        last_s = time.monotonic()
        while not self._stop.is_set():
            if self._on_demand:
                self._requested.wait()
                self._requested.clear()
                if self._stop.is_set():
                    return False
            ok, image = capture.read()
            arrival_s = time.monotonic()
            if not ok or image is None:
                with self._changed:
                    self._failed_reads += 1
                if not self._on_demand and arrival_s - last_s >= REOPEN_AFTER_S:
                    return True
                self._stop.wait(_RETRY_AFTER_FAILED_READ_S)
                continue
            last_s = arrival_s
            frame = Frame(to_rgb(image, self.width_px, self.height_px), arrival_s)
            with self._changed:
                self._received += 1
                missing = 0 if self._on_demand else self._drops.observe(arrival_s)
                self._latest = frame
                self._changed.notify_all()
            if missing:
                logger.warning("camera %r: about %d frame(s) dropped", self.config.source,
                               missing)
        return False
