"""Run recordings: an MCAP file, written by the Foxglove SDK, that Foxglove opens.

One ``RunRecorder`` per file. The positioning loop calls ``look`` once per look (its
``recorder`` hook); the grasp is recorded through ``recording_sensor`` (every wrench reading)
and ``grasp_event`` (what ended it). Channels, messages and log times:
``controller.recording.channels`` (the same channels the live view serves).

The file is written under a temporary name beside it and renamed over it once complete, so a
crash or a failed write (a full disk) leaves no half-written recording at its name. The JSON
Lines iteration log is not touched.
"""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import secrets
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import foxglove
from foxglove import Context
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from controller.loop.record import IterationRecord
from controller.recording.channels import CellChannels, RecordingError, RecordingSensor
from controller.recording.overlay import Overlay
from controller.systems.estimator import TranslationEstimate
from drivers.core.pose import Pose
from drivers.interfaces import Frame, Wrench, WrenchSensor

logger = logging.getLogger(__name__)

PROFILE = ""  # no ROS message profile: Foxglove's protobuf and JSON encodings


class _File:
    """The temporary file as the SDK's MCAP writer sees it: the first write error is kept for
    ``RunRecorder.close`` (and later writes are dropped) instead of being raised into the SDK."""

    def __init__(self, file, path: Path) -> None:
        self._file = file
        self._path = path
        self.error: str | None = None

    def write(self, data: bytes) -> int:
        if self.error is None:
            try:
                self._file.write(data)
            except OSError as exc:  # the run goes on unrecorded; close() reports the failure
                self.error = exc.strerror or str(exc)
                logger.error("recording %s failed: %s", self._path, self.error)
        return len(data)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._file.seek(offset, whence)

    def flush(self) -> None:
        if self.error is None:
            try:
                self._file.flush()
            except OSError as exc:
                self.error = exc.strerror or str(exc)


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
        self.path = Path(path)
        self.image_format = image_format
        self.max_runs = max_runs
        self._runs: list[str] = []
        self._active = max_runs != 0  # the current run is recorded (False past max_runs)
        self._lock = threading.Lock()
        self.looks = 0
        # held for the recorder's life: the SDK detaches a dropped context's sinks
        self._context = Context()
        self._channels = CellChannels(self._context, image_format, jpeg_quality)
        # Written under a temporary name beside the file (created anew, never through a link,
        # locked so remove_stale_temp_files leaves it alone) and renamed over it once complete.
        self._tmp = self.path.parent / f".{self.path.name}.{secrets.token_hex(4)}.tmp"
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self._tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW
                         | os.O_CLOEXEC, 0o644)
            fcntl.flock(fd, fcntl.LOCK_EX)
            self._file = os.fdopen(fd, "wb")
        except OSError as exc:
            raise RecordingError(f"recording {self.path}: {exc.strerror or exc}") from None
        self._sink = _File(self._file, self.path)
        self._writer = foxglove.open_mcap(
            self._sink, context=self._context, writer_options=MCAPWriteOptions(
                compression=MCAPCompression.Zstd, profile=PROFILE, compression_threads=0))
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
            self._channels.close()
            error = None
            try:
                self._writer.close()
                error = self._sink.error
                if error is None:
                    self._file.flush()
                    os.fsync(self._file.fileno())
                self._file.close()
                if error is None:
                    os.replace(self._tmp, self.path)  # replaces a link there, never follows it
            except OSError as exc:
                error = error or exc.strerror or str(exc)
            if error is not None:
                with contextlib.suppress(OSError):
                    self._file.close()
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(self._tmp)
                raise RecordingError(f"recording {self.path} not written: {error}")
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

        Raises:
            RecordingError: the frame cannot be encoded.
        """
        with self._lock:
            if self._closed or not self._take(record.run_id):
                return
            try:
                self._channels.look(record, frame, estimate, estimator, error_at_look)
            except RecordingError as exc:
                raise RecordingError(f"recording {self.path}: {exc}") from None
            self.looks += 1

    def pose(self, pose: Pose, t_s: float | None = None) -> None:
        """Record the tool pose (``world`` -> ``tool``) at ``t_s`` (default: now, monotonic)."""
        with self._lock:
            if not self._closed and self._active:
                self._channels.pose(pose, time.monotonic() if t_s is None else t_s)

    def wrench(self, wrench: Wrench, t_s: float | None = None) -> None:
        """Record one wrist reading at ``t_s`` (default: now, monotonic)."""
        with self._lock:
            if not self._closed and self._active:
                self._channels.wrench(wrench, time.monotonic() if t_s is None else t_s)

    def grasp_event(self, result: Any, t_s: float | None = None) -> None:
        """Record how a grasp ended (``controller.loop.grasp.GraspResult``)."""
        with self._lock:
            if not self._closed and self._active:
                self._channels.grasp_event(result, time.monotonic() if t_s is None else t_s)

    def recording_sensor(self, sensor: WrenchSensor,
                         clock: Callable[[], float] | None = None) -> WrenchSensor:
        """``sensor`` with every ``read()`` also recorded (for the guarded grasp), stamped by
        ``clock`` (cell seconds; default ``time.monotonic``)."""
        return RecordingSensor(sensor, self, clock)


def overlay_from_record(entry: dict[str, Any]) -> Overlay:
    """The overlay stored in a recorded iteration record."""
    return Overlay.from_dict(entry.get("overlay") or {})
