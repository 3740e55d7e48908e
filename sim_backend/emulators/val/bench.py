"""Round trip of VAL commands through the real driver and a pty, against 9600-baud wire time.

Example: finepos bench val --json out/bench-val.json

  runs the VAL emulator over the simulated arm on a pty, sends each command (``where``,
  ``speed 50``) many times through ValArm and prints, per command, the median round trip, the
  bytes on the line (command out; echo, output and prompt back) and the time those bytes would
  take on the real 9600-baud 8N1 line (10 bits per byte, both directions one after the other):
  the pty's overhead is then a small fraction of what the real line costs. Then, with the
  emulator's realistic timing (``--timed-repeats`` exchanges each, default 5: they take real
  seconds), ``where``, ``speed 50`` and a 5 mm out-and-back move: the wall-clock round trip
  next to the wire time the paced line took and the motion time the arm took
  (``timed.<command>``: ``wall_ms``, ``wire_ms``, ``motion_ms``, ``other_ms``).
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
    parser.add_argument("--timed-repeats", type=int, default=5,
                        help="exchanges per command against the realistic emulator (default 5)")


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
    report = {"transport": "pty", "repeats": args.repeats, "commands": results,
              "timed": measure_timed(max(1, args.timed_repeats))}
    write_json(args.json, report)
    return 0


def measure_timed(repeats: int) -> dict[str, dict[str, float]]:
    """Wall time, wire time and motion time of ``where``, ``speed 50`` and a 5 mm move (there
    and back, one exchange each way) against the emulator with realistic timing."""
    from drivers.core.pose import ToolStep
    from drivers.core.timing import TimingConfig
    from sim_backend.cell.scene_config import SceneConfig
    from sim_backend.cell.sim_cell import SimCell
    from sim_backend.emulators.cell import CellEmulators

    with SimCell(SceneConfig()) as cell, \
            CellEmulators(cell, timing=TimingConfig()) as emulators, \
            ValArm(ValConfig(port=emulators.val_url)) as arm:
        link, timing = emulators.val._link, emulators.timing
        home = arm.pose()
        targets = [home.moved_in_tool_frame(ToolStep(5.0, 0.0, 0.0, 0.0)), home]
        moves = iter(targets * repeats * 2)
        commands = {"where": arm.pose, "speed": lambda: arm.set_speed(50),
                    "move_5mm": lambda: arm.move_to(next(moves))}
        out = {}
        for name, call in commands.items():
            rows = []
            for _ in range(repeats):
                wire0, motion0 = link.wire_s, timing.motion_s
                start = time.perf_counter()
                call()
                wall = time.perf_counter() - start
                rows.append((wall, link.wire_s - wire0, timing.motion_s - motion0))
            wall, wire, motion = (statistics.median(r[i] for r in rows) for i in range(3))
            out[name] = {"wall_ms": wall * 1e3, "wire_ms": wire * 1e3, "motion_ms": motion * 1e3,
                         "other_ms": (wall - wire - motion) * 1e3}
        arm.set_speed(100)
    return out
