"""Emulate a Magellan serial 3D mouse on a pty, optionally with the real spacenavd reading it.

Example: finepos sim magellan-emulator --spacenavd --keyboard

  prints the pty and, with --spacenavd, ``SPNAV_SOCKET=...`` to export for the client (e.g.
  ``finepos teach --device spacenav`` in another terminal); keys then jog (see
  sim_backend.emulators.magellan.keyboard). With ``--script jog.yaml`` (see
  sim_backend.emulators.magellan.script) every press of Enter plays the script. Without
  --spacenavd, point your own spacenavd at the printed pty (``serial = /dev/pts/N`` in its
  config). Ctrl-C or SIGTERM stops; the daemon is stopped before the pty is closed.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import tempfile

from sim_backend.emulators.magellan.emulator import MagellanEmulator
from sim_backend.emulators.magellan.keyboard import drive_from_keyboard
from sim_backend.emulators.magellan.script import Step, load_script
from sim_backend.emulators.magellan.spacenavd import Spacenavd

_READY_TIMEOUT_S = 10.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--keyboard", action="store_true",
                        help="drive the cap from the keyboard (stdin must be a terminal)")
    source.add_argument("--script", metavar="FILE",
                        help="YAML script of motions and button presses, played on Enter")
    parser.add_argument("--spacenavd", action="store_true",
                        help="also run the real spacenavd on the pty (in a temporary folder)")
    parser.add_argument("--deflection", type=int, default=200, metavar="COUNTS",
                        help="keyboard deflection in device counts (default 200)")
    parser.add_argument("--report-period-s", type=float, default=0.02,
                        help="how often the mouse repeats a held motion (default 0.02 s)")


def run(args: argparse.Namespace) -> int:
    script = load_script(args.script) if args.script else None
    signal.signal(signal.SIGTERM, signal.default_int_handler)  # unwind (daemon first) as on ^C
    with contextlib.ExitStack() as stack:
        mouse = stack.enter_context(MagellanEmulator(args.report_period_s))
        print(f"Magellan mouse on {mouse.url}", flush=True)
        if args.spacenavd:
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="spacenavd-"))
            daemon = stack.enter_context(Spacenavd(mouse.url, folder))  # exits before mouse
            if not mouse.wait_ready(_READY_TIMEOUT_S):
                print(f"spacenavd did not probe the mouse:\n{daemon.log_tail()}",
                      file=sys.stderr)
                return 1
            print(f"SPNAV_SOCKET={daemon.socket_path}", flush=True)
        if script is None:
            drive_from_keyboard(mouse, args.deflection)
        else:
            _play_on_enter(mouse, script)
    return 0


def _play_on_enter(mouse: MagellanEmulator, script: list[Step]) -> None:
    print("Enter plays the script; Ctrl-D or Ctrl-C stops.", flush=True)
    for _ in sys.stdin:
        mouse.play(script)
