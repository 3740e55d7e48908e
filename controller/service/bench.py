"""Service load: status requests per second from N clients, and the loop's iteration jitter.

Example: finepos bench service --json out/bench-service.json

Starts ``finepos serve`` on the simulated cell in a temporary folder (waiting for its READY=1 on
a private NOTIFY_SOCKET), teaches, acquires and trains through the control API, then runs the
same positioning jobs twice: alone, and while --clients connections send ``status`` requests as
fast as they are answered (each connection is paced by ``service.request_rate_hz``). Iteration
times (grab + perceive + move, from the iteration log) are summarised per phase (p50, p95, max;
jitter_ms is p95 minus median; loop_p95_ratio / loop_max_ratio: under load over alone). Then
--idle-peers connections that send nothing are opened and --aborts positioning jobs are aborted
mid-move, each ``abort`` through a fresh connection: ``abort_latency_ms`` (p50, p95, max) is the
round trip, which includes the arm's reply to the halt (up to ``service.abort_wait_s``).
Then, unless --live-clients is 0, the same positioning jobs with the live view on
(``service.live``) three times: with no live client, with one client that subscribes to every
channel and never reads (``controller.service.live_bench``), and with --live-clients clients
that read everything. ``live`` summarises each phase's loop period (ms from one look's record
to the next of the same run: grab, perceive, move, the log and the live view's messages);
``stalled_p95_ratio`` and ``clients_p95_ratio`` are over the phase without clients
(target: at most 1.1).
Then, unless --halt-aborts is 0, the same with the real VAL driver during realistic VAL moves
(``controller.service.halt_bench``: the service in this process on the emulated cell, --idle-peers
half idle and half byte-a-second peers): ``halted_ms`` (p50, p95, max) is from the abort sent
to the arm at rest, read from the cell (``halt`` holds the abort round trips there, the time to
the VAL prompt and the move segmenting used, --segment-mm / --segment-deg: 5 mm / 2.5 deg by
default, the setting that meets 300 ms; 0 and 0 for whole moves). Prints JSON (and writes it
to --json).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import selectors
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

from controller.loop.iteration_log import read_log
from controller.service.client import ServiceClient
from drivers.core.files import write_json

OFFSETS = ((12.0, -8.0, 20.0), (-15.0, 10.0, -25.0), (8.0, 14.0, 10.0), (-10.0, -12.0, -15.0))
START_TIMEOUT_S = 120.0
STOP_TIMEOUT_S = 10.0
# The move segmenting of the halted_ms phase: the setting that keeps the arm's halt within
# 300 ms (p95) on the modelled PUMA 260 timing (bench service: 5 / 2.5 -> p95 281 ms,
# 10 / 5 -> 352 ms, whole moves -> 950 ms), at the cost of slower long moves.
SEGMENT_MM = 5.0
SEGMENT_DEG = 2.5


def _count(minimum: int):
    """An argparse type: an integer of at least ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value
    return parse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--json``, ``--clients`` and ``--runs``."""
    parser.add_argument("--json", metavar="OUT", help="also write the report here")
    parser.add_argument("--clients", type=_count(1), default=8, help="concurrent status clients")
    parser.add_argument("--runs", type=_count(1), default=3,
                        help=f"positioning runs per phase, from each of {len(OFFSETS)} offsets")
    parser.add_argument("--aborts", type=_count(0), default=20,
                        help="aborts sent during positioning moves, with --idle-peers connected")
    parser.add_argument("--idle-peers", type=_count(0), default=200,
                        help="connections that send nothing, open while the aborts are sent")
    parser.add_argument("--halt-aborts", type=_count(0), default=50,
                        help="aborts during realistic VAL moves, for halted_ms (0: skip)")
    parser.add_argument("--segment-mm", type=_non_negative, default=SEGMENT_MM,
                        help="VAL move segments (arm.max_segment_mm) in the halted_ms phase "
                             f"(default {SEGMENT_MM:g}; 0 with --segment-deg 0: whole moves)")
    parser.add_argument("--segment-deg", type=_non_negative, default=SEGMENT_DEG,
                        help="arm.max_segment_deg in the halted_ms phase "
                             f"(default {SEGMENT_DEG:g})")
    parser.add_argument("--live-clients", type=_count(0), default=20,
                        help="reading live-view clients in the last live phase (0: no live "
                             "phases)")
    parser.add_argument("--skip-load", action="store_true",
                        help="only the halted_ms phase (no status flood, no simulated-arm aborts)")


def _non_negative(text: str) -> float:
    """An argparse type: a finite number >= 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0.0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


