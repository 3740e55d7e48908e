"""How soon an ``abort`` stops the arm during a realistic VAL move, with many idle and slow peers.

Part of ``finepos bench service`` (``--halt-aborts``). Serves a simulated cell over its device
emulators with the realistic timing (the VAL line paced at its baud rate, each ``do move``
answered after its motion time), runs the service in this process on the real drivers, teaches,
and starts ``acquire`` jobs (moves between the grid's poses). While ``peers`` connections are
open (half send nothing, half send one byte a second; any the service closes are opened again),
each abort is sent through a fresh connection at a random moment of a move the VAL emulator is
running. Per abort:

- ``abort_ms``: the round trip of the ``abort`` request;
- ``halted_ms``: from sending it to the arm at rest (cell time: the emulated cell runs on the
  wall clock): the last change of the cell's arm pose, read every 5 ms from the cell itself;
- ``prompt_ms``: from sending it to the VAL prompt of the last motion command that was running
  or started after it (the arm's servo settling, ``timing.arm.settle_s``, included);
- ``motions_after_abort``: motion commands the emulator received after the abort was answered
  (must stay 0).

How far the arm goes after an abort is bounded by the VAL driver's move segmenting
(``arm.max_segment_mm`` / ``max_segment_deg``): the segment under way is finished, the next one
is not sent (``--segment-mm`` / ``--segment-deg`` override the config for a comparison).
"""

from __future__ import annotations

import contextlib
import random
import shutil
import socket
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from controller.service.client import ServiceClient, ServiceError
from controller.service.soak import (
    cell_opener,
    is_motion,
    running_service,
    served_cell,
    soak_config,
)

JOB_TIMEOUT_S = 120.0
PEER_PERIOD_S = 1.0  # slow peers send one byte this often; closed peers are reopened
MOTION_WAIT_S = 30.0
POSE_SAMPLE_S = 0.005  # the arm's pose is read this often around an abort
ABORT_INTO_MOVE_S = 0.6  # an abort is sent up to this long after a move started


class MotionWatch:
    """The VAL emulator's motion commands with their start and end times (monotonic s)."""

    def __init__(self) -> None:
        self._changed = threading.Condition()
        self.motions: list[list[float | None]] = []  # [start, end or None while running]

    def on_val(self, event: str, text: str) -> None:
        """The VAL emulator's listener."""
        if not is_motion(text):
            return
        with self._changed:
            if event == "command":
                self.motions.append([time.monotonic(), None])
            elif event == "done" and self.motions and self.motions[-1][1] is None:
                self.motions[-1][1] = time.monotonic()
            self._changed.notify_all()

    def count(self) -> int:
        """Motion commands received so far."""
        with self._changed:
            return len(self.motions)

    def wait_running(self, after: int, timeout_s: float) -> float | None:
        """Wait for motion command number ``after`` or a later one to be in progress; returns
        its start time (None on timeout)."""
        with self._changed:
            if not self._changed.wait_for(
                    lambda: self._running() and len(self.motions) > after, timeout_s):
                return None
            return self.motions[-1][0]

    def running_since(self, start: float) -> bool:
        """Whether the motion that started at ``start`` is still running."""
        with self._changed:
            return self._running() and self.motions[-1][0] == start

    def _running(self) -> bool:
        return bool(self.motions) and self.motions[-1][1] is None

    def durations_ms(self) -> list[float]:
        """How long each finished motion command ran (ms)."""
        with self._changed:
            return [(end - start) * 1e3 for start, end in self.motions if end is not None]

    def halted_at(self, since: float, timeout_s: float) -> float | None:
        """When the arm came to rest after ``since``: the end of the last motion that ran at or
        started after ``since`` (``since`` when none did). Waits up to ``timeout_s`` for a
        motion still running (the job may end before the arm does); None if it did not end."""
        with self._changed:
            if not self._changed.wait_for(lambda: not self._running(), timeout_s):
                return None
            ends = [end for _, end in self.motions if end is not None and end >= since]
        return max(ends, default=since)

    def started_after(self, since: float) -> int:
        """How many motion commands started after ``since``."""
        with self._changed:
            return sum(1 for start, _ in self.motions if start > since)


class PoseSampler:
    """Reads the emulated cell's arm pose every ``period_s`` from a thread, and remembers when
    it last changed: the moment the arm came to rest, read from the cell itself."""

    def __init__(self, cell, period_s: float = POSE_SAMPLE_S) -> None:
        self._cell = cell
        self._period_s = period_s
        self._stop = threading.Event()
        self.last_change: float | None = None
        self._thread = threading.Thread(target=self._run, name="pose-sampler", daemon=True)

    def _run(self) -> None:
        last = self._cell.arm_pose()
        while not self._stop.wait(self._period_s):
            pose = self._cell.arm_pose()
            if pose != last:
                self.last_change, last = time.monotonic(), pose

    def __enter__(self) -> PoseSampler:
        self._thread.start()
        return self

    def __exit__(self, *exc_info) -> None:
        self._stop.set()
        self._thread.join()


