"""Chapter 12: corner control of limit cycles.

Scenarios:

* ``ch12_design_loop`` — the nine designs of the convergence study (examples A and B, three
  offsets each), each designed and verified by shooting: seconds per design, serial against
  2 local worker processes (``nscontrol.sweep``);
* ``ch12_corner_diagram`` — the controlled cycle against the corner position (example A,
  k of the λ_d = 0.5, z_d = 0.005 design, 8 corner offsets, shooting each): serial against
  2 worker processes;
* ``ch12_dask`` — both on a Dask ``LocalCluster`` with 2 workers (one thread each, both warm)
  against serial: ``parallel_efficiency`` ``t_serial / (2 t_dask)`` per sweep and over both,
  the points chunked as ``nscontrol.sweep.run`` chooses, values compared bit for bit;
  three paired rounds (serial, then Dask), medians and ranges with the load average.

Every timed run follows a warm-up in the same process (compiled kernels, imports).

No Siconos counterpart: the corner controller is a Filippov system with a codimension-2
corner, which we integrate with our own event-driven Filippov integrator.

Run: ``nscontrol bench ch12 --json`` (``--quick``: 3 designs, 3 corner offsets).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

import numpy as np
from harness import dask_client, efficiency, warm_workers

from nscontrol import sweep
from nscontrol.analysis.corner_maps import CornerFamily, corner_diagram
from nscontrol.examples import ch12_corner_control as ex


def _timed(fn: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _targets(quick: bool) -> list[tuple[str, float, float]]:
    return list(ex.DESIGN_TARGETS[:: 3] if quick else ex.DESIGN_TARGETS)


def _mus(quick: bool) -> list[float]:
    return [0.001, 0.002, 0.004] if quick else list(np.geomspace(0.0005, 0.008, 8))


def _family() -> CornerFamily:
    d = ex.design_a(0.005)
    return CornerFamily(d.site, d.system.b, d.k)


def _design_loop(targets: list[Any], executor: Any) -> tuple[Any, float]:
    return _timed(lambda: sweep.run(ex.design_point, targets, executor=executor,
                                    progress=False))


def _same_diagram(a: Any, b: Any) -> bool:
    """Two corner diagrams are equal bit for bit (NaN where NaN)."""
    return all(np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)
               for k in ("offset", "offset_sigma", "multiplier", "q", "a"))


def _dask(targets: list[Any], mus: list[float], fam: CornerFamily, ser: Any, dia: Any,
          rounds: int) -> dict[str, Any]:
    """Both sweeps on a 2-worker Dask ``LocalCluster`` (each worker as warm as this process:
    every point run once), in ``rounds`` paired rounds of (serial designs, serial
    diagram, Dask designs, Dask diagram); each round's efficiency from its own serial times
    (the machine's speed drifts between rounds), medians and ranges reported."""
    import os
    import statistics

    with dask_client() as client:
        if client is None:  # pragma: no cover - optional extra
            return {"scenario": "ch12_dask", "size": len(mus), "ours_s_per_solve": None,
                    "reference": None, "reference_s_per_solve": None, "ratio": None,
                    "accuracy": {}, "note": "dask[distributed] not installed"}
        # as warm as this process, which has run every point before (the serial and
        # process-pool scenarios): each worker runs both sweeps once, serially
        warm_workers(client, sweep.run, ex.design_point, targets, executor="serial",
                     progress=False)
        warm_workers(client, corner_diagram, fam, mus)
        times, same_des, same_dia = [], True, True
        for _ in range(rounds):
            _, t_ser = _design_loop(targets, "serial")
            _, t_dser = _timed(lambda: corner_diagram(fam, mus))
            des, t_designs = _design_loop(targets, client)
            dia3, t_dia = _timed(lambda: corner_diagram(fam, mus, executor=client))
            same_des &= des.values == ser.values
            same_dia &= _same_diagram(dia, dia3)
            times.append((t_ser, t_dser, t_designs, t_dia))
    med = [statistics.median(t[k] for t in times) for k in range(4)]
    both = [efficiency(a + b, c + d) for a, b, c, d in times]
    designs = [efficiency(a, c) for a, _, c, _ in times]
    diagram = [efficiency(b, d) for _, b, _, d in times]
    return {"scenario": f"ch12_dask (median of {rounds} paired rounds)",
            "size": len(targets) + len(mus),
            "ours_s_per_solve": med[2] / len(targets), "reference": "serial",
            "reference_s_per_solve": med[0] / len(targets), "ratio": med[0] / med[2],
            "accuracy": {"designs_serial_seconds": med[0], "designs_dask_seconds": med[2],
                         "diagram_serial_seconds": med[1], "diagram_dask_seconds": med[3],
                         "designs_parallel_efficiency": statistics.median(designs),
                         "diagram_parallel_efficiency": statistics.median(diagram),
                         "parallel_efficiency": statistics.median(both),
                         "parallel_efficiency_range": [min(both), max(both)],
                         "seconds_all": times, "load_average": os.getloadavg()[0],
                         "designs_identical_to_serial": same_des,
                         "diagram_identical_to_serial": same_dia},
            "note": "parallel_efficiency: serial / (2 x Dask) over both sweeps"}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    targets, mus = _targets(quick), _mus(quick)
    fam = _family()
    ex.design_point(targets[0])                    # warm-up (compiled kernels, imports)
    corner_diagram(fam, mus[:1])
    ser, t_ser = _design_loop(targets, "serial")
    with ProcessPoolExecutor(2) as pool:           # forked: the kernels are loaded
        par, t_par = _design_loop(targets, pool)
    yield {"scenario": "ch12_design_loop", "size": len(targets),
           "ours_s_per_solve": t_ser / len(targets), "reference": "serial",
           "reference_s_per_solve": None, "ratio": t_ser / t_par,
           "accuracy": {"serial_seconds": t_ser, "two_workers_seconds": t_par,
                        "processes_efficiency": efficiency(t_ser, t_par),
                        "identical_to_serial": par.values == ser.values,
                        "max_multiplier_error": max(abs(v["multiplier"] - t[1]) for v, t in
                                                    zip(ser.values, targets, strict=True))}}
    dia, t_dser = _timed(lambda: corner_diagram(fam, mus))
    with ProcessPoolExecutor(2) as pool:
        dia2, t_dpar = _timed(lambda: corner_diagram(fam, mus, executor=pool))
    q_err = np.abs(dia.offset_sigma / dia.mu / dia.q - 1.0)
    yield {"scenario": "ch12_corner_diagram", "size": len(mus),
           "ours_s_per_solve": t_dser / len(mus), "reference": "serial",
           "reference_s_per_solve": None, "ratio": t_dser / t_dpar,
           "accuracy": {"serial_seconds": t_dser, "two_workers_seconds": t_dpar,
                        "processes_efficiency": efficiency(t_dser, t_dpar),
                        "identical_to_serial": _same_diagram(dia, dia2),
                        "max_q_error": float(np.max(q_err))}}
    yield _dask(targets, mus, fam, ser, dia, 1 if quick else 3)
