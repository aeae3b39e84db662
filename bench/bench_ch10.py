"""Chapter 10: the ZAD-controlled buck converter.

Scenarios:

* ``ch10_diagram_serial`` — the acceptance diagram of the duty against ``k_s`` (PL-ZAD,
  δ = 0.35, T = 0.18, x_ref = 0.8, u ∈ {-1, 1}; ``k_s`` from 0.05 to 8 by 0.005, 1 591 points,
  each started 1e-6 off its 1T orbit, 40 000 transient + 128 recorded periods) through
  ``analysis.duty_diagram`` in this process; wall time (goal: under 30 s) and the flip read
  off it against the bisected one;
* ``ch10_diagram_dask`` — the same on a ``LocalCluster`` with 1 and 2 worker processes (one
  thread each); parallel efficiency ``t1 / (2 t2)`` (goal: at least 0.85) and identity with
  the serial diagram;
* ``ch10_map_vs_switching`` — one period ``x_k -> x_{k+1}`` by the compiled closed form
  against the same map through ``simulate(closed_loop_switched, method="switching")`` (the
  generic PWM route: exact piecewise flows, with the duty law called from Python) on 200
  random states; both are exact, so they meet the 1e-9 accuracy of ``x_{k+1}`` at once
  (their difference is reported); ratio of the times per period.

Run: ``nscontrol bench ch10 --json`` (``--quick``: ``k_s`` step 0.05, 5 000 periods).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from nscontrol import simulate
from nscontrol.analysis.converter_orbits import brute_force_flip, duty_diagram
from nscontrol.design.converter_regulation import ZADController, critical_ks
from nscontrol.systems.buck import BuckConverter

DELTA, T, XREF = 0.35, 0.18, 0.8


def _grid(quick: bool) -> tuple[np.ndarray, int]:
    step = 0.05 if quick else 0.005
    return np.round(np.arange(0.05, 8.0 + step / 2, step), 6), (5_000 if quick else 40_000)


def _diagram(ks: np.ndarray, n_transient: int, executor: Any) -> Any:
    return duty_diagram(BuckConverter.normalized(DELTA), ks, T=T, x_ref=XREF,
                        n_transient=n_transient, n_record=128, chunk_size=50,
                        executor=executor, progress=False)


def _warm_worker() -> None:
    """Load the compiled kernels in a worker before the clock starts."""
    _diagram(np.array([5.0]), 10, "serial")


def _serial(quick: bool) -> tuple[dict[str, Any], Any]:
    ks, nt = _grid(quick)
    _warm_worker()
    t0 = time.perf_counter()
    dd = _diagram(ks, nt, "serial")
    seconds = time.perf_counter() - t0
    kc = critical_ks(BuckConverter.normalized(DELTA), T=T, x_ref=XREF)
    periods = ks.size * (nt + 128)
    return {"scenario": f"ch10_diagram_serial: duty against k_s, {ks.size} points x "
                        f"{nt} + 128 periods",
            "size": ks.size, "ours_s_per_solve": seconds, "reference": "goal: 30 s",
            "reference_s_per_solve": 30.0, "ratio": 30.0 / seconds,
            "accuracy": {"ns_per_period": seconds / periods * 1e9,
                         "flip_brute_force": brute_force_flip(dd), "flip_bisection": kc,
                         "failed_points": len(dd.diagram.errors)}}, dd


def _dask(quick: bool, serial: Any) -> dict[str, Any]:
    ks, nt = _grid(quick)
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - optional extra
        return {"scenario": "ch10_diagram_dask", "size": ks.size, "ours_s_per_solve": None,
                "reference": None, "reference_s_per_solve": None, "ratio": None,
                "accuracy": {}, "note": "dask[distributed] not installed"}
    times: dict[int, float] = {}
    same = True
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            client.run(_warm_worker)
            t0 = time.perf_counter()
            dd = _diagram(ks, nt, client)
            times[workers] = time.perf_counter() - t0
            same = same and bool(np.array_equal(dd.duty_ratios, serial.duty_ratios,
                                                equal_nan=True))
    return {"scenario": "ch10_diagram_dask: the same diagram on 2 Dask workers",
            "size": ks.size, "ours_s_per_solve": times[2], "reference": "1 Dask worker",
            "reference_s_per_solve": times[1], "ratio": times[1] / times[2],
            "accuracy": {"parallel_efficiency": times[1] / (2 * times[2]),
                         "identical_to_serial": same}}


def _map_vs_switching(quick: bool) -> dict[str, Any]:
    n = 50 if quick else 200
    rng = np.random.default_rng(10)
    X = np.column_stack([rng.uniform(0.5, 1.1, n), rng.uniform(-0.3, 0.3, n)])
    ctrl = ZADController(BuckConverter.normalized(DELTA), 5.0, T, XREF)
    loop, sw = ctrl.loop(), ctrl.switched()
    loop(X[0])
    simulate(sw, X[0], (0.0, T), method="switching")             # warm both routes
    t0 = time.perf_counter()
    ours = np.array([loop(x) for x in X])
    t_ours = (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    ref = np.array([simulate(sw, x, (0.0, T), method="switching", n_samples=2).x[-1]
                    for x in X])
    t_ref = (time.perf_counter() - t0) / n
    # the map in a loop without Python calls per period (what diagrams use)
    rec = loop.run(X[0], 10, n_transient=10)
    t0 = time.perf_counter()
    loop.run(X[0], 1, n_transient=100_000)
    t_kernel = (time.perf_counter() - t0) / 100_000
    return {"scenario": "ch10_map_vs_switching: one period x_k -> x_{k+1}, compiled closed "
                        "form vs simulate(method='switching')",
            "size": n, "ours_s_per_solve": t_ours, "reference": "simulate(method='switching')",
            "reference_s_per_solve": t_ref, "ratio": t_ref / t_ours,
            "accuracy": {"max_abs_difference": float(np.max(np.abs(ours - ref))),
                         "required": 1e-9, "kernel_loop_s_per_period": t_kernel,
                         "ratio_kernel_loop": t_ref / t_kernel,
                         "recorded_periods": int(rec.duties.size)}}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    record, serial = _serial(quick)
    yield record
    yield _dask(quick, serial)
    yield _map_vs_switching(quick)
