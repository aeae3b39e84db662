"""Siconos side of bench_contacts.py: one-step frictional contact problems and the brick
stack by Moreau-Jean with friction.

Run by /usr/bin/python3 (Debian's python3-siconos). Reads JSON on stdin:
``{"kind": "one_step", "dim", "W" (rows), "q", "mu", "solver": "nsgs"|"lemke", "tol",
"max_iter", "budget"}``, ``{"kind": "stack", "n", "mu", "width", "height", "mass", "g",
"angle", "h", "steps", "solver", "tol", "max_iter"}`` or ``{"kind": "fc3d", "npz",
"path" (optional), "tol", "max_iter", "runs", "budget"}`` (:func:`fc3d`); prints one JSON
line.
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk
import siconos.numerics as sn


def _options(dim, solver, tol, max_iter):
    if dim == 3:
        so = sn.SolverOptions(sn.SICONOS_FRICTION_3D_NSGS)
        # full error evaluation: the sweep counts are then those the tolerance needed
        so.iparam[sn.SICONOS_FRICTION_3D_IPARAM_ERROR_EVALUATION] = \
            sn.SICONOS_FRICTION_3D_NSGS_ERROR_EVALUATION_FULL
    else:
        so = sn.SolverOptions(sn.SICONOS_FRICTION_2D_LEMKE if solver == "lemke"
                              else sn.SICONOS_FRICTION_2D_NSGS)
    so.dparam[sn.SICONOS_DPARAM_TOL] = tol
    so.iparam[sn.SICONOS_IPARAM_MAX_ITER] = max_iter
    return so


def one_step(sc):
    dim = sc["dim"]
    W = np.asfortranarray(np.array(sc["W"], dtype=float))
    q = np.array(sc["q"], dtype=float)
    mu = np.array(sc["mu"], dtype=float)
    nc = q.size // dim
    driver = sn.fc3d_driver if dim == 3 else sn.fc2d_driver

    def solve():
        pb = sn.FrictionContactProblem(dim, nc, W, q, mu)
        r, u = np.zeros(q.size), np.zeros(q.size)
        so = _options(dim, sc["solver"], sc["tol"], sc["max_iter"])
        info = driver(pb, r, u, so)
        return info, r, so.iparam[sn.SICONOS_IPARAM_ITER_DONE], so.dparam[sn.SICONOS_DPARAM_RESIDU]

    info, r, its, res = solve()

    def timed():
        t0 = time.process_time()
        solve()
        return time.process_time() - t0

    times = _cpu_runs(timed, sc.get("runs", 3), sc["budget"])
    return {"seconds": float(np.median(times)), "times": times, "info": int(info),
            "r": r.tolist(), "iterations": int(its), "residual": float(res)}


def _cpu_runs(fn, runs, budget):
    """Seconds of CPU time per call of ``fn`` in ``runs`` runs (each a batch of calls sized to
    about ``budget / runs``); ``fn`` returns the seconds to count (it times itself)."""
    once = max(fn(), 1e-7)
    batch = max(1, min(20000, int(budget / runs / once)))
    return [sum(fn() for _ in range(batch)) / batch for _ in range(runs)]


def fc3d(sc):
    """One FC3D problem given as arrays (``npz``: dense ``W`` or CSC ``p, i, x, shape``;
    ``q``, ``mu``), NSGS with full error evaluation. Times, in CPU seconds per call and
    ``runs`` runs: ``whole`` (build the problem from the arrays, the options, solve),
    ``alone`` (the driver on a built problem: the file read by Siconos itself when ``path``
    is a ``.dat``) and ``warm`` (the driver from its own solution)."""
    import warnings

    import scipy.sparse as sp

    warnings.simplefilter("ignore")
    data = np.load(sc["npz"])
    q, mu = data["q"], data["mu"]
    nc = mu.size
    dense = "W" in data
    if dense:
        W = np.asfortranarray(data["W"])
    else:
        W = sp.csc_matrix((data["x"], data["i"], data["p"]), shape=tuple(data["shape"]))

    def build():
        if dense:
            return sn.FrictionContactProblem(3, nc, W, q, mu)
        _, Wsbm = sn.SBM_from_csparse(3, W)
        pb = sn.FrictionContactProblem()
        pb.dimension, pb.numberOfContacts, pb.M, pb.q, pb.mu = 3, nc, Wsbm, q, mu
        return pb

    def whole():
        t0 = time.process_time()
        pb = build()
        r, u = np.zeros(q.size), np.zeros(q.size)
        so = _options(3, "nsgs", sc["tol"], sc["max_iter"])
        sn.fc3d_driver(pb, r, u, so)
        return time.process_time() - t0

    path = sc.get("path")
    built = (sn.frictionContact_new_from_filename(path) if path and path.endswith(".dat")
             else build())
    last = {}

    def alone(start=None):
        r = np.zeros(q.size) if start is None else start.copy()
        u = np.zeros(q.size)
        so = _options(3, "nsgs", sc["tol"], sc["max_iter"])
        t0 = time.process_time()
        info = sn.fc3d_driver(built, r, u, so)
        seconds = time.process_time() - t0
        last.update(info=int(info), r=r, iterations=int(so.iparam[sn.SICONOS_IPARAM_ITER_DONE]),
                    residual=float(so.dparam[sn.SICONOS_DPARAM_RESIDU]))
        return seconds

    runs, budget = sc["runs"], sc["budget"]
    t_alone = _cpu_runs(alone, runs, budget)
    cold = dict(last)
    t_whole = _cpu_runs(whole, runs, budget)
    solution = cold["r"].copy()
    t_warm = _cpu_runs(lambda: alone(solution), runs, budget)
    return {"whole": t_whole, "alone": t_alone, "warm": t_warm, "info": cold["info"],
            "iterations": cold["iterations"], "residual": cold["residual"],
            "warm_iterations": last["iterations"], "r": cold["r"].tolist(),
            "alone_native_file": bool(path and path.endswith(".dat"))}


def stack(sc):
    n, mu, w, H, m, g, angle = (sc["n"], sc["mu"], sc["width"], sc["height"], sc["mass"],
                                sc["g"], sc["angle"])
    h, steps = sc["h"], sc["steps"]
    inertia = m * (w * w + H * H) / 12.0
    nsds = sk.NonSmoothDynamicalSystem(0.0, h * steps)
    bodies = []
    for i in range(n):
        ds = sk.LagrangianLinearTIDS([0.0, H * (0.5 + i), 0.0], [0.0, 0.0, 0.0],
                                     np.diag([m, m, inertia]))
        ds.setFExtPtr(np.array([-m * g * np.sin(angle), -m * g * np.cos(angle), 0.0]))
        nsds.insertDynamicalSystem(ds)
        bodies.append(ds)
    nsl = sk.NewtonImpactFrictionNSL(0.0, 0.0, mu, 2)
    inters = []
    for i in range(n):
        for a in (-0.5 * w, 0.5 * w):
            if i == 0:
                Hm = np.array([[0.0, 1.0, a], [1.0, 0.0, 0.5 * H]])
                b = np.array([-0.5 * H, 0.0])
            else:
                Hm = np.array([[0.0, -1.0, -a, 0.0, 1.0, a],
                               [-1.0, 0.0, 0.5 * H, 1.0, 0.0, 0.5 * H]])
                b = np.array([-H, 0.0])
            inter = sk.Interaction(nsl, sk.LagrangianLinearTIR(Hm.copy(), b.copy()))
            if i == 0:
                nsds.link(inter, bodies[0])
            else:
                nsds.link(inter, bodies[i - 1], bodies[i])
            inters.append(inter)
    osi = sk.MoreauJeanOSI(0.5)
    osi.setConstraintActivationThreshold(1e-12)
    solver_id = (sn.SICONOS_FRICTION_2D_LEMKE if sc["solver"] == "lemke"
                 else sn.SICONOS_FRICTION_2D_NSGS)
    osnspb = sk.FrictionContact(2, solver_id)
    so = osnspb.numericsSolverOptions()
    so.dparam[sn.SICONOS_DPARAM_TOL] = sc["tol"]
    so.iparam[sn.SICONOS_IPARAM_MAX_ITER] = sc["max_iter"]
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), osi, osnspb)
    residuals, iterations, k = [], [], 0
    start = time.perf_counter()
    while sim.hasNextEvent() and k < steps:
        sim.computeOneStep()
        residuals.append(float(so.dparam[sn.SICONOS_DPARAM_RESIDU]))
        iterations.append(int(so.iparam[sn.SICONOS_IPARAM_ITER_DONE]))
        sim.nextStep()
        k += 1
    seconds = time.perf_counter() - start
    drift = max(max(abs(ds.q()[0]), abs(ds.q()[1] - H * (0.5 + i)), abs(ds.q()[2]))
                for i, ds in enumerate(bodies))
    return {"steps": k, "seconds": seconds, "max_residual": max(residuals),
            "mean_iterations": float(np.mean(iterations)), "drift": float(drift)}


def main():
    sc = json.loads(sys.stdin.read())
    out = {"one_step": one_step, "stack": stack, "fc3d": fc3d}[sc["kind"]](sc)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
