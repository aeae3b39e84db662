"""Run under the nosnoc venv (``.venv-nosnoc``, nosnoc 0.2 from PyPI, not committed): solves
switching optimal control problems with nosnoc's FESD and prints one JSON line per problem
(its optimum, switching time, wall time of ``solver.solve()``). Payloads on stdin, one per
line: ``{"cases": [...], "repeats": int}``, each answered by its records then
``{"done": true}``.

* ``speedup``: ``x' = u + a1`` for ``x < 0``, ``u + a2`` for ``x > 0`` from ``-L`` to
  ``x_T`` in ``T``, least ``∫ u²`` (nscontrol.optimal.SpeedUp, closed form ``s* = 1/2``),
  implicit Euler (Radau IIA, one stage), one input per stage, ``N`` stages of ``Nfe``
  elements; with ``equidistant: false`` the stage lengths are free too (nosnoc's
  ``equidistant_control_grid``), which makes it nscontrol.optimal's transcription: one
  input per element, element lengths free summing to ``T``.
* ``motor_with_friction``: the model and problem of nosnoc's published example
  ``examples/motor_with_friction/motor_with_friction_ocp.py`` (a linear motor with a spring
  load and Coulomb friction on the slide, one switching surface ``v1 = 0``, least ``∫ u²``
  to a target in 0.08 s, ``|u| <= 5``), discretised as nscontrol.optimal's transcription:
  implicit Euler (Radau IIA, one stage), ``N`` stages of one element, free lengths.
* ``oscillator`` and ``relay``: nosnoc's published simulation examples
  ``examples/oscillator/oscillator_example.py`` (two linear spirals switching on the unit
  circle, 29 steps to ``T = π/2``, closed-form end state) and
  ``examples/relay/relay_feedback_system.py`` (Piiroinen and Kuznetsov's third-order relay
  feedback system, 200 steps to ``T = 10``), with their default options: one
  ``NosnocSolver`` stepped by ``NosnocSimLooper``; the end state is printed.
* ``sliding_mode_ocp``: the problem of nosnoc's published example
  ``examples/sliding_mode_ocp/sliding_mode_ocp.py`` (two switching surfaces, a sliding
  mode), its default options, run for nosnoc's time alone (nscontrol.optimal's
  SwitchingProblem has one switching hyperplane).
* ``sliding_mode_ocp_as_ours`` and ``cart_pole_with_friction``: nosnoc's published
  ``sliding_mode_ocp`` and ``cart_pole_with_friction`` problems, discretised as
  nscontrol.optimal.FesdProblem (implicit Euler, the case's stages, elements and step
  equilibration, its cross complementarity pairs and IPOPT iteration limit); their
  trajectories, algebraic variables and objective after each relaxed solve are printed,
  the caller recomputes the cost and the complementarity residual.
* ``simple_car``: the problem of nosnoc's published example
  ``examples/simple_car_algebraics/simple_car_algebraic.py`` (a car whose input gains 5
  below 15 m/s and 3 above, the switching function an algebraic ``z = v - 15``, least
  ``∫ u²`` to ``(500, 0)`` in 30 s), discretised as nscontrol.optimal.FesdProblem (implicit
  Euler, the case's step equilibration in place of the example's ``L2_RELAXED_SCALED``);
  its trajectory is printed.
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


def motor_with_friction(case):
    m1, m2, k, c_damping, u_max, R, L, K_F, K_S, F_R = (1.03, 0.56, 2.4e3, 0.0, 5.0, 2.0,
                                                        2e-3, 12.0, 12.0, 2.1)
    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u")
    A = np.array([[0, 1, 0, 0, 0],
                  [-k / m1, -c_damping / m1, k / m1, c_damping / m1, K_F / m1],
                  [0, 0, 0, 1, 0],
                  [k / m2, c_damping / m2, -k / m2, -c_damping / m2, 0],
                  [0, -K_S / L, 0, 0, -R / L]])
    B = np.zeros((5, 1))
    B[-1, 0] = 1 / L
    C1 = np.array([0, -F_R / m1, 0, 0, 0])
    F = [ca.horzcat(A @ x + B @ u + C1, A @ x + B @ u - C1)]
    model = nosnoc.NosnocModel(x=x, F=F, S=[np.array([[1], [-1]])], c=[x[1]],
                               x0=np.zeros(5), u=u)
    ocp = nosnoc.NosnocOcp(lbu=-u_max * np.ones(1), ubu=u_max * np.ones(1), f_q=u ** 2,
                           g_terminal=x - np.array([0.01, 0, 0.01, 0, 0]))
    opts = nosnoc.NosnocOpts()
    opts.use_fesd = True
    opts.irk_scheme = nosnoc.IrkSchemes.RADAU_IIA
    opts.n_s = 1
    opts.N_stages = case["N"]
    opts.N_finite_elements = 1
    opts.terminal_time = 0.08
    opts.equidistant_control_grid = False
    opts.gamma_h = case.get("gamma_h", 1.0)   # element lengths in [(1-γ) h̄, (1+γ) h̄]
    opts.comp_tol = case.get("comp_tol", 1e-9)
    opts.homotopy_update_slope = 0.1
    opts.print_level = 0
    return model, ocp, opts


def oscillator(case):
    omega = 2 * np.pi
    A1 = np.array([[1, omega], [-omega, 1]])
    A2 = np.array([[1, -omega], [omega, 1]])
    x = ca.SX.sym("x", 2)
    model = nosnoc.NosnocModel(x=x, F=[ca.horzcat(A1 @ x, A2 @ x)], S=[np.array([[1], [-1]])],
                               c=[x[0] ** 2 + x[1] ** 2 - 1], x0=np.array([np.exp(-1), 0.0]))
    opts = nosnoc.NosnocOpts()
    opts.comp_tol = 1e-8
    opts.homotopy_update_slope = 0.1
    opts.N_finite_elements = 2
    opts.n_s = 3
    opts.step_equilibration = nosnoc.StepEquilibrationMode.DIRECT_COMPLEMENTARITY
    opts.print_level = 0
    opts.terminal_time = (np.pi / 2) / 29
    return model, None, opts, 29


def relay(case):
    omega, xi, sigma = 25.0, 0.05, 1.0
    A = np.array([[-(2 * xi * omega + 1), 1, 0], [-(2 * xi * omega + omega ** 2), 0, 1],
                  [-omega ** 2, 0, 0]])
    b = np.array([[1], [-2 * sigma], [1]])
    x = ca.SX.sym("x", 3)
    model = nosnoc.NosnocModel(x=x, F=[ca.horzcat(A @ x + b, A @ x - b)],
                               S=[np.array([[-1], [1]])], c=[x[0]],
                               x0=np.array([0, -0.001, -0.02]))
    opts = nosnoc.NosnocOpts()
    opts.use_fesd = True
    opts.pss_mode = nosnoc.PssMode.STEWART
    opts.irk_scheme = nosnoc.IrkSchemes.RADAU_IIA
    opts.N_finite_elements = 2
    opts.n_s = 2
    opts.mpcc_mode = nosnoc.MpccMode.SCHOLTES_INEQ
    opts.cross_comp_mode = nosnoc.CrossComplementarityMode.SUM_LAMBDAS_COMPLEMENT_WITH_EVERY_THETA
    opts.step_equilibration = nosnoc.StepEquilibrationMode.HEURISTIC_MEAN
    opts.comp_tol = 1e-6
    opts.print_level = 0
    opts.homotopy_update_rule = nosnoc.HomotopyUpdateRule.LINEAR
    opts.irk_representation = nosnoc.IrkRepresentation.INTEGRAL
    opts.terminal_time = 10.0 / 200
    return model, None, opts, 200


SIMULATIONS = ("oscillator", "relay")


def simulate(case):
    """One run of a simulation example: the looper's end state and wall time."""
    model, _, opts, nsim = globals()[case["name"]](case)
    start, cpu = time.perf_counter(), time.process_time()
    solver = nosnoc.NosnocSolver(opts, model)
    looper = nosnoc.NosnocSimLooper(solver, model.x0, nsim)
    looper.run()
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    res = looper.get_results()
    return wall, np.asarray(res["X_sim"][-1], float).tolist(), len(res["switch_times"]), cpu


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


