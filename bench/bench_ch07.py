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
* the kappa diagram (kappa in [0, 1.5], set-point runs at h = 1e-3, T = 10): wall time
  serial, on 2 local worker processes and on 2 Dask workers (a ``LocalCluster``, when
  ``dask.distributed`` is installed), all through ``nscontrol.sweep``;
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
from harness import run_siconos, siconos_available, siconos_version

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


def _dask_seconds(kappas: list[float]) -> tuple[float | None, str]:
    """Wall time of the diagram on a 2-worker Dask ``LocalCluster`` (processes, one thread
    each), the cluster's start-up excluded; ``None`` and why when Dask is missing."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        return None, "dask.distributed not installed (the 'cluster' extra)"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        ex_dask = client.get_executor()
        sweep.run(ex.kappa_point, kappas[:2], executor=ex_dask, progress=False)   # warm-up
        _, seconds = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor=ex_dask,
                                              progress=False))
    return seconds, ""


def _diagram(quick: bool) -> dict[str, Any]:
    kappas = list(np.linspace(0.0, 1.5, 21 if quick else ex.KAPPA_POINTS))
    ex.kappa_point(1.0)                                  # warm-up (compiled kernels)
    _, serial = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor="serial",
                                         progress=False))
    with ProcessPoolExecutor(2) as pool:
        _, parallel = _timed(lambda: sweep.run(ex.kappa_point, kappas, executor=pool,
                                               progress=False))
    dask_seconds, why = _dask_seconds(kappas)
    accuracy: dict[str, Any] = {"serial_seconds": serial, "two_workers_seconds": parallel,
                                "two_dask_workers_seconds": dask_seconds}
    if why:
        accuracy["dask_note"] = why
    return {"scenario": f"ch07 kappa diagram, {len(kappas)} runs of {ex.KAPPA_T:g} s at "
                        f"h = {ex.KAPPA_H:g}: serial vs 2 worker processes (and 2 Dask "
                        f"workers)",
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
