"""Soak: position + grasp cycles through the service on the emulated cell, with faults.

Example: finepos bench soak --cycles 100 --faults --seed 1 --json out/soak.json

Serves one simulated cell over its device emulators in this process (the VAL II monitor and the
ATI F/T controller on TCP ports of 127.0.0.1, the hand camera as an MJPEG stream), runs the
service (``controller.service.service.Service``, what ``finepos serve`` runs) on the real
drivers pointed at them, and commands it over its control socket as a client program would:
teach, acquire and train once, then ``--cycles`` times put the part back where it was taught,
``position`` from a random offset and ``grasp``.

With ``--faults``, about one cycle in three gets one fault at a random moment of its position
or grasp job, through the emulators' knobs: the VAL link dropped, garbage on the VAL line, a VAL
reply delayed beyond the driver's timeout or never sent, the camera stream gone, the wrench
sensor reporting an error, a client killed while its request runs (or halfway through sending
it), or an ``abort``. The client then recovers as an operator would: once the job has ended it
removes the cause (the knob is set back), sends ``reset`` until the service is idle again, and
carries on with the next cycle. A fault counts as injected once it took effect (an emulator
acted on it, the abort stopped a running job, the killed client's job ran or its half request
arrived) and as recovered once the service was idle again after the reset (a killed client:
its job ended without a fault and the service still answers).

The report::

    cycles, faults_injected, faults_recovered (also per kind in "faults"),
    unsafe_motions: motion commands (``do ...``, ``calibrate``) the VAL monitor ran after a
        fault took effect, a job ended by an abort, a fault or a refusal, and before the
        ``reset`` that followed; counted from the lines the emulator received. A VAL fault
        counts from the moment the emulator acted on it (garbage sent, link dropped, reply
        held back); a camera or wrench fault, an abort or a refused step from the moment the
        client learnt that the job had ended;
    log_lines_lost: iterations the positioning jobs reported that have no record in the
        service's iteration log (``iterations.jsonl``), plus damaged lines in it;
    partial_files: temporary (``.*.tmp``), empty or unparseable files left in the state and log
        folders after the service stopped;
    rss_growth_mb, fd_growth: this process's resident memory and open file descriptors (from
        /proc; the service, its devices and the emulators all live in it) at the end over their
        value after the first cycles (the warm-up, when caches fill);
    seconds: wall time of the cycles.

``--timing realistic`` runs the emulators on the ``timing`` section's durations (paced lines,
moves that take their motion time, the camera at its frame rate); ideal (default) is as fast as
it goes. Prints JSON (and writes it to --json).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import logging
import os
import random
import shutil
import socket
import struct
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from controller.config import config_from_mapping
from controller.devices import open_devices
from controller.loop.iteration_log import scan_log
from controller.service.client import ServiceClient, ServiceError
from controller.service.service import ITERATION_LOG_NAME, Service
from drivers.core.files import write_json
from drivers.core.timing import TimingConfig

if TYPE_CHECKING:  # the emulators load where a cell is served (served_cell, _inject)
    from sim_backend.emulators.cell import CellEmulators

logger = logging.getLogger(__name__)

FAULT_KINDS = ("val_link_drop", "val_garbage", "val_reply_delay", "val_no_reply",
               "camera_gone", "wrench_error", "client_killed", "abort")
FAULT_RATE = 0.35  # share of cycles that get a fault with --faults
OFFSET_MM = 20.0  # start offsets: uniform in [-OFFSET_MM, OFFSET_MM] per axis
OFFSET_DEG = 20.0
PROGRESS_EVERY = 50  # cycles between progress lines in the log
WARM_UP_CYCLES = 5  # rss and fd growth are measured from the end of this cycle
# The VAL driver's timeouts in the soak (the defaults wait a minute for a move): long enough
# for a move of the realistic cell, short enough that a held-back reply costs seconds.
EXCHANGE_TIMEOUT_S = 1.5
MOVE_TIMEOUT_S = {"ideal": 3.0, "realistic": 8.0}
NO_REPLY_S = 3600.0  # a reply this late is a missing one (the knob is set back first)
JOB_TIMEOUT_S = 300.0  # bounds only: a job that has not ended by then fails the soak
RECOVERY_TIMEOUT_S = 60.0
POLL_S = 0.05
# A fault goes in at a random moment this long into its job (ideal jobs take about 0.4 s).
INJECT_WITHIN_S = {"ideal": 0.2, "realistic": 1.5}
MOTION_COMMANDS = ("do", "calibrate", "execute")  # monitor commands that move the arm or hand


class SoakError(RuntimeError):
    """The soak could not go on (the service stopped answering, a job never ended)."""


def is_motion(line: str) -> bool:
    """Whether a VAL monitor line asks for motion (``do ...`` but ``do set``,
    ``cal[ibrate]``, ``ex[ecute]`` of a program)."""
    words = line.strip().split(None, 2)
    if not words:
        return False
    head = words[0].lower()
    if head == "do":
        return len(words) < 2 or words[1].lower() != "set"
    return ((len(head) >= 3 and "calibrate".startswith(head))
            or (len(head) >= 2 and "execute".startswith(head)))


class MotionLedger:
    """What the VAL monitor ran, against the windows in which no motion is allowed.

    ``open(reason)`` starts a window (a fault took effect, a job was aborted or refused);
    ``close()`` ends them all (the reset that followed was answered). Every motion line the
    emulator runs while a window is open is an unsafe motion. Thread-safe: the emulator's
    serving thread reports lines, the soak's thread opens and closes windows.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._open: set[str] = set()
        self.motions = 0
        self.unsafe: list[dict[str, Any]] = []
        self.val_faults: Counter[str] = Counter()

    def open(self, reason: str) -> None:
        """Forbid motion from now until ``close``."""
        with self._lock:
            self._open.add(reason)

    def close(self) -> None:
        """Allow motion again (after a successful reset)."""
        with self._lock:
            self._open.clear()

    @property
    def is_open(self) -> bool:
        """Whether motion is forbidden now."""
        with self._lock:
            return bool(self._open)

    def on_val(self, event: str, text: str) -> None:
        """The VAL emulator's listener (``ValEmulator.add_listener``)."""
        with self._lock:
            if event == "fault":
                self.val_faults[text] += 1
                self._open.add(f"val_{text}")
            elif event == "command" and is_motion(text):
                self.motions += 1
                if self._open:
                    self.unsafe.append({"line": text.strip()[:80],
                                        "after": sorted(self._open), "time": time.time()})
                    logger.error("unsafe motion %r after %s", text.strip(), sorted(self._open))


