"""Time the ATI F/T driver's reading round trip over a pty against the wire time at the baud rate.

Example: finepos bench ati --reads 200

Prints JSON: the median and 95th percentile of ``read()`` (one ``QR`` exchange) through the
real driver and the emulator over a pty, the bytes of one exchange, and what those bytes take on
a real line at ``--baud`` (10 bits per byte, 8N1), so the pty overhead can be compared with it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from drivers.ati import AtiConfig, AtiWrenchSensor
from drivers.interfaces import Wrench, WrenchSensor
from sim_backend.emulators.ati.emulator import AtiEmulator

_BITS_PER_BYTE = 10  # start + 8 data + stop


class _ConstantWrench(WrenchSensor):
    """A sensor at a fixed, typical load (what the emulator serves during the benchmark)."""

    def _open(self) -> None:
        pass

    def _close(self) -> None:
        pass

    def _read(self) -> Wrench:
        return Wrench(1.5, -2.0, 9.81, 0.12, -0.2, 0.05)

    def _bias(self) -> None:
        pass


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--reads", type=int, default=200, help="readings to time (default 200)")
    parser.add_argument("--baud", type=int, default=9600, help="line speed compared against")


def run(args: argparse.Namespace) -> int:
    with _ConstantWrench() as backing, AtiEmulator(backing) as emulator, \
            AtiWrenchSensor(AtiConfig(port=emulator.url)) as sensor:
        reply_bytes = len(emulator.controller.execute("QR"))
        durations_ms = []
        for _ in range(args.reads):
            start_s = time.perf_counter()
            sensor.read()
            durations_ms.append((time.perf_counter() - start_s) * 1000.0)
    exchange_bytes = len(b"QR\r") + reply_bytes
    wire_ms = exchange_bytes * _BITS_PER_BYTE / args.baud * 1000.0
    median_ms = statistics.median(durations_ms)
    print(json.dumps({
        "reads": args.reads,
        "pty_read_median_ms": round(median_ms, 3),
        "pty_read_p95_ms": round(statistics.quantiles(durations_ms, n=20)[-1], 3),
        "exchange_bytes": exchange_bytes,
        "wire_ms_at_baud": round(wire_ms, 2),
        "baud": args.baud,
        "pty_overhead_vs_wire": round(median_ms / wire_ms, 4),
    }))
    return 0
