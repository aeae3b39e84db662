"""Siconos side of bench_lcp.py: time Siconos's LCP solvers on the problems we are given.

Run by /usr/bin/python3 (Debian's python3-siconos, numpy 1.x). Reads JSON on stdin:
``{"problems": [{"name", "M_npy", "q_npy", "methods": ["lemke"|"pgs", ...]}],
"budget": seconds, "pgs_tol": float, "pgs_max_iter": int}`` and prints one JSON line per
(problem, method): ``{"name", "method", "s_per_solve", "calls", "info", "residual", "z"}``.
"""

import json
import sys
import time

import numpy as np
import siconos.numerics as sn


def residual(M, q, z):
    """max |min(z, Mz + q)| / (1 + max|q|): the figure nscontrol reports."""
    w = M @ z + q
    return float(np.max(np.abs(np.minimum(z, w))) / (1.0 + np.max(np.abs(q))))


def solver(method, pgs_tol, pgs_max_iter):
    if method == "lemke":
        return sn.lcp_lexicolemke, sn.SolverOptions(sn.SICONOS_LCP_LEMKE)
    options = sn.SolverOptions(sn.SICONOS_LCP_PGS)
    options.iparam[sn.SICONOS_IPARAM_MAX_ITER] = pgs_max_iter
    options.dparam[sn.SICONOS_DPARAM_TOL] = pgs_tol
    return sn.lcp_pgs, options


def time_solve(M, q, method, budget, pgs_tol, pgs_max_iter):
    """Seconds per solve (median of repeated calls within ``budget``), with the last z."""
    lcp = sn.LCP(M, q)
    fn, options = solver(method, pgs_tol, pgs_max_iter)
    times = []
    start = time.perf_counter()
    while True:
        z = np.zeros(q.shape[0])
        w = np.zeros(q.shape[0])
        t0 = time.perf_counter()
        info = fn(lcp, z, w, options)
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - start > budget or len(times) >= 200:
            break
    times.sort()
    return times[len(times) // 2], len(times), int(info), z


def main():
    payload = json.load(sys.stdin)
    for prob in payload["problems"]:
        M = np.ascontiguousarray(np.load(prob["M_npy"]))
        q = np.ascontiguousarray(np.load(prob["q_npy"]))
        for method in prob["methods"]:
            t, calls, info, z = time_solve(M, q, method, payload["budget"],
                                           payload["pgs_tol"], payload["pgs_max_iter"])
            print(json.dumps({"name": prob["name"], "method": method, "s_per_solve": t,
                              "calls": calls, "info": info, "residual": residual(M, q, z),
                              "z": z.tolist()}), flush=True)


if __name__ == "__main__":
    main()