@dataclasses.dataclass
class FaultTally:
    """Per fault kind: injected (took effect), recovered, and injected knobs that never acted."""

    injected: Counter[str] = dataclasses.field(default_factory=Counter)
    recovered: Counter[str] = dataclasses.field(default_factory=Counter)
    missed: Counter[str] = dataclasses.field(default_factory=Counter)
    problems: list[str] = dataclasses.field(default_factory=list)

    def as_dict(self) -> dict[str, dict[str, int]]:
        """{kind: {"injected", "recovered", "missed"}} for every kind tried."""
        kinds = sorted(set(self.injected) | set(self.missed))
        return {k: {"injected": self.injected[k], "recovered": self.recovered[k],
                    "missed": self.missed[k]} for k in kinds}


def process_usage() -> tuple[float, int]:
    """(resident memory in MB, open file descriptors) of this process, from /proc."""
    rss_kb = 0
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss_kb = int(line.split()[1])
    return rss_kb / 1024.0, len(os.listdir("/proc/self/fd"))


def partial_files(folders: list[Path]) -> list[str]:
    """Files an interrupted or torn write left: ``.*.tmp``, empty files, JSON or JSON-lines
    files that do not parse (a torn last line included)."""
    found = []
    for folder in folders:
        if not folder.is_dir():
            continue
        for path in sorted(p for p in folder.rglob("*") if p.is_file()):
            if path.name.startswith(".") and path.name.endswith(".tmp"):
                found.append(str(path))
            elif path.stat().st_size == 0:
                found.append(str(path))
            elif path.suffix == ".json" and not _parses(path):
                found.append(str(path))
            elif path.suffix == ".jsonl" and scan_log(path)[1]:
                found.append(str(path))
    return found


