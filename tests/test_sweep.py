"""nscontrol.sweep: grid order, per-point failures, local processes and an in-process Dask
cluster behind the same call."""

import math
import operator
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


def test_unpicklable_function_is_a_per_point_error_not_a_crash():
    with ProcessPoolExecutor(1) as pool:
        res = sweep.run(lambda p: p, [1, 2], executor=pool, progress=False)
    assert len(res.failed) == 2 and res.values == (None, None)


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
