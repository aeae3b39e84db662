"""nscontrol.sweep: grid order, per-point failures, local processes and an in-process Dask
cluster behind the same call."""

import math
import operator
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from functools import partial

import pytest

from nscontrol import sweep
from nscontrol.errors import ModelError

GRID = [4.0, -1.0, 9.0, 0.25, -4.0, 16.0]
EXPECTED = (2.0, None, 3.0, 0.5, None, 4.0)


def _check_sqrt_sweep(res: sweep.SweepResult) -> None:
    assert res.grid == tuple(GRID)
    assert res.values == EXPECTED
    assert [e.index for e in res.failed] == [1, 4]
    assert all(e.type == "ValueError" and "math domain" in e.message for e in res.failed)
    assert res.succeeded == (0, 2, 3, 5)
    assert not res.ok
    with pytest.raises(sweep.SweepError, match="2 of 6 sweep points failed"):
        res.raise_on_error()


def test_serial_and_threads_keep_grid_order_and_record_failures():
    _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor="serial", progress=False))
    with ThreadPoolExecutor(2) as pool:
        _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor=pool, progress=False))


def test_process_pool_with_picklable_function():
    with ProcessPoolExecutor(2) as pool:
        _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor=pool, progress=False))
        # partial of a module-level function is picklable too
        res = sweep.run(partial(operator.mul, 3), range(5), executor=pool, progress=False)
    assert res.values == (0, 3, 6, 9, 12) and res.ok


def test_default_executor_is_local_processes():
    res = sweep.run(math.sqrt, GRID, progress=False)
    _check_sqrt_sweep(res)


class _HoldsLock:
    """A module-level callable that cannot be pickled (it holds a lock)."""

    def __init__(self, delay=0.0):
        self.lock = threading.Lock()
        self.delay = delay

    def __call__(self, point):
        with self.lock:
            time.sleep(self.delay)
            return 2 * point


def _pid_after(seconds):
    time.sleep(seconds)
    return os.getpid()


def test_unpicklable_function_is_a_per_point_error_not_a_crash():
    with ProcessPoolExecutor(1) as pool:
        res = sweep.run(lambda p: p, [1, 2], executor=pool, progress=False)
    assert len(res.failed) == 2 and res.values == (None, None)
    assert "module-level function" in res.failed[0].message


def test_callable_holding_a_lock_on_processes_names_the_rule():
    fn = _HoldsLock()
    assert sweep.run(fn, [1, 2], executor="serial", progress=False).values == (2, 4)
    with ProcessPoolExecutor(1) as pool:
        res = sweep.run(fn, [1, 2, 3], executor=pool, progress=False)
    assert res.values == (None, None, None)
    assert [e.index for e in res.failed] == [0, 1, 2]
    for e in res.failed:
        assert "_thread.lock" in e.message and "fn cannot be pickled" in e.message


@pytest.mark.cluster
def test_unpicklable_function_on_a_process_dask_cluster_is_recorded_per_point():
    """Dask serialises at submit: every point gets its error, none is lost to a crash."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        res = sweep.run(_HoldsLock(), [1, 2, 3], executor=client, progress=False)
        good = sweep.run(math.sqrt, [4.0, 9.0], executor=client, progress=False)
    assert res.values == (None, None, None) and [e.index for e in res.failed] == [0, 1, 2]
    assert all("_thread.lock" in e.message and "executor='serial'" in e.message
               for e in res.failed)
    assert good.values == (2.0, 3.0)


def test_auto_executor_stays_serial_for_cheap_points_and_uses_processes_for_costly_ones():
    cheap = sweep.run(_pid_after, [0.0] * 6, executor="auto", progress=False)
    assert set(cheap.values) == {os.getpid()}  # 6 x ~0 s: a pool would not pay
    costly = sweep.run(_pid_after, [0.15] * 4, executor="auto", progress=False)
    assert costly.values[0] == os.getpid()  # the timed pilot point
    if (os.cpu_count() or 1) > 1:  # 3 x 0.15 s > AUTO_PARALLEL_SECONDS: workers
        assert os.getpid() not in costly.values[1:]
    # an unpicklable fn never goes to processes under "auto", however costly
    locked = sweep.run(_HoldsLock(0.15), [1.0, 2.0, 3.0], executor="auto", progress=False)
    assert locked.values == (2.0, 4.0, 6.0)
    _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor="auto", progress=False))


@pytest.mark.cluster
def test_dask_local_cluster_executor_client_and_address():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor=client.get_executor(),
                                    progress=False))
        _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor=client, progress=False))
        _check_sqrt_sweep(sweep.run(math.sqrt, GRID, executor=cluster.scheduler_address,
                                    progress=False))


def test_progress_bar_on_stderr(capsys):
    sweep.run(math.sqrt, [1.0, 4.0], executor="serial", progress=True, desc="roots")
    assert "roots" in capsys.readouterr().err


def test_bad_arguments():
    with pytest.raises(ModelError, match="fn: expected a callable"):
        sweep.run(3, [1])
    with pytest.raises(ModelError, match="executor: expected"):
        sweep.run(math.sqrt, [1.0], executor=42)
    empty = sweep.run(math.sqrt, [])
    assert empty.values == () and empty.ok
