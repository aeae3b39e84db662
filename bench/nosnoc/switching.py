"""Run under the nosnoc venv (``.venv-nosnoc``, nosnoc 0.2 from PyPI, not committed): solves
switching optimal control problems with nosnoc's FESD and prints one JSON line per problem
(its optimum, switching time, wall time of ``solver.solve()``). Payload on stdin:
``{"cases": [...], "repeats": int}``.

* ``speedup``: ``x' = u + a1`` for ``x < 0``, ``u + a2`` for ``x > 0`` from ``-L`` to
  ``x_T`` in ``T``, least ``∫ u²`` (nscontrol.optimal.SpeedUp, closed form ``s* = 1/2``),
  implicit Euler (Radau IIA, one stage), one input per stage, ``N`` stages of ``Nfe``
  elements; with ``equidistant: false`` the stage lengths are free too (nosnoc's
  ``equidistant_control_grid``), which makes it nscontrol.optimal's transcription: one
  input per element, element lengths free summing to ``T``.
* ``sliding_mode_ocp``: the problem of nosnoc's published example
  ``examples/sliding_mode_ocp/sliding_mode_ocp.py`` (two switching surfaces, a sliding
  mode), its default options, run for nosnoc's time alone (nscontrol.optimal's
  SwitchingProblem has one switching hyperplane).
"""

import json
import sys
import time

import casadi as ca
import nosnoc
import numpy as np


def speedup(case):
    x = ca.SX.sym("x")
    u = ca.SX.sym("u")
    a1, a2, L, xT, T = case["a1"], case["a2"], case["L"], case["x_T"], case["T"]
    F = [ca.horzcat(u + a1, u + a2)]
    model = nosnoc.NosnocModel(x=x, F=F, S=[np.array([[-1], [1]])], c=[x], x0=np.array([-L]),
                               u=u)
    ocp = nosnoc.NosnocOcp(f_q=u ** 2, g_terminal=x - xT)
    opts = nosnoc.NosnocOpts()
    opts.use_fesd = True
    opts.irk_scheme = nosnoc.IrkSchemes.RADAU_IIA
    opts.n_s = 1
    opts.N_stages = case["N"]
    opts.N_finite_elements = case.get("Nfe", 2)
    opts.terminal_time = T
    opts.equidistant_control_grid = case.get("equidistant", False)
    opts.comp_tol = case.get("comp_tol", 1e-9)
    opts.homotopy_update_slope = 0.1
    opts.print_level = 0
    return model, ocp, opts


def sliding_mode_ocp(case):
    from casadi import SX, horzcat, vertcat
    x1, x2, v1, v2, u1, u2 = (SX.sym(n) for n in ("x1", "x2", "v1", "v2", "u1", "u2"))
    x, u = vertcat(x1, x2, v1, v2), vertcat(u1, u2)
    F = [horzcat(vertcat(-1 + v1, 0, u1, u2), vertcat(1 + v1, 0, u1, u2)),
         horzcat(vertcat(0, -1 + v2, u1, u2), vertcat(0, 1 + v2, u1, u2))]
    c = [x1 + 0.15 * x2 ** 2, x2 - 0.05 * x1 ** 3]
    S = [np.array([[1], [-1]]), np.array([[1], [-1]])]
    x0 = np.array([2 * np.pi / 3, np.pi / 3, 0.0, 0.0])
    target = np.array([-np.pi / 6, -np.pi / 4])
    model = nosnoc.NosnocModel(x=x, F=F, S=S, c=c, x0=x0, u=u)
    ocp = nosnoc.NosnocOcp(lbu=-10 * np.ones(2), ubu=10 * np.ones(2), f_q=v1 ** 2 + v2 ** 2,
                           f_terminal=SX.zeros(1), g_terminal=x[:2] - target)
    opts = nosnoc.NosnocOpts()
    opts.irk_representation = nosnoc.IrkRepresentation.DIFFERENTIAL
    opts.comp_tol = 1e-9
    opts.homotopy_update_slope = 0.1
    opts.n_s = 2
    opts.step_equilibration = nosnoc.StepEquilibrationMode.HEURISTIC_MEAN
    opts.rho_h = 1e1
    opts.print_level = 0
    opts.N_stages = 6
    opts.N_finite_elements = 6
    opts.terminal_time = 4.0
    return model, ocp, opts


def main():
    payload = json.load(sys.stdin)
    for case in payload["cases"]:
        walls, results = [], None
        for _ in range(payload.get("repeats", 3)):
            model, ocp, opts = globals()[case["name"]](case)
            start = time.perf_counter()
            solver = nosnoc.NosnocSolver(opts, model, ocp)
            results = solver.solve()
            walls.append(time.perf_counter() - start)
        out = {"name": case["name"], "walls": walls, "status": str(results.get("status")),
               "cost": float(results.get("cost_val", np.nan)) if "cost_val" in results
               else None, "keys": sorted(results)}
        if case["name"] == "speedup":
            t = np.asarray(results["t_grid"], float)
            xs = np.asarray(results["x_traj"], float).reshape(-1)
            k = int(np.flatnonzero(xs >= -1e-7)[0])   # first grid point on the surface
            out["switch_time"] = float(t[k])
            us = np.asarray(results["u_traj"], float).reshape(-1)
            h = np.diff(np.asarray(results["t_grid_u"], float))
            out["effort"] = float(np.sum(h * us ** 2))
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
