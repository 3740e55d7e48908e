"""Live view: the latest look's hand-camera frame with its overlay, as a camera-like source.

``LiveView`` is a look recorder (the positioning loop's ``recorder`` hook) and has the one
method an MJPEG server needs from a camera, ``grab()``; serve it on loopback with the camera
stream server (``drivers.camera.mjpeg_server.MjpegServer(live_view, port)``), for a browser on
the cell's PC. ``Tee`` hands each look to several recorders (a recording and
the live view). Off unless a caller builds one (service key ``service.live_view_port``).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import cv2
import numpy as np

from controller.loop.record import IterationRecord
from controller.recording.overlay import draw, look_texts, overlay_of
from controller.systems.estimator import TranslationEstimate
from drivers.interfaces import Frame, WrenchSensor


class LiveView:
    """The latest annotated look (RGB, ``scale`` times the camera frame), for an MJPEG server.

    Args:
        scale: size of the served image in camera frames.
        width_px, height_px: the camera frame's size (the image served before the first look
            is a grey one of the scaled size).
    """

    def __init__(self, scale: int = 3, width_px: int = 192, height_px: int = 144) -> None:
        self.scale = scale
        self.width_px, self.height_px = width_px * scale, height_px * scale
        self._lock = threading.Lock()
        self._image = np.full((self.height_px, self.width_px, 3), 64, np.uint8)
        self.looks = 0

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Draw the look's overlay on its frame and make it the image ``grab`` serves."""
        entry = record.as_dict()
        if error_at_look is not None:
            entry["error"] = {"x_mm": error_at_look[0], "y_mm": error_at_look[1],
                              "phi_deg": error_at_look[2]}
        bgr = draw(frame.image, overlay_of(record, estimate, estimator), look_texts(entry),
                   self.scale)
        image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        with self._lock:
            self._image = image
            self.looks += 1

    def grab(self) -> Frame:
        """The latest annotated look (HxWx3 uint8 RGB), stamped now."""
        with self._lock:
            return Frame(self._image, time.monotonic())

    def recording_sensor(self, sensor: WrenchSensor, clock: Any = None) -> WrenchSensor:
        """The live view shows no readings: ``sensor`` unchanged."""
        return sensor

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """The live view shows no grasp events."""


class Tee:
    """Hands every look, reading and grasp event to each of ``recorders``."""

    def __init__(self, *recorders: Any) -> None:
        self.recorders = [r for r in recorders if r is not None]

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Pass the look to every recorder."""
        for r in self.recorders:
            r.look(record, frame, estimate, estimator, error_at_look)

    def recording_sensor(self, sensor: WrenchSensor, clock: Any = None) -> WrenchSensor:
        """``sensor`` wrapped by every recorder in turn."""
        for r in self.recorders:
            sensor = r.recording_sensor(sensor, clock)
        return sensor

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """Pass the grasp's end to every recorder."""
        for r in self.recorders:
            r.grasp_event(result, t_s)
