"""nscontrol.sweep in chunks: several points per task give the same values and errors, bit for
bit, as one point per task and as ``"serial"``; a failing, crashing, interrupted or
unpicklable point inside a chunk costs only itself; the chunk sizes follow the rule of the
module docstring (pilots of one point, then ``min_task_seconds`` per task, at least two
chunks per worker left)."""

import math
import os
import threading
from concurrent.futures import Executor, ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

import nscontrol.sweep as sweep_mod
from nscontrol import sweep
from nscontrol.errors import ModelError

N = 40


def _orbit(p):
    """A value whose last bits depend on every operation: 200 logistic-map iterations (a
    chaotic map doubles any rounding difference at each step) and an array of sines."""
    x = 0.1 + 0.8 * (p % 7) / 7.0 + 1e-3 * p
    for _ in range(200):
        x = 3.99 * x * (1.0 - x)
    return x, np.sin(np.arange(5.0) * x + p)


def _fails_at_5_and_17(p):
    if p in (5, 17):
        raise ValueError(f"bad point {p}")
    return _orbit(p)


def _exit_at_3(p):
    if p == 3:
        os._exit(7)
    return p * p


def _interrupt_at_3(p):
    if p == 3:
        raise KeyboardInterrupt
    return p * p


def _identity(p):
    return p


def _bits(res):
    """Values as bytes (exact comparison of floats and arrays); None where a point failed."""
    return [None if v is None else (float(v[0]).hex(), v[1].tobytes()) for v in res.values]


class _CountingPool(ProcessPoolExecutor):
    """A local pool recording how many points each task carries."""

    def __init__(self, workers):
        super().__init__(workers)
        self.sizes = []

    def submit(self, fn, /, *args, **kwargs):
        self.sizes.append(len(args[0]))
        return super().submit(fn, *args, **kwargs)


class _CountingExecutor(Executor):
    """Any executor (here Dask's), recording how many points each task carries."""

    def __init__(self, inner, client):
        self.inner, self._client, self.sizes = inner, client, []

    def submit(self, fn, /, *args, **kwargs):
        self.sizes.append(len(args[0]))
        return self.inner.submit(fn, *args, **kwargs)


# ----------------------------------------------------------------------------- same results


@pytest.mark.parametrize("chunk", [None, 1, 3, 7, N])
def test_chunked_process_pool_equals_serial_bit_for_bit(chunk):
    serial = sweep.run(_orbit, range(N), executor="serial", progress=False)
    with _CountingPool(2) as pool:
        res = sweep.run(_orbit, range(N), executor=pool, chunk=chunk, progress=False)
    assert res.ok and _bits(res) == _bits(serial)
    assert sum(pool.sizes) == N
    if chunk is None:   # automatic: a pilot per worker, then chunks of several points
        assert pool.sizes[:2] == [1, 1] and max(pool.sizes) > 1
    else:
        assert pool.sizes == [min(chunk, N - k) for k in range(0, N, chunk)]


def test_chunked_threads_and_default_pool_equal_serial():
    serial = _bits(sweep.run(_orbit, range(N), executor="serial", progress=False))
    with ThreadPoolExecutor(2) as pool:
        assert _bits(sweep.run(_orbit, range(N), executor=pool, chunk=5,
                               progress=False)) == serial
    assert _bits(sweep.run(_orbit, range(N), progress=False)) == serial