def summarise_ms(values_ms: list[float]) -> dict[str, float | int]:
    """count, p50 (= median), p95, max, standard deviation (ms) and jitter = p95 - median."""
    ordered = sorted(values_ms)
    if not ordered:
        return {"count": 0}
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    median = statistics.median(ordered)
    return {"count": len(ordered), "p50_ms": median, "median_ms": median, "p95_ms": p95,
            "max_ms": ordered[-1],
            "std_ms": statistics.pstdev(ordered), "jitter_ms": p95 - median}


def _ratio(iteration: dict[str, dict], key: str) -> float | None:
    """Under load over alone for one statistic (targets: p95 <= 1.5, max <= 3)."""
    alone, loaded = iteration["alone"].get(key), iteration["under_load"].get(key)
    return loaded / alone if alone and loaded is not None else None


def _wait_ready(notify: socket.socket, process: subprocess.Popen) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    with selectors.DefaultSelector() as selector:
        selector.register(notify, selectors.EVENT_READ)
        while time.monotonic() < deadline and process.poll() is None:
            if selector.select(1.0) and b"READY=1" in notify.recv(4096).split(b"\n"):
                return
    raise RuntimeError("the service did not report READY=1 (see its log)")


def _hammer(path: Path, stop: threading.Event, latencies_ms: list[float]) -> None:
    with ServiceClient(path) as client:
        while not stop.is_set():
            t0 = time.perf_counter()
            client.call("status")
            latencies_ms.append((time.perf_counter() - t0) * 1e3)


def _position_runs(client: ServiceClient, runs: int) -> list[str]:
    run_ids = []
    for _ in range(runs):
        for offset in OFFSETS:
            job = client.call("position", timeout_s=None, offset=list(offset), wait=True)["job"]
            if job["result"] is not None:
                run_ids.append(job["result"]["run_id"])
    return run_ids


def _abort_latencies(path: Path, client: ServiceClient, aborts: int, idle_peers: int,
                     seed: int = 14) -> tuple[list[float], int]:
    """Round trips (ms) of ``abort`` sent mid-move through a fresh connection while
    ``idle_peers`` connections send nothing; also how many answers reported the arm halted."""
    rng = random.Random(seed)
    peers = []
    latencies_ms: list[float] = []
    halted = 0
    try:
        for _ in range(idle_peers):
            peer = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            peer.connect(str(path))
            peers.append(peer)
        for i in range(aborts):
            offset = OFFSETS[i % len(OFFSETS)]
            client.call("position", offset=list(offset), wait=False)
            time.sleep(rng.uniform(0.02, 0.2))
            with ServiceClient(path) as operator:
                t0 = time.perf_counter()
                answer = operator.call("abort")
                latencies_ms.append((time.perf_counter() - t0) * 1e3)
            halted += bool(answer["halted"])
            while client.call("status")["state"] != "idle":
                time.sleep(0.02)
    finally:
        for peer in peers:
            peer.close()
    return latencies_ms, halted


def _iteration_ms(log: Path, run_ids: list[str]) -> list[float]:
    wanted = set(run_ids)
    per_run: dict[str, list[float]] = defaultdict(list)
    for record in read_log(log):
        if record.get("run_id") in wanted and record.get("loop_kind") in ("half", "full"):
            per_run[record["run_id"]].append(sum(record["timings_ms"].values()))
    return [ms for run in per_run.values() for ms in run]


