"""Class 5: a sweep never loses its healthy points.

A worker that dies (``os._exit``, SIGSEGV) costs only its own point; ``SystemExit`` is a
point's error; ``KeyboardInterrupt`` propagates with the finished points attached; a typo in
an executor name, a non-iterable grid and a value that cannot travel back are reported with
the argument or point they concern. Values are compared exactly (integers and the bits of
``math.sqrt``, the same function in every process).
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor

import numpy as np
import pytest

import nscontrol.sweep as sweep_mod
from nscontrol import sweep
from nscontrol.errors import ModelError

N = 12



def _exit_at_3(p):
    if p == 3:
        os._exit(7)
    return p * p


def _exit_at_0_and_11(p):
    if p in (0, 11):
        os._exit(1)
    return p * p


def _slow_exit_at_3(p):
    import time

    time.sleep(0.05)
    return _exit_at_3(p)


def _segfault_at_5(p):
    if p == 5:
        import faulthandler

        faulthandler.disable()          # a real crash, without pytest's traceback dump
        os.kill(os.getpid(), signal.SIGSEGV)
    return p * p


def _exit_at_2_5_8(p):
    if p in (2, 5, 8):
        os._exit(3)
    return p * p


def _sys_exit_at_4(p):
    if p == 4:
        sys.exit(2)
    if p == 6:
        sys.exit(0)
    return p * p


def _interrupt_at_3(p):
    if p == 3:
        raise KeyboardInterrupt
    return p * p


def _lock_at_2(p):
    return threading.Lock() if p == 2 else p * p


def _identity(p):
    return p


def assert_healthy_points_kept(res, bad: set[int]) -> None:
    """Every point outside ``bad`` has its exact value; every point in it an error."""
    assert len(res) == N
    for i in range(N):
        if i in bad:
            assert res.values[i] is None and res.errors[i] is not None, i
        else:
            assert res.errors[i] is None and res.values[i] == i * i, (i, res.errors[i])


# ----------------------------------------------------------------------------- crashes


@pytest.mark.parametrize(("fn", "bad"), [(_exit_at_3, {3}), (_exit_at_0_and_11, {0, 11}),
                                         (_segfault_at_5, {5}), (_exit_at_2_5_8, {2, 5, 8})])
def test_dead_worker_costs_only_its_point(fn, bad):
    res = sweep.run(fn, range(N), progress=False)
    assert_healthy_points_kept(res, bad)
    for i in bad:
        e = res.errors[i]
        assert e.type == "WorkerDied" and f"point {i}" in e.message and "died" in e.message


def test_dead_worker_in_a_user_pool_and_in_auto():
    with ProcessPoolExecutor(max_workers=2) as pool:
        assert_healthy_points_kept(sweep.run(_exit_at_3, range(N), executor=pool,
                                             progress=False), {3})



@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="'auto' stays serial on one CPU, where "
                    "os._exit would end the test process itself")
def test_dead_worker_in_auto_pool():
    # the pilot (point 0, 0.05 s) predicts 0.55 s > AUTO_PARALLEL_SECONDS: the rest go to a pool
    res = sweep.run(_slow_exit_at_3, range(N), executor="auto", progress=False)
    assert_healthy_points_kept(res, {3})


def test_restarts_are_bounded(monkeypatch):
    monkeypatch.setattr(sweep_mod, "MAX_POOL_RESTARTS", 1)
    res = sweep.run(_exit_at_2_5_8, range(N), progress=False)
    assert len(res) == N
    for i in range(N):                    # every point settled: a value or a stated error
        assert (res.errors[i] is None) == (res.values[i] is not None)
        if res.errors[i] is None:
            assert res.values[i] == i * i
        elif res.errors[i].type != "WorkerDied":
            assert "executor='serial'" in res.errors[i].message
            assert "MAX_POOL_RESTARTS = 1 fresh pools spent" in res.errors[i].message
    assert all(res.errors[i] is not None for i in (2, 5, 8))


# ----------------------------------------------------------------------------- BaseException


@pytest.mark.parametrize("executor", ["serial", "threads", "processes"])
def test_system_exit_is_a_point_error(executor):
    if executor == "threads":
        with ThreadPoolExecutor(2) as pool:
            res = sweep.run(_sys_exit_at_4, range(N), executor=pool, progress=False)
    else:
        res = sweep.run(_sys_exit_at_4, range(N), executor=None if executor == "processes"
                        else executor, progress=False)
    assert_healthy_points_kept(res, {4, 6})
    assert res.errors[4].type == "SystemExit" and "sys.exit(2)" in res.errors[4].message
    assert "sys.exit(0)" in res.errors[6].message


def test_keyboard_interrupt_keeps_finished_points_serial():
    with pytest.raises(KeyboardInterrupt) as info:
        sweep.run(_interrupt_at_3, range(N), executor="serial", progress=False)
    partial = info.value.sweep_result
    assert partial.values[:3] == (0, 1, 4)
    assert all(e.type == "KeyboardInterrupt" for e in partial.errors[3:])
    assert any("err.sweep_result" in n for n in info.value.__notes__)


@pytest.mark.parametrize("executor", ["threads", "processes"])
def test_keyboard_interrupt_keeps_finished_points_parallel(executor):
    with pytest.raises(KeyboardInterrupt) as info:
        if executor == "threads":
            with ThreadPoolExecutor(2) as pool:
                sweep.run(_interrupt_at_3, range(N), executor=pool, progress=False)
        else:
            sweep.run(_interrupt_at_3, range(N), progress=False)
    partial = info.value.sweep_result
    assert partial.errors[3].type == "KeyboardInterrupt"
    for i in range(N):    # which points finished depends on scheduling; none is wrong
        assert (partial.values[i] == i * i) if partial.errors[i] is None \
            else partial.values[i] is None


# ----------------------------------------------------------------------------- arguments


@pytest.mark.parametrize(("name", "hint"), [("seriall", "did you mean 'serial'"),
                                            ("Serial", "did you mean 'serial'"),
                                            ("autoo", "did you mean 'auto'"),
                                            ("localhost", ""), ("tcp://host", ""),
                                            ("host:99999", ""), ("http://h:8786", ""),
                                            ("", "")])
def test_executor_typo_refused(name, hint):
    with pytest.raises(ModelError) as info:
        sweep.run(_identity, [1, 2], executor=name, progress=False)
    msg = str(info.value)
    assert msg.startswith("executor:") and "tcp://host:port or host:port" in msg
    assert hint in msg


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "scheduler:8786", "[::1]:8786",
                                     "tls://a.example.org:1", "inproc://10.0.0.1/123/1"])
def test_scheduler_addresses_accepted(address):
    sweep_mod._check_executor(address)        # no exception; nothing is dialled here


@pytest.mark.parametrize("grid", [5, None, 3.0, np.float64(1.0), "abc", b"ab"])
def test_grid_must_be_an_iterable_of_points(grid):
    with pytest.raises(ModelError) as info:
        sweep.run(_identity, grid, executor="serial", progress=False)
    msg = str(info.value)
    assert msg.startswith("grid:") and ("[point]" in msg or "list of points" in msg)


# ----------------------------------------------------------------------------- values


@pytest.mark.parametrize("executor", [None, "pool"])
def test_unpicklable_value_names_its_point(executor):
    if executor == "pool":
        with ProcessPoolExecutor(2) as pool:
            res = sweep.run(_lock_at_2, range(N), executor=pool, progress=False)
    else:
        res = sweep.run(_lock_at_2, range(N), progress=False)
    assert_healthy_points_kept(res, {2})
    msg = res.errors[2].message
    assert "value fn returned for point 2" in msg and "cannot be sent back" in msg
    assert "_thread.lock" in msg and "executor='serial'" in msg


def test_unpicklable_value_is_fine_in_threads():
    with ThreadPoolExecutor(2) as pool:
        res = sweep.run(_lock_at_2, range(4), executor=pool, progress=False)
    assert res.ok and isinstance(res.values[2], type(threading.Lock()))


def test_unpicklable_point_is_named():
    grid = [1, threading.Lock(), 3]
    res = sweep.run(_identity, grid, progress=False)
    assert res.values[0] == 1 and res.values[2] == 3
    assert "point 1 cannot be pickled" in res.errors[1].message


def test_math_sqrt_values_exact_through_processes():
    res = sweep.run(math.sqrt, [2.0, 3.0], progress=False)
    assert res.values == (math.sqrt(2.0), math.sqrt(3.0))


# ----------------------------------------------------------------------------- time budget

#: Seconds: a healthy point here takes microseconds, a hanging one forever; 2 s keeps a
#: healthy point clear of the budget even on a machine descheduling workers under load.
BUDGET = 2.0


def _hang_at_3(p):
    if p == 3:
        import time

        time.sleep(3600)
    return p * p


def _hang_at_3_and_8(p):
    return _hang_at_3(3 if p == 8 else p) if p in (3, 8) else p * p


def _hang_at_3_exit_at_8(p):
    if p == 8:
        os._exit(5)
    return _hang_at_3(p)


def assert_over_budget(res, bad: set[int]) -> None:
    for i in bad:
        e = res.errors[i]
        assert e.type == "BudgetExceededError", e
        assert f"point {i} ran longer than point_timeout={BUDGET:g} s" in e.message
        assert "raise point_timeout" in e.message


@pytest.mark.parametrize("executor", [None, "auto", "pool"])
def test_point_over_its_time_budget_is_recorded_and_stopped(executor):
    import time

    start = time.perf_counter()
    if executor == "pool":
        with ProcessPoolExecutor(max_workers=2) as pool:
            res = sweep.run(_hang_at_3, range(N), executor=pool, point_timeout=BUDGET,
                            progress=False)
    else:
        res = sweep.run(_hang_at_3, range(N), executor=executor, point_timeout=BUDGET,
                        progress=False)
    elapsed = time.perf_counter() - start
    assert_healthy_points_kept(res, {3})
    assert_over_budget(res, {3})
    # stopped within 1.25 budgets (the look every budget/4), plus pools started and ended:
    # nowhere near the hour the point would sleep
    assert elapsed < 1.25 * BUDGET + 60.0


def test_ended_workers_do_not_spend_the_restart_budget(monkeypatch):
    """Two points over budget with no restart allowed: their workers are ended, each
    settling its point, and every other point still gets its value."""
    monkeypatch.setattr(sweep_mod, "MAX_POOL_RESTARTS", 0)
    res = sweep.run(_hang_at_3_and_8, range(N), point_timeout=BUDGET, progress=False)
    assert_healthy_points_kept(res, {3, 8})
    assert_over_budget(res, {3, 8})


def test_time_budget_and_a_dead_worker_in_one_sweep():
    res = sweep.run(_hang_at_3_exit_at_8, range(N), point_timeout=BUDGET, progress=False)
    assert_healthy_points_kept(res, {3, 8})
    assert_over_budget(res, {3})
    assert res.errors[8].type == "WorkerDied"


@pytest.mark.parametrize("executor", ["serial", "threads", "tcp://scheduler:8786"])
def test_time_budget_refused_where_a_point_cannot_be_stopped(executor):
    with ThreadPoolExecutor(2) as threads:
        with pytest.raises(ModelError) as info:
            sweep.run(_identity, [1, 2], point_timeout=1.0, progress=False,
                      executor=threads if executor == "threads" else executor)
    msg = str(info.value)
    assert msg.startswith("point_timeout:") and "local process pools" in msg
    assert "Dask" in msg


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "1", True])
def test_time_budget_must_be_a_positive_number(bad):
    with pytest.raises(ModelError, match="^point_timeout: expected"):
        sweep.run(_identity, [1], point_timeout=bad, progress=False)
