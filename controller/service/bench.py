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
Prints JSON (and writes it to --json).
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


def _measure(work: Path, clients: int, runs: int, aborts: int, idle_peers: int) -> dict:
    config = work / "finepos.yaml"
    sock = work / "finepos.sock"
    config.write_text(json.dumps({
        "controller": {"paths": {"state_dir": str(work / "state"), "log_dir": str(work / "log")}},
        "service": {"socket_path": str(sock), "max_clients": clients + 4,
                    "max_clients_per_uid": clients + 4}}))
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
                    aborts_ms, halted = _abort_latencies(sock, client, aborts, idle_peers)
            finally:
                process.send_signal(signal.SIGTERM)
                process.wait(STOP_TIMEOUT_S)
    all_latencies = [ms for lat in latencies for ms in lat]
    log = work / "log" / "iterations.jsonl"
    iteration = {"alone": summarise_ms(_iteration_ms(log, alone)),
                 "under_load": summarise_ms(_iteration_ms(log, loaded))}
    return {
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


def run(args: argparse.Namespace) -> int:
    """Measure in a temporary folder and print the JSON report (also to ``--json``)."""
    with tempfile.TemporaryDirectory(prefix="finepos-bench-service-") as tmp:
        report = _measure(Path(tmp), args.clients, args.runs, args.aborts, args.idle_peers)
    write_json(args.json, report)
    return 0
