"""The NLPs of :class:`~nscontrol.optimal.contact.ContactProblem` (built with CasADi's
``Opti``: the Jacobians and Hessians are CasADi's sparse algorithmic derivatives) and the
Scholtes homotopy that solves them with IPOPT.

The step and the complementarity pairs are written once, over array operations
(:class:`Ops`), and evaluated on CasADi's symbols for the constraints and on numpy arrays for
the residual of a plan.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validation import FloatArray
from ..errors import SolverError
from ._casadi import require_casadi

if TYPE_CHECKING:
    from .contact import ContactProblem, Relaxation

#: IPOPT's statuses that count as a solution.
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: The contact variables, (m, N) each: normal force, friction β⁺, β⁻, slip speed.
CONTACT_VARS = ("LN", "BP", "BM", "S")


@dataclass(frozen=True)
class Ops:
    """Matrix product and constant of one array family (numpy's or CasADi's)."""

    mm: Any
    const: Any


def numpy_ops() -> Ops:
    """Ops on numpy arrays."""
    return Ops(mm=lambda A, B: A @ B, const=lambda a: np.asarray(a, float))


def casadi_ops() -> Ops:
    """Ops on CasADi symbols."""
    ca = require_casadi()
    return Ops(mm=lambda A, B: ca.mtimes(A, B), const=lambda a: ca.DM(np.asarray(a, float)))


def pairs(problem: ContactProblem, var: dict[str, Any], ops: Ops) -> list[tuple[Any, Any]]:
    """The complementarity pairs ``(a, b)``, each ``(m, N)``: Newton's law at velocity
    level and planar Coulomb friction (the module docstring of
    :mod:`nscontrol.optimal.contact`)."""
    s, n, N = problem.system, problem.system.n_dof, problem.steps
    X = var["X"]
    Vk, Vn = X[n:, :-1], X[n:, 1:]
    G = ops.const(s.dense_gap_matrix())
    e = ops.const(np.tile(s.restitution[:, None], (1, N)))
    out = [(var["LN"], ops.mm(G, Vn) + e * ops.mm(G, Vk))]
    if s.friction_dim:
        ut = ops.mm(ops.const(s.tangent_matrix), Vn)
        mu = ops.const(np.tile(np.asarray(s.friction)[:, None], (1, N)))
        out += [(var["BP"], var["S"] + ut), (var["BM"], var["S"] - ut),
                (var["S"], mu * var["LN"] - var["BP"] - var["BM"])]
    return out


def pair_values(problem: ContactProblem, sol: dict[str, Any], active: np.ndarray
                ) -> list[tuple[FloatArray, FloatArray]]:
    """The pairs of a numeric solution at the active entries (flattened)."""
    if not problem.system.n_contacts:
        return []
    mask = np.asarray(active, bool)
    return [(np.asarray(a)[mask], np.asarray(b)[mask])
            for a, b in pairs(problem, sol, numpy_ops())]


def _variables(opti: Any, problem: ContactProblem) -> dict[str, Any]:
    s, N = problem.system, problem.steps
    var = {"X": opti.variable(s.n_states, N + 1), "U": opti.variable(problem.n_inputs, N),
           "h": opti.variable() if problem.minimum_time else problem.h}
    for name in CONTACT_VARS[: 4 if s.friction_dim else 1] if s.n_contacts else ():
        var[name] = opti.variable(s.n_contacts, N)
    return var


def _dynamics(opti: Any, problem: ContactProblem, var: dict[str, Any]) -> None:
    """The Moreau–Jean step between every two grid points, the end conditions, the bounds."""
    ca, ops = require_casadi(), casadi_ops()
    s, n, N, th, h = problem.system, problem.system.n_dof, problem.steps, problem.theta, var["h"]
    X, U = var["X"], var["U"]
    Qk, Qn, Vk, Vn = X[:n, :-1], X[:n, 1:], X[n:, :-1], X[n:, 1:]
    S = np.eye(n) if s.actuation is None else s.actuation
    f = ops.const(np.tile(s.constant_force[:, None], (1, N))) + ops.mm(ops.const(S), U)
    Mhat = ops.const(s.mass_matrix())
    if s.stiffness is not None:
        f = f - ops.mm(ops.const(s.stiffness), Qk + h * th * Vk)
        Mhat = Mhat + h ** 2 * th ** 2 * ops.const(s.stiffness)
    if s.damping is not None:
        f = f - ops.mm(ops.const(s.damping), Vk)
        Mhat = Mhat + h * th * ops.const(s.damping)
    if s.n_contacts:
        f = f + ops.mm(ops.const(s.dense_gap_matrix().T), var["LN"])
    if s.friction_dim:
        f = f + ops.mm(ops.const(np.asarray(s.tangent_matrix).T), var["BP"] - var["BM"])
    opti.subject_to(ca.vec(ops.mm(Mhat, Vn - Vk) - h * f) == 0)
    opti.subject_to(ca.vec(Qn - Qk - h * ((1 - th) * Vk + th * Vn)) == 0)
    opti.subject_to(X[:, 0] == problem.x0)
    if problem.x_final is not None:
        idx = np.flatnonzero(~np.isnan(problem.x_final)).tolist()
        opti.subject_to(X[idx, N] == problem.x_final[idx])
    _bounds(opti, problem, var)


def _bounds(opti: Any, problem: ContactProblem, var: dict[str, Any]) -> None:
    ca = require_casadi()
    N = problem.steps
    for bound, sign in ((problem.u_min, 1.0), (problem.u_max, -1.0)):
        if bound is not None:
            opti.subject_to(ca.vec(sign * (var["U"] - np.tile(bound[:, None], (1, N)))) >= 0)
    if problem.minimum_time:
        lo, hi = problem.h_bounds
        opti.subject_to(opti.bounded(lo, var["h"], hi))


def _complementarity(opti: Any, problem: ContactProblem, var: dict[str, Any],
                     active: np.ndarray, sigma: Any, branches: list[np.ndarray] | None
                     ) -> None:
    """Relaxed pairs ``a, b >= 0, a b <= σ`` on the active entries (or, with ``branches``,
    the polish: ``a = 0 <= b`` where the branch is true, ``b = 0 <= a`` elsewhere), the
    contact variables zero on the inactive ones."""
    ca = require_casadi()
    on = np.flatnonzero(active.ravel(order="F")).tolist()
    off = np.flatnonzero(~active.ravel(order="F")).tolist()
    for name in CONTACT_VARS:
        if name in var and off:
            opti.subject_to(ca.vec(var[name])[off] == 0)
    if not on:
        return
    for i, (a, b) in enumerate(pairs(problem, var, casadi_ops())):
        av, bv = ca.vec(a)[on], ca.vec(b)[on]
        if branches is None:
            opti.subject_to(av >= 0)
            opti.subject_to(bv >= 0)
            opti.subject_to(av * bv <= sigma)
            continue
        za = branches[i]
        for zero, other in ((np.flatnonzero(za), av), (np.flatnonzero(~za), bv)):
            if zero.size:
                opti.subject_to(other[zero.tolist()] == 0)
        for keep, other in ((np.flatnonzero(za), bv), (np.flatnonzero(~za), av)):
            if keep.size:
                opti.subject_to(other[keep.tolist()] >= 0)


def _cost(problem: ContactProblem, var: dict[str, Any]) -> Any:
    ca = require_casadi()
    J = problem.effort * var["h"] * ca.sumsqr(var["U"])
    return J + problem.steps * var["h"] if problem.minimum_time else J


class _NLP:
    """One NLP (relaxed with a parameter ``σ``, or the polish of fixed branches)."""

    def __init__(self, problem: ContactProblem, active: np.ndarray,
                 relaxation: Relaxation, branches: list[np.ndarray] | None = None) -> None:
        ca = require_casadi()
        self.problem, self.relaxation = problem, relaxation
        self.opti = opti = ca.Opti()
        self.var = _variables(opti, problem)
        self.sigma = opti.parameter()
        _dynamics(opti, problem, self.var)
        _complementarity(opti, problem, self.var, active, self.sigma, branches)
        self.cost = _cost(problem, self.var)
        opti.minimize(self.cost)

    def solve(self, guess: dict[str, Any], sigma: float) -> tuple[dict[str, Any], dict]:
        """Solve from ``guess`` (primal, and dual when it has ``lam_g`` of this NLP's size);
        returns the solution and the stage's record."""
        opti, rel = self.opti, self.relaxation
        for name, sym in self.var.items():
            if name != "h" or self.problem.minimum_time:
                opti.set_initial(sym, guess[name])
        warm = guess.get("lam_g") is not None and guess["lam_g"].size == opti.ng
        if warm:
            opti.set_initial(opti.lam_g, guess["lam_g"])
        opti.set_value(self.sigma, sigma)
        opti.solver("ipopt", {"print_time": False, "error_on_fail": False},
                    {"print_level": 0, "sb": "yes", "tol": rel.tol,
                     "acceptable_constr_viol_tol": rel.tol,
                     "max_iter": int(rel.max_iter),
                     **({"warm_start_init_point": "yes", "mu_init": 1e-6} if warm else {})})
        start = time.perf_counter()
        sol = opti.solve()
        elapsed = time.perf_counter() - start
        stats = sol.stats()
        record = {"sigma": sigma, "iterations": int(stats.get("iter_count", 0)),
                  "status": str(stats.get("return_status", "")), "solve_time": elapsed,
                  "ipopt_time": float(stats.get("t_wall_total", elapsed))}
        return self._values(sol, guess), record

    def _values(self, sol: Any, guess: dict[str, Any]) -> dict[str, Any]:
        out = dict(guess)
        for name, sym in self.var.items():
            value = sol.value(sym)
            out[name] = (float(value) if name == "h" else
                         np.asarray(value, float).reshape(np.shape(guess[name])))
        out["cost"] = float(sol.value(self.cost))
        out["lam_g"] = np.asarray(sol.value(self.opti.lam_g), float).reshape(-1)
        return out


def solve_homotopy(problem: ContactProblem, active: np.ndarray, guess: dict[str, Any],
                   relaxation: Relaxation, stages: list[dict[str, Any]]
                   ) -> tuple[dict[str, Any], bool]:
    """The relaxed solves along ``relaxation.sigmas()`` then the polish; the records are
    appended to ``stages``. Returns the solution and whether the polish was kept."""
    nlp = _NLP(problem, active, relaxation)
    guess = {**guess, "lam_g": None}
    for sigma in relaxation.sigmas():
        sol, record = nlp.solve(guess, sigma)
        stages.append(record)
        if record["status"] not in SOLVED:
            raise SolverError(f"optimal: IPOPT failed on the relaxation σ = {sigma:.3g} "
                              f"({record['status']}); try a larger sigma0, more steps or a "
                              "feasible initial guess", status=record["status"])
        guess = sol
    if not relaxation.polish or not problem.system.n_contacts:
        return guess, False
    branches = [a <= b for a, b in pair_values(problem, guess, active)]
    polish = _NLP(problem, active, relaxation, branches)
    sol, record = polish.solve({**guess, "lam_g": None}, 0.0)
    record["sigma"] = "polish"
    stages.append(record)
    if record["status"] in SOLVED and sol["cost"] <= guess["cost"] + 1e-6 * (
            1.0 + abs(guess["cost"])):
        return sol, True
    return guess, False
