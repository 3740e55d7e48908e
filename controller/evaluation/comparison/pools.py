"""Where independent experiment jobs run: in this process, in local worker processes, or on Ray.

A job is a module-level function ``fn(task, tick)`` returning a picklable result; ``tick(n=1)``
reports n units of progress (trials, say) while the job runs. ``open_pool`` picks the pool;
every pool's ``run(fn, tasks, ...)`` returns the results in task order and drives one tqdm bar
whose total is the sum of the tasks' weights (a task's share is completed when it finishes, so
jobs that never tick still advance the bar).

Local workers are spawned, not forked: each is a fresh interpreter that opens its own PyBullet
client, and keeps BLAS to one thread (the pool already uses the cores). They log warnings and
errors only, or everything when the parent logs at DEBUG. Ray is an optional extra
(``pip install 'finepos[ray]'``), imported only when a Ray address is given; on a cluster, every
node needs finepos installed. Ray jobs report progress when they finish, not per tick.
"""

from __future__ import annotations

import functools
import logging
import multiprocessing
import queue
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

from tqdm import tqdm

from drivers.core.errors import FineposError

logger = logging.getLogger(__name__)

Tick = Callable[..., None]
Job = Callable[[Any, Tick], Any]

POLL_S = 0.2  # how often the parent drains the workers' progress ticks

_TICKS: Any = None  # the worker's end of the progress queue (set by _init_worker)


class _Progress:
    """One bar over all tasks; each task advances it by at most its weight."""

    def __init__(self, weights: Sequence[int], desc: str, unit: str, enabled: bool) -> None:
        self.weights = list(weights)
        self.done = [0] * len(self.weights)
        self.bar = tqdm(total=sum(self.weights), desc=desc, unit=unit,
                        disable=None if enabled else True)

    def tick(self, index: int, n: int = 1) -> None:
        """Advance task ``index`` by ``n`` units, never beyond its weight."""
        n = max(0, min(n, self.weights[index] - self.done[index]))
        self.done[index] += n
        self.bar.update(n)

    def finish(self, index: int) -> None:
        """Complete task ``index``'s share of the bar."""
        self.tick(index, self.weights[index] - self.done[index])

    def close(self) -> None:
        """Close the bar."""
        self.bar.close()


def _weights(tasks: Sequence[Any], weights: Sequence[int] | None) -> list[int]:
    if weights is None:
        return [1] * len(tasks)
    if len(weights) != len(tasks):
        raise ValueError(f"{len(weights)} weights for {len(tasks)} tasks")
    return [int(w) for w in weights]


class InlinePool:
    """Runs the jobs one after another in this process (``--workers 1``)."""

    workers = 1

    def __enter__(self) -> InlinePool:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def run(self, fn: Job, tasks: Sequence[Any], *, weights: Sequence[int] | None = None,
            desc: str = "jobs", unit: str = "job", progress: bool = True) -> list[Any]:
        """Run ``fn(task, tick)`` for each task in turn; returns the results in task order.

        A job's own error propagates; the jobs after it do not run.

        Args:
            fn: the job (see the module docstring).
            tasks: one job argument each.
            weights: progress units per task (None: 1 each).
            desc: the progress bar's label.
            unit: the progress bar's unit.
            progress: show the progress bar.

        Raises:
            ValueError: ``weights`` and ``tasks`` differ in length.
        """
        bar = _Progress(_weights(tasks, weights), desc, unit, progress)
        try:
            results = []
            for i, task in enumerate(tasks):
                results.append(fn(task, functools.partial(bar.tick, i)))
                bar.finish(i)
            return results
        finally:
            bar.close()


def _worker_log_level() -> int:
    parent = logging.getLogger().getEffectiveLevel()
    return parent if parent <= logging.DEBUG else max(parent, logging.WARNING)


def _init_worker(ticks, log_level: int) -> None:
    global _TICKS
    from threadpoolctl import threadpool_limits

    _TICKS = ticks
    logging.basicConfig(level=log_level,
                        format="%(asctime)s %(levelname)s %(processName)s %(name)s: %(message)s")
    threadpool_limits(1)


def _worker_tick(run_id: int, index: int, n: int = 1) -> None:
    _TICKS.put((run_id, index, n))


