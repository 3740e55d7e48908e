"""Run recordings: an MCAP file that Foxglove and the ROS 2 bag tools open.

One ``RunRecorder`` per file. The positioning loop calls ``look`` once per look (its
``recorder`` hook); the grasp is recorded through ``recording_sensor`` (every wrench reading)
and ``grasp_event`` (what ended it). Channels and schemas: ``controller.recording.schemas``.

Log time is cell time: the camera's frame time (``Frame.timestamp_s``, the monotonic clock the
drivers stamp frames with) for a look's image, annotations and record, and the same clock for
the tool pose after the move; the wrench readings and the guard events are stamped with the
clock the caller passes (``CellDevices.clock``: the simulated cell's virtual clock under
realistic timing). Log times never go back within a file. The JSON Lines iteration log is not
touched.
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import logging
import math
import os
import secrets
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from mcap.writer import CompressionType, Writer

from controller.loop.iteration_log import to_json_line
from controller.loop.record import IterationRecord
from controller.recording import schemas
from controller.recording.overlay import Overlay, look_texts, overlay_of, to_annotations
from controller.systems.estimator import TranslationEstimate
from drivers.core.errors import FineposError
from drivers.core.pose import Pose
from drivers.interfaces import Frame, Wrench, WrenchSensor

logger = logging.getLogger(__name__)

PROFILE = ""  # no ROS message profile: Foxglove's JSON encoding
IMAGE_FORMATS = ("jpeg", "png")


class RecordingError(FineposError):
    """A recording cannot be written (bad path, closed recorder)."""


def _ns(t_s: float) -> int:
    return max(0, int(round(t_s * 1e9)))


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": t_ns // 1_000_000_000, "nsec": t_ns % 1_000_000_000}


def _quaternion(r: np.ndarray) -> dict[str, float]:
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
    return {"x": x, "y": y, "z": z, "w": w}


class RunRecorder:
    """Writes one MCAP recording; use as a context manager (the file is complete on exit).

    Args:
        path: the ``.mcap`` file (its folder is created).
        image_format: ``jpeg`` (small, lossy) or ``png`` (lossless) for the frames.
        jpeg_quality: 1..100.
        max_runs: record only the first this many positioning runs (None: all); later looks
            are ignored, and so are the readings and grasp events that follow them
            (``evaluate --record`` keeps the first N trials).

    Raises:
        RecordingError: the format is unknown or the file cannot be created.
    """

    def __init__(self, path: str | Path, image_format: str = "jpeg", jpeg_quality: int = 90,
                 max_runs: int | None = None) -> None:
        if image_format not in IMAGE_FORMATS:
            raise RecordingError(f"recording image format: expected one of "
                                 f"{', '.join(IMAGE_FORMATS)}, got {image_format!r}")
        self.path = Path(path)
        self.image_format = image_format
        self._encode_args = ([cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
                             if image_format == "jpeg" else [])
        self.max_runs = max_runs
        self._runs: list[str] = []
        self._active = max_runs != 0  # the current run is recorded (False past max_runs)
        self._lock = threading.Lock()
        self._last_ns = 0
        self.looks = 0
        # Written under a temporary name beside the file (created anew, never through a link,
        # locked so remove_stale_temp_files leaves it alone) and renamed over it once complete.
        self._tmp = self.path.parent / f".{self.path.name}.{secrets.token_hex(4)}.tmp"
        self._error: str | None = None  # the first failed write: close() reports it
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                         | os.O_CLOEXEC, 0o644)
            fcntl.flock(fd, fcntl.LOCK_EX)
            self._file = os.fdopen(fd, "wb")
        except OSError as exc:
            raise RecordingError(f"recording {self.path}: {exc.strerror or exc}") from None
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="finepos")
        self._channels: dict[str, int] = {}
        for topic, (name, schema) in schemas.CHANNELS.items():
            schema_id = self._writer.register_schema(
                name=name, encoding="jsonschema", data=json.dumps(schema).encode())
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id)
        self._closed = False

    # -- lifecycle -----------------------------------------------------------------------
    def close(self) -> None:
        """Finish the file (summary and index), sync it and rename it into place; later calls
        do nothing.

        Raises:
            RecordingError: a write failed (a full disk): no file is left at ``path`` (an
                older one there stays), nor a partial one beside it.
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                if self._error is None:
                    self._writer.finish()
                    self._file.flush()
                    os.fsync(self._file.fileno())
                self._file.close()
                if self._error is None:
                    os.replace(self._tmp, self.path)  # replaces a link there, never follows it
            except OSError as exc:
                self._error = exc.strerror or str(exc)
            if self._error is not None:
                with contextlib.suppress(OSError):
                    self._file.close()
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(self._tmp)
                raise RecordingError(f"recording {self.path} not written: {self._error}")
        with contextlib.suppress(OSError):
            dir_fd = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- messages ------------------------------------------------------------------------
    def _write(self, topic: str, t_ns: int, message: dict[str, Any] | str) -> None:
        data = message if isinstance(message, str) else json.dumps(message,
                                                                  separators=(",", ":"))
        t_ns = max(t_ns, self._last_ns)  # log time never goes back within a file
        self._last_ns = t_ns
        if self._error is not None:
            return
        try:
            self._writer.add_message(self._channels[topic], log_time=t_ns, data=data.encode(),
                                     publish_time=t_ns)
        except OSError as exc:  # the run goes on unrecorded; close() reports the failure
            self._error = exc.strerror or str(exc)
            logger.error("recording %s failed: %s", self.path, self._error)

    def _take(self, run_id: str) -> bool:
        """Whether looks of ``run_id`` are recorded (the first ``max_runs`` runs are)."""
        if run_id not in self._runs:
            if self.max_runs is not None and len(self._runs) >= self.max_runs:
                self._active = False
                return False
            self._runs.append(run_id)
        self._active = True
        return True

    def look(self, record: IterationRecord, frame: Frame, estimate: TranslationEstimate,
             estimator: Any = None,
             error_at_look: tuple[float, float, float] | None = None) -> None:
        """Record one look of the positioning loop: the frame, its overlay, the record and
        the tool pose after the move (the loop's ``recorder`` hook).

        Args:
            record: the look's complete iteration record (as the JSON Lines log has it).
            frame: the grabbed frame.
            estimate: the look's translation estimate (its percept gives the overlay).
            estimator: the estimator that made it (the Gabor bundle's ROI and taught centre).
            error_at_look: the true error when the frame was taken (simulated cell only).
        """
        with self._lock:
            if self._closed or not self._take(record.run_id):
                return
            t_ns = _ns(frame.timestamp_s)
            stamp = _stamp(t_ns)
            overlay = overlay_of(record, estimate, estimator)
            entry = record.as_dict()
            entry["error_at_look"] = (None if error_at_look is None else
                                      {"x_mm": error_at_look[0], "y_mm": error_at_look[1],
                                       "phi_deg": error_at_look[2]})
            entry["overlay"] = overlay.as_dict()
            ok, encoded = cv2.imencode(".jpg" if self.image_format == "jpeg" else ".png",
                                       cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR),
                                       self._encode_args)
            if not ok:
                raise RecordingError(f"recording {self.path}: cannot encode the frame")
            self._write(schemas.IMAGE_TOPIC, t_ns, {
                "timestamp": stamp, "frame_id": schemas.CAMERA_FRAME,
                "data": base64.b64encode(encoded.tobytes()).decode("ascii"),
                "format": self.image_format})
            self._write(schemas.ANNOTATIONS_TOPIC, t_ns,
                        to_annotations(overlay, stamp, look_texts(entry)))
            self._write(schemas.ITERATION_TOPIC, t_ns, to_json_line(entry))
            if record.pose_after is not None:
                moved_ns = t_ns + _ns(sum(record.timings_ms.values()) / 1e3)
                self._pose(record.pose_after, moved_ns)
            self.looks += 1

    def _pose(self, pose: Pose, t_ns: int) -> None:
        p = pose.position_mm / 1000.0
        self._write(schemas.TF_TOPIC, t_ns, {
            "timestamp": _stamp(t_ns), "parent_frame_id": "world", "child_frame_id": "tool",
            "translation": {"x": p[0], "y": p[1], "z": p[2]},
            "rotation": _quaternion(pose.rotation())})

    def pose(self, pose: Pose, t_s: float | None = None) -> None:
        """Record the tool pose (``world`` -> ``tool``) at ``t_s`` (default: now, monotonic)."""
        with self._lock:
            if not self._closed and self._active:
                self._pose(pose, _ns(time.monotonic() if t_s is None else t_s))

    def wrench(self, wrench: Wrench, t_s: float | None = None) -> None:
        """Record one wrist reading at ``t_s`` (default: now, monotonic)."""
        with self._lock:
            if not self._closed and self._active:
                self._write(schemas.WRENCH_TOPIC,
                            _ns(time.monotonic() if t_s is None else t_s), wrench.as_dict())

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """Record how a grasp ended (``controller.loop.grasp.GraspResult``)."""
        with self._lock:
            if not self._closed and self._active:
                self._write(schemas.GUARD_TOPIC,
                            _ns(time.monotonic() if t_s is None else t_s),
                            to_json_line(result.as_dict()))

    def recording_sensor(self, sensor: WrenchSensor,
                         clock: Callable[[], float] | None = None) -> WrenchSensor:
        """``sensor`` with every ``read()`` also recorded (for the guarded grasp), stamped by
        ``clock`` (cell seconds; default ``time.monotonic``)."""
        return _RecordingSensor(sensor, self, clock)


class _RecordingSensor:
    """Passes everything to the wrapped sensor; records what ``read`` returns."""

    def __init__(self, sensor: WrenchSensor, recorder: RunRecorder,
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


def overlay_from_record(entry: dict[str, Any]) -> Overlay:
    """The overlay stored in a recorded iteration record."""
    return Overlay.from_dict(entry.get("overlay") or {})
