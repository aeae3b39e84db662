"""Siconos side of bench_lcp.py: time Siconos's LCP solvers on the problems we are given.

Run by /usr/bin/python3 (Debian's python3-siconos, numpy 1.x). Reads JSON on stdin:
``{"problems": [{"name", "M_npy", "q_npy", "methods": ["lemke"|"pgs", ...]}],
"budget": seconds, "pgs_tol": float, "pgs_max_iter": int}`` and prints one JSON line per
(problem, method): ``{"name", "method", "s_per_solve", "whole_s_per_solve", "calls", "info",
"residual", "z"}``.

Two timings, both warm, each the median of single timed calls:

- ``s_per_solve``, the solver alone: the problem (``sn.LCP``) and the options built once,
  then ``lcp_lexicolemke`` / ``lcp_pgs`` on fresh ``z, w`` (what a caller reusing one
  problem pays per solve);
- ``whole_s_per_solve``, the whole Python call: build the problem and the options, allocate
  ``z, w``, solve (what ``solve_lcp(M, q)`` does on our side).
"""

import json
import sys
import time

import numpy as np
import siconos.numerics as sn


def residual(M, q, z):
    """max |min(z, Mz + q)| / (1 + max|q|): the figure nscontrol reports."""
    w = M @ z + q
    return float(np.max(np.abs(np.minimum(z, w)), initial=0.0) / (1.0 + np.max(np.abs(q))))


def options(method, pgs_tol, pgs_max_iter):
    if method == "lemke":
        return sn.SolverOptions(sn.SICONOS_LCP_LEMKE)
    so = sn.SolverOptions(sn.SICONOS_LCP_PGS)
    so.iparam[sn.SICONOS_IPARAM_MAX_ITER] = pgs_max_iter
    so.dparam[sn.SICONOS_DPARAM_TOL] = pgs_tol
    return so


SOLVERS = {"lemke": sn.lcp_lexicolemke, "pgs": sn.lcp_pgs}


def median_of_calls(fn, budget):
    """Median of individually timed calls (at most 200, within ``budget``), after one
    warm-up call, and the number of calls."""
    fn()
    times = []
    start = time.perf_counter()
    while True:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - start > budget or len(times) >= 200:
            break
    times.sort()
    return times[len(times) // 2], len(times)


def time_solve(M, q, method, budget, pgs_tol, pgs_max_iter):
    n = q.shape[0]
    fn = SOLVERS[method]
    lcp = sn.LCP(M, q)
    so = options(method, pgs_tol, pgs_max_iter)
    out = {}

    def solver_alone():
        z = np.zeros(n)
        w = np.zeros(n)
        out["info"] = fn(lcp, z, w, so)
        out["z"] = z

    def whole_call():
        problem = sn.LCP(M, q)
        opts = options(method, pgs_tol, pgs_max_iter)
        z = np.zeros(n)
        w = np.zeros(n)
        fn(problem, z, w, opts)
        return z

    alone, calls = median_of_calls(solver_alone, budget)
    whole, _ = median_of_calls(whole_call, budget)
    return alone, whole, calls, int(out["info"]), out["z"]


def main():
    payload = json.load(sys.stdin)
    for prob in payload["problems"]:
        M = np.ascontiguousarray(np.load(prob["M_npy"]))
        q = np.ascontiguousarray(np.load(prob["q_npy"]))
        for method in prob["methods"]:
            alone, whole, calls, info, z = time_solve(M, q, method, payload["budget"],
                                                      payload["pgs_tol"],
                                                      payload["pgs_max_iter"])
            print(json.dumps({"name": prob["name"], "method": method, "s_per_solve": alone,
                              "whole_s_per_solve": whole, "calls": calls, "info": info,
                              "residual": residual(M, q, z), "z": z.tolist()}), flush=True)


if __name__ == "__main__":
    main()
