"""The controller service: one process owning the cell's devices, commanded over the control socket.

Threads and what they do:

- the control loop (the thread calling ``run``; the main thread under ``finepos serve``) starts
  everything, then every tick carries out a pending config reload, retries the devices with
  backoff while in fault, reads the arm's pose while idle (noticing a lost link), and pings the
  systemd watchdog: only while it runs and no arm command has hung beyond
  ``service.stall_timeout_s``. On stop it aborts the job, then closes the server, the devices and
  the iteration log, in that order;
- the idle poll and each reconnection attempt run in a short-lived thread of their own, which
  the control loop waits for unless a stop comes first: a stop never waits on a silent link;
- the worker: one thread per job, one job at a time, holding the device lock;
- the server's accept and connection threads, which call ``handle``.

``stop`` and ``request_reload`` only set events, so signal handlers may call them. Locks are
taken in one order: the device lock before the state lock, never the other way round.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from calibration_free.errors import DatasetError
from controller.config import cell_part, with_part
from controller.devices import open_devices
from controller.fine_positioner import FinePositioner
from controller.loop.iteration_log import IterationLog
from controller.service.backoff import Backoff
from controller.service.cell_connection import CellConnection, DeviceOpener
from controller.service.commands import JOB_COMMANDS
from controller.service.config_reload import restart_only_changes
from controller.service.events import EventHub, Subscription
from controller.service.jobs import (
    BODIES,
    Job,
    JobContext,
    JobFailed,
    classify,
    is_disk_full,
)
from controller.service.listeners import read_token
from controller.service.model_slot import DEFAULT_SYSTEM, PartModels
from controller.service.peer import PeerPolicy
from controller.service.protocol import EncodedResult, Request, RequestError
from controller.service.sd_notify import Notifier
from controller.service.server import ControlServer
from controller.service.snapshot import StatusSnapshot
from controller.service.states import JOB_STATES, State, StateMachine
from controller.service.watchdog import WatchdogPinger
from controller.teach.state_folder import StateFolder
from controller.teach.state_lock import locked_state_folder
from drivers.core.errors import ConfigError, FineposError
from drivers.core.files import has_room, remove_stale_temp_files
from drivers.core.typed_config import to_mapping
from drivers.interfaces import Lifecycle

logger = logging.getLogger(__name__)

ITERATION_LOG_NAME = "iterations.jsonl"
TICK_S = 0.5  # longest sleep of the control loop (it wakes at once for stop, reload, job end)
# What an abort answer tells the operator when the arm did not acknowledge the halt.
PENDANT_STOP = ("the arm's controller did not acknowledge a halt: if the arm may be moving, "
                "press the stop button on the teach pendant")
_RECORDING_NAME = re.compile(r"job-(\d{1,9})-\w+\.mcap")  # what _job_recording writes
_REFUSAL_CODES = {State.STARTING: "not_ready", State.FAULT: "fault", State.STOPPING: "stopping"}


class Service:
    """See the module docstring. ``reload_config`` re-reads the config file (None: no file, so
    a reload keeps the config and reloads the model only)."""

    def __init__(self, config, *, socket_path: str | Path | None = None,
                 opener: DeviceOpener = open_devices, notifier: Notifier | None = None,
                 reload_config: Callable[[], Any] | None = None) -> None:
        self.config = config
        self.socket_path = Path(socket_path or config.service.socket_path)
        self.serving = threading.Event()
        self._reload_config = reload_config
        self._notifier = notifier or Notifier({})
        self._machine = StateMachine(self._on_transition)
        self._cell = CellConnection(config, opener)
        self._hub = EventHub()
        self._models = PartModels()
        self._part = cell_part(config)  # the part of the positioner in use (self._fp)
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._reload = threading.Event()
        self._device_lock = threading.Lock()
        self._started_at = time.time()
        self._log: IterationLog | None = None
        self._server: ControlServer | None = None
        self._live_view = None
        self._metrics_server = None
        self._fp: FinePositioner | None = None
        self._job: Job | None = None
        self._job_thread: threading.Thread | None = None
        self._next_job_id = 1
        self._last_job: dict[str, Any] | None = None
        self._last_iteration: dict[str, Any] | None = None
        self._last_reload: dict[str, Any] | None = None
        self._status = StatusSnapshot(self._build_status, self._status_key)
        self._fault: dict[str, Any] | None = None
        self._backoff = Backoff(config.service.reconnect_initial_s, config.service.reconnect_max_s)
        self._next_reconnect_s = 0.0
        self._reconnected = False
        self._stop_deadline_s = time.monotonic() + config.service.stop_timeout_s

    # -- lifecycle -----------------------------------------------------------------------------
    def stop(self) -> None:
        """Ask the service to shut down (safe from a signal handler)."""
        self._stop.set()
        self._wake.set()

    def request_reload(self) -> None:
        """Ask for the config and model to be reloaded (safe from a signal handler)."""
        self._reload.set()
        self._wake.set()

    def run(self) -> int:
        """Serve until ``stop``; returns the exit status (0)."""
        cfg = self.config
        logger.info("resolved config (%s): %s", cfg.source,
                    json.dumps(to_mapping(cfg), sort_keys=True))
        policy = PeerPolicy.from_config(cfg.service.allowed_users, cfg.service.allowed_groups)
        token = read_token(cfg.service.tcp.token_file) if cfg.service.tcp is not None else None
        log_path = Path(cfg.controller.paths.log_dir) / ITERATION_LOG_NAME
        with contextlib.ExitStack() as stack:
            # before anything is written: a second service or a CLI writer on this state
            # folder is refused, naming this process
            stack.enter_context(locked_state_folder(
                cfg.controller.paths.state_dir, f"finepos serve on {self.socket_path}"))
            self._remove_stale_temp_files()
            self._next_job_id = _first_free_job_id(cfg.service.record_dir)
            self._log = stack.enter_context(IterationLog(log_path))
            self._log.subscribe(self._on_record)
            logger.info("iteration records go to %s", log_path)
            stack.callback(self._cell.close)
            self._live_view = self._start_live_view(stack, token)
            self._start_metrics(stack, token)
            self._server = stack.enter_context(
                ControlServer(self.socket_path, cfg.service, policy, self, token))
            stack.callback(lambda: self._server.close(self._stop_budget_s(0.6)))
            stack.callback(self._stop_job)
            self._fp = FinePositioner(None, with_part(cfg, self._part), log=self._log,
                                      state_dir=self._folder().part_dir(self._part))
            self._open_devices()
            self._start_up_check()
            self.serving.set()
            state, _, reason = self._machine.snapshot()
            self._notifier.ready(f"{state.value}: {reason}")
            self._control_loop()
            self._stop_deadline_s = time.monotonic() + cfg.service.stop_timeout_s
            with self._machine.lock:
                self._machine.transition(State.STOPPING, "stop requested")
            self._notifier.stopping("stopping")
        logger.info("stopped")
        return 0

    def job_still_running(self) -> bool:
        """Whether a job thread outlived the shutdown (a ``train`` cannot be interrupted): the
        caller must then end the process without running library finalizers under it."""
        thread = self._job_thread
        return thread is not None and thread.is_alive()

    def _stop_budget_s(self, fraction: float) -> float:
        """``fraction`` of the time left until the shutdown deadline (service.stop_timeout_s)."""
        return max(0.0, (self._stop_deadline_s - time.monotonic()) * fraction)

    def _remove_stale_temp_files(self) -> None:
        """Remove what interrupted atomic writes (a kill during train or acquire) left behind."""
        folders = [*self._folder().folders(), Path(self.config.controller.paths.log_dir)]
        for folder in folders:
            remove_stale_temp_files(folder)

    def _open_devices(self) -> None:
        try:
            self._cell.open()
        except (FineposError, OSError) as exc:
            with self._machine.lock:
                self._enter_fault(f"cannot open the devices: {type(exc).__name__}: {exc}")
            return
        with self._machine.lock:
            self._attach_devices()
            self._machine.transition(State.IDLE, "devices open")

    def _start_up_check(self) -> None:
        """``service.self_check_at_start``: look at the taught pose (the arm moves there) and
        go to fault when the camera or the part has changed since teach-in, or an acquired
        set it compares with is damaged, instead of positioning on a wrong mapping. Skipped,
        with a log line, when nothing is taught or trained yet or the devices did not open."""
        if not self.config.service.self_check_at_start:
            return
        with self._machine.lock:
            fp = self._fp if self._machine.state is State.IDLE else None
        if fp is None or fp.devices is None:
            return
        from controller.calibration.self_check import run_self_check

        try:
            with self._device_lock:
                result = run_self_check(fp, DEFAULT_SYSTEM)
        except DatasetError as exc:  # an acquired set damaged: the check cannot vouch
            with self._machine.lock:
                self._enter_fault(f"self-check at start: {exc}", "self_check")
            return
        except (FineposError, OSError) as exc:
            logger.warning("start-up self-check skipped: %s", exc)
            return
        logger.info("start-up self-check: %s", result.message)
        if result.fired:
            with self._machine.lock:
                self._enter_fault(f"self-check at start: {result.message}", "self_check")

    def _folder(self, config=None) -> StateFolder:
        """The state folder (``config``: default the service's), one sub-folder per part."""
        config = config or self.config
        return StateFolder(config.controller.paths.state_dir, cell_part(config), config.parts)

    def _positioner(self, part: str, config=None) -> FinePositioner:
        """A FinePositioner for ``part`` on the opened devices (``config``: default the
        service's), with the config set up for that part and the part's state folder."""
        config = config or self.config
        return FinePositioner(self._cell.job_devices() if self._cell.is_open else None,
                              with_part(config, part), log=self._log,
                              state_dir=self._folder(config).part_dir(part))

    def _attach_devices(self) -> None:
        """Give the positioner the opened devices and load the model of every taught part
        found in the state folder."""
        self._fp = self._positioner(self._part)
        for part in self._folder().taught():
            fp = self._fp if part == self._part else self._positioner(part)
            slot = self._models.slot(part)
            if slot.model is None and fp.model_path(DEFAULT_SYSTEM).exists():
                try:
                    slot.load(fp, DEFAULT_SYSTEM)
                except (FineposError, OSError) as exc:
                    logger.warning("no %s model in use: %s", part, exc)

    def _stop_job(self) -> None:
        """Abort the running job and wait up to service.stop_timeout_s for it to end."""
        with self._machine.lock:
            job, thread = self._job, self._job_thread
        if job is None or thread is None:
            return
        self._abort_job(job, self._stop_budget_s(0.3))
        thread.join(self._stop_budget_s(0.5))
        if thread.is_alive():
            logger.error("job %d (%s) still running at shutdown; closing the devices under it",
                         job.id, job.kind)
            job.finish("aborted", "the service stopped while the job was still running")

    # -- the control loop ----------------------------------------------------------------------
    def _control_loop(self) -> None:
        watchdog = WatchdogPinger(self._notifier)
        next_poll_s = time.monotonic() + self.config.service.idle_poll_s
        while not self._stop.is_set():
            now_s = time.monotonic()
            cfg = self.config.service
            try:
                if self._reload.is_set():
                    self._reload_if_idle()
                self._reconnect_if_due(now_s)
                if cfg.idle_poll_s > 0 and now_s >= next_poll_s:
                    next_poll_s = now_s + cfg.idle_poll_s
                    if self._machine.state is State.IDLE:
                        self._unless_stopped(self._poll_arm, "idle-poll")
            except Exception as exc:  # the service never exits on a device or file error
                logger.exception("control loop")
                with self._machine.lock:
                    if self._machine.state is State.IDLE:
                        self._enter_fault(f"control loop: {type(exc).__name__}: {exc}")
            busy_s = self._cell.arm.busy_for_s() if self._cell.arm is not None else 0.0
            watchdog.tick(now_s, busy_s, cfg.stall_timeout_s)
            self._wake.wait(min(s for s in (TICK_S, watchdog.interval_s, cfg.idle_poll_s) if s))
            self._wake.clear()

    def _unless_stopped(self, work: Callable[[], None], name: str) -> None:
        """Run ``work`` (device exchanges: the idle poll, a reconnection) in its own thread and
        wait until it ends or a stop is requested, so a stop never waits on a device: an
        exchange still running then is abandoned, and ends when the shutdown closes the devices
        under it (or at its own timeout). Re-raises what ``work`` raised."""
        done = threading.Event()
        errors: list[Exception] = []

        def run() -> None:
            try:
                work()
            except Exception as exc:  # noqa: BLE001 - re-raised in the control loop below
                errors.append(exc)
            finally:
                done.set()
                self._wake.set()

        threading.Thread(target=run, name=name, daemon=True).start()
        while not done.is_set() and not self._stop.is_set():
            self._wake.wait()
            self._wake.clear()
        if not done.is_set():
            logger.warning("stop requested during the %s: its device exchange is abandoned",
                           name)
        elif errors:
            raise errors[0]

    def _poll_arm(self) -> None:
        """While idle, read the pose: a lost link shows up without waiting for a command."""
        if self._machine.state is not State.IDLE or not self._device_lock.acquire(blocking=False):
            return
        try:
            if self._machine.state is State.IDLE and self._cell.arm is not None:
                self._cell.arm.pose()
        except (FineposError, OSError) as exc:
            with self._machine.lock:
                if self._machine.state is State.IDLE:
                    self._enter_fault(f"arm check while idle: {type(exc).__name__}: {exc}")
        finally:
            self._device_lock.release()

    def _reconnect_if_due(self, now_s: float) -> None:
        with self._machine.lock:
            if self._machine.state is not State.FAULT or now_s < self._next_reconnect_s:
                return
            if self._fault is not None and self._fault.get("code") == "disk_full":
                self._resume_if_space(now_s)
                return
            if self._fault is not None and self._fault.get("code") == "self_check":
                return  # the devices are fine: the cell needs a new teach-in (after a reset)
            if self._reconnected:
                return
        self._unless_stopped(self._reconnect, "reconnect")

    def _reconnect(self) -> None:
        """One reconnection attempt (in fault, when due): on failure the next is scheduled."""
        with self._device_lock:
            try:
                self._cell.recover()
            except (FineposError, OSError) as exc:
                with self._machine.lock:
                    delay_s = self._backoff.next_delay_s()
                    self._next_reconnect_s = time.monotonic() + delay_s
                message = (f"reconnect attempt {self._backoff.attempts} failed: "
                           f"{type(exc).__name__}: {exc}; next in {delay_s:.1f} s")
                logger.warning("%s", message)
                self._notifier.status(f"fault: {message}")
                return
            with self._machine.lock:
                self._reconnected = True
                if self._fp is None or self._fp.devices is None:
                    self._attach_devices()
        logger.info("devices reconnected; send reset to resume")
        self._notifier.status("fault: devices reconnected; send reset to resume")

    def _resume_if_space(self, now_s: float) -> None:
        """In a ``disk_full`` fault: go idle once the log and state folders have room again (lock
        held)."""
        paths = self.config.controller.paths
        if all(has_room(folder) for folder in (paths.log_dir, paths.state_dir)):
            self._fault = None
            self._machine.transition(State.IDLE, "disk space is back: the iteration log "
                                                 "writes again")
        else:
            self._next_reconnect_s = now_s + self._backoff.next_delay_s()

    def _enter_fault(self, reason: str, code: str = "device") -> None:
        """Go to (or stay in) fault for ``reason``; call with the state lock held.

        ``code``: ``device`` (a reset reconnects the devices), ``disk_full`` (the iteration
        log, a dataset or a model did not fit; the service goes idle by itself once the log and
        state folders have room again) or ``self_check`` (the start-up self-check fired: the
        cell needs a new teach-in; a reset lets the operator start it).
        """
        self._fault = {"code": code, "reason": reason, "since": time.time()}
        self._hub.publish({"event": "fault", "code": code, "reason": reason,
                           "devices": self._devices_not_active(), "time": time.time()})
        cfg = self.config.service
        self._backoff = Backoff(cfg.reconnect_initial_s, cfg.reconnect_max_s)
        self._next_reconnect_s = time.monotonic() + self._backoff.next_delay_s()
        self._reconnected = False
        if self._machine.state is State.FAULT:
            logger.error("still in fault: %s", reason)
            self._notifier.status(f"fault: {reason}")
        else:
            self._machine.transition(State.FAULT, reason)

    def _devices_not_active(self) -> dict[str, str]:
        """The devices that are not active, with their state (``cell: not_open`` when the
        devices are not open)."""
        try:
            named = self._cell.named()
        except FineposError:  # not open (or closed meanwhile by a job changing parts)
            return {"cell": "not_open"}
        return {name: device.state.value for name, device in named
                if device.state is not Lifecycle.ACTIVE}

    # -- config reload (SIGHUP) ----------------------------------------------------------------
    def _reload_if_idle(self) -> None:
        with self._machine.lock:
            if self._job is not None or self._machine.state in (State.STARTING, State.STOPPING):
                return  # retried once the job has ended
            self._reload.clear()
            old, part = self.config, self._part
        try:
            new = self._reload_config() if self._reload_config is not None else old
            changed = restart_only_changes(old, new)
            if changed:
                raise ConfigError(f"{', '.join(changed)} changed: that needs a restart "
                                  "(systemctl restart finepos)")
            policy = PeerPolicy.from_config(new.service.allowed_users, new.service.allowed_groups)
            fp = self._positioner(part, new)
            models = self._load_models(self._folder(new).taught(), None, new)
        except Exception as exc:  # noqa: BLE001 - whatever the file holds, the old config stays
            detail = str(exc) if isinstance(exc, (FineposError, OSError)) else \
                f"{type(exc).__name__}: {exc}"
            self._reloaded(False, f"refused, the old config and model stay: {detail}")
            return
        with self._machine.lock:
            if self._job is not None:  # a job started meanwhile: apply after it
                self._reload.set()
                return
            self.config = new
            self._fp = fp
            for kind, (model, path) in models.items():
                self._models.slot(kind).set(model, path)
            if self._cell.arm is not None:
                self._cell.arm.inner.limits = new.safety
            if self._server is not None:
                self._server.policy = policy
        loaded = ", ".join(f"{kind} {model.system}" for kind, (model, _) in models.items())
        self._reloaded(True, f"config {new.source} and models {loaded or '(none)'} reloaded")

    def _reloaded(self, ok: bool, message: str) -> None:
        self._last_reload = {"ok": ok, "message": message, "at": time.time()}
        (logger.info if ok else logger.error)("reload: %s", message)
        state, _, reason = self._machine.snapshot()
        self._notifier.status(f"{state.value}: {reason}; reload {message}")

    # -- events --------------------------------------------------------------------------------
    def _on_transition(self, old: State, new: State, reason: str) -> None:
        (logger.error if new is State.FAULT else logger.info)(
            "state %s -> %s: %s", old.value, new.value, reason)
        self._notifier.status(f"{new.value}: {reason}")
        self._hub.publish({"event": "state", "state": new.value, "previous": old.value,
                           "reason": reason, "time": time.time()})

    def _on_job_end(self, job: Job) -> None:
        """A job ended (called before anyone waiting for it wakes)."""
        self._hub.publish({"event": "job", "job": job.report(), "time": time.time()})

    def _on_record(self, record: dict[str, Any]) -> None:
        self._last_iteration = record
        self._hub.publish({"event": "iteration", "record": record})

    # -- requests (called from connection threads) ---------------------------------------------
    def subscribe(self) -> Subscription:
        """A new subscription to the event stream (state changes, iteration records)."""
        return self._hub.subscribe()

    def handle(self, request: Request) -> dict[str, Any]:
        """The result of one validated request: a job command starts a job, the rest answer now.

        A job command with ``wait`` returns once the job ended, else as soon as it started.

        Raises:
            RequestError: refused in this state (``busy``, ``fault``, ``not_ready``, ``stopping``),
                arguments this cell cannot serve (``bad_request``), or a failed reset or reload.
        """
        if request.cmd in JOB_COMMANDS:
            return self._start_job(request.cmd, request.args)
        handlers: dict[str, Callable[[], dict[str, Any]]] = {
            "status": self.status,
            "abort": self.abort,
            "reset": self.reset,
            "reload": lambda: self.reload_model(request.args["system"], request.args["part"]),
        }
        if request.cmd not in handlers:
            raise RequestError("bad_request", f"{request.cmd} is not a command on this connection")
        return handlers[request.cmd]()

    def status(self) -> EncodedResult:
        """The ``status`` answer (encoded JSON object): state, job, last pose, last iteration,
        model, fault, config; served from a snapshot (``controller.service.snapshot``)."""
        return self._status.get()

    def _status_key(self) -> tuple:
        """The objects the status answer is built from (a new object: rebuild it)."""
        job = self._job
        arm = self._cell.arm
        return (self._machine.snapshot(), job, job is not None and job.done.is_set(),
                self._last_job, arm.last_pose() if arm is not None else None,
                self._last_iteration, self._fault, self._reconnected, self._backoff.attempts,
                self._models.marker(), self._part, self._last_reload, self.config, self._log,
                self._server.client_count if self._server is not None else 0)

    def _build_status(self) -> dict[str, Any]:
        with self._machine.lock:
            state, since, reason = self._machine.snapshot()
            seen = self._cell.arm.last_pose() if self._cell.arm is not None else None
            fault = None
            if self._fault is not None:
                fault = {**self._fault, "devices": self._cell.not_active(),
                         "reconnected": self._reconnected,
                         "reconnect_attempts": self._backoff.attempts}
            return {
                "state": state.value, "since": since, "reason": reason, "pid": os.getpid(),
                "uptime_s": time.time() - self._started_at,
                "job": self._job.report() if self._job is not None else None,
                "last_job": self._last_job,
                "pose": {**seen[0].as_dict(), "at": seen[1]} if seen is not None else None,
                "last_iteration": self._last_iteration,
                "part": self._part,
                "model": self._models.info(self._part),
                "parts": self._parts_status(),
                "fault": fault,
                "config": {"source": self.config.source, "last_reload": self._last_reload},
                "iteration_log": str(self._log.path) if self._log is not None else None,
                "clients": self._server.client_count if self._server is not None else 0,
            }

    def _parts_status(self) -> dict[str, Any]:
        """Per taught part: its state folder and its model in use (None: none loaded)."""
        try:
            taught = self._folder().taught()
        except OSError as exc:  # an unreadable state folder: reported, never raised
            return {"error": f"{type(exc).__name__}: {exc}"}
        return {kind: {"state_dir": str(folder), "model": self._models.info(kind)}
                for kind, folder in taught.items()}

    def _refusal(self, state: State) -> RequestError:
        if state is State.FAULT:
            reason = self._fault["reason"] if self._fault else "fault"
            return RequestError("fault", f"in fault ({reason}); motion is refused until a "
                                         "reset succeeds")
        if state in _REFUSAL_CODES:
            return RequestError(_REFUSAL_CODES[state], f"the service is {state.value}")
        job = self._job
        return RequestError("busy", f"busy: job {job.id} ({job.kind}) is running" if job else
                            f"busy: {state.value}")

    def _check_job_args(self, kind: str, args: dict[str, Any]) -> None:
        simulated = self._cell.cell is not None
        if kind == "teach" and args["auto"] and not simulated:
            raise RequestError("bad_request", "teach auto needs the simulated cell")
        if kind == "position" and args["offset"] is not None and not simulated:
            raise RequestError("bad_request", "offset places the simulated arm; on a real cell "
                                              "the loop starts where the arm is")

    def _job_part(self, kind: str, requested: str | None) -> str:
        """The part a job works on: ``requested``; else for ``teach`` the cell's (the simulated
        table's, or controller.part), for the others the one taught (the cell's when none is).
        Raises RequestError ``bad_request`` for a part the config does not know, or when
        several parts are taught and none is named."""
        cell = self._cell.cell
        default = cell.object_kind if cell is not None else self.config.controller.part
        try:
            if kind == "teach":
                return self.config.parts.check(requested or default)
            return self._folder().resolve(requested, default)
        except ConfigError as exc:
            raise RequestError("bad_request", str(exc)) from exc

    def _start_job(self, kind: str, args: dict[str, Any]) -> dict[str, Any]:
        with self._machine.lock:
            state = self._machine.state
            if state is not State.IDLE:
                raise self._refusal(state)
            self._check_job_args(kind, args)
            args = {**args, "part": self._job_part(kind, args["part"])}
            job = Job(self._next_job_id, kind, args, on_end=self._on_job_end)
            self._next_job_id += 1
            assert self._cell.arm is not None
            self._cell.arm.resume()
            self._job = job
            self._machine.transition(JOB_STATES[kind], f"job {job.id}: {kind}")
            self._job_thread = threading.Thread(target=self._run_job, args=(job,),
                                                name=f"job-{job.id}-{kind}", daemon=True)
            self._job_thread.start()
        if args["wait"]:
            job.done.wait()
        return {"job": job.report()}

    def _start_live_view(self, stack: contextlib.ExitStack, token: str | None):
        """With ``service.live``: every job's looks, poses, readings and records served to
        Foxglove over its WebSocket protocol (closed with the service); None otherwise."""
        cfg = self.config.service.live
        if cfg is None:
            return None
        from controller.recording.live import LiveServer

        return stack.enter_context(LiveServer(cfg.port, cfg.address, token=token))

    def _start_metrics(self, stack: contextlib.ExitStack, token: str | None) -> None:
        """With ``service.metrics_port``: Prometheus metrics fed by the event stream, served on
        ``service.metrics_address`` by a thread of their own (closed with the service)."""
        cfg = self.config.service
        if cfg.metrics_port is None:
            return
        from controller.service.metrics import MetricsServer, ServiceMetrics

        metrics = ServiceMetrics(
            clients=lambda: self._server.client_count if self._server is not None else 0,
            models=self._models.infos)
        self._hub.add_listener(metrics.on_event)
        self._metrics_server = MetricsServer(metrics, cfg.metrics_address, cfg.metrics_port,
                                             token).start()
        stack.callback(lambda: self._metrics_server.close(self._stop_budget_s(0.5)))

    @contextlib.contextmanager
    def _job_recording(self, job: Job, fp: FinePositioner, failures: list[str]):
        """Record a position or grasp job (``service.record_dir``: ``job-<id>-<kind>.mcap``)
        and show its looks on the live view, for the job's duration; a recording that could
        not be written is appended to ``failures`` (the job's result reports it)."""
        record_dir = self.config.service.record_dir
        recorders = []
        if record_dir is not None and job.kind in ("position", "grasp"):
            from controller.recording.writer import RunRecorder

            recorders.append(RunRecorder(Path(record_dir) / f"job-{job.id:05d}-{job.kind}.mcap"))
        if self._live_view is not None:
            recorders.append(self._live_view)
        if not recorders:
            yield
            return
        from controller.recording.live import Tee

        fp.recorder = recorders[0] if len(recorders) == 1 else Tee(*recorders)
        try:
            yield
        finally:
            fp.recorder = None
            for recorder in recorders:
                if recorder is not self._live_view:
                    try:
                        recorder.close()
                    except (FineposError, OSError) as exc:
                        logger.error("job %d: %s", job.id, exc)
                        failures.append(str(exc))

    def _job_positioner(self, job: Job) -> FinePositioner:
        """The positioner of the job's part (device lock held): on the simulated cell that part
        is put on the table first (the cell is built anew with it)."""
        part = job.args["part"]
        cell = self._cell.cell
        if cell is not None and cell.object_kind != part:
            logger.info("job %d: the simulated cell is built anew with the %s on the table",
                        job.id, part)
            with self._machine.lock:
                self._fp = None  # an abort meanwhile halts the arm directly
            self._cell.close()
            self._cell.config = with_part(self.config, part)
            self._cell.open()
            if job.abort.is_set():
                raise FineposError("aborted before the job started")
        with self._machine.lock:
            if self._fp is None or self._part != part or self._fp.devices is None:
                self._part, self._fp = part, self._positioner(part)
            return self._fp

    def _run_job(self, job: Job) -> None:
        exc: Exception | None = None
        result = None
        recording_failures: list[str] = []
        try:
            with self._device_lock:
                fp = self._job_positioner(job)
                with self._job_recording(job, fp, recording_failures):
                    result = BODIES[job.kind](JobContext(fp, job.args,
                                                         self._models.slot(job.args["part"])))
        except JobFailed as failed:
            exc, result = failed, failed.result
        except Exception as error:  # classified below: every way a job can end is reported
            exc = error
        if recording_failures:
            result = {**(result or {}), "recording_error": recording_failures[0]}
        outcome, reason = classify(exc, job.abort.is_set(), self._cell.not_active())
        if exc is not None and not isinstance(exc, FineposError):
            logger.error("job %d (%s) raised", job.id, job.kind, exc_info=exc)
        with self._machine.lock:
            if not job.finish(outcome, reason, result):
                return
            self._last_job = job.report()
            self._job = None
            if self._machine.state is not State.STOPPING:
                if is_disk_full(exc):
                    self._enter_fault(f"{job.kind} job {job.id}: {reason}", "disk_full")
                elif outcome == "fault":
                    self._enter_fault(f"{job.kind} job {job.id}: {reason}")
                else:
                    detail = "" if outcome == "done" else f": {reason}"
                    self._machine.transition(State.IDLE,
                                             f"job {job.id} ({job.kind}) {outcome}{detail}")
        self._wake.set()

    def _halt_unreachable(self) -> str | None:
        """Why no halt can reach the arm now (its link is not open), else None."""
        arm = self._cell.arm
        if arm is None or not self._cell.is_open:
            return "the devices are not open: no halt can reach the arm"
        if arm.state is Lifecycle.DISCONNECTED:
            return "the arm is disconnected: no halt can reach it"
        return None

    def _abort_job(self, job: Job, wait_s: float) -> str | None:
        """Preempt ``job`` and halt the arm; returns why halting failed, if it did."""
        job.abort.set()
        if self._cell.arm is not None:
            self._cell.arm.preempt()
        unreachable = self._halt_unreachable()
        if unreachable is not None:
            return unreachable
        fp = self._fp
        if fp is not None and fp.devices is not None:
            return self._halt(fp.abort, wait_s)
        return self._halt(self._cell.arm.halt, wait_s) if self._cell.arm is not None else None

    def _halt(self, halt: Callable[[], None], wait_s: float) -> str | None:
        """Run ``halt`` in its own thread and wait at most ``wait_s`` for it.

        Returns None once it succeeded, else why not (its error, or that it is still waiting for
        the arm's reply: a dead link must not hold up an abort or a shutdown; the outcome then
        comes as a ``halt`` event and in the log).
        """
        outcome: list[str | None] = []

        def run() -> None:
            try:
                halt()
                outcome.append(None)
            except Exception as exc:  # noqa: BLE001 - reported, never raised into a thread
                outcome.append(f"{type(exc).__name__}: {exc}")
            if late.is_set():
                (logger.info if outcome[0] is None else logger.error)(
                    "late halt: %s", outcome[0] or "done")
                self._hub.publish({"event": "halt", "ok": outcome[0] is None,
                                   "error": outcome[0], "time": time.time()})

        late = threading.Event()
        thread = threading.Thread(target=run, name="halt", daemon=True)
        thread.start()
        thread.join(wait_s)
        if not outcome:
            late.set()
            if outcome:  # finished between the join and the flag
                return outcome[0]
            return f"no reply to the halt within {wait_s:g} s; still waiting (see the halt event)"
        if outcome[0] is not None:
            logger.error("halt failed: %s", outcome[0])
        return outcome[0]

    def abort(self) -> dict[str, Any]:
        """Preempt the running job (if any) and halt the arm. Training moves nothing and
        cannot be interrupted: it runs to its end (the answer says so).

        ``halted`` is true only when the arm's controller acknowledged the halt. Otherwise
        ``halt_error`` says why not (the arm disconnected, the devices not open, no reply in
        time, the halt refused) and ``action`` tells the operator to use the teach pendant."""
        started_s = time.monotonic()
        with self._machine.lock:
            job = self._job
        preempt = job is not None and job.kind != "train"
        wait_s = self.config.service.abort_wait_s
        if preempt:
            logger.warning("abort requested: job %d (%s)", job.id, job.kind)
            halt_error = self._abort_job(job, wait_s)
        else:
            halt_error = self._halt_unreachable()
            if halt_error is None:
                halt_error = self._halt(self._cell.arm.halt, wait_s)
        answer = {"aborted": job.report() if preempt else None,
                  "halted": halt_error is None, "halt_error": halt_error}
        if halt_error is not None:
            logger.error("abort: the arm did not acknowledge a halt: %s", halt_error)
            answer["action"] = PENDANT_STOP
        if job is not None and not preempt:
            answer["note"] = (f"job {job.id} (train) moves nothing and cannot be interrupted; "
                              "it ends by itself")
        self._hub.publish({"event": "abort", "job": job.id if preempt else None,
                           "halted": halt_error is None,
                           "seconds": time.monotonic() - started_s, "time": time.time()})
        return answer

    def reset(self) -> dict[str, Any]:
        """Leave fault: reconnect what is not active, read every device once, go idle."""
        with self._machine.lock:
            state = self._machine.state
            if state is State.IDLE:
                return {"state": state.value, "reset": "nothing to reset"}
            if state is not State.FAULT:
                raise self._refusal(state)
        with self._device_lock:
            try:
                self._cell.recover()
                self._cell.probe()
            except (FineposError, OSError) as exc:
                reason = f"reset failed: {type(exc).__name__}: {exc}"
                with self._machine.lock:
                    if self._machine.state is State.FAULT:
                        self._enter_fault(reason)
                raise RequestError("fault", f"{reason}; still in fault") from exc
            with self._machine.lock:
                if self._machine.state is State.FAULT:
                    if self._fp is None or self._fp.devices is None:
                        self._attach_devices()
                    self._fault = None
                    self._machine.transition(State.IDLE, "reset")
                state = self._machine.state
        return {"state": state.value, "reset": "devices checked"}

    def _load_models(self, part_names, system: str | None, config=None,
                     skip_untrained: bool = True) -> dict[str, tuple]:
        """Load the model of each part in ``part_names`` from its state folder: ``system``,
        else the one in use for that part, else gabor. With ``skip_untrained``, a part with
        no model in use and no such file (taught, not trained yet) is left out. Returns
        {part: (model, file)}; raises the first error, having put nothing into use."""
        loaded = {}
        for kind in part_names:
            in_use = (self._models.info(kind) or {}).get("system")
            chosen = system or in_use or DEFAULT_SYSTEM
            fp = self._positioner(kind, config)
            if skip_untrained and in_use is None and not fp.model_path(chosen).exists():
                continue
            loaded[kind] = (fp.load_model(system=chosen), fp.model_path(chosen))
        return loaded

    def reload_model(self, system: str | None, part: str | None = None) -> dict[str, Any]:
        """Load the model of ``part`` (None: of every taught part) from the state folder into
        use; if any cannot be loaded, every old one stays in use."""
        with self._machine.lock:
            state = self._machine.state
            if state not in (State.IDLE, State.FAULT):
                raise self._refusal(state)
        part_names = [part] if part is not None else list(self._folder().taught())
        try:
            models = self._load_models(part_names, system, skip_untrained=part is None)
        except (FineposError, OSError) as exc:
            raise RequestError("failed", f"model not loaded, the old one stays in use: "
                                         f"{exc}") from exc
        if not models:
            raise RequestError("failed", "no taught part has a trained model yet: nothing to "
                                         "load")
        for kind, (model, path) in models.items():
            self._models.slot(kind).set(model, path)
        logger.info("models reloaded: %s", {kind: self._models.info(kind) for kind in models})
        return {"model": self._models.info(self._part),
                "models": {kind: self._models.info(kind) for kind in models}}


def _first_free_job_id(record_dir: str | None) -> int:
    """The first job id after those of the recordings in ``record_dir`` (1 when there are
    none), so a restarted service never writes over an earlier run's recording."""
    if record_dir is None:
        return 1
    try:
        names = [entry.name for entry in os.scandir(record_dir)]
    except OSError:
        return 1
    ids = [int(match.group(1)) for name in names
           if (match := _RECORDING_NAME.fullmatch(name)) is not None]
    return max(ids, default=0) + 1
