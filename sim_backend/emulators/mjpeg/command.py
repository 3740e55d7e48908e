"""Serve the simulated hand camera (or any OpenCV source) as an MJPEG stream over HTTP.

Example: finepos sim camera-stream --config deploy/finepos.yaml --port 8080

  prints http://127.0.0.1:8080/stream.mjpg (and /snapshot.jpg), to use as
  ``camera: {type: opencv, source: http://127.0.0.1:8080/stream.mjpg}``. The cell is built from
  the ``scene:`` section of --config (defaults without it); in this process nothing moves the
  arm, so for a hardware-in-the-loop run serve MjpegServer from the process that runs the VAL
  emulator on the same cell. ``--source 0`` relays a real camera (device index, file or URL)
  instead. With --timing realistic (the default) frames come at timing.camera.frame_rate_hz
  (--fps is then ignored), exposed for exposure_s and delivered latency_frames late. Ctrl-C or
  SIGTERM stops it.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path

from drivers.camera import OpenCvCamera, OpenCvCameraConfig
from drivers.camera.mjpeg_server import MjpegServer
from drivers.interfaces import Camera
from sim_backend.cell.timing import add_timing_argument, cell_timing, timing_from_args
from sim_backend.emulators.val.command import wait_for_stop_signal


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, help="root config file (its scene: section)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the cell (camera noise)")
    parser.add_argument("--port", type=int, default=0, help="TCP port (default 0: any free)")
    parser.add_argument("--fps", type=float, default=10.0, help="frame rate (default 10)")
    parser.add_argument("--source", help="relay this OpenCV source instead of the simulation")
    parser.add_argument("--jpeg-quality", type=int, default=95, choices=range(1, 101),
                        metavar="1..100", help="JPEG quality (default 95)")
    parser.add_argument("--chroma", choices=["444", "420"], default="444",
                        help="JPEG chroma subsampling (default 444; many network cameras send "
                             "420, which biases saturation-channel localisation by ~0.2 mm)")
    add_timing_argument(parser)


def run(args: argparse.Namespace) -> int:
    with contextlib.ExitStack() as stack:
        camera = stack.enter_context(_camera(args, stack))
        timing = timing_from_args(args) if args.source is None else None
        fps = timing.camera.frame_rate_hz if timing else args.fps
        server = stack.enter_context(MjpegServer(camera, port=args.port, fps=fps,
                                                 jpeg_quality=args.jpeg_quality,
                                                 chroma=args.chroma))
        print(server.stream_url, server.snapshot_url, flush=True)
        wait_for_stop_signal()
    return 0


def _camera(args: argparse.Namespace, stack: contextlib.ExitStack) -> Camera:
    if args.source is not None:
        source = int(args.source) if args.source.isdigit() else args.source
        return OpenCvCamera(OpenCvCameraConfig(source=source))
    from sim_backend.cell.scene_config import load_cell
    from sim_backend.cell.sim_cell import (
        SimCell,  # PyBullet is imported only when the cell is needed
    )
    from sim_backend.devices import SimCamera

    scene, parts = load_cell(args.config)
    config = timing_from_args(args)
    timing = cell_timing("realistic", config, wall=True) if config else None
    return SimCamera(stack.enter_context(SimCell(scene, seed=args.seed, parts=parts)), timing)
