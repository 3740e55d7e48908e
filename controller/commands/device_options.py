"""``--arm/--port``, ``--camera``, ``--wrench/--wrench-port``: pick device backends on the
command line instead of in the config file (e.g. the emulators of ``finepos sim val-emulator``).
"""

from __future__ import annotations

import argparse

from controller.devices import ARM_BACKENDS, WRENCH_BACKENDS, with_device


def add_device_options(parser: argparse.ArgumentParser) -> None:
    """Add the ``devices`` group: ``--arm/--port``, ``--camera``, ``--wrench/--wrench-port``."""
    group = parser.add_argument_group(
        "devices", "override the config's arm, camera and wrench sections, e.g. --arm val "
                   "--port /dev/pts/3 --wrench ati --wrench-port /dev/pts/4 --camera "
                   "http://127.0.0.1:8080/stream.mjpg")
    group.add_argument("--arm", choices=sorted(ARM_BACKENDS), help="arm backend")
    group.add_argument("--port", metavar="URL",
                       help="the arm's serial port (val): /dev/ttyS0, /dev/pts/N, "
                            "socket://HOST:PORT")
    group.add_argument("--camera", metavar="SOURCE",
                       help="'sim', or an OpenCV source (opencv backend): a device index, a "
                            "file or a stream URL")
    group.add_argument("--wrench", choices=sorted(WRENCH_BACKENDS), help="wrench backend")
    group.add_argument("--wrench-port", metavar="URL",
                       help="the wrench sensor's serial port (ati)")


def apply_device_options(config, args: argparse.Namespace):
    """``config`` with the backends the device options name (unchanged without them)."""
    if args.arm or args.port:
        port = {"port": args.port} if args.port else {}
        config = with_device(config, "arm", args.arm or config.arm.type, **port)
    if args.wrench or args.wrench_port:
        port = {"port": args.wrench_port} if args.wrench_port else {}
        config = with_device(config, "wrench", args.wrench or config.wrench.type, **port)
    if args.camera == "sim":
        config = with_device(config, "camera", "sim")
    elif args.camera is not None:
        source = int(args.camera) if args.camera.isdigit() else args.camera
        config = with_device(config, "camera", "opencv", source=source)
    return config
