"""Frictional contacts: one-step problems, brick stacks by Moreau-Jean, and Siconos' files.

Scenarios (each side measured in the same run):

* one-step planar problem (the first step of a tilted stack of 10 bricks, 20 contacts):
  ours (NSGS at 1e-8, and Lemke on the planar LCP) against Siconos ``fc2d_driver`` (NSGS at
  1e-8, and Lemke): seconds per solve, residual, iterations;
* one-step spatial problem (20 contacts, dense SPD W of condition 50, μ = 0.5): our NSGS
  against Siconos ``fc3d_driver`` NSGS (full error evaluation), both at 1e-10;
* stacks of 10, 100 and 1000 bricks at rest (two corner contacts per interface, μ = 0.5,
  h = 1e-3): our frictional Moreau-Jean (NSGS at 1e-12) against Siconos' MoreauJeanOSI +
  FrictionContact(2) with NSGS at 1e-8 (its sweep cap 10 000, 1000 for 1000 bricks):
  steps/s, largest residual, sweeps per step, drift;
* the Siconos FC3D benchmark files (``../shared/benchmarks/siconos-fc3d``, skipped when
  absent): our NSGS from zero at 1e-8 against Siconos' NSGS at 1e-8 on the file it reads
  itself (``.hdf5`` files: Siconos' figures from ``reference.json``).

Residuals are the natural map of De Saxcé's form over ``max(‖q‖, ‖r‖, ‖u‖)`` on both sides.
Run: ``nscontrol bench contacts --json`` (``--quick``: fewer steps, five files).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import json
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version, time_per_call

import nscontrol as nsc
from nscontrol.numerics import friction_residual, solve_friction_contact
from nscontrol.systems import brick_stack, brick_stack_rest_state


def _find_files() -> Path:
    """``shared/benchmarks/siconos-fc3d`` in the nearest folder above this one that has it
    (``$NSCONTROL_FC3D_DIR`` first)."""
    env = os.environ.get("NSCONTROL_FC3D_DIR")
    if env:
        return Path(env)
    for parent in Path(__file__).resolve().parents:
        candidate = parent / "shared" / "benchmarks" / "siconos-fc3d"
        if candidate.is_dir():
            return candidate
    return Path("shared/benchmarks/siconos-fc3d")


FILES = _find_files()
H = 1e-3


def _stack_problem(n: int, angle: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first step's planar problem of a resting stack (W, q, μ)."""
    s = brick_stack(n, 0.5, angle=angle)
    from scipy import sparse

    x0 = brick_stack_rest_state(n)
    T = sparse.csr_matrix(s.tangent_matrix)
    G = sparse.csr_matrix(s.gap_matrix)
    m = s.n_contacts
    perm = np.ravel(np.column_stack([np.arange(m), m + np.arange(m)]))
    Hm = sparse.vstack([G, T]).tocsr()[perm]
    minv = sparse.diags(1.0 / s.mass)
    W = (Hm @ minv @ Hm.T).toarray()
    v_free = x0[3 * n:] + H * (minv @ s.constant_force)
    return W, Hm @ v_free, np.full(m, 0.5)


def _one_step_planar(quick: bool) -> dict[str, Any]:
    W, q, mu = _stack_problem(10, 0.1)
    lcp = solve_friction_contact(W, q, mu, dim=2, method="lcp")
    nsgs = solve_friction_contact(W, q, mu, dim=2, method="nsgs", tol=1e-8)
    t_lcp = time_per_call(lambda: solve_friction_contact(W, q, mu, dim=2, method="lcp"),
                          budget=0.3 if quick else 1.0)
    t_nsgs = time_per_call(lambda: solve_friction_contact(W, q, mu, dim=2, method="nsgs",
                                                          tol=1e-8),
                           budget=0.3 if quick else 1.0)
    record: dict[str, Any] = {
        "scenario": "one-step planar problem, 10-brick stack tilted 0.1 rad (20 contacts)",
        "size": 20, "ours_s_per_solve": t_nsgs, "reference": None,
        "reference_s_per_solve": None, "ratio": None,
        "accuracy": {"ours_nsgs_residual": nsgs.residual, "ours_nsgs_sweeps": nsgs.iterations,
                     "ours_lcp_residual": lcp.residual, "ours_lcp_s_per_solve": t_lcp}}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    theirs = {}
    for solver in ("nsgs", "lemke"):
        out = run_siconos("contacts.py", {"kind": "one_step", "dim": 2, "W": W.tolist(),
                                          "q": q.tolist(), "mu": mu.tolist(),
                                          "solver": solver, "tol": 1e-8, "max_iter": 100000,
                                          "budget": 0.3 if quick else 1.0})[-1]
        out["own_residual"] = friction_residual(W, q, mu, out["r"], 2)
        theirs[solver] = out
    record.update(reference=siconos_version() + " fc2d_driver NSGS (tol 1e-8)",
                  reference_s_per_solve=theirs["nsgs"]["seconds"],
                  ratio=theirs["nsgs"]["seconds"] / t_nsgs)
    for solver, out in theirs.items():
        record["accuracy"].update({
            f"siconos_{solver}_residual": out["own_residual"],
            f"siconos_{solver}_iterations": out["iterations"],
            f"siconos_{solver}_s_per_solve": out["seconds"], f"siconos_{solver}_info": out["info"]})
    return record


