"""Periodic orbits: brute-force bifurcation diagram (serial, Dask), continuation, scipy.

Scenarios
---------
* ``orbits_bruteforce_serial`` — the impact oscillator's diagram, 1000 values of ``F`` (200
  transient + 100 sampled periods each, one sweep direction), serial.
* ``orbits_bruteforce_scipy`` — the same points with ``scipy.integrate.solve_ivp`` (DOP853,
  ``rtol=1e-10``, a terminal event at the stop and a restart after each impact) on every
  ``stride``-th value; speed ratio per point, and the largest difference of the sampled
  points where both settled on a period-1 or period-2 orbit (chaotic windows diverge by
  nature and are left out).
* ``orbits_bruteforce_dask`` — the serial diagram on a ``LocalCluster`` with 1 and 2 worker
  processes (one thread each); parallel efficiency ``t1 / (2 t2)``.
* ``orbits_continuation_flip`` — continuation of the impacting branch from ``F = 2.2`` down
  through the flip to grazing (steps, corrector iterations, time, errors against the closed
  forms); reference: brute-force bisection of the flip (each trial 200 + 100 periods,
  period-1 vs period-2), the time it takes and the accuracy it reaches.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np

from nscontrol.analysis.bifurcation import bifurcation_diagram
from nscontrol.analysis.continuation import continue_orbit
from nscontrol.analysis.periodic import period_multiplicity
from nscontrol.examples.impact_oscillator_bifurcation import bifurcation_family

N_TRANSIENT, N_SAMPLE = 200, 100


def _diagram(values: np.ndarray, executor: Any = "serial", chunk: int = 100) -> Any:
    return bifurcation_diagram(bifurcation_family("forcing"), values, n_transient=N_TRANSIENT,
                               n_sample=N_SAMPLE, directions=("up",), chunk_size=chunk,
                               executor=executor, progress=False, parameter_name="F")


def _scipy_point(F: float, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stroboscopic samples by DOP853 with impact events and restarts."""
    from scipy.integrate import solve_ivp

    osc = bifurcation_family("forcing").oscillator(F)
    m, c, k, w, d, r = (osc.mass, osc.damping, osc.stiffness, osc.omega, osc.stop,
                        osc.restitution)

    def rhs(t: float, x: np.ndarray) -> list[float]:
        return [x[1], (F * np.cos(w * t) - c * x[1] - k * x[0]) / m]

    def hit(t: float, x: np.ndarray) -> float:
        return x[0] - d
    hit.terminal, hit.direction = True, 1.0

    T = osc.period
    samples = T * np.arange(N_TRANSIENT, N_TRANSIENT + N_SAMPLE + 1)
    out, t, x = [], 0.0, np.asarray(x0, float)
    tf = samples[-1]
    while t < tf:
        sol = solve_ivp(rhs, (t, tf), x, method="DOP853", rtol=1e-10, atol=1e-12,
                        events=hit, dense_output=True)
        seg_end = sol.t[-1]
        mask = (samples >= t) & (samples <= seg_end)
        out.extend(sol.sol(samples[mask]).T[:, :] if mask.any() else [])
        samples = samples[~mask]
        x = sol.y[:, -1].copy()
        t = seg_end
        if sol.status == 1:
            if x[1] < 1e-7 and F * np.cos(w * t) - k * d >= 0.0:
                # impacts accumulate while the force presses the mass on the stop: it sticks
                # until F cos(ωt) falls below k d (the same Zeno exit as event_driven)
                t = _release_time(t, F, w, k * d)
                held = (samples >= sol.t[-1]) & (samples <= t)
                out.extend([[d, 0.0]] * int(held.sum()))
                samples = samples[~held]
                x = np.array([d, 0.0])
            else:
                x[1] = -r * x[1]
            x[0] = d - 1e-15          # just inside, so the event does not fire again at once
    X = np.array(out)
    return X[:-1], X[-1]


def _warm_worker() -> None:
    """Run a few points in this process (numba caches, imports) before timing."""
    _diagram(np.linspace(0.2, 2.2, 4), chunk=2)


def _release_time(t: float, F: float, w: float, kd: float) -> float:
    """First time after ``t`` with ``F cos(ωs) = kd`` and the force decreasing."""
    if F <= kd:
        return np.inf
    phase = np.arccos(kd / F)                  # cos(ωs) = kd/F, decreasing at ωs = phase
    n = np.ceil((w * t - phase) / (2 * np.pi))
    return float((phase + 2 * np.pi * n) / w)