@contextlib.contextmanager
def slow_peers(path: Path, count: int) -> Iterator[list[socket.socket]]:
    """``count`` connections kept open: even ones send nothing, odd ones a byte a second
    (a request line that never ends); one the service closes is opened again."""
    stop = threading.Event()
    peers: list[socket.socket | None] = [None] * count

    def connect() -> socket.socket | None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.connect(str(path))
        except OSError:
            sock.close()
            return None
        sock.setblocking(False)
        return sock

    def keep() -> None:
        while not stop.is_set():
            for i in range(count):
                sock = peers[i]
                alive = sock is not None
                if sock is not None:
                    try:
                        if sock.recv(4096) == b"":
                            alive = False
                    except BlockingIOError:
                        pass
                    except OSError:
                        alive = False
                    if alive and i % 2:
                        try:
                            sock.send(b" ")
                        except OSError:
                            alive = False
                if not alive:
                    if sock is not None:
                        sock.close()
                    peers[i] = connect()
            stop.wait(PEER_PERIOD_S)

    for i in range(count):
        peers[i] = connect()
    thread = threading.Thread(target=keep, name="slow-peers", daemon=True)
    thread.start()
    try:
        yield [p for p in peers if p is not None]
    finally:
        stop.set()
        thread.join()
        for sock in peers:
            if sock is not None:
                sock.close()


def measure_halts(aborts: int, peers: int, seed: int = 14, segment_mm: float | None = None,
                  segment_deg: float | None = None) -> dict[str, Any]:
    """Run the aborts (see the module docstring); returns the per-abort rows and the
    segmenting in use (``segment_mm`` and ``segment_deg``, both or neither: override the
    driver's default)."""
    if (segment_mm is None) != (segment_deg is None):
        raise ValueError("segment_mm and segment_deg: give both or neither")
    work = Path(tempfile.mkdtemp(prefix="fp-halt-", dir="/tmp"))
    try:
        with served_cell("realistic", seed) as emulators:
            watch = MotionWatch()
            assert emulators.val is not None
            emulators.val.add_listener(watch.on_val)
            segmenting = {} if segment_mm is None else {"max_segment_mm": segment_mm,
                                                         "max_segment_deg": segment_deg}
            config = soak_config(work, work / "fp.sock", emulators, "realistic", **segmenting)
            arm_options = config.arm.options
            with running_service(config, cell_opener(emulators)) as service, \
                    ServiceClient(service.socket_path, timeout_s=JOB_TIMEOUT_S) as client:
                job = client.call("teach", timeout_s=JOB_TIMEOUT_S, auto=True, wait=True)["job"]
                if job["outcome"] != "done":
                    raise RuntimeError(f"teach ended {job['outcome']}: {job['reason']}")
                with slow_peers(service.socket_path, peers):
                    rows = _aborts(service.socket_path, client, watch, emulators.cell, aborts,
                                   seed)
        return {"rows": rows, "move_ms": watch.durations_ms(),
                "segment_mm": arm_options.max_segment_mm,
                "segment_deg": arm_options.max_segment_deg}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _aborts(path: Path, client: ServiceClient, watch: MotionWatch, cell, aborts: int,
            seed: int) -> list[dict[str, Any]]:
    rng = random.Random(seed)
    rows: list[dict[str, Any]] = []
    job_seed = 0
    while len(rows) < aborts:
        # Past the acquisition's first move (back to the taught pose, often no way at all),
        # at a random moment of one between its grid poses.
        after = watch.count() + rng.randint(1, 4)
        client.call("acquire", set="nn1", seed=job_seed)
        job_seed += 1
        while True:
            start = watch.wait_running(after, MOTION_WAIT_S)
            if start is None:
                raise RuntimeError(f"no VAL move running within {MOTION_WAIT_S:.0f} s")
            time.sleep(max(0.0, start + rng.uniform(0.0, ABORT_INTO_MOVE_S) - time.monotonic()))
            if watch.running_since(start):
                break
        with PoseSampler(cell) as sampler, ServiceClient(path, timeout_s=10.0) as operator:
            sent = time.monotonic()
            try:
                answer = operator.call("abort")
            except ServiceError as exc:  # the job ended on its own first: try again
                answer = {"error": exc.code}
            answered = time.monotonic()
            deadline = time.monotonic() + JOB_TIMEOUT_S
            while client.call("status")["state"] not in ("idle", "fault"):
                if time.monotonic() > deadline:
                    raise RuntimeError("the aborted job did not end")
                time.sleep(0.02)
            prompt = watch.halted_at(sent, JOB_TIMEOUT_S)
            if prompt is None:
                raise RuntimeError("the arm did not come to rest after an abort")
            time.sleep(2 * POSE_SAMPLE_S)
        if "error" in answer:
            continue
        halted = max(sent, sampler.last_change or sent)
        rows.append({"abort_ms": (answered - sent) * 1e3, "halted_ms": (halted - sent) * 1e3,
                     "prompt_ms": (prompt - sent) * 1e3,
                     "motions_after_abort": watch.started_after(answered),
                     "halt_acknowledged": bool(answer.get("halted"))})
        if client.call("status")["state"] == "fault":
            client.call("reset")
    return rows
