"""Chapter 12: corner control of limit cycles.

Scenarios:

* ``ch12_design_loop`` — the nine designs of the convergence study (examples A and B, three
  offsets each), each designed and verified by shooting: seconds per design, serial against
  2 local worker processes (``nscontrol.sweep``);
* ``ch12_corner_diagram`` — the controlled cycle against the corner position (example A,
  k of the λ_d = 0.5, z_d = 0.005 design, 8 corner offsets, shooting each): serial against
  2 worker processes;
* ``ch12_dask`` — both on a Dask ``LocalCluster`` with 2 workers against serial.

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


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    targets, mus = _targets(quick), _mus(quick)
    fam = _family()
    ser, t_ser = _design_loop(targets, "serial")
    with ProcessPoolExecutor(2) as pool:
        par, t_par = _design_loop(targets, pool)
    same = [a == b for a, b in zip(ser.values, par.values, strict=True)]
    yield {"scenario": "ch12_design_loop", "size": len(targets),
           "ours_s_per_solve": t_ser / len(targets), "reference": "serial",
           "reference_s_per_solve": None, "ratio": t_ser / t_par,
           "accuracy": {"serial_seconds": t_ser, "two_workers_seconds": t_par,
                        "identical_to_serial": all(same),
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
                        "identical_to_serial": bool(np.array_equal(dia.offset, dia2.offset)),
                        "max_q_error": float(np.max(q_err))}}
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - optional extra
        yield {"scenario": "ch12_dask", "size": len(mus), "ours_s_per_solve": None,
               "reference": None, "reference_s_per_solve": None, "ratio": None,
               "accuracy": {}, "note": "dask[distributed] not installed"}
        return
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        client.submit(ex.design_point, targets[0]).result()      # warm the workers
        _, t_dask_designs = _design_loop(targets, client)
        dia3, t_dask_dia = _timed(lambda: corner_diagram(fam, mus, executor=client))
    yield {"scenario": "ch12_dask", "size": len(targets) + len(mus),
           "ours_s_per_solve": t_dask_designs / len(targets), "reference": "serial",
           "reference_s_per_solve": t_ser / len(targets), "ratio": t_ser / t_dask_designs,
           "accuracy": {"designs_serial_seconds": t_ser, "designs_dask_seconds": t_dask_designs,
                        "diagram_serial_seconds": t_dser, "diagram_dask_seconds": t_dask_dia,
                        "diagram_identical_to_serial": bool(np.array_equal(dia.offset,
                                                                           dia3.offset))}}
