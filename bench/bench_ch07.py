"""Chapter 7: the one-link robot with friction compensation and a reduced-order observer.

Scenarios:

* the reference example's 10 s set-point run (Stribeck friction, h = 1e-4, exact
  compensation): our steps/s with the blocks' compiled forms (the default) against the same
  loop with their Python methods (``closed_loop(..., compiled=False)``), in the same run (no
  Siconos counterpart of the set-valued Stribeck law);
* the same loop on Coulomb friction (T_s = T_c = 0.2, no viscous term), T = 2 s, on the
  default path (``simulate_friction_loop``, i.e. ``nscontrol.simulate`` of ``friction_loop``:
  the compiled blocks; ``accuracy.path`` says which ran) against Siconos (relay Lur'e
  system by EulerMoreauOSI + Relay, the same controller and observer written again in its
  script, the torque held in the system's ``b``): steps/s of both and
  ``max |theta_ours - theta_siconos|`` (our compiled blocks, and the Python ones);
* the kappa diagram (kappa in [0, 1.5], set-point runs at h = 1e-3, T = 10, ~30 ms each):
  wall time serial, on 2 local worker processes and on 2 Dask workers (a ``LocalCluster``,
  one thread each, both warm, when ``dask.distributed`` is installed), all through
  ``nscontrol.sweep``; ``parallel_efficiency`` is ``t_serial / (2 t_dask)`` with the points
  chunked as ``sweep.run`` chooses, beside the same with one point per task (``chunk=1``),
  and the values of every run compared bit for bit with the serial ones; three paired
  rounds (serial, processes, Dask), each round's efficiency from its own serial time,
  medians and ranges reported with the load average;
* the chapter 7 example end to end (``nscontrol run ch07``, without figures; not with
  ``--quick``): its wall time.

Run: ``nscontrol bench ch07 --json`` (``--quick``: 21 kappa points, 2 s runs).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from harness import (
    dask_client,
    efficiency,
    run_siconos,
    siconos_available,
    siconos_version,
    warm_workers,
)

from nscontrol import sweep
from nscontrol.design.friction_compensation import PDLaw, SetPoint, simulate_friction_loop
from nscontrol.examples import ch07_friction_compensation as ex
from nscontrol.laws import Stribeck
from nscontrol.systems import OneLinkRobot

P = ex.REFERENCE


def _timed(fn: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _loop_speed(robot: Any, pd: Any, h: float, T: float, kappa: float) -> tuple[Any, float,
                                                                                  float]:
    """The run with compiled blocks, its steps/s and the Python blocks' steps/s."""
    def once(T_run: float, compiled: bool = True) -> Any:
        return simulate_friction_loop(robot, pd, l=P["l"], kappa=kappa, h=h, T=T_run,
                                      compiled=compiled)
    once(0.01)                                           # warm-up (compiled kernels)
    run, seconds = _timed(lambda: once(T))
    steps = run.t.size - 1
    T_py = min(T, 2.0)                                   # the Python blocks: a shorter run
    py, py_seconds = _timed(lambda: once(T_py, compiled=False))
    return run, steps / seconds, (py.t.size - 1) / py_seconds


def _reference_run(quick: bool) -> dict[str, Any]:
    T = 2.0 if quick else P["T"]
    robot = OneLinkRobot(P["J"], ex.reference_friction())
    pd = PDLaw(P["kp"], P["kd"], P["J"], SetPoint(P["theta_r"]))
    run, ours, python = _loop_speed(robot, pd, P["h"], T, 1.0)
    return {"scenario": f"ch07 set-point run, Stribeck, h = {P['h']:g}, T = {T:g}: compiled "
                        f"blocks vs the same blocks in Python",
            "size": run.t.size - 1, "ours_steps_per_s": ours,
            "reference": "python blocks (closed_loop(..., compiled=False))",
            "reference_steps_per_s": python, "ratio": ours / python,
            "note": "no Siconos counterpart of the set-valued Stribeck law",
            "accuracy": {"final_error": float(abs(run.error[-1])),
                         "path": run.trajectory.stats["controller"]}}


def _coulomb_run(quick: bool) -> dict[str, Any]:
    T, h, Tc, kappa = 2.0, P["h"], 0.2, 1.0
    robot = OneLinkRobot(P["J"], Stribeck(Tc, Tc, 1.0, 2.0, 0.0))
    pd = PDLaw(P["kp"], P["kd"], P["J"], SetPoint(P["theta_r"]))
    run, ours, python = _loop_speed(robot, pd, h, T, kappa)
    steps = run.t.size - 1
    record: dict[str, Any] = {
        "scenario": f"ch07 one-link, Coulomb friction, PD + compensation + observer, "
                    f"h = {h:g}, T = {T:g}",
        "size": steps, "ours_steps_per_s": ours, "reference": None,
        "reference_steps_per_s": None, "ratio": None,
        "accuracy": {"python_blocks_steps_per_s": python,
                     "path": run.trajectory.stats["controller"]}}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    sic = run_siconos("ch07_one_link.py", {
        "J": P["J"], "Tc": Tc, "kp": P["kp"], "kd": P["kd"], "l": P["l"], "kappa": kappa,
        "theta_r": P["theta_r"], "theta0": 0.0, "h": h, "T": T,
        "repeats": 1 if quick else 3})[-1]
    theirs = np.array(sic["theta"])
    n = min(theirs.size, run.theta.size)
    theirs_speed = sic["steps"] / sic["seconds"]
    record.update(reference=siconos_version() + " EulerMoreauOSI + Relay (Python loop)",
                  reference_steps_per_s=theirs_speed, ratio=ours / theirs_speed)
    record["accuracy"].update(
        max_theta_difference=float(np.max(np.abs(run.theta[:n] - theirs[:n]))),
        python_blocks_ratio=python / theirs_speed)
    return record


