"""Serve the VAL II monitor of the simulated PUMA 260 on a pseudo-terminal or a TCP port.

Example: finepos sim val-emulator --pty --boot-questions

  prints ``VAL emulator on PORT`` (PORT: ``/dev/pts/N``, or ``socket://127.0.0.1:N`` with
  --tcp; use it as ``arm: {type: val, port: PORT}``), then serves the simulated cell's arm until
  SIGINT or SIGTERM. The scene comes from the ``scene:`` section of --config FILE. Fault
  knobs: --reply-delay-s, --drop-link-after-lines, --garbage HEX, --forced-error TEXT (see
  sim_backend.val_emulator.server.ValFaults).
"""

from __future__ import annotations

import argparse
import logging
import signal
import threading

from sim_backend.val_emulator.server import DEFAULT_GARBAGE, ValEmulator, ValFaults
from sim_backend.val_emulator.sim_arm import SIM_KINEMATICS, simulated_arm

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


def wait_for_stop_signal() -> int:
    """Block until SIGINT or SIGTERM arrives; returns its number."""
    stop = threading.Event()
    received: list[int] = []

    def handler(signum, _frame) -> None:
        received.append(signum)
        stop.set()

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        stop.wait()
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
    return received[0]


def run(args: argparse.Namespace) -> int:
    faults = ValFaults(reply_delay_s=args.reply_delay_s,
                       drop_link_after_lines=args.drop_link_after_lines,
                       garbage=args.garbage or b"", forced_error=args.forced_error)
    logger.info("VAL emulator: scene %s, seed %d, %s, boot questions %s, %s",
                args.config or "default", args.seed,
                "pty" if args.tcp is None else f"tcp port {args.tcp}", args.boot_questions, faults)
    with simulated_arm(args.config, args.seed) as arm, \
            ValEmulator(arm, tcp_port=args.tcp, boot_questions=args.boot_questions,
                        kinematics=SIM_KINEMATICS, faults=faults) as emulator:
        print(f"VAL emulator on {emulator.url}", flush=True)
        signum = wait_for_stop_signal()
    print(f"stopped by {signal.Signals(signum).name}", flush=True)
    return 0