def _period_ms(log: Path, run_ids: list[str]) -> list[float]:
    """The loop's period: ms from each look's record to the next look's of the same run."""
    wanted = set(run_ids)
    times: dict[str, list[float]] = defaultdict(list)
    for record in read_log(log):
        if record.get("run_id") in wanted:
            times[record["run_id"]].append(record["time"])
    return [(b - a) * 1e3 for run in times.values()
            for a, b in zip(run, run[1:], strict=False)]


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _live_phases(client: ServiceClient, port: int, runs: int, clients: int) -> dict:
    """The positioning runs of each live phase (none, stalled, clients: their run ids), taken
    in turns, each offset of OFFSETS once per phase before the next, so that a change in the
    machine's other load falls on all three alike; and the fewest messages a reading client
    got in one turn."""
    from controller.recording.channels import JSON_CHANNELS, TF_TOPIC
    from controller.service.live_bench import LiveClient

    topics = ("/hand_camera/image", "/hand_camera/annotations", TF_TOPIC, *JSON_CHANNELS)
    phases: dict = {"none": [], "stalled": [], "clients": [], "messages_per_client": None}

    def position(phase: str, offset: tuple[float, float, float]) -> None:
        job = client.call("position", timeout_s=None, offset=list(offset), wait=True)["job"]
        if job["result"] is not None:
            phases[phase].append(job["result"]["run_id"])

    # one stalled client for the whole bench, subscribed during its phase only: its messages
    # pile up in the server (up to its queue, then the oldest are dropped) as a hung viewer's
    stalled = LiveClient(port, topics, reading=False, subscribed=False)
    try:
        for _ in range(runs):
            for offset in OFFSETS:
                position("none", offset)
                stalled.subscribe()
                position("stalled", offset)
                stalled.unsubscribe()
                _readers_position(position, port, topics, clients, offset, phases)
    finally:
        stalled.close()
    return phases


def _readers_position(position, port: int, topics: tuple[str, ...], clients: int,
                      offset: tuple[float, float, float], phases: dict) -> None:
    """One position job of the ``clients`` phase, with ``clients`` reading live clients."""
    from controller.service.live_bench import LiveClient

    readers: list[LiveClient] = []
    try:
        for _ in range(clients):
            readers.append(LiveClient(port, topics, reading=True))
        position("clients", offset)
    finally:
        for reader in readers:
            reader.close()
    fewest = min(reader.messages for reader in readers)
    phases["messages_per_client"] = min(fewest, phases["messages_per_client"] or fewest)


