"""The service's jobs: what each one does with the FinePositioner, and how it ended.

A job runs in the worker thread with the devices to itself. Its body returns a JSON-able result,
or raises JobFailed when the library reported an unsuccessful outcome (object lost, loop
rejected, grasp guard tripped). ``classify`` turns whatever ended a job into its outcome:

- ``fault``: a device error (timeout, protocol error, lost link, controller fault), a device
  left not active, or an unexpected exception; the service goes to fault;
- ``aborted``: an abort was requested (and no device fault came with it);
- ``failed``: the job could not do its work (no teach-in yet, no model, unsuccessful outcome,
  a step the safety layer refused); the service stays usable;
- ``done``.
"""

from __future__ import annotations

import errno
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from controller.fine_positioner import FinePositioner
from controller.loop.iteration_log import LogWriteError
from controller.service.model_slot import ModelSlot
from drivers.core.errors import (
    DeviceFaultError,
    DeviceNotConnectedError,
    DeviceTimeoutError,
    FineposError,
    ProtocolError,
)
from drivers.core.pose import ToolStep

DEVICE_ERRORS = (DeviceFaultError, DeviceTimeoutError, ProtocolError, DeviceNotConnectedError)


class JobFailed(FineposError):
    """A job ended without success but without error; ``result`` says what was reached."""

    def __init__(self, reason: str, result: dict[str, Any] | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.result = result


@dataclass
class Job:
    """One job: what was asked, and once ``done`` is set, how it ended."""

    id: int
    kind: str
    args: dict[str, Any]
    started_at: float = field(default_factory=time.time)
    abort: threading.Event = field(default_factory=threading.Event)
    done: threading.Event = field(default_factory=threading.Event)
    outcome: str | None = None
    reason: str = ""
    result: dict[str, Any] | None = None
    seconds: float | None = None
    on_end: Callable[[Job], None] | None = field(default=None, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def finish(self, outcome: str, reason: str, result: dict[str, Any] | None = None) -> bool:
        """Record the end (the first call wins); returns whether this call did. ``on_end`` is
        called with the job ended, before ``done`` wakes anyone waiting for it."""
        with self._lock:
            if self.outcome is not None:
                return False
            self.outcome, self.reason, self.result = outcome, reason, result
            self.seconds = time.time() - self.started_at
            if self.on_end is not None:
                self.on_end(self)
            self.done.set()
            return True

    def report(self) -> dict[str, Any]:
        """The job as ``status`` shows it; outcome, reason, result and seconds once it ended."""
        report = {"id": self.id, "kind": self.kind, "args": self.args,
                  "started_at": self.started_at}
        if self.outcome is not None:
            report.update(outcome=self.outcome, reason=self.reason, result=self.result,
                          seconds=self.seconds)
        return report


@dataclass(frozen=True)
class JobContext:
    """What a job body gets: the FinePositioner of the job's part (its config and state folder
    set up for that part), the validated arguments (``part`` resolved), that part's model
    slot."""

    fp: FinePositioner
    args: dict[str, Any]
    models: ModelSlot

    @property
    def part(self) -> str:
        """The part the job works on."""
        return self.fp.config.controller.part


def _teach(ctx: JobContext) -> dict[str, Any]:
    fp, args = ctx.fp, ctx.args
    state = (fp.teach_auto() if args["auto"] else
             fp.teach("current", args["grasp_depth_mm"], args["object_width_mm"]))
    return {"part": ctx.part, "state_file": str(fp.state_path),
            "nominal_pose": state.nominal_pose.as_dict(),
            "object": state.object_kind, "kappa": state.kappa, "source": state.source}


def _acquire(ctx: JobContext) -> dict[str, Any]:
    name = ctx.args["set"]
    data = ctx.fp.acquire(name, seed=ctx.args["seed"], progress=False)
    return {"part": ctx.part, "set": name, "images": len(data),
            "file": str(ctx.fp.dataset_path(name)), "seconds": data.metadata.get("seconds")}


def _train(ctx: JobContext) -> dict[str, Any]:
    system = ctx.args["system"]
    model = ctx.fp.train(system)
    ctx.models.set(model, ctx.fp.model_path(system))
    return {"part": ctx.part, "system": system, "model": str(ctx.fp.model_path(system)),
            "train_images": model.train_images, "train_seconds": model.train_seconds}


def _rezero(ctx: JobContext) -> dict[str, Any]:
    system = ctx.args["system"]
    model, report = ctx.fp.rezero(ctx.args["frames"], system, ctx.args["heading_step"])
    in_use = ctx.models.model
    if in_use is None or in_use.system == system:  # another system in use stays in use
        ctx.models.set(model, ctx.fp.model_path(system))
    return {"part": ctx.part, "system": system, "model": str(ctx.fp.model_path(system)),
            **report}


def _position(ctx: JobContext) -> dict[str, Any]:
    fp, args = ctx.fp, ctx.args
    fp.use_model(ctx.models.require(fp))
    if args["offset"] is not None:
        dx, dy, dphi = args["offset"]
        fp.move_to(fp.state().nominal_pose.moved_in_tool_frame(ToolStep(-dx, -dy, 0.0, -dphi)))
    result = fp.position(args["max_loops"], then_grasp=args["grasp"])
    # the grasp makes the converged step with its first move, and adds it to the run
    grasp = fp.grasp() if args["grasp"] and result.ok else None
    error = result.states[-1].error
    report = {"part": ctx.part, "run_id": result.run_id, "outcome": result.outcome,
              "reason": result.reason, "loops": result.loops, "iterations": result.iterations,
              "error": list(error) if error is not None else None}
    if not result.ok:
        raise JobFailed(f"{result.outcome}: {result.reason}", report)
    if grasp is not None:
        report["grasp"] = grasp.as_dict()
        if not grasp.success:
            raise JobFailed(f"grasp failed: {grasp.reason}", report)
    return report


def _grasp(ctx: JobContext) -> dict[str, Any]:
    result = ctx.fp.grasp()
    report = {"part": ctx.part, **result.as_dict()}
    if not result.success:
        raise JobFailed(f"grasp failed: {result.reason}", report)
    return report


BODIES: dict[str, Callable[[JobContext], dict[str, Any]]] = {
    "teach": _teach,
    "acquire": _acquire,
    "train": _train,
    "rezero": _rezero,
    "position": _position,
    "grasp": _grasp,
}


def is_disk_full(exc: BaseException | None) -> bool:
    """Whether ``exc`` says a file system or quota is full (a log, dataset or model write)."""
    if isinstance(exc, LogWriteError):
        return exc.disk_full
    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


def classify(exc: BaseException | None, aborted: bool,
             not_active: dict[str, str]) -> tuple[str, str]:
    """(outcome, reason) of a job that raised ``exc`` (None: returned normally)."""
    if not_active:
        devices = "; ".join(f"{name}: {why}" for name, why in not_active.items())
        cause = f" ({type(exc).__name__}: {exc})" if exc is not None else ""
        return "fault", f"device fault: {devices}{cause}"
    if isinstance(exc, DEVICE_ERRORS):
        return "fault", f"device error: {type(exc).__name__}: {exc}"
    if isinstance(exc, LogWriteError):  # "disk_full: ..." when the disk is full
        return "fault", str(exc)
    if is_disk_full(exc):  # a dataset or model that did not fit (the old file stays)
        return "fault", f"disk_full: {exc.strerror}: {exc.filename or ''}".rstrip(": ")
    if aborted:
        return "aborted", "aborted by request"
    if exc is None:
        return "done", "done"
    if isinstance(exc, JobFailed):
        return "failed", exc.reason
    if isinstance(exc, FineposError):
        return "failed", f"{type(exc).__name__}: {exc}"
    return "fault", f"internal error: {type(exc).__name__}: {exc}"