def _as_ours(opts, case):
    """nosnoc's options set to nscontrol.optimal's scheme: implicit Euler (Radau IIA, one
    stage), the case's stages, elements per stage and step equilibration. The differential
    representation: with one stage its cost weight is 1 (``h L(x_{k+1}, u)``, ours), where
    the integral one weighs the stage cost by 1/2 (a quadrature over the element's two
    end points that drops the left one).

    Two more settings make the relaxed problems ours, not only their limit:

    * the cross complementarity as ours, one pair per product (``θ_k ∘ λ_k <= σ`` and
      ``θ_k ∘ λ_{k-1} <= σ``: ``COMPLEMENT_ALL_STAGE_VALUES_WITH_EACH_OTHER``); nosnoc's
      default relaxes their sum, ``θ_k ∘ (λ_{k-1} + λ_k) <= σ``, the same complementarity
      at ``σ = 0`` but another path of relaxed optima, which ends in another local optimum
      (sliding_mode_ocp: 5.58964 against 5.56875);
    * IPOPT's iteration limit per solve as ours (``case["max_iter"]``, nscontrol's
      ``Relaxation.max_iter``): nosnoc's 500 stops the first relaxed solve of the cart-pole
      (657 iterations) unconverged, and the homotopy continues from that point."""
    opts.irk_scheme = nosnoc.IrkSchemes.RADAU_IIA
    opts.irk_representation = nosnoc.IrkRepresentation.DIFFERENTIAL
    cross = nosnoc.CrossComplementarityMode
    opts.cross_comp_mode = cross.COMPLEMENT_ALL_STAGE_VALUES_WITH_EACH_OTHER
    opts.nlp_max_iter = case["max_iter"]
    opts.n_s = 1
    opts.N_stages = case["N"]
    opts.N_finite_elements = case["Nfe"]
    opts.rho_h = case["rho_h"]
    opts.step_equilibration = getattr(nosnoc.StepEquilibrationMode, case["equilibration"])
    opts.comp_tol = case.get("comp_tol", 1e-9)
    opts.homotopy_update_slope = 0.1
    opts.print_level = 0
    return opts