def _brute_bisection(lo: float, hi: float, rtol: float) -> tuple[float, int, float]:
    """Bisection of the flip by brute force: period 1 above, not period 1 below; each trial
    starts on the attractor of the last period-1 trial (a cold start may reach the period-6
    attractor coexisting there)."""
    fam = bifurcation_family("forcing")
    x = fam.oscillator(hi).admissible_orbit().x0
    trials, t0 = 0, time.perf_counter()
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        bd = bifurcation_diagram(fam, [mid], n_transient=N_TRANSIENT, n_sample=N_SAMPLE,
                                 directions=("up",), x0=x, progress=False)
        trials += 1
        if bd.multiplicity[0, 0] == 1:
            hi, x = mid, bd.points[0, 0, -1]     # warm start from the last period-1 attractor
        else:
            lo = mid
    return 0.5 * (lo + hi), trials, time.perf_counter() - t0


def run(quick: bool = False) -> Iterator[dict]:
    n = 100 if quick else 1000
    values = np.linspace(0.2, 2.2, n)
    _diagram(values[:4])                                        # warm caches and compilation
    t0 = time.perf_counter()
    bd = _diagram(values)
    t_serial = time.perf_counter() - t0
    yield {"scenario": "orbits_bruteforce_serial", "size": n, "ours_s_per_solve": t_serial,
           "reference": None, "reference_s_per_solve": None, "ratio": None,
           "accuracy": {"failed_points": len(bd.errors),
                        "periods_per_point": N_TRANSIENT + N_SAMPLE}}

    stride = 50 if quick else 20
    idx = np.arange(0, n, stride)
    t0 = time.perf_counter()
    ref = [_scipy_point(values[i], np.zeros(2))[0] for i in idx]
    t_scipy = (time.perf_counter() - t0) / len(idx)
    t0 = time.perf_counter()
    ours = _diagram(values[idx], chunk=1)     # cold starts, as the scipy runs
    t_ours = (time.perf_counter() - t0) / len(idx)
    settled = [j for j, i in enumerate(idx) if ours.multiplicity[0, j] in (1, 2)
               and period_multiplicity(ref[j], rtol=1e-6) == ours.multiplicity[0, j]]
    diff = max((float(np.max(np.abs(ours.points[0, j] - ref[j]))) for j in settled),
               default=float("nan"))
    yield {"scenario": "orbits_bruteforce_scipy", "size": len(idx),
           "ours_s_per_solve": t_ours, "reference": "scipy DOP853+events+restarts",
           "reference_s_per_solve": t_scipy, "ratio": t_scipy / t_ours,
           "accuracy": {"max_sample_difference_settled": diff, "settled_points": len(settled),
                        "scipy_rtol": 1e-10}}

    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - optional extra
        yield {"scenario": "orbits_bruteforce_dask", "size": n, "ours_s_per_solve": None,
               "reference": None, "reference_s_per_solve": None, "ratio": None,
               "accuracy": {}, "note": "dask[distributed] not installed"}
    else:
        times = {}
        for workers in (1, 2):
            with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster, Client(cluster) as client:
                client.run(_warm_worker)      # every worker loads the compiled kernels
                t0 = time.perf_counter()
                bd_d = _diagram(values, executor=client)
                times[workers] = time.perf_counter() - t0
        yield {"scenario": "orbits_bruteforce_dask", "size": n,
               "ours_s_per_solve": times[2], "reference": "same on 1 Dask worker",
               "reference_s_per_solve": times[1], "ratio": times[1] / times[2],
               "accuracy": {"parallel_efficiency": times[1] / (2 * times[2]),
                            "identical_to_serial": bool(np.array_equal(
                                bd_d.points, bd.points, equal_nan=True))}}

    fam = bifurcation_family("forcing")
    osc = fam.base
    Fg = osc.grazing_forcing()
    F_flip = osc.flip_forcing((1.1 * Fg, 4 * Fg))
    x_hi = osc.with_(forcing=2.2).admissible_orbit().x0
    t0 = time.perf_counter()
    br = continue_orbit(fam, 2.2, x_hi, p_range=(0.9 * Fg, 3.0), step=0.05, step_max=0.2,
                        direction=-1, parameter_name="F", locate_tol=1e-6)
    t_cont = time.perf_counter() - t0
    flip = br.special("flip")[0]
    graze = br.special("grazing")[0]
    F_bis, trials, t_bis = _brute_bisection(1.0, 2.2, 1e-6)
    yield {"scenario": "orbits_continuation_flip", "size": br.n_steps,
           "ours_s_per_solve": t_cont, "reference": "brute-force bisection (300 periods/trial)",
           "reference_s_per_solve": t_bis, "ratio": t_bis / t_cont,
           "accuracy": {"flip_rel_error": abs(flip.parameter - F_flip) / F_flip,
                        "grazing_rel_error": abs(graze.parameter - Fg) / Fg,
                        "corrector_iterations": br.corrector_iterations,
                        "bisection_trials": trials,
                        "bisection_rel_error": abs(F_bis - F_flip) / F_flip}}
