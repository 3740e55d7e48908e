"""Serve the VAL II monitor of the simulated PUMA 260 on a pseudo-terminal or a TCP port.

Example: finepos sim val-emulator --pty --boot-questions

  prints ``VAL emulator on PORT`` (PORT: ``/dev/pts/N``, or ``socket://127.0.0.1:N`` with
  --tcp; use it as ``arm: {type: val, port: PORT}``), then serves the simulated cell's arm until
  SIGINT or SIGTERM. The scene comes from the ``scene:`` section of --config FILE, the
  durations from its ``timing:`` section: with --timing realistic (the default) the line runs
  at the VAL baud rate (9600) both ways and ``do move`` answers after the motion time;
  --timing ideal answers at once. Fault
  knobs: --reply-delay-s, --drop-link-after-lines, --garbage HEX, --forced-error TEXT (see
  sim_backend.emulators.val.server.ValFaults).

Example (hardware in the loop): finepos sim val-emulator --ati --mjpeg 0 --write-config hil.yaml

  also serves the same cell's wrist sensor as an ATI F/T controller (``ATI F/T emulator on
  PORT``, a second pty) and its hand camera as an MJPEG stream (``camera stream on URL``), prints
  the matching device options for ``finepos position`` and writes them as a config file
  (--config's sections with arm, wrench and camera replaced): ``finepos position --config
  hil.yaml --offset 12,-8,20 --grasp`` then runs the loop and the grasp through the real drivers.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import threading
from pathlib import Path

import yaml

from drivers.core.errors import ConfigError
from drivers.core.files import atomic_write_text
from drivers.core.typed_config import load_yaml_file
from sim_backend.cell.timing import add_timing_argument, timing_from_args
from sim_backend.emulators.cell import DEFAULT_FPS, CellEmulators
from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValFaults

logger = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="serve on a new pty (the default)")
    where.add_argument("--tcp", type=int, metavar="PORT",
                       help="serve on 127.0.0.1:PORT instead (0: any free port)")
    parser.add_argument("--config", metavar="FILE", help="config file with the scene: section")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated cell")
    parser.add_argument("--boot-questions", action="store_true",
                        help="ask 'Load VAL from floppy (Y/N)?' and 'Initialize (Y/N)?' first")
    parser.add_argument("--reply-delay-s", type=float, default=0.0,
                        help="pause between the echo and the reply of every line")
    parser.add_argument("--drop-link-after-lines", type=int, metavar="N",
                        help="answer N lines, then drop the link (pty: silence; TCP: hang up)")
    parser.add_argument("--garbage", metavar="HEX", nargs="?", type=bytes.fromhex,
                        const=DEFAULT_GARBAGE,
                        help=f"send these bytes before every reply (default "
                             f"{DEFAULT_GARBAGE.hex()})")
    parser.add_argument("--forced-error", metavar="TEXT",
                        help="answer every command with *TEXT* instead of running it")
    ati = parser.add_mutually_exclusive_group()
    ati.add_argument("--ati", action="store_true",
                     help="also serve the wrist sensor as an ATI F/T controller on a pty")
    ati.add_argument("--ati-tcp", type=int, metavar="PORT",
                     help="the same on 127.0.0.1:PORT instead of a pty (0: any free port)")
    parser.add_argument("--mjpeg", type=int, metavar="PORT",
                        help="also serve the hand camera as an MJPEG stream on "
                             "http://127.0.0.1:PORT (0: any free port)")
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS,
                        help=f"frame rate of the stream with --timing ideal (default "
                             f"{DEFAULT_FPS:g}; realistic: timing.camera.frame_rate_hz)")
    parser.add_argument("--write-config", metavar="FILE", type=Path,
                        help="write a config file whose devices are these emulators")
    add_timing_argument(parser)


class StopSignals:
    """Catches SIGINT and SIGTERM while inside the ``with`` block (the previous handlers come
    back on leaving it); ``wait()`` blocks until one arrived and returns its number. Enter it
    before printing that the service is up, so a signal sent in reply is never lost."""

    def __init__(self) -> None:
        self._arrived = threading.Event()
        self._received: list[int] = []
        self._previous: dict = {}

    def __enter__(self) -> StopSignals:
        self._previous = {sig: signal.signal(sig, self._handler)
                          for sig in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc_info) -> None:
        for sig, old in self._previous.items():
            signal.signal(sig, old)

    def _handler(self, signum, _frame) -> None:
        self._received.append(signum)
        self._arrived.set()

    def wait(self) -> int:
        self._arrived.wait()
        return self._received[0]


def wait_for_stop_signal() -> int:
    """Block until SIGINT or SIGTERM arrives; returns its number."""
    with StopSignals() as stop:
        return stop.wait()


def run(args: argparse.Namespace) -> int:
    from sim_backend.cell.scene_config import load_cell
    from sim_backend.cell.sim_cell import (
        SimCell,  # PyBullet is imported only when the cell is needed
    )

    faults = ValFaults(reply_delay_s=args.reply_delay_s,
                       drop_link_after_lines=args.drop_link_after_lines,
                       garbage=args.garbage or b"", forced_error=args.forced_error)
    logger.info("VAL emulator: scene %s, seed %d, %s, boot questions %s, %s",
                args.config or "default", args.seed,
                "pty" if args.tcp is None else f"tcp port {args.tcp}", args.boot_questions, faults)
    if args.write_config and (args.mjpeg is None or not (args.ati or args.ati_tcp is not None)):
        raise ConfigError("--write-config: serve all three devices of the cell (--ati and "
                          "--mjpeg), or a simulated device in the client would be another cell")
    scene, parts = load_cell(args.config)
    with contextlib.ExitStack() as stack:
        cell = stack.enter_context(SimCell(scene, seed=args.seed, parts=parts))
        emulators = stack.enter_context(CellEmulators(
            cell, val_tcp_port=args.tcp, ati=args.ati, ati_tcp_port=args.ati_tcp,
            mjpeg_port=args.mjpeg, fps=args.fps, boot_questions=args.boot_questions,
            faults=faults, timing=timing_from_args(args)))
        stop = stack.enter_context(StopSignals())
        devices = emulators.device_sections()
        print(f"VAL emulator on {emulators.val_url}", flush=True)
        if emulators.ati_url:
            print(f"ATI F/T emulator on {emulators.ati_url}", flush=True)
        if emulators.stream_url:
            print(f"camera stream on {emulators.stream_url}", flush=True)
        print("device options: " + " ".join(device_options(devices)), flush=True)
        if args.write_config:
            write_config(args.write_config, args.config, devices)
            print(f"config written to {args.write_config}", flush=True)
        signum = stop.wait()
    print(f"stopped by {signal.Signals(signum).name}", flush=True)
    return 0


def device_options(devices: dict[str, dict]) -> list[str]:
    """The ``finepos position`` command-line options naming the same devices."""
    options = ["--arm", "val", "--port", devices["arm"]["port"]]
    if "wrench" in devices:
        options += ["--wrench", "ati", "--wrench-port", devices["wrench"]["port"]]
    if "camera" in devices:
        options += ["--camera", devices["camera"]["source"]]
    return options


def write_config(path: Path, base_config: str | None, devices: dict[str, dict]) -> None:
    """``base_config``'s sections (if given) with the device sections replaced, atomically."""
    data = load_yaml_file(base_config) if base_config else {}
    data.update(devices)
    header = "# Written by finepos sim val-emulator: the real drivers against its emulators.\n"
    atomic_write_text(path, header + yaml.safe_dump(data, sort_keys=False))