def sliding_mode_ocp_as_ours(case):
    """nosnoc's sliding_mode_ocp (its problem and options) with one Radau stage, as ours."""
    model, ocp, opts = sliding_mode_ocp(case)
    return model, ocp, _as_ours(opts, case)


def cart_pole_with_friction(case):
    """The problem of nosnoc's published example
    ``examples/cart_pole_with_friction/cart_pole_with_friction.py``: a cart-pole swung up
    from hanging to upright against Coulomb friction on the cart (one switching surface,
    the cart's speed; nonlinear fields), tracking cost, T = 5, 20 stages of 2 elements, with
    one Radau stage (as ours)."""
    F_fric, m1, m2, l, g = case["friction"], 1.0, 0.1, 1.0, 9.81
    px, th, v, om, u = (ca.SX.sym(n) for n in ("px", "theta", "v", "theta_dot", "u"))
    q_dot = ca.vertcat(v, om)
    x = ca.vertcat(px, th, v, om)
    M = ca.vertcat(ca.horzcat(m1 + m2, m2 * l * ca.cos(th)),
                   ca.horzcat(m2 * l * ca.cos(th), m2 * l ** 2))
    C = ca.SX.zeros(2, 2)
    C[0, 1] = -m2 * l * om * ca.sin(th)
    f_all = ca.vertcat(u, -m2 * g * l * ca.sin(th)) - C @ q_dot
    f_1 = ca.vertcat(q_dot, ca.inv(M) @ (f_all - ca.vertcat(F_fric, 0)))
    f_2 = ca.vertcat(q_dot, ca.inv(M) @ (f_all + ca.vertcat(F_fric, 0)))
    model = nosnoc.NosnocModel(x=x, F=[ca.horzcat(f_1, f_2)], c=[v],
                               S=[np.array([[1], [-1]])], x0=np.array(case["x0"]), u=u)
    x_ref = np.array(case["x_ref"])
    Q, Qt, R = np.diag(case["Q"]), np.diag(case["Q_terminal"]), case["R"]
    f_q = (x - x_ref).T @ Q @ (x - x_ref) + R * u ** 2
    f_terminal = (x - x_ref).T @ Qt @ (x - x_ref)
    ubx = np.array([case["x_max"], np.inf, np.inf, np.inf])
    ocp = nosnoc.NosnocOcp(lbu=-np.array([case["u_max"]]), ubu=np.array([case["u_max"]]),
                           f_q=f_q, f_terminal=f_terminal, lbx=-ubx, ubx=ubx)
    opts = nosnoc.NosnocOpts()
    opts.terminal_time = case["T"]
    return model, ocp, _as_ours(opts, case)


