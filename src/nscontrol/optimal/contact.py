r"""Trajectory optimisation of a Lagrangian system with unilateral contacts and planar
Coulomb friction, transcribed by the Moreau–Jean step of the library's integrator.

The step (``docs/optimal.md``; the frictional Moreau–Jean of
:mod:`nscontrol.simulate.moreau_jean` with linear forces), at step ``h`` and weight ``θ``::

    M̂ (v_{k+1} - v_k) = h (f_k + Gᵀ λ_k + Tᵀ τ_k),    M̂ = M + hθ D + h²θ² K,
    f_k = f0 - K (q_k + hθ v_k) - D v_k + S u_k,
    q_{k+1} = q_k + h ((1-θ) v_k + θ v_{k+1}),

and, on each contact ``j`` the test ``g_j(q_k) + γ h G_j v_k <= 0`` closes (the *active*
contacts of step ``k``), Newton's law at velocity level and Coulomb's law in its planar
complementarity form (``τ = β⁺ - β⁻``, ``s`` the slip speed)::

    0 <= λ ⟂ G v_{k+1} + e G v_k >= 0,      0 <= β⁺ ⟂ s + T v_{k+1} >= 0,
    0 <= s ⟂ μ λ - β⁺ - β⁻ >= 0,            0 <= β⁻ ⟂ s - T v_{k+1} >= 0;

``λ = β⁺ = β⁻ = s = 0`` on the others. The forces are the step's impulses over ``h``.

Each pair ``0 <= a ⟂ b >= 0`` is relaxed to ``a, b >= 0, a b <= σ`` (Scholtes) and IPOPT
solves the relaxed problem for a decreasing sequence of ``σ``, each solve warm-started from the
last (primal and dual). A *polish* then fixes, for every pair, the factor the last solve
found smaller to zero and solves that smooth problem (no products): when it converges, the
complementarity holds to IPOPT's tolerance instead of ``√σ``. The active sets are fixed while
IPOPT runs; they are recomputed from the plan and the problem solved again until they agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_real_scalar,
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import DimensionError, ModelError
from ..systems.lagrangian import LagrangianSystem
from ._casadi import require_casadi
from .plan import ContactPlan

__all__ = ["ContactProblem", "Relaxation"]


@dataclass(frozen=True)
class Relaxation:
    """The Scholtes homotopy: ``σ`` from ``sigma0`` divided by ``factor`` per solve down to
    ``sigma_min``, then the polish.

    Parameters
    ----------
    sigma0 : float
        First relaxation (force × velocity units), ``> 0``.
    factor : float
        Ratio of two successive ``σ``, in ``(0, 1)``.
    sigma_min : float
        Last relaxation, ``> 0``.
    polish : bool
        Solve the smooth problem of the branches found by the last relaxed solve.
    tol : float
        IPOPT's tolerance, ``> 0``.
    max_iter : int
        IPOPT's iteration limit per solve.
    early_polish : bool
        With ``polish``: as soon as two successive relaxed solves choose the same branch
        of every pair, try the polish, and stop the homotopy there when its cost is the
        limit of the relaxed path (the relaxed cost plus ``σ`` times the multipliers of
        the products, within a tenth of that rise); otherwise go on. Skips the last
        relaxations, which lead to the same point.
    settle_fraction : float
        With ``early_polish``: the polish is tried once at most this fraction of the pairs
        changed branch between two successive relaxed solves, in ``[0, 1]`` (``0``: none).
        A pair near its corner (both sides ``O(√σ)``) can swap branch with no change of the
        solution, so waiting for no change at all costs a relaxation; a polish costs a few
        iterations, a relaxed solve tens, and a polish off the path is discarded anyway.
    stage_tol : float
        IPOPT's tolerance on a relaxed solve before the last is ``max(tol, stage_tol σ)``:
        such a solve is a waypoint, whose point the next relaxation moves by ``O(σ)``
        (``0``: ``tol`` on every solve). The last relaxation and the polish use ``tol``.
    """

    sigma0: float = 1e-3
    factor: float = 0.1
    sigma_min: float = 1e-8
    polish: bool = True
    tol: float = 1e-10
    max_iter: int = 3000
    early_polish: bool = True
    stage_tol: float = 1e-2
    settle_fraction: float = 0.03

    def __post_init__(self) -> None:
        check_positive("sigma0", self.sigma0)
        check_in_interval("factor", self.factor, 0.0, 1.0, open_interval=True)
        check_positive("sigma_min", self.sigma_min)
        check_bool("polish", self.polish)
        check_positive("tol", self.tol)
        check_integer("max_iter", self.max_iter, minimum=1)
        check_bool("early_polish", self.early_polish)
        check_positive("stage_tol", self.stage_tol, allow_zero=True)
        check_in_interval("settle_fraction", self.settle_fraction, 0.0, 1.0)

    def sigmas(self) -> list[float]:
        """The sequence ``sigma0, sigma0 factor, ...``, ending at ``sigma_min``."""
        out, s = [], float(self.sigma0)
        while s > self.sigma_min * (1.0 + 1e-9):
            out.append(s)
            s *= self.factor
        return [*out, float(self.sigma_min)]


@dataclass(frozen=True, eq=False)
class ContactProblem:
    """Move a Lagrangian system with contacts from ``x0`` in ``steps`` Moreau–Jean steps,
    at least effort (``h Σ u_kᵀ u_k``, weighted by ``effort``) or in least time ``N h``.

    Parameters
    ----------
    system : LagrangianSystem
        Constant mass, linear forces, affine gaps; frictionless or planar Coulomb friction.
    x0 : array_like (2 n,)
        Admissible initial state.
    steps : int
        Number of steps ``N``.
    h : float
        The step; with ``minimum_time`` the initial guess of the free step.
    x_final : array_like (2 n,), optional
        Final state; a NaN component is left free.
    u_min, u_max : array_like (p,), optional
        Input bounds (a scalar applies to every input).
    effort : float
        Weight of ``h Σ |u_k|²`` in the cost, ``>= 0``.
    minimum_time : bool
        Add ``N h`` to the cost, ``h`` a decision variable in ``h_bounds``.
    h_bounds : (float, float), optional
        Range of the free step (default ``(h / 10, 10 h)``).
    theta, gamma : float
        θ and γ of the Moreau–Jean step (the integrator's defaults ½, ½): the replay must
        use the same.
    active_tol : float
        Tolerance of the active-set test on the plan (the plan's gaps are exact to the
        solver's tolerance only).

    Raises
    ------
    ModelError
        A system the transcription does not cover, a bad option value.
    DimensionError
        ``x0``, ``x_final`` or a bound of the wrong length.
    """

    system: LagrangianSystem
    x0: Any
    steps: int
    h: float
    x_final: Any = None
    u_min: Any = None
    u_max: Any = None
    effort: float = 1.0
    minimum_time: bool = False
    h_bounds: Any = None
    theta: float = 0.5
    gamma: float = 0.5
    active_tol: float = 1e-8
    n_inputs: int = field(init=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        s = check_type("system", self.system, LagrangianSystem)
        if not s.is_linear or s.friction_dim > 1:
            raise ModelError("system: the transcription needs a constant mass, linear forces "
                             "(f0, K, D), affine gaps and at most planar friction; linearise "
                             "the model about its working configuration")
        set_(self, "x0", s.check_state(self.x0))
        set_(self, "steps", check_integer("steps", self.steps, minimum=1))
        set_(self, "h", check_positive("h", self.h))
        p = s.n_dof if s.actuation is None else s.actuation.shape[1]
        set_(self, "n_inputs", p)
        set_(self, "x_final", None if self.x_final is None else _vector_with_nan(
            "x_final", self.x_final, s.n_states))
        for name in ("u_min", "u_max"):
            set_(self, name, _bound(name, getattr(self, name), p))
        if self.u_min is not None and self.u_max is not None and np.any(self.u_min > self.u_max):
            raise ModelError(f"u_max: below u_min somewhere ({self.u_max} < {self.u_min}); "
                             "give u_min <= u_max")
        set_(self, "effort", check_positive("effort", self.effort, allow_zero=True))
        set_(self, "minimum_time", check_bool("minimum_time", self.minimum_time))
        set_(self, "h_bounds", _h_bounds(self.h_bounds, self.h))
        set_(self, "theta", check_in_interval("theta", self.theta, 0.5, 1.0))
        set_(self, "gamma", check_in_interval("gamma", self.gamma, 0.0, 1.0))
        set_(self, "active_tol", check_positive("active_tol", self.active_tol,
                                                allow_zero=True))

    def solve(self, relaxation: Relaxation | None = None, *, max_rounds: int = 5,
              guess: Any = None) -> ContactPlan:
        """Solve the homotopy (and the polish), recomputing the active sets from the plan
        until they agree (at most ``max_rounds`` times).

        Parameters
        ----------
        relaxation : Relaxation, optional
            The homotopy (default :class:`Relaxation()`).
        max_rounds : int
            Rounds of the active-set iteration.
        guess : Trajectory or array_like (N + 1, 2 n), optional
            States to start from (a ``Trajectory``'s ``x``, e.g. a Moreau–Jean run at the
            same ``h``); the first active sets are read from it. Default: the straight line
            of :func:`initial_guess`. A contact the guess never closes starts inactive: a
            motion that must land on it needs a guess that lands.

        Returns
        -------
        ContactPlan
            ``stats['active_set_consistent']`` says whether the last round's active sets
            are those of the plan.

        Raises
        ------
        SolverError
            IPOPT failed on a relaxed problem (its status in the message).
        """
        relaxation = Relaxation() if relaxation is None else check_type(
            "relaxation", relaxation, Relaxation)
        check_integer("max_rounds", max_rounds, minimum=1)
        guess = initial_guess(self, guess)
        sol, active, stages, polished, rounds, consistent = solve_rounds(
            self, lambda active: _ContactNLP(self, active), guess, relaxation, max_rounds)
        return _plan(self, sol, active, stages, polished, rounds, consistent)


def solve_rounds(problem: ContactProblem, make_nlp: Any, guess: dict[str, Any],
                 relaxation: Relaxation, max_rounds: int) -> tuple[Any, ...]:
    """The active-set iteration of :meth:`ContactProblem.solve` for any transcription on
    its grid (``make_nlp(active)`` builds the NLP of fixed active sets): solve, re-derive the
    active sets from the plan, until they agree or ``max_rounds``. Returns the solution,
    the last active sets, the stages, whether the polish was kept, the rounds and whether
    the sets agree."""
    from .homotopy import solve_homotopy

    active = active_sets(problem, guess["X"], guess["h"])
    stages: list[dict[str, Any]] = []
    rounds, consistent, polished = 0, False, False
    while rounds < max_rounds and not consistent:
        rounds += 1
        guess, polished = solve_homotopy(make_nlp(active), guess, relaxation, stages)
        new = active_sets(problem, guess["X"], guess["h"])
        consistent = bool(np.array_equal(new, active))
        if not consistent and rounds < max_rounds:
            active = new
    return guess, active, stages, polished, rounds, consistent


def _vector_with_nan(name: str, value: ArrayLike, size: int) -> FloatArray:
    """A float vector of ``size`` whose NaN entries mean 'free' (infinities refused)."""
    arr = as_float_array(name, value, finite=False).reshape(-1)
    if arr.shape != (size,):
        raise DimensionError(f"{name}: expected {size} values, got shape {np.shape(value)}")
    if np.isinf(arr).any():
        raise ModelError(f"{name}: infinite entries; use NaN for a free component")
    return arr


def _bound(name: str, value: Any, p: int) -> FloatArray | None:
    if value is None:
        return None
    if np.ndim(value) == 0:
        return np.full(p, as_real_scalar(name, value))
    return as_vector(name, value, p)


def _h_bounds(value: Any, h: float) -> tuple[float, float]:
    if value is None:
        return (h / 10.0, 10.0 * h)
    lo, hi = (check_positive("h_bounds", v) for v in value)
    if not lo <= h <= hi:
        raise ModelError(f"h_bounds: ({lo}, {hi}) must contain the initial step h = {h}")
    return (lo, hi)


def initial_guess(problem: ContactProblem, states: Any = None) -> dict[str, Any]:
    """The given ``states`` (``(N + 1, 2 n)``, or a ``Trajectory``'s), or positions on the
    straight line from ``q0`` to the final ones (``q0`` where free) at the matching constant
    speed (the end velocities as given); zero inputs and forces, the given step. (A guess
    at rest would start the homotopy in the stuck branch of friction, a local optimum that
    never moves on some steps.)"""
    s, N, n = problem.system, problem.steps, problem.system.n_dof
    x0 = problem.x0
    xf = x0 if problem.x_final is None else np.where(np.isnan(problem.x_final), x0,
                                                     problem.x_final)
    X = x0[:, None] + (xf - x0)[:, None] * np.linspace(0.0, 1.0, N + 1)[None, :]
    if N > 1:
        X[n:, 1:-1] = ((xf[:n] - x0[:n]) / (N * problem.h))[:, None]
    if states is not None:
        X = as_matrix("guess", getattr(states, "x", states), rows=N + 1, cols=s.n_states).T
    zeros = np.zeros((s.n_contacts, N))
    return {"X": X, "U": np.zeros((problem.n_inputs, N)), "LN": zeros, "BP": zeros,
            "BM": zeros, "S": zeros, "h": problem.h, "lam_g": None}


def active_sets(problem: ContactProblem, X: FloatArray, h: float) -> np.ndarray:
    """``(m, N)``: contact ``j`` closed at step ``k`` by Moreau–Jean's test
    ``g_j(q_k) + γ h G_j v_k <= active_tol``."""
    s, n = problem.system, problem.system.n_dof
    G = s.dense_gap_matrix()
    Q, V = X[:n, :-1], X[n:, :-1]
    pred = G @ Q + np.asarray(s.gap_offset)[:, None] + problem.gamma * h * (G @ V)
    return pred <= problem.active_tol


def _plan(problem: ContactProblem, sol: dict[str, Any], active: np.ndarray,
          stages: list[dict[str, Any]], polished: bool, rounds: int, consistent: bool
          ) -> ContactPlan:
    """The plan of a solution (its residual measured here, on the active pairs)."""
    from .homotopy import residual, stage_stats

    h, N = float(sol["h"]), problem.steps
    stats = {**stage_stats(stages, polished), "active_set_rounds": rounds,
             "active_set_consistent": consistent, "theta": problem.theta,
             "gamma": problem.gamma}
    return ContactPlan(t=h * np.arange(N + 1, dtype=np.float64), x=sol["X"].T.copy(),
                       u=sol["U"].T.copy(), normal=sol["LN"].T.copy(),
                       friction=(sol["BP"] - sol["BM"]).T.copy(), active=active.T.copy(),
                       h=h, cost=float(sol["cost"]),
                       residual=residual(_ContactNLP(problem, active), sol), stats=stats,
                       state_names=problem.system.state_names)


#: The contact unknowns, (m, N) each: normal force, friction β⁺, β⁻, slip speed.
CONTACT_VARS = ("LN", "BP", "BM", "S")


class _ContactNLP:
    """The NLP of a :class:`ContactProblem` with fixed active sets (a
    :class:`~nscontrol.optimal.homotopy.Builder`)."""

    def __init__(self, problem: ContactProblem, active: np.ndarray, x0: Any = None) -> None:
        self.problem, self.active = problem, np.asarray(active, bool)
        self.x0 = problem.x0 if x0 is None else x0     # a CasADi parameter in MPC
        self.on = np.flatnonzero(self.active.ravel(order="F"))
        self.off = np.flatnonzero(~self.active.ravel(order="F"))

    def variables(self, opti: Any) -> dict[str, Any]:
        p = self.problem
        s, N = p.system, p.steps
        var = {"X": opti.variable(s.n_states, N + 1), "U": opti.variable(p.n_inputs, N),
               "h": opti.variable() if p.minimum_time else float(p.h)}
        for name in CONTACT_VARS[: 4 if s.friction_dim else 1] if s.n_contacts else ():
            var[name] = opti.variable(s.n_contacts, N)
        return var

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        """The Moreau–Jean steps, the end conditions, the bounds, no force on the inactive
        contacts."""
        ca = casadi()
        _dynamics(opti, self.problem, var, self.x0)
        _bounds(opti, self.problem, var)
        for name in CONTACT_VARS:
            if name in var and self.off.size:
                opti.subject_to(ca.vec(var[name])[self.off.tolist()] == 0)

    def cost(self, var: dict[str, Any]) -> Any:
        p, ca = self.problem, casadi()
        J = p.effort * var["h"] * ca.sumsqr(var["U"])
        return J + p.steps * var["h"] if p.minimum_time else J

    def pair_keys(self) -> list[tuple[Any, Any]]:
        """The unknown each pair's first entries are (the second are expressions)."""
        names = CONTACT_VARS[: 4 if self.problem.system.friction_dim else 1]
        return [([(name, int(j)) for j in self.on], None) for name in names]

    def pairs(self, var: dict[str, Any], ops: Any) -> list[tuple[Any, Any]]:
        """Newton's law at velocity level and planar Coulomb friction (the module
        docstring), on the active entries."""
        s, n, N = self.problem.system, self.problem.system.n_dof, self.problem.steps
        if not s.n_contacts:
            return []
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
        return [(ops.select(a, self.on), ops.select(b, self.on)) for a, b in out]


def _dynamics(opti: Any, problem: ContactProblem, var: dict[str, Any], x0: Any) -> None:
    """The Moreau–Jean step between every two grid points and the end conditions (the
    initial state ``x0``: the problem's, or a parameter)."""
    ca = casadi()
    s, n, N, th, h = problem.system, problem.system.n_dof, problem.steps, problem.theta, var["h"]
    X, U = var["X"], var["U"]
    Qk, Qn, Vk, Vn = X[:n, :-1], X[:n, 1:], X[n:, :-1], X[n:, 1:]
    S = np.eye(n) if s.actuation is None else s.actuation
    f = ca.DM(np.tile(s.constant_force[:, None], (1, N))) + ca.mtimes(ca.DM(S), U)
    Mhat = ca.DM(s.mass_matrix())
    if s.stiffness is not None:
        f = f - ca.mtimes(ca.DM(s.stiffness), Qk + h * th * Vk)
        Mhat = Mhat + h ** 2 * th ** 2 * ca.DM(s.stiffness)
    if s.damping is not None:
        f = f - ca.mtimes(ca.DM(s.damping), Vk)
        Mhat = Mhat + h * th * ca.DM(s.damping)
    if s.n_contacts:
        f = f + ca.mtimes(ca.DM(s.dense_gap_matrix().T), var["LN"])
    if s.friction_dim:
        f = f + ca.mtimes(ca.DM(np.asarray(s.tangent_matrix).T), var["BP"] - var["BM"])
    opti.subject_to(ca.vec(ca.mtimes(Mhat, Vn - Vk) - h * f) == 0)
    opti.subject_to(ca.vec(Qn - Qk - h * ((1 - th) * Vk + th * Vn)) == 0)
    opti.subject_to(X[:, 0] == x0)
    if problem.x_final is not None:
        idx = np.flatnonzero(~np.isnan(problem.x_final)).tolist()
        opti.subject_to(X[idx, N] == problem.x_final[idx])


def _bounds(opti: Any, problem: ContactProblem, var: dict[str, Any]) -> None:
    ca, N = casadi(), problem.steps
    for bound, sign in ((problem.u_min, 1.0), (problem.u_max, -1.0)):
        if bound is not None:
            opti.subject_to(ca.vec(sign * (var["U"] - np.tile(bound[:, None], (1, N)))) >= 0)
    if problem.minimum_time:
        lo, hi = problem.h_bounds
        opti.subject_to(opti.bounded(lo, var["h"], hi))


def casadi() -> Any:
    """The casadi module (the extra's check)."""
    return require_casadi()
