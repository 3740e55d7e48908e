"""Serve the simulated wrist force-torque sensor as an ATI F/T controller on a pty (or TCP).

Example: finepos sim ati-emulator --config deploy/finepos.yaml

  prints the port (e.g. /dev/pts/5) to use as ``wrench: {type: ati, port: /dev/pts/5}``. The
  cell is built from the ``scene:`` section of --config (defaults without it). In this process
  nothing moves the arm, so the readings are the sensor at rest: for a hardware-in-the-loop run
  serve AtiEmulator from the process that runs the VAL emulator on the same cell. With
  --timing realistic (the default) the line runs at timing.ati_baud (38400) both ways. Ctrl-C
  or SIGTERM stops it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from sim_backend.cell.timing import add_timing_argument, timing_from_args
from sim_backend.emulators.ati.emulator import AtiEmulator
from sim_backend.emulators.val.command import wait_for_stop_signal


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", type=Path, help="root config file (its scene: section)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the cell (noise)")
    parser.add_argument("--tcp-port", type=int, metavar="PORT",
                        help="serve on 127.0.0.1:PORT (0: any free port) instead of a pty")
    parser.add_argument("--counts-per-force", type=float, default=20.0,
                        help="counts per N the emulated controller reports (default 20)")
    parser.add_argument("--counts-per-torque", type=float, default=333.33,
                        help="counts per N*m (default 333.33)")
    add_timing_argument(parser)


def run(args: argparse.Namespace) -> int:
    from sim_backend.cell.scene_config import load_cell
    from sim_backend.cell.sim_cell import (
        SimCell,  # PyBullet is imported only when the cell is needed
    )
    from sim_backend.devices import SimWrenchSensor

    scene, parts = load_cell(args.config)
    timing = timing_from_args(args)
    with SimCell(scene, seed=args.seed, parts=parts) as cell, SimWrenchSensor(cell) as sensor, \
            AtiEmulator(sensor, args.counts_per_force, args.counts_per_torque,
                        tcp_port=args.tcp_port,
                        baud=timing.ati_baud if timing else None) as emulator:
        print(emulator.url, flush=True)
        wait_for_stop_signal()
    return 0