def _parses(path: Path) -> bool:
    try:
        json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return False
    return True


def lost_log_lines(log_path: Path, reported: dict[str, int]) -> tuple[int, int]:
    """(iterations reported by positioning jobs that have no record in the log, damaged lines)."""
    if not log_path.exists():
        return sum(reported.values()), 0
    records, damaged = scan_log(log_path)
    logged = Counter(r.get("run_id") for r in records)
    return sum(max(0, n - logged[run]) for run, n in reported.items()), damaged


def soak_config(work: Path, socket_path: Path, emulators: CellEmulators, timing: str,
                **arm_options: Any):
    """The service's config: files under ``work``, the drivers on ``emulators``, short timeouts
    (``arm_options``: more VAL driver options)."""
    sections = emulators.device_sections()
    sections["arm"].update(exchange_timeout_s=EXCHANGE_TIMEOUT_S,
                           move_timeout_s=MOVE_TIMEOUT_S[timing], **arm_options)
    sections["camera"].update(timeout_s=EXCHANGE_TIMEOUT_S)
    return config_from_mapping({
        **sections,
        "scene": {"timing": timing},
        "controller": {"paths": {"state_dir": str(work / "state"),
                                 "log_dir": str(work / "log")}},
        "service": {"socket_path": str(socket_path), "reconnect_initial_s": 0.1,
                    "reconnect_max_s": 1.0, "stop_timeout_s": 5.0},
    }, "<soak>")


@contextlib.contextmanager
def served_cell(timing: str, seed: int) -> Iterator[CellEmulators]:
    """A new simulated cell served over its emulators (VAL and ATI on TCP, MJPEG stream)."""
    from sim_backend.cell.scene_config import SimArmConfig
    from sim_backend.cell.sim_cell import SimCell  # PyBullet only when a cell is built
    from sim_backend.emulators.cell import CellEmulators

    probe = config_from_mapping({"scene": {"timing": timing}})
    with contextlib.ExitStack() as stack:
        cell = stack.enter_context(SimCell(probe.scene, SimArmConfig(), seed=seed))
        yield stack.enter_context(CellEmulators(
            cell, val_tcp_port=0, ati=True, ati_tcp_port=0, mjpeg_port=0,
            timing=TimingConfig() if timing == "realistic" else None))


def cell_opener(emulators: CellEmulators) -> Callable:
    """A device opener for the service: the real drivers on ``emulators``, with the served
    cell as ``CellDevices.cell`` (teach-in and offsets need it)."""

    @contextlib.contextmanager
    def opener(config, seed: int = 0, activate: bool = True):
        with open_devices(config, seed=seed, activate=activate) as devices:
            yield dataclasses.replace(devices, cell=emulators.cell)

    return opener


@contextlib.contextmanager
def running_service(config, opener: Callable) -> Iterator[Service]:
    """The service in a thread of this process; stopped (as by SIGTERM) on exit."""
    service = Service(config, opener=opener)
    errors: list[BaseException] = []

    def run() -> None:
        try:
            service.run()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)
            service.serving.set()

    thread = threading.Thread(target=run, name="soak-service")
    thread.start()
    try:
        if not service.serving.wait(120.0) or errors:
            raise SoakError(f"the service did not start: {errors[0] if errors else 'timeout'}")
        yield service
    finally:
        service.stop()
        thread.join(30.0)
        if thread.is_alive():
            raise SoakError("the service did not stop within 30 s")
    if errors:
        raise SoakError(f"the service failed: {type(errors[0]).__name__}: {errors[0]}")