def _call_in_worker(fn: Job, run_id: int, index: int, task: Any) -> Any:
    return fn(task, functools.partial(_worker_tick, run_id, index))


class LocalPool:
    """Spawned worker processes on this machine (concurrent.futures)."""

    def __init__(self, workers: int) -> None:
        if workers < 1:
            raise ValueError(f"workers must be >= 1, got {workers}")
        self.workers = workers
        context = multiprocessing.get_context("spawn")
        self._ticks = context.Queue()
        self._runs = 0
        self._executor = ProcessPoolExecutor(workers, mp_context=context,
                                             initializer=_init_worker,
                                             initargs=(self._ticks, _worker_log_level()))

    def __enter__(self) -> LocalPool:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # On an error or Ctrl-C, drop the queued jobs and do not wait for running ones.
        self._executor.shutdown(wait=exc_type is None, cancel_futures=True)
        self._ticks.close()

    def _drain(self, run_id: int, bar: _Progress) -> None:
        while True:
            try:
                rid, index, n = self._ticks.get_nowait()
            except queue.Empty:
                return
            if rid == run_id:  # a late tick of an earlier run is dropped
                bar.tick(index, n)

    def run(self, fn: Job, tasks: Sequence[Any], *, weights: Sequence[int] | None = None,
            desc: str = "jobs", unit: str = "job", progress: bool = True) -> list[Any]:
        """Like ``InlinePool.run``, in the worker processes; ``fn`` must be module-level.

        The first job error that is collected is raised; jobs not yet started are then cancelled.
        """
        self._runs += 1
        run_id = self._runs
        bar = _Progress(_weights(tasks, weights), desc, unit, progress)
        futures = {self._executor.submit(_call_in_worker, fn, run_id, i, task): i
                   for i, task in enumerate(tasks)}
        results: list[Any] = [None] * len(tasks)
        pending = set(futures)
        try:
            while pending:
                done, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
                self._drain(run_id, bar)
                for future in done:
                    i = futures[future]
                    results[i] = future.result()
                    bar.finish(i)
            return results
        finally:
            for future in pending:
                future.cancel()
            bar.close()


def import_ray():
    """The ``ray`` module, or a FineposError saying how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise FineposError("--ray needs the optional Ray extra: pip install 'finepos[ray]' "
                           f"({exc})") from exc
    return ray


def _no_tick(n: int = 1) -> None:
    return None


def _call_on_ray(fn: Job, task: Any) -> Any:
    return fn(task, _no_tick)


class RayPool:
    """Ray tasks on the cluster at ``address`` ("auto": the running one; "local": a new
    single-machine cluster), one CPU each."""

    def __init__(self, address: str) -> None:
        self._ray = import_ray()
        self._ray.init(address=address)
        self.workers = int(self._ray.cluster_resources().get("CPU", 1))
        self._remote = self._ray.remote(num_cpus=1)(_call_on_ray)
        logger.info("Ray cluster at %s: %d CPUs", address, self.workers)

    def __enter__(self) -> RayPool:
        return self

    def __exit__(self, *exc) -> None:
        self._ray.shutdown()

    def run(self, fn: Job, tasks: Sequence[Any], *, weights: Sequence[int] | None = None,
            desc: str = "jobs", unit: str = "job", progress: bool = True) -> list[Any]:
        """Like ``InlinePool.run``, as Ray tasks; the bar advances only as jobs finish.

        The first job error that is collected is raised; the pending tasks are then cancelled.
        """
        ray = self._ray
        bar = _Progress(_weights(tasks, weights), desc, unit, progress)
        refs = [self._remote.remote(fn, task) for task in tasks]
        index = {ref: i for i, ref in enumerate(refs)}
        results: list[Any] = [None] * len(tasks)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    results[index[ref]] = ray.get(ref)
                    bar.finish(index[ref])
            return results
        finally:
            for ref in pending:
                ray.cancel(ref)
            bar.close()


def open_pool(workers: int, ray_address: str | None = None):
    """A Ray pool when an address is given, else local processes (in-process for 1 worker).

    Raises:
        FineposError: fewer than 1 worker, or ray is not installed when an address is given.
    """
    if workers < 1:
        raise FineposError(f"--workers must be at least 1, got {workers}")
    if ray_address is not None:
        return RayPool(ray_address)
    if workers <= 1:
        return InlinePool()
    return LocalPool(workers)