@pytest.mark.cluster
def test_chunked_dask_local_cluster_equals_serial_bit_for_bit():
    distributed = pytest.importorskip("dask.distributed")
    serial = sweep.run(_fails_at_5_and_17, range(N), executor="serial", progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        counting = _CountingExecutor(client.get_executor(), client)
        auto = sweep.run(_fails_at_5_and_17, range(N), executor=counting, progress=False)
        fixed = sweep.run(_fails_at_5_and_17, range(N), executor=client, chunk=6,
                          progress=False)
        locked = sweep.run(_identity, [1, 2, threading.Lock(), 4, 5], executor=client,
                           chunk=5, progress=False)
    for res in (auto, fixed):
        assert _bits(res) == _bits(serial)
        assert [e.index for e in res.failed] == [5, 17]
        assert all(e.type == "ValueError" and "bad point" in e.message for e in res.failed)
    assert counting.sizes[:2] == [1, 1] and max(counting.sizes) > 1  # 2 workers: 2 pilots
    assert sum(counting.sizes) == N
    # a point Dask cannot serialise fails alone; its chunk's other points are sent again
    assert locked.values[:2] == (1, 2) and locked.values[3:] == (4, 5)
    assert locked.errors[2] is not None and "point 2" in locked.errors[2].message


# ----------------------------------------------------------------------------- nothing lost


@pytest.mark.parametrize("executor", ["threads", "pool"])
def test_a_failing_point_inside_a_chunk_costs_only_itself(executor):
    serial = sweep.run(_fails_at_5_and_17, range(N), executor="serial", progress=False)
    with (ThreadPoolExecutor(2) if executor == "threads" else ProcessPoolExecutor(2)) as ex:
        res = sweep.run(_fails_at_5_and_17, range(N), executor=ex, chunk=8, progress=False)
    assert _bits(res) == _bits(serial)
    assert res.succeeded == tuple(i for i in range(N) if i not in (5, 17))
    for i in (5, 17):
        e = res.errors[i]
        assert e.index == i and e.type == "ValueError" and f"bad point {i}" in e.message
        assert "_fails_at_5_and_17" in e.traceback   # the worker's own traceback


def test_a_crash_inside_a_chunk_costs_only_its_point():
    res = sweep.run(_exit_at_3, range(12), chunk=6, progress=False)
    assert res.values == tuple(None if i == 3 else i * i for i in range(12))
    assert res.failed == (res.errors[3],) and res.errors[3].type == "WorkerDied"


def _hang_at_3(p):
    if p == 3:
        import time

        time.sleep(3600)
    return p * p


def test_a_point_over_its_budget_inside_a_chunk_costs_only_itself():
    # 2 s: a healthy point takes microseconds, even on a loaded machine far below that
    res = sweep.run(_hang_at_3, range(12), chunk=6, point_timeout=2.0, progress=False)
    assert res.values == tuple(None if i == 3 else i * i for i in range(12))
    assert res.failed == (res.errors[3],) and res.errors[3].type == "BudgetExceededError"


def test_an_unpicklable_point_inside_a_chunk_costs_only_itself():
    res = sweep.run(_identity, [1, 2, threading.Lock(), 4, 5], chunk=5, progress=False)
    assert res.values[:2] == (1, 2) and res.values[3:] == (4, 5)
    assert "point 2 cannot be pickled" in res.errors[2].message


@pytest.mark.parametrize("executor", ["threads", "pool"])
def test_an_interrupt_inside_a_chunk_keeps_the_points_it_finished(executor):
    with (ThreadPoolExecutor(1) if executor == "threads" else ProcessPoolExecutor(1)) as ex:
        with pytest.raises(KeyboardInterrupt) as info:
            sweep.run(_interrupt_at_3, range(12), executor=ex, chunk=12, progress=False)
    partial = info.value.sweep_result
    assert partial.values[:3] == (0, 1, 4)      # run in the same task before the interrupt
    assert all(e.type == "KeyboardInterrupt" for e in partial.errors[3:])


def test_progress_counts_points_not_tasks(monkeypatch):
    counted = []

    class Bar:
        def update(self, n):
            counted.append(n)

        def close(self):
            pass

    monkeypatch.setattr(sweep_mod, "_bar", lambda total, progress, desc: Bar())
    with ThreadPoolExecutor(2) as pool:
        sweep.run(_identity, range(N), executor=pool, chunk=10, progress=True)
    assert counted == [1] * N


# ----------------------------------------------------------------------------- sizing


def _plan(n, workers, per_point, min_seconds=0.5):
    """The sizes the automatic chunker hands out for ``n`` points costing ``per_point`` s each:
    the pilots go out together, then each task reports its time as it is cut (the rule, free
    of any scheduling)."""
    sizing = sweep_mod._Sizing(None, min_seconds)
    plan = sweep_mod._Chunker([(i, i) for i in range(n)], workers, sizing)
    sizes = [len(plan.take()) for _ in range(min(workers, n))]
    sizing.observe(sum(sizes), per_point * sum(sizes))
    while plan:
        sizes.append(len(plan.take()))
        sizing.observe(sizes[-1], per_point * sizes[-1])
    return sizes


def test_automatic_chunks_last_min_task_seconds_until_the_tail():
    # 2000 points of 10 ms (20 s of work), 2 workers: pilots, then 0.5 s tasks (50 points)
    sizes = _plan(2000, 2, 0.01)
    assert sizes[:2] == [1, 1] and sum(sizes) == 2000
    # 0.5 / (measured time per point) is 50 up to the rounding of the summed times: 50 or 51
    full = [s for s in sizes if s in (50, 51)]
    assert sum(full) >= 2000 - 2 - 4 * 50   # all but the last 2 chunks per worker
    assert max(sizes) <= 51
    # the tail shrinks to single points, so the workers end within ~one point of each other
    tail = sizes[next(k for k, s in enumerate(sizes) if 1 < s < 50):]
    assert tail == sorted(tail, reverse=True) and tail[-1] == 1


def test_automatic_chunks_keep_two_per_worker_and_never_split_long_points():
    # cheap points: the balance bound decides (remaining / (2 x workers))
    sizes = _plan(1000, 4, 1e-6)
    assert sizes[:4] == [1, 1, 1, 1] and sum(sizes) == 1000
    remaining = 1000 - 4
    for s in sizes[4:]:
        assert s == max(1, min(math.ceil(remaining / 8), remaining))
        remaining -= s
    # points longer than min_task_seconds: one per task
    assert _plan(9, 2, 0.6) == [1] * 9


def test_sizing_rule_directly():
    sizing = sweep_mod._Sizing(None, 0.5)
    assert sizing.size(100, 2) == 1 and sizing.in_flight(2) == 2      # pilots
    sizing.observe(2, 0.2)                                           # 0.1 s per point
    assert sizing.size(100, 2) == 5 and sizing.in_flight(2) == 4     # 5 x 0.1 s = 0.5 s
    long = sweep_mod._Sizing(None, 0.5)
    long.observe(2, 1.2)                     # 0.6 s per point: a point fills a task alone
    assert long.size(100, 2) == 1 and long.in_flight(2) == 2          # none queued
    assert sizing.size(12, 2) == 3                                   # 12 / (2 x 2)
    assert sizing.size(1, 2) == 1
    fixed = sweep_mod._Sizing(7)
    assert fixed.size(100, 2) == 7 and fixed.size(3, 2) == 3
    assert fixed.in_flight(2) == math.inf


class _InFlightExecutor(Executor):
    """Wraps an executor, recording the most tasks ever submitted and not yet finished."""

    def __init__(self, inner, client=None):
        self.inner, self.running, self.most, self.lock = inner, 0, 0, threading.Lock()
        if client is not None:
            self._client = client

    def _finished(self, _):
        with self.lock:
            self.running -= 1

    def submit(self, fn, /, *args, **kwargs):
        with self.lock:
            self.running += 1
            self.most = max(self.most, self.running)
        future = self.inner.submit(fn, *args, **kwargs)
        future.add_done_callback(self._finished)
        return future


def _slow(p):
    """A point lasting 20 ms or more (sleeps): longer than ``min_task_seconds=0.005``."""
    import time

    time.sleep(0.02)
    return _orbit(p)


def test_long_points_are_handed_to_free_workers_only():
    # a queued task waits in the queue of the worker the executor chose: behind a long point
    # it would wait while the other worker idles, so long points are never queued (the old
    # rule kept two per worker in flight: 4 here)
    serial = sweep.run(_orbit, range(12), executor="serial", progress=False)
    with ThreadPoolExecutor(2) as pool:
        ex = _InFlightExecutor(pool)
        res = sweep.run(_slow, range(12), executor=ex, min_task_seconds=0.005, progress=False)
    assert _bits(res) == _bits(serial)
    assert ex.most == 2
    # short points still keep one queued per worker
    with ThreadPoolExecutor(2) as pool:
        ex = _InFlightExecutor(pool)
        sweep.run(_slow, range(12), executor=ex, min_task_seconds=10.0, progress=False)
    assert ex.most == 4


@pytest.mark.cluster
def test_dask_long_points_one_per_worker_and_a_failure_costs_only_its_point():
    distributed = pytest.importorskip("dask.distributed")
    serial = sweep.run(_fails_at_5_and_17, range(24), executor="serial", progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        assert sweep_mod._workers(client.get_executor()) == 2
        ex = _InFlightExecutor(client.get_executor(), client)
        res = sweep.run(_slow_or_fails, range(24), executor=ex, min_task_seconds=0.005,
                        progress=False)
    assert _bits(res) == _bits(serial) and ex.most == 2
    assert [e.index for e in res.failed] == [5, 17]


def _slow_or_fails(p):
    _slow(p)
    return _fails_at_5_and_17(p)


@pytest.mark.parametrize(("kw", "name"), [({"chunk": 0}, "chunk"), ({"chunk": 2.5}, "chunk"),
                                          ({"chunk": "3"}, "chunk"), ({"chunk": True}, "chunk"),
                                          ({"min_task_seconds": 0}, "min_task_seconds"),
                                          ({"min_task_seconds": -1.0}, "min_task_seconds"),
                                          ({"min_task_seconds": float("nan")},
                                           "min_task_seconds")])
def test_bad_chunk_options_are_refused_by_name(kw, name):
    with pytest.raises(ModelError, match=f"^{name}: expected"):
        sweep.run(_identity, [1, 2], executor="serial", progress=False, **kw)