def simple_car(case):
    """nosnoc's simple car (its model, the algebraic ``z`` included, and problem) with
    one Radau stage and the case's step equilibration, as ours."""
    q, v, z, u = (ca.SX.sym(n) for n in ("q", "v", "z", "u"))
    x = ca.vertcat(q, v)
    A = np.array([[0, 1], [0, 0]])
    F = [ca.horzcat(A @ x + np.array([[0], [case["k1"]]]) @ u,
                    A @ x + np.array([[0], [case["k2"]]]) @ u)]
    model = nosnoc.NosnocModel(x=x, F=F, S=[np.array([[-1], [1]])], c=[z],
                               x0=np.array(case["x0"]), u=u, z=z,
                               g_z=z - (v - case["v_switch"]),
                               z0=[case["x0"][1] - case["v_switch"]])
    ocp = nosnoc.NosnocOcp(lbu=-case["u_max"] * np.ones(1), ubu=case["u_max"] * np.ones(1),
                           f_q=u ** 2, g_terminal=x - np.array(case["x_final"]))
    opts = nosnoc.NosnocOpts()
    opts.use_fesd = True
    opts.rootfinder_for_initial_z = True
    opts.terminal_time = case["T"]
    return model, ocp, _as_ours(opts, case)


def _homotopy_record(solver, results):
    """The algebraic variables of each element (``θ``, ``λ``: the caller computes the
    complementarity residual by its own formula), nosnoc's own residual (largest product),
    the objective after each relaxed solve with its ``σ`` (the caller estimates from the
    last two how far the last relaxation's optimum is from the limit's), and the status of
    the last solve."""
    prob, opts = solver.problem, solver.opts
    theta, lam = (np.asarray(results[key], float).reshape(len(results[key]), -1).tolist()
                  for key in ("theta_list", "lambda_list"))
    sigmas, objectives, sigma = [], [], opts.sigma_0
    for w in results["w_all"][1:]:
        solver.setup_p_val(sigma, 0.0)
        sigmas.append(sigma)
        objectives.append(float(prob.cost_fun(w, solver.p_val)))
        sigma = solver.homotopy_sigma_update(sigma)
    solver.setup_p_val(sigmas[-1], 0.0)
    return {"theta": theta, "lambda": lam, "sigmas": sigmas, "objectives": objectives,
            "comp_res": float(prob.comp_res(results["w_sol"], solver.p_val)),
            "last_status": str(solver.solver.stats()["return_status"])}


#: Cases whose trajectories are printed (the cost is recomputed by the caller).
TRAJECTORIES = ("sliding_mode_ocp_as_ours", "cart_pole_with_friction", "simple_car")


def main():
    """One payload per stdin line, each answered by its records then ``{"done": true}``:
    the caller keeps this process and sends a case at a time, alternating with its own
    solves (the two sides timed in the same minute)."""
    for text in sys.stdin:
        if text.strip():
            answer(json.loads(text))
            print(json.dumps({"done": True}), flush=True)


def answer(payload):
    """The records of one payload's cases, one JSON line each."""
    for case in payload["cases"]:
        if case["name"] in SIMULATIONS:
            runs = [simulate(case) for _ in range(payload.get("repeats", 3))]
            print(json.dumps({"name": case["name"], "walls": [r[0] for r in runs],
                              "cpus": [r[3] for r in runs], "x_end": runs[-1][1],
                              "switches": runs[-1][2],
                              "status": "simulated"}), flush=True)
            continue
        walls, cpus, results = [], [], None
        for _ in range(payload.get("repeats", 3)):
            model, ocp, opts = globals()[case["name"]](case)
            start, cpu = time.perf_counter(), time.process_time()
            solver = nosnoc.NosnocSolver(opts, model, ocp)
            results = solver.solve()
            walls.append(time.perf_counter() - start)
            cpus.append(time.process_time() - cpu)
        out = {"name": case["name"], "walls": walls, "cpus": cpus,
               "status": str(results.get("status")),
               "cost": float(results.get("cost_val", np.nan)) if "cost_val" in results
               else None, "keys": sorted(results)}
        if case["name"] in ("speedup", "motor_with_friction"):
            us = np.asarray(results["u_traj"], float).reshape(-1)
            h = np.diff(np.asarray(results["t_grid_u"], float))
            out["effort"] = float(np.sum(h * us ** 2))
            out["x_traj"] = np.asarray(results["x_traj"], float).tolist()
        if case["name"] in TRAJECTORIES:
            out.update({key: np.asarray(results[key], float).tolist()
                        for key in ("x_traj", "u_traj", "t_grid", "t_grid_u")})
            out.update(_homotopy_record(solver, results))
            out["iterations"] = [int(i) for i in results.get("nlp_iter", [])]  # per solve
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