def kill_client(sock: socket.socket) -> None:
    """Close ``sock`` as a killed process's socket goes (a reset, nothing more sent)."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


class Soak:
    """One soak run; ``run()`` returns the report. See the module docstring.

    fault_rate: the share of cycles that get a fault (with ``faults``); kinds: the fault kinds
    drawn from; reset_after_abort: the client sends ``reset`` after an aborted job before moving
    again (as it must; False makes a client that does not, whose next motion is an unsafe one);
    programs: the VAL driver's program path (``arm.programs``): the grasp's descent runs as a
    program on the emulated controller, stopped by the emulated sensor's output.
    """

    def __init__(self, cycles: int, faults: bool, seed: int, timing: str = "ideal", *,
                 fault_rate: float = FAULT_RATE, kinds: tuple[str, ...] = FAULT_KINDS,
                 reset_after_abort: bool = True, programs: bool = False) -> None:
        if not 0.0 <= fault_rate <= 1.0:
            raise ValueError(f"fault_rate must be within [0, 1], got {fault_rate}")
        if timing not in MOVE_TIMEOUT_S:
            raise ValueError(f"timing must be ideal or realistic, got {timing!r}")
        unknown = [k for k in kinds if k not in FAULT_KINDS]
        if unknown:
            raise ValueError(f"unknown fault kind {unknown[0]!r} (known: {', '.join(FAULT_KINDS)})")
        self.cycles = cycles
        self.faults = faults
        self.timing = timing
        self.kinds = kinds
        self.fault_rate = fault_rate
        self.reset_after_abort = reset_after_abort
        self.programs = programs
        self.rng = random.Random(seed)
        self.seed = seed
        self.ledger = MotionLedger()
        self.tally = FaultTally()
        self.reported_iterations: dict[str, int] = {}
        self.outcomes: Counter[str] = Counter()
        self.emulators: CellEmulators | None = None
        self.socket_path: Path | None = None
        self._client: ServiceClient | None = None
        self._part_pose: tuple[float, float, float] | None = None
        # What the emulators had counted when the knobs were last set back.
        self._val_faults_before: Counter[str] = Counter()
        self._camera_refused = 0
        self._ati_replies = 0

    # -- the whole run ---------------------------------------------------------------------
    def run(self) -> dict[str, Any]:
        """Set up, teach and train, run the cycles, stop, and report."""
        work = Path(tempfile.mkdtemp(prefix="fp-soak-", dir="/tmp"))  # short AF_UNIX path
        try:
            return self._run(work)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _run(self, work: Path) -> dict[str, Any]:
        self.socket_path = work / "fp.sock"
        with served_cell(self.timing, self.seed) as emulators:
            self.emulators = emulators
            assert emulators.val is not None
            emulators.val.add_listener(self.ledger.on_val)
            config = soak_config(work, self.socket_path, emulators, self.timing,
                                 programs=self.programs)
            with running_service(config, cell_opener(emulators)), \
                    ServiceClient(self.socket_path, timeout_s=JOB_TIMEOUT_S) as client:
                self._client = client
                self._prepare()
                usage0, t0 = process_usage(), time.perf_counter()
                for cycle in range(self.cycles):
                    self._cycle()
                    if cycle + 1 == min(WARM_UP_CYCLES, self.cycles):
                        usage0 = process_usage()
                    if (cycle + 1) % PROGRESS_EVERY == 0:
                        logger.info("soak: %d of %d cycles, %d faults injected, %d recovered, "
                                    "%d unsafe motions", cycle + 1, self.cycles,
                                    sum(self.tally.injected.values()),
                                    sum(self.tally.recovered.values()), len(self.ledger.unsafe))
                seconds = time.perf_counter() - t0
                usage1 = process_usage()
                self._client = None
        lost, damaged = lost_log_lines(work / "log" / ITERATION_LOG_NAME,
                                       self.reported_iterations)
        partial = partial_files([work / "state", work / "log"])
        tally = self.tally
        return {
            "cycles": self.cycles,
            "faults_injected": sum(tally.injected.values()),
            "faults_recovered": sum(tally.recovered.values()),
            "unsafe_motions": len(self.ledger.unsafe),
            "log_lines_lost": lost + damaged,
            "partial_files": len(partial),
            "rss_growth_mb": round(usage1[0] - usage0[0], 2),
            "fd_growth": usage1[1] - usage0[1],
            "seconds": round(seconds, 1),
            "faults": tally.as_dict(),
            "val_faults_seen": dict(self.ledger.val_faults),
            "outcomes": dict(self.outcomes),
            "motions": self.ledger.motions,
            "positioning_runs": len(self.reported_iterations),
            "iterations_reported": sum(self.reported_iterations.values()),
            "unsafe": self.ledger.unsafe[:20],
            "partial": partial[:20],
            "problems": tally.problems[:50],
            "rss_mb": round(usage1[0], 1), "fds": usage1[1],
            "timing": self.timing, "seed": self.seed,
        }

    def _prepare(self) -> None:
        """Teach at the part's pose, acquire both grids, train (once, before the cycles)."""
        client = self._require_client()
        for cmd, args in (("teach", {"auto": True}), ("acquire", {"set": "nn1"}),
                          ("acquire", {"set": "nn2"}), ("train", {})):
            job = client.call(cmd, timeout_s=JOB_TIMEOUT_S, wait=True, **args)["job"]
            if job["outcome"] != "done":
                raise SoakError(f"{cmd} ended {job['outcome']}: {job['reason']}")
        assert self.emulators is not None
        self._part_pose = self.emulators.cell.object_pose()

    def _require_client(self) -> ServiceClient:
        if self._client is None:
            raise SoakError("the soak is not running")
        return self._client

    # -- one cycle -------------------------------------------------------------------------
    def _cycle(self) -> None:
        assert self.emulators is not None and self._part_pose is not None
        self.emulators.cell.place_object(*self._part_pose)  # put back (released if held)
        kind = (self.rng.choice(self.kinds)
                if self.faults and self.rng.random() < self.fault_rate else None)
        stage = self.rng.choice(("position", "grasp"))
        if kind == "camera_gone":
            stage = "position"  # the grasp does not look
        elif kind == "wrench_error":
            stage = "grasp"  # positioning does not feel
        offset = [self.rng.uniform(-OFFSET_MM, OFFSET_MM), self.rng.uniform(-OFFSET_MM, OFFSET_MM),
                  self.rng.uniform(-OFFSET_DEG, OFFSET_DEG)]
        job = self._job("position", {"offset": offset}, kind if stage == "position" else None)
        if job is None or job["outcome"] != "done":
            return
        self._job("grasp", {}, kind if stage == "grasp" else None)

    def _job(self, cmd: str, args: dict[str, Any], fault: str | None) -> dict[str, Any] | None:
        """Run one job, with ``fault`` injected while it runs; recover if it did not end well.
        Returns the ended job (None when a half-sent request started none)."""
        before = self._last_job_id()
        if fault == "client_killed" and self.rng.random() < 0.5:
            self._half_request_killed(cmd, args)
            return None
        killed = fault == "client_killed"
        sock = self._start_job_from_killable_client(cmd, args) if killed else None
        if not killed:
            self._require_client().call(cmd, **args)
        if fault is not None:
            self._inject(fault, sock)
        job = self._wait_job_end(before)
        self.outcomes[f"{cmd}:{job['outcome']}"] += 1
        result = job.get("result") or {}
        if cmd == "position" and "run_id" in result and "iterations" in result:
            self.reported_iterations[result["run_id"]] = result["iterations"]
        took_effect = self._took_effect(fault, job) if fault is not None else False
        self._clear_knobs()
        if fault is not None:
            (self.tally.injected if took_effect else self.tally.missed)[fault] += 1
        needs_reset = job["outcome"] != "done" or self._state() == "fault" or self.ledger.is_open
        if needs_reset:
            self.ledger.open(f"{cmd}:{job['outcome']}")
            if job["outcome"] == "aborted" and not self.reset_after_abort:
                recovered = self._state() == "idle"
            else:
                recovered = self._reset()
        else:
            recovered = self._state() == "idle"
        if fault is not None and took_effect:
            if recovered and (fault != "client_killed" or job["outcome"] == "done"):
                self.tally.recovered[fault] += 1
            else:
                self.tally.problems.append(
                    f"{fault} during {cmd}: job {job['outcome']} ({job['reason']}), "
                    f"state {self._state()}")
        elif not recovered:
            self.tally.problems.append(f"{cmd} without a fault left the service in "
                                       f"{self._state()}: {job['reason']}")
        return job

    # -- injecting -------------------------------------------------------------------------
    def _inject(self, fault: str, sock: socket.socket | None) -> None:
        """Wait a random moment into the running job, then inject ``fault``."""
        from sim_backend.emulators.val.server import DEFAULT_GARBAGE, ValFaults

        emulators = self.emulators
        assert emulators is not None and emulators.val is not None
        assert emulators.mjpeg is not None and emulators.ati is not None
        time.sleep(self.rng.uniform(0.0, INJECT_WITHIN_S[self.timing]))
        if fault == "val_link_drop":
            emulators.val.set_faults(ValFaults(drop_link_after_lines=self.rng.randint(0, 2)))
        elif fault == "val_garbage":
            emulators.val.set_faults(ValFaults(garbage=DEFAULT_GARBAGE))
        elif fault == "val_reply_delay":
            emulators.val.set_faults(ValFaults(reply_delay_s=MOVE_TIMEOUT_S[self.timing] + 1.0))
        elif fault == "val_no_reply":
            emulators.val.set_faults(ValFaults(reply_delay_s=NO_REPLY_S))
        elif fault == "camera_gone":
            self._camera_refused = emulators.mjpeg.refused
            emulators.mjpeg.set_gone(True)
        elif fault == "wrench_error":
            self._ati_replies = emulators.ati.replies_sent
            emulators.ati.faults.status_word = 0x8001
        elif fault == "client_killed":
            assert sock is not None
            kill_client(sock)
        elif fault == "abort":
            with ServiceClient(self.socket_path, timeout_s=30.0) as operator:
                with contextlib.suppress(ServiceError):  # refused: the job had ended
                    operator.call("abort")

    def _took_effect(self, fault: str, job: dict[str, Any]) -> bool:
        """Whether the injected ``fault`` acted (see the module docstring)."""
        emulators = self.emulators
        assert emulators is not None and emulators.mjpeg is not None and emulators.ati is not None
        name = fault.removeprefix("val_")
        if fault in ("val_reply_delay", "val_no_reply"):
            name = "reply_delay"
        if fault.startswith("val_"):
            return self.ledger.val_faults[name] > self._val_faults_before.get(name, 0)
        if fault == "camera_gone":
            return emulators.mjpeg.refused > self._camera_refused
        if fault == "wrench_error":
            return emulators.ati.replies_sent > self._ati_replies and job["outcome"] != "done"
        if fault == "abort":
            return job["outcome"] == "aborted"
        return True  # client_killed: its job ran

    def _clear_knobs(self) -> None:
        """The operator removes every cause (knobs back to normal)."""
        from sim_backend.emulators.val.server import ValFaults

        emulators = self.emulators
        assert emulators is not None and emulators.val is not None
        assert emulators.mjpeg is not None and emulators.ati is not None
        emulators.val.set_faults(ValFaults())
        emulators.mjpeg.set_gone(False)
        emulators.ati.faults.status_word = 0
        self._val_faults_before = Counter(self.ledger.val_faults)

    def _start_job_from_killable_client(self, cmd: str, args: dict[str, Any]) -> socket.socket:
        """Send a job request with ``wait`` from a separate connection (to be killed)."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(str(self.socket_path))
        sock.sendall(json.dumps({"cmd": cmd, "args": {**args, "wait": True}}).encode() + b"\n")
        return sock

    def _half_request_killed(self, cmd: str, args: dict[str, Any]) -> None:
        """A client killed while sending its request: half a line, then a reset connection.
        The service must start nothing and keep answering."""
        line = json.dumps({"cmd": cmd, "args": args}).encode()
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(str(self.socket_path))
        sock.sendall(line[:self.rng.randint(1, len(line) - 1)])
        time.sleep(self.rng.uniform(0.0, 0.05))
        kill_client(sock)
        self.tally.injected["client_killed"] += 1
        if self._state() == "idle":
            self.tally.recovered["client_killed"] += 1
        else:
            self.tally.problems.append(f"half request killed: state {self._state()}")

    # -- the client side -------------------------------------------------------------------
    def _status(self) -> dict[str, Any]:
        return self._require_client().call("status")

    def _state(self) -> str:
        return self._status()["state"]

    def _last_job_id(self) -> int:
        last = self._status().get("last_job")
        return last["id"] if last else 0

    def _wait_job_end(self, before: int) -> dict[str, Any]:
        """The first job after ``before`` once it has ended."""
        deadline = time.monotonic() + JOB_TIMEOUT_S
        while time.monotonic() < deadline:
            status = self._status()
            last = status.get("last_job")
            if last and last["id"] > before and "outcome" in last and status.get("job") is None:
                return last
            time.sleep(POLL_S)
        raise SoakError(f"no job ended within {JOB_TIMEOUT_S:.0f} s")

    def _reset(self) -> bool:
        """Send ``reset`` until the service is idle; close the motion windows then."""
        client = self._require_client()
        deadline = time.monotonic() + RECOVERY_TIMEOUT_S
        while time.monotonic() < deadline:
            try:
                state = client.call("reset")["state"]
            except ServiceError as exc:
                logger.info("reset refused (%s): %s", exc.code, exc)
                time.sleep(0.5)
                continue
            if state == "idle":
                self.ledger.close()
                return True
            time.sleep(POLL_S)
        return False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--cycles``, ``--faults``, ``--seed``, ``--timing`` and ``--json``."""
    parser.add_argument("--cycles", type=_positive_int, default=100,
                        help="position + grasp cycles (default 100)")
    parser.add_argument("--faults", action="store_true", help="inject faults at random")
    parser.add_argument("--seed", type=int, default=0, help="seed of the faults and offsets")
    parser.add_argument("--timing", choices=("ideal", "realistic"), default="ideal",
                        help="the emulated cell's timing (default ideal: as fast as it goes)")
    parser.add_argument("--programs", action="store_true",
                        help="the VAL driver's program path (arm.programs): the grasp's "
                             "descent, close and lift as one program on the emulated "
                             "controller")
    parser.add_argument("--json", metavar="OUT", help="also write the report here")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def run(args: argparse.Namespace) -> int:
    """Run the soak and print the JSON report (also to ``--json``); 1 when an invariant fails
    (recovered != injected, an unsafe motion, a lost log line, a partial file)."""
    report = Soak(args.cycles, args.faults, args.seed, args.timing,
                  programs=args.programs).run()
    write_json(args.json, report)
    ok = (report["faults_recovered"] == report["faults_injected"]
          and report["unsafe_motions"] == 0 and report["log_lines_lost"] == 0
          and report["partial_files"] == 0)
    return 0 if ok else 1
