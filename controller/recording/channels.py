"""The channels of a run recording and of the live view, built from the Foxglove SDK's messages.

``CellChannels`` opens every channel in one ``foxglove.Context`` and turns a look of the
positioning loop, a tool pose, a wrench reading and a grasp's end into messages on them:

- ``/hand_camera/image``: ``foxglove.CompressedImage`` (JPEG or PNG, frame ``hand_camera``);
- ``/hand_camera/annotations``: ``foxglove.ImageAnnotations`` (the look's overlay);
- ``/tf``: ``foxglove.FrameTransform`` (``world`` -> ``tool``, metres);
- ``/finepos/iteration``: JSON, the iteration record as the JSON Lines log has it, plus the
  overlay and the error at the look;
- ``/finepos/wrench``: JSON, one wrist reading (``fx_n`` ... ``tz_nm``);
- ``/finepos/guard_event``: JSON, how a force-guarded grasp ended.

The typed channels are protobuf-encoded with the SDK's schemas; the JSON channels carry a named
schema (``finepos.IterationRecord`` ...) whose JSON Schema is only ``{"type": "object"}``: the
record's fields are documented where they are made (``controller.loop.record``). Whatever sinks
the context has (an MCAP writer, a WebSocket server) receive every message; a message whose
channel has no sink is not built, so a live view nobody watches encodes no frame.

Log time is cell time in nanoseconds: the camera's frame time (``Frame.timestamp_s``) for a
look's image, annotations and record, the same clock plus the look's timings for the tool pose
after its move, and the caller's clock for wrench readings and grasp events. Log times never go
back on a context.
"""

from __future__ import annotations

import json
import math
import threading
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np
from foxglove import Channel, Context, Schema
from foxglove.channels import (
    CompressedImageChannel,
    FrameTransformChannel,
    ImageAnnotationsChannel,
)
from foxglove.messages import CompressedImage, FrameTransform, Quaternion, Timestamp, Vector3

from controller.loop.iteration_log import to_json_line
from controller.loop.record import IterationRecord
from controller.recording.overlay import look_texts, overlay_of, to_annotations
from controller.systems.estimator import TranslationEstimate
from drivers.core.errors import FineposError
from drivers.core.pose import Pose
from drivers.interfaces import Frame, Wrench, WrenchSensor

IMAGE_TOPIC = "/hand_camera/image"
ANNOTATIONS_TOPIC = "/hand_camera/annotations"
TF_TOPIC = "/tf"
ITERATION_TOPIC = "/finepos/iteration"
GUARD_TOPIC = "/finepos/guard_event"
WRENCH_TOPIC = "/finepos/wrench"
CAMERA_FRAME = "hand_camera"
IMAGE_FORMATS = ("jpeg", "png")
# The JSON channels: topic -> schema name.
JSON_CHANNELS = {ITERATION_TOPIC: "finepos.IterationRecord",
                 GUARD_TOPIC: "finepos.GuardEvent",
                 WRENCH_TOPIC: "finepos.WrenchReading"}
_OBJECT_SCHEMA = b'{"type":"object"}'


class RecordingError(FineposError):
    """A recording or live view cannot be made (bad path or port, closed recorder)."""


def ns(t_s: float) -> int:
    """Seconds as nanoseconds (never negative)."""
    return max(0, int(round(t_s * 1e9)))