def _one_step_spatial(quick: bool) -> dict[str, Any]:
    rng = np.random.default_rng(20)
    m = 20
    Q, _ = np.linalg.qr(rng.standard_normal((3 * m, 3 * m)))
    W = Q @ np.diag(np.geomspace(1.0, 50.0, 3 * m)) @ Q.T
    W = 0.5 * (W + W.T)
    q = rng.standard_normal(3 * m)
    mu = np.full(m, 0.5)
    ours = solve_friction_contact(W, q, mu, dim=3, method="nsgs", tol=1e-10)
    t = time_per_call(lambda: solve_friction_contact(W, q, mu, dim=3, method="nsgs",
                                                     tol=1e-10), budget=0.3 if quick else 1.0)
    record: dict[str, Any] = {
        "scenario": "one-step spatial problem, 20 contacts, dense SPD W (cond 50), mu 0.5",
        "size": m, "ours_s_per_solve": t, "reference": None, "reference_s_per_solve": None,
        "ratio": None, "accuracy": {"ours_residual": ours.residual,
                                    "ours_sweeps": ours.iterations}}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    out = run_siconos("contacts.py", {"kind": "one_step", "dim": 3, "W": W.tolist(),
                                      "q": q.tolist(), "mu": mu.tolist(), "solver": "nsgs",
                                      "tol": 1e-10, "max_iter": 100000,
                                      "budget": 0.3 if quick else 1.0})[-1]
    record.update(reference=siconos_version() + " fc3d_driver NSGS (tol 1e-10, full error)",
                  reference_s_per_solve=out["seconds"], ratio=out["seconds"] / t)
    record["accuracy"].update(
        siconos_residual=friction_residual(W, q, mu, out["r"], 3),
        siconos_sweeps=out["iterations"],
        max_impulse_difference=float(np.max(np.abs(np.array(out["r"]) - ours.r))))
    return record


def _stack(n: int, quick: bool) -> dict[str, Any]:
    system = brick_stack(n, 0.5)
    x0 = brick_stack_rest_state(n)
    steps = 50 if quick else 300
    nsc.simulate(system, x0, (0.0, 2 * H), method="moreau_jean", h=H, progress=False)
    start = time.perf_counter()
    traj = nsc.simulate(system, x0, (0.0, steps * H), method="moreau_jean", h=H,
                        progress=False, signals=["impulse"])
    seconds = time.perf_counter() - start
    record: dict[str, Any] = {
        "scenario": f"stack of {n} bricks at rest, two corner contacts per interface, "
                    f"mu 0.5, h = {H:g}, {steps} steps",
        "size": n, "ours_steps_per_s": steps / seconds, "reference": None,
        "reference_steps_per_s": None, "ratio": None,
        "accuracy": {"ours_max_residual": traj.stats["max_contact_residual"],
                     "ours_sweeps_per_step": traj.stats["contact_sweeps"] / steps,
                     "ours_drift": float(np.max(np.abs(traj.x[-1] - x0)))}}
    ok, why = siconos_available()
    if not ok:
        record["note"] = why
        return record
    their_steps = {10: 100, 100: 10, 1000: 2}[n] if not quick else {10: 20, 100: 3,
                                                                      1000: 1}[n]
    out = run_siconos("contacts.py", {
        "kind": "stack", "n": n, "mu": 0.5, "width": 0.2, "height": 0.1, "mass": 1.0,
        "g": 9.81, "angle": 0.0, "h": H, "steps": their_steps, "solver": "nsgs", "tol": 1e-8,
        "max_iter": 10000 if n < 1000 else 1000}, timeout=1800)[-1]
    theirs = out["steps"] / out["seconds"]
    record.update(reference=siconos_version() + " MoreauJeanOSI + FrictionContact(2) NSGS "
                  "(tol 1e-8)", reference_steps_per_s=theirs,
                  ratio=record["ours_steps_per_s"] / theirs)
    record["accuracy"].update(siconos_max_residual=out["max_residual"],
                              siconos_sweeps_per_step=out["mean_iterations"],
                              siconos_drift=out["drift"], siconos_steps=out["steps"])
    return record