def _same(a: Any, b: Any) -> bool:
    """Two sweeps of the diagram gave the same values, bit for bit (NaN where NaN)."""
    return bool(np.array_equal(np.asarray(a.values, float), np.asarray(b.values, float),
                               equal_nan=True))


def _rounds(kappas: list[float], pool: Any, client: Any, rounds: int
            ) -> tuple[list[tuple[float, float, float]], Any, bool]:
    """``rounds`` paired rounds of (serial, 2 processes, 2 Dask workers) on warm workers:
    the times of each, the serial values and whether every run gave them bit for bit."""
    times, same, ser = [], True, None
    for _ in range(rounds):
        ser, t_ser = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor="serial",
                                              progress=False))
        par, t_par = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor=pool,
                                              progress=False))
        same &= _same(par, ser)
        t_dask = float("nan")
        if client is not None:
            dsk, t_dask = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor=client,
                                                   progress=False))
            same &= _same(dsk, ser)
        times.append((t_ser, t_par, t_dask))
    return times, ser, same


def _diagram(quick: bool) -> dict[str, Any]:
    """Serial, 2 processes and 2 Dask workers in paired rounds (each round's efficiency from
    its own serial time: the machine's speed drifts between rounds), medians reported."""
    import os
    import statistics

    kappas = list(np.linspace(0.0, 1.5, 21 if quick else ex.KAPPA_POINTS))
    ex.kappa_point(1.0)                                  # warm-up (compiled kernels)
    with ProcessPoolExecutor(2) as pool, dask_client() as client:
        list(pool.map(ex.kappa_point, [1.0, 1.0]))       # the same warm-up in each worker
        if client is not None:
            warm_workers(client, ex.kappa_point, 1.0)
        times, ser, same = _rounds(kappas, pool, client, 1 if quick else 3)
        single = None
        if client is not None:
            single, t_single = _timed(lambda: sweep.run(ex.kappa_point, kappas,
                                                        executor=client, chunk=1,
                                                        progress=False))
    serial = statistics.median(t for t, _, _ in times)
    parallel = statistics.median(t for _, t, _ in times)
    procs = [efficiency(s, p) for s, p, _ in times]
    accuracy: dict[str, Any] = {
        "serial_seconds": serial, "two_workers_seconds": parallel,
        "processes_efficiency": statistics.median(procs),
        "processes_efficiency_range": [min(procs), max(procs)],
        "serial_seconds_all": [t for t, _, _ in times],
        "processes_identical_to_serial": same, "load_average": os.getloadavg()[0]}
    if single is None:
        accuracy["dask_note"] = "dask.distributed not installed (the 'cluster' extra)"
    else:
        dask = [efficiency(s, d) for s, _, d in times]
        accuracy.update({
            "two_dask_workers_seconds": statistics.median(d for _, _, d in times),
            "parallel_efficiency": statistics.median(dask),
            "parallel_efficiency_range": [min(dask), max(dask)],
            "dask_seconds_all": [d for _, _, d in times],
            "dask_identical_to_serial": same and _same(single, ser),
            "dask_one_point_per_task_seconds": t_single,
            "parallel_efficiency_one_point_per_task": efficiency(serial, t_single)})
    return {"scenario": f"ch07 kappa diagram, {len(kappas)} runs of {ex.KAPPA_T:g} s at "
                        f"h = {ex.KAPPA_H:g}: serial vs 2 worker processes and 2 Dask "
                        f"workers (parallel_efficiency: serial / (2 x Dask), chunked points, "
                        f"median of {len(times)} paired rounds)",
            "size": len(kappas), "ours_steps_per_s": None, "reference": "serial",
            "reference_steps_per_s": None, "ratio": serial / parallel,
            "accuracy": accuracy}


def _example() -> dict[str, Any]:
    from nscontrol.examples import ch07_friction_compensation as module

    result, seconds = _timed(lambda: module.run(None))
    failed = [c.key for c in result.checks if not c.passed]
    return {"scenario": "ch07 example end to end (nscontrol run ch07, no figures)",
            "size": 1, "ours_steps_per_s": None, "reference": None,
            "reference_steps_per_s": None, "ratio": None,
            "note": "wall time of the example; target well under 60 s",
            "accuracy": {"seconds": seconds, "failed_checks": failed}}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    yield _reference_run(quick)
    yield _coulomb_run(quick)
    yield _diagram(quick)
    if not quick:
        yield _example()