def quaternion(r: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    m = np.asarray(r, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, \
            (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, \
            (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, \
            (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, \
            (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return x, y, z, w


def timestamp(t_ns: int) -> Timestamp:
    """A Foxglove time of ``t_ns`` nanoseconds."""
    return Timestamp(t_ns // 1_000_000_000, t_ns % 1_000_000_000)


class CellChannels:
    """Every channel of the cell in ``context``; the ``look`` ... ``grasp_event`` methods log on
    them (thread-safe).

    Args:
        context: the Foxglove context whose sinks receive the messages.
        image_format: ``jpeg`` (small, lossy) or ``png`` (lossless) for the frames.
        jpeg_quality: 1..100.

    Raises:
        RecordingError: the image format is unknown.
    """

    def __init__(self, context: Context, image_format: str = "jpeg",
                 jpeg_quality: int = 90) -> None:
        if image_format not in IMAGE_FORMATS:
            raise RecordingError(f"recording image format: expected one of "
                                 f"{', '.join(IMAGE_FORMATS)}, got {image_format!r}")
        self.image_format = image_format
        self._encode_args = ([cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
                             if image_format == "jpeg" else [])
        self._lock = threading.Lock()
        self._last_ns = 0
        self._image = CompressedImageChannel(IMAGE_TOPIC, context=context)
        self._annotations = ImageAnnotationsChannel(ANNOTATIONS_TOPIC, context=context)
        self._tf = FrameTransformChannel(TF_TOPIC, context=context)
        self._json = {topic: Channel(topic, message_encoding="json", context=context,
                                     schema=Schema(name=name, encoding="jsonschema",
                                                   data=_OBJECT_SCHEMA))
                      for topic, name in JSON_CHANNELS.items()}

    def subscribed(self) -> set[str]:
        """The topics whose channel has a sink (a recording, a subscribed client) now."""
        return {channel.topic() for channel in (self._image, self._annotations, self._tf,
                                                *self._json.values()) if channel.has_sinks()}

    def close(self) -> None:
        """Close every channel (a WebSocket client sees them unadvertised)."""
        for channel in (self._image, self._annotations, self._tf, *self._json.values()):
            channel.close()

    def _time(self, t_ns: int) -> int:
        """``t_ns``, or the last log time when it would go back (call under the lock)."""
        self._last_ns = max(t_ns, self._last_ns)
        return self._last_ns

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Log one look of the positioning loop: the frame, its overlay, the record and the
        tool pose after the move.

        Raises:
            RecordingError: the frame cannot be encoded.
        """
        with self._lock:
            t_ns = self._time(ns(frame.timestamp_s))
            stamp = timestamp(t_ns)
            wanted = self._image.has_sinks() or self._annotations.has_sinks() \
                or self._json[ITERATION_TOPIC].has_sinks()
            if wanted:
                overlay = overlay_of(record, estimate, estimator)
                entry = record.as_dict()
                entry["error_at_look"] = (None if error_at_look is None else
                                          {"x_mm": error_at_look[0], "y_mm": error_at_look[1],
                                           "phi_deg": error_at_look[2]})
                entry["overlay"] = overlay.as_dict()
                if self._image.has_sinks():
                    self._image.log(CompressedImage(
                        timestamp=stamp, frame_id=CAMERA_FRAME, data=self._encode(frame),
                        format=self.image_format), log_time=t_ns)
                if self._annotations.has_sinks():
                    self._annotations.log(to_annotations(overlay, stamp, look_texts(entry)),
                                          log_time=t_ns)
                self._json[ITERATION_TOPIC].log(to_json_line(entry), log_time=t_ns)
            if record.pose_after is not None:
                moved_ns = t_ns + ns(sum(record.timings_ms.values()) / 1e3)
                self._pose(record.pose_after, self._time(moved_ns))

    def _encode(self, frame: Frame) -> bytes:
        ok, encoded = cv2.imencode(".jpg" if self.image_format == "jpeg" else ".png",
                                   cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR),
                                   self._encode_args)
        if not ok:
            raise RecordingError("cannot encode the frame")
        return encoded.tobytes()

    def _pose(self, pose: Pose, t_ns: int) -> None:
        if not self._tf.has_sinks():
            return
        p = pose.position_mm / 1000.0
        x, y, z, w = quaternion(pose.rotation())
        self._tf.log(FrameTransform(
            timestamp=timestamp(t_ns), parent_frame_id="world", child_frame_id="tool",
            translation=Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
            rotation=Quaternion(x=x, y=y, z=z, w=w)), log_time=t_ns)

    def pose(self, pose: Pose, t_s: float) -> None:
        """Log the tool pose (``world`` -> ``tool``) at ``t_s`` (cell seconds)."""
        with self._lock:
            self._pose(pose, self._time(ns(t_s)))

    def wrench(self, wrench: Wrench, t_s: float) -> None:
        """Log one wrist reading at ``t_s`` (cell seconds)."""
        with self._lock:
            self._json[WRENCH_TOPIC].log(json.dumps(wrench.as_dict(), separators=(",", ":")),
                                         log_time=self._time(ns(t_s)))

    def grasp_event(self, result: Any, t_s: float) -> None:
        """Log how a grasp ended (``controller.loop.grasp.GraspResult``) at ``t_s``."""
        with self._lock:
            self._json[GUARD_TOPIC].log(to_json_line(result.as_dict()),
                                        log_time=self._time(ns(t_s)))


class RecordingSensor:
    """Passes everything to the wrapped sensor; hands what ``read`` returns to
    ``recorder.wrench`` (a ``RunRecorder`` or ``LiveServer``)."""

    def __init__(self, sensor: WrenchSensor, recorder: Any,
                 clock: Callable[[], float] | None) -> None:
        self._sensor = sensor
        self._recorder = recorder
        self._clock = clock

    def read(self) -> Wrench:
        """The wrapped sensor's reading, also written to the recording (cell-clock time)."""
        wrench = self._sensor.read()
        self._recorder.wrench(wrench, self._clock() if self._clock is not None else None)
        return wrench

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sensor, name)
