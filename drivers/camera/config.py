"""Configuration of the OpenCV camera driver (config section ``camera: {type: opencv, ...}``)."""

from __future__ import annotations

from dataclasses import dataclass, field

_POSITIVE = {"min": 0.0, "exclusive_min": True}


@dataclass(frozen=True)
class OpenCvCameraConfig:
    """Where frames come from and how long to wait for them.

    source: a device index (``0``), a device or video file path, or a stream URL such as
    ``http://127.0.0.1:8080/stream.mjpg`` (anything ``cv2.VideoCapture`` opens);
    timeout_s: longest wait for a frame in ``grab()`` (also FFmpeg's read timeout);
    settle_s: ``grab()`` takes the first frame that arrives at least this long after the call:
    one that arrives sooner may have been exposed before it (the stream's latency: encoding,
    transfer, decoding; set it above the camera's latency, for network cameras often 0.1 s);
    open_timeout_s: longest wait for the source to open;
    gap_factor: an interval between frames longer than this many times the median interval
    counts as dropped frames (see ``FrameStats``).
    """

    source: int | str
    timeout_s: float = field(default=2.0, metadata=_POSITIVE)
    settle_s: float = field(default=0.05, metadata={"min": 0.0})
    open_timeout_s: float = field(default=5.0, metadata=_POSITIVE)
    gap_factor: float = field(default=2.5, metadata={"min": 1.5})
