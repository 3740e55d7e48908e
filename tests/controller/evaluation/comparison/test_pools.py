"""Job pools: results in task order, progress ticks, and the Ray extra's clear error."""

from __future__ import annotations

import sys

import pytest

from controller.evaluation.comparison import pools
from drivers.core.errors import FineposError


def square_with_ticks(task: int, tick) -> int:
    for _ in range(task):
        tick()
    return task * task


def test_inline_pool_runs_in_order_and_counts_progress():
    with pools.open_pool(1) as pool:
        assert isinstance(pool, pools.InlinePool)
        assert pool.run(square_with_ticks, [3, 1, 2], weights=[3, 1, 2],
                        progress=False) == [9, 1, 4]


def test_progress_never_exceeds_a_tasks_weight():
    bar = pools._Progress([2, 3], "t", "unit", enabled=False)
    bar.tick(0, 5)
    bar.finish(1)
    bar.finish(0)
    assert bar.done == [2, 3]
    bar.close()


def test_local_pool_uses_spawned_workers_and_keeps_task_order():
    tasks = list(range(6))
    with pools.open_pool(2) as pool:
        assert isinstance(pool, pools.LocalPool) and pool.workers == 2
        assert pool.run(square_with_ticks, tasks, weights=tasks, progress=False) == \
            [t * t for t in tasks]
        assert pool.run(square_with_ticks, [4], progress=False) == [16]  # a second run


def test_weights_must_match_tasks():
    with pytest.raises(ValueError, match="2 weights for 1 tasks"):
        pools.InlinePool().run(square_with_ticks, [1], weights=[1, 1], progress=False)


def test_ray_missing_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(FineposError, match=r"pip install 'finepos\[ray\]'"):
        pools.open_pool(2, ray_address="auto")


def test_at_least_one_worker():
    with pytest.raises(FineposError, match="--workers must be at least 1"):
        pools.open_pool(0)