def _measure(work: Path, clients: int, runs: int, aborts: int, idle_peers: int,
             live_clients: int) -> dict:
    config = work / "finepos.yaml"
    sock = work / "finepos.sock"
    live_port = _free_port()
    config.write_text(json.dumps({
        "controller": {"paths": {"state_dir": str(work / "state"), "log_dir": str(work / "log")}},
        "service": {"socket_path": str(sock), "max_clients": clients + 4,
                    "max_clients_per_uid": clients + 4,
                    **({"live": {"port": live_port}} if live_clients else {})}}))
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as notify, \
            open(work / "service.log", "wb") as service_log:
        notify.bind(str(work / "notify"))
        env = {**os.environ, "NOTIFY_SOCKET": str(work / "notify")}
        command = [sys.executable, "-m", "controller.cli", "serve", "--config", str(config)]
        with subprocess.Popen(command, env=env, stdout=service_log,
                              stderr=subprocess.STDOUT) as process:
            try:
                _wait_ready(notify, process)
                with ServiceClient(sock) as client:
                    for cmd, args in (("teach", {"auto": True}), ("acquire", {"set": "nn1"}),
                                      ("acquire", {"set": "nn2"}), ("train", {})):
                        client.call(cmd, timeout_s=None, wait=True, **args)
                    alone = _position_runs(client, runs)
                    stop = threading.Event()
                    latencies: list[list[float]] = [[] for _ in range(clients)]
                    threads = [threading.Thread(target=_hammer, args=(sock, stop, lat))
                               for lat in latencies]
                    t0 = time.perf_counter()
                    for thread in threads:
                        thread.start()
                    loaded = _position_runs(client, runs)
                    stop.set()
                    for thread in threads:
                        thread.join()
                    seconds = time.perf_counter() - t0
                    live = (_live_phases(client, live_port, runs, live_clients)
                            if live_clients else None)
                    aborts_ms, halted = _abort_latencies(sock, client, aborts, idle_peers)
            finally:
                process.send_signal(signal.SIGTERM)
                process.wait(STOP_TIMEOUT_S)
    all_latencies = [ms for lat in latencies for ms in lat]
    log = work / "log" / "iterations.jsonl"
    iteration = {"alone": summarise_ms(_iteration_ms(log, alone)),
                 "under_load": summarise_ms(_iteration_ms(log, loaded))}
    report = {
        "clients": clients, "seconds": seconds, "status_requests": len(all_latencies),
        "status_per_second": len(all_latencies) / seconds,
        "status_latency_ms": summarise_ms(all_latencies),
        "iteration_ms": iteration,
        "loop_p95_ratio": _ratio(iteration, "p95_ms"),
        "loop_max_ratio": _ratio(iteration, "max_ms"),
        "abort_latency_ms": {key.removesuffix("_ms"): value
                             for key, value in summarise_ms(aborts_ms).items()
                             if key in ("p50_ms", "p95_ms", "max_ms")},
        "aborts": {"sent": len(aborts_ms), "halted": halted, "idle_peers": idle_peers},
        "cpu_count": os.cpu_count(),
    }
    if live is not None:
        period = {phase: summarise_ms(_period_ms(log, live[phase]))
                  for phase in ("none", "stalled", "clients")}
        none_p95 = period["none"].get("p95_ms")
        report["live"] = {
            "period_ms": period, "live_clients": live_clients,
            "messages_per_client": live["messages_per_client"],
            **{f"{phase}_p95_ratio": (period[phase]["p95_ms"] / none_p95 if none_p95 else None)
               for phase in ("stalled", "clients")}}
    return report


def _percentiles(values_ms: list[float]) -> dict[str, float]:
    """{"p50", "p95", "max"} of ``values_ms``."""
    return {key.removesuffix("_ms"): value for key, value in summarise_ms(values_ms).items()
            if key in ("p50_ms", "p95_ms", "max_ms")}


def halted_report(aborts: int, peers: int, segment_mm: float | None,
                  segment_deg: float | None) -> dict:
    """The halted_ms phase's part of the report (``controller.service.halt_bench``)."""
    from controller.service.halt_bench import measure_halts

    measured = measure_halts(aborts, peers, segment_mm=segment_mm, segment_deg=segment_deg)
    rows = measured["rows"]
    return {
        "halted_ms": _percentiles([row["halted_ms"] for row in rows]),
        "halt": {"aborts": len(rows), "peers": peers,
                 "abort_latency_ms": _percentiles([row["abort_ms"] for row in rows]),
                 "prompt_ms": _percentiles([row["prompt_ms"] for row in rows]),
                 "move_ms": _percentiles(measured["move_ms"]),
                 "motions_after_abort": sum(row["motions_after_abort"] for row in rows),
                 "halt_acknowledged": sum(row["halt_acknowledged"] for row in rows),
                 "segment_mm": measured["segment_mm"], "segment_deg": measured["segment_deg"]},
    }


def run(args: argparse.Namespace) -> int:
    """Measure in a temporary folder and print the JSON report (also to ``--json``)."""
    if (args.segment_mm == 0) != (args.segment_deg == 0):
        raise SystemExit("finepos bench service: --segment-mm and --segment-deg: both 0 (whole "
                         "moves) or both above 0")
    report: dict = {}
    if not args.skip_load:
        with tempfile.TemporaryDirectory(prefix="finepos-bench-service-") as tmp:
            report = _measure(Path(tmp), args.clients, args.runs, args.aborts, args.idle_peers,
                              args.live_clients)
    if args.halt_aborts:
        report.update(halted_report(args.halt_aborts, args.idle_peers, args.segment_mm,
                                    args.segment_deg))
    write_json(args.json, report)
    return 0
