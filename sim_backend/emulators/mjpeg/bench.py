"""Time the OpenCV camera driver on the MJPEG-over-HTTP stream: opening, and waiting for frames.

Example: finepos bench camera-stream --fps 30 --grabs 60

Serves a synthetic 192x144 camera through ``MjpegServer`` and reads it with ``OpenCvCamera``
(FFmpeg backend). Prints JSON: time to open the stream, and the median / 95th percentile of
``grab()``, which waits for the next frame to arrive (in this back-to-back loop one frame
period; after an arm move, half a period on average), with the driver's frame counters.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from drivers.camera import OpenCvCamera, OpenCvCameraConfig
from drivers.camera.mjpeg_server import MjpegServer
from drivers.interfaces import Camera, Frame


class _MovingBars(Camera):
    """Vertical bars that shift one pixel per frame (so every JPEG differs)."""

    def __init__(self) -> None:
        super().__init__()
        self._shift = 0

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _grab(self) -> Frame:
        self._shift += 1
        columns = (np.arange(self.width_px) + self._shift) // 8 % 2 * 255
        image = np.repeat(np.tile(columns.astype(np.uint8), (self.height_px, 1))[..., None],
                          3, axis=2)
        return Frame(image, time.monotonic())


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--fps", type=float, default=30.0, help="stream frame rate (default 30)")
    parser.add_argument("--grabs", type=int, default=60, help="frames to time (default 60)")


def run(args: argparse.Namespace) -> int:
    with _MovingBars() as source, MjpegServer(source, fps=args.fps) as server:
        camera = OpenCvCamera(OpenCvCameraConfig(source=server.stream_url))
        start_s = time.perf_counter()
        with camera:
            open_s = time.perf_counter() - start_s
            waits_ms = []
            for _ in range(args.grabs):
                start_s = time.perf_counter()
                camera.grab()
                waits_ms.append((time.perf_counter() - start_s) * 1000.0)
            stats = camera.stats
    print(json.dumps({
        "fps": args.fps,
        "grabs": args.grabs,
        "open_s": round(open_s, 3),
        "grab_median_ms": round(statistics.median(waits_ms), 2),
        "grab_p95_ms": round(statistics.quantiles(waits_ms, n=20)[-1], 2),
        "frame_period_ms": round(1000.0 / args.fps, 2),
        "received": stats.received,
        "failed_reads": stats.failed_reads,
        "dropped": stats.dropped,
    }))
    return 0