def _read_dat(path: Path) -> tuple[int, Any, np.ndarray, np.ndarray]:
    """``(dim, W, q, μ)`` of a Siconos ``.dat`` problem (dense or sparse-block ``W``)."""
    from scipy import sparse

    tok = path.read_text().split()
    pos = 0

    def take(k: int = 1) -> list[str]:
        nonlocal pos
        out = tok[pos:pos + k]
        pos += k
        return out

    dim, nc = int(take()[0]), int(take()[0])
    storage = int(take()[0])
    if storage == 0:
        s0, s1 = (int(x) for x in take(2))
        take(2)
        W: Any = np.array(take(s0 * s1), float).reshape(s1, s0).T
    else:
        s0, s1 = (int(x) for x in take(2))
        take(1)                                         # nbblocks
        b0, b1 = (int(x) for x in take(2))
        rows = [0] + [int(x) for x in take(b0)]
        cols = [0] + [int(x) for x in take(b1)]
        f1, f2 = (int(x) for x in take(2))
        rowptr = [int(x) for x in take(f1)]
        colidx = [int(x) for x in take(f2)]
        blocks = {}
        for _ in range(f2):
            k = int(take()[0])
            blocks[k] = k
            bi = next(i for i in range(len(rowptr) - 1) if rowptr[i] <= k < rowptr[i + 1])
            bj = colidx[k]
            nr, ncl = rows[bi + 1] - rows[bi], cols[bj + 1] - cols[bj]
            vals = np.array(take(nr * ncl), float).reshape(ncl, nr).T
            blocks[k] = (rows[bi], cols[bj], vals)
        trip_r, trip_c, trip_v = [], [], []
        for r0, c0, vals in blocks.values():
            rr, cc = np.nonzero(np.ones_like(vals))
            trip_r += list(r0 + rr)
            trip_c += list(c0 + cc)
            trip_v += list(vals[rr, cc])
        W = sparse.csr_matrix((trip_v, (trip_r, trip_c)), shape=(s0, s1))
    q = np.array(take(dim * nc), float)
    mu = np.array(take(nc), float)
    return dim, W, q, mu


def _read_hdf5(path: Path) -> tuple[int, Any, np.ndarray, np.ndarray]:
    import h5py
    from scipy import sparse

    with h5py.File(path, "r") as f:
        g = f["fclib_local"]
        Wg = g["W"]
        m, n, nz = int(Wg["m"][0]), int(Wg["n"][0]), int(Wg["nz"][0])
        p, i, x = Wg["p"][:], Wg["i"][:], Wg["x"][:]
        W = (sparse.csc_matrix((x, i, p), shape=(m, n)) if nz == -1
             else sparse.csr_matrix((x, i, p), shape=(m, n)))
        return (int(g["spacedim"][0]), W, g["vectors"]["q"][:].astype(float),
                g["vectors"]["mu"][:].astype(float))


def _files(quick: bool) -> Iterator[dict[str, Any]]:
    if not FILES.is_dir():
        yield {"scenario": "Siconos FC3D benchmark files", "size": 0, "ours_s_per_solve": None,
               "reference": None, "reference_s_per_solve": None, "ratio": None,
               "note": f"{FILES} absent", "accuracy": {}}
        return
    ref = {p["file"]: p for p in json.loads((FILES / "reference.json").read_text())["problems"]}
    names = sorted(ref, key=lambda k: ref[k]["n_contacts"])
    if quick:
        names = names[::7]
    ok, why = siconos_available()
    for name in names:
        path = FILES / name
        dim, W, q, mu = (_read_hdf5 if name.endswith(".hdf5") else _read_dat)(path)
        try:
            start = time.perf_counter()
            res = solve_friction_contact(W, q, mu, dim=dim, method="nsgs", tol=1e-8,
                                         max_sweeps=20000, r0=np.zeros_like(q))
            seconds, status, residual, sweeps = (time.perf_counter() - start, "solved",
                                                 res.residual, res.iterations)
        except nsc.errors.SolverError as err:
            seconds, status = time.perf_counter() - start, str(err).split("(")[1][:60]
            residual, sweeps = float("nan"), 20000
        record: dict[str, Any] = {
            "scenario": f"FC3D file {name} ({ref[name]['n_contacts']} contacts), NSGS tol 1e-8",
            "size": ref[name]["n_contacts"], "ours_s_per_solve": seconds,
            "reference": None, "reference_s_per_solve": None, "ratio": None,
            "accuracy": {"ours_residual": residual, "ours_sweeps": sweeps,
                         "ours_status": status}}
        if ok and not name.endswith(".hdf5"):
            out = run_siconos("contacts.py", {"kind": "file", "path": str(path), "tol": 1e-8,
                                              "max_iter": 20000,
                                              "budget": 0.2 if quick else 1.0})[-1]
            record.update(reference=siconos_version() + " fc3d_driver NSGS (tol 1e-8, full)",
                          reference_s_per_solve=out["seconds"],
                          ratio=out["seconds"] / seconds)
            record["accuracy"].update(siconos_residual=out["residual"],
                                      siconos_sweeps=out["iterations"],
                                      siconos_info=out["info"])
        else:
            tight = ref[name]["tight_full"]
            record["note"] = ("Siconos figures from reference.json (not re-run: "
                              + ("fclib .hdf5 not readable by its Python module)"
                                 if ok else why + ")"))
            record["accuracy"].update(siconos_residual=tight["residual"],
                                      siconos_sweeps=tight["iterations"],
                                      siconos_seconds_recorded=tight["time_s"])
        yield record


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    yield _one_step_planar(quick)
    yield _one_step_spatial(quick)
    for n in (10, 100, 1000):
        yield _stack(n, quick)
    yield from _files(quick)
