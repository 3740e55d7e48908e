"""Round trip of VAL commands through the real driver and a pty, against 9600-baud wire time.

Example: finepos bench val --json out/bench-val.json

  runs the VAL emulator over the simulated arm on a pty, sends each command (``where``,
  ``speed 50``) many times through ValArm and prints, per command, the median round trip, the
  bytes on the line (command out; echo, output and prompt back) and the time those bytes would
  take on the real 9600-baud 8N1 line (10 bits per byte, both directions one after the other):
  the pty's overhead is then a small fraction of what the real line costs.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

from drivers.core.files import write_json
from drivers.val.arm import ValArm
from drivers.val.config import ValConfig
from sim_backend.emulators.val.server import ValEmulator
from sim_backend.emulators.val.sim_arm import SIM_KINEMATICS, simulated_arm

WIRE_BAUD = 9600
BITS_PER_BYTE = 10  # start bit, 8 data bits, stop bit


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="OUT", required=True, help="write the results here")
    parser.add_argument("--repeats", type=int, default=300, help="exchanges per command")


def measure(arm: ValArm, call: Callable[[], object], repeats: int) -> dict[str, float]:
    """Median round trip of ``call`` (one exchange) and its wire time at 9600 baud."""
    round_trips_s, sent, received = [], [], []
    for _ in range(repeats):
        written0, read0 = arm.link.bytes_written, arm.link.bytes_read
        start = time.perf_counter()
        call()
        round_trips_s.append(time.perf_counter() - start)
        sent.append(arm.link.bytes_written - written0)
        received.append(arm.link.bytes_read - read0)
    line_bytes = statistics.median(sent) + statistics.median(received)
    wire_s = line_bytes * BITS_PER_BYTE / WIRE_BAUD
    round_trip_s = statistics.median(round_trips_s)
    return {
        "round_trip_median_ms": round_trip_s * 1e3,
        "round_trip_p90_ms": statistics.quantiles(round_trips_s, n=10)[-1] * 1e3,
        "bytes_sent": statistics.median(sent),
        "bytes_received": statistics.median(received),
        "wire_time_ms_at_9600_baud": wire_s * 1e3,
        "overhead_vs_wire_ratio": round_trip_s / wire_s,
    }


def run(args: argparse.Namespace) -> int:
    with simulated_arm() as backing, \
            ValEmulator(backing, kinematics=SIM_KINEMATICS) as emulator, \
            ValArm(ValConfig(port=emulator.url)) as arm:
        commands = {"where": arm.pose, "speed": lambda: arm.set_speed(50)}
        results = {name: measure(arm, call, args.repeats) for name, call in commands.items()}
    report = {"transport": "pty", "repeats": args.repeats, "commands": results}
    write_json(args.json, report)
    return 0
