r"""Model predictive control through contact and friction, as a sampled block.

:class:`ContactMPC` is a sampled :class:`~nscontrol.systems.feedback.Controller`: at every
sampling instant it reads the plant's state, solves the contact transcription of
:class:`~nscontrol.optimal.ContactProblem` over a receding horizon from that state (the same
Moreau–Jean steps, the same complementarity pairs), applies the first planned input (held
over the sample) and keeps the plan, shifted by one step, as the next sample's initial guess.

The NLP is built once, with every contact of every step in it: the initial state and the
relaxation ``σ`` are CasADi parameters and the active sets (the contacts each step closes)
are constraint bounds — on an inactive entry the forces are fixed at zero and the velocity
condition is free, Moreau–Jean's ``λ = 0`` — so that a sample costs the IPOPT iterations
alone, whatever contacts it closes. The first sample runs the whole Scholtes homotopy of
the block's :class:`~nscontrol.optimal.Relaxation` from a cold start.

**The later samples (frictionless contacts): a QP with complementarity.** The model being
linear, with the active sets fixed a sample's problem is a convex QP (the tracking cost, the
steps, the input bounds) with the pairs ``0 <= λ ⟂ b >= 0`` (``b`` Newton's velocity
condition, a linear row). Choosing for each pair the side held at zero — the contact's
*mode*: ``b = 0 <= λ`` (the impact) or ``λ = 0 <= b`` (no force) — leaves an ordinary QP.
The mode iteration solves it by an active-set iteration over the modes and the input bounds
together (:class:`_ModeQP`): start from the modes and bounds of the shifted plan, solve the
equality-constrained QP of the sides and bounds held (one dense KKT solve, the states
eliminated by the steps), then hold what the solution violates, release a bound whose
multiplier has the wrong sign, and hand a pair's zero to its other side when the held
side's multiplier asks to leave zero (the mode changes); the first few iterations change
every status found wrong at once (a primal-dual active set), the later ones the worst one
only. When nothing changes, every pair holds one side exactly at zero, the bounds and the
other sides hold, and the multipliers of the held sides have their signs: a strongly
stationary point of the problem with exact complementarity, the QP's optimum for those
modes. The active sets are then re-derived from the plan and the iteration repeated until
they agree (``max_rounds``). When it does not settle within ``max_mode_iterations`` KKT
solves, or a KKT system has no solution (held rows that contradict each other; dependent
but consistent ones are solved by least norm), the sample falls back to IPOPT (one relaxed
solve at ``σ = relaxation.sigma_min`` from the shifted plan and the last IPOPT multipliers);
so does every sample of a model with friction (the iteration did not settle on the
sticking of the pushed block). ``solver="ipopt"`` solves every sample by IPOPT.

The block's internal state is the record of its last solve — wall and CPU time, IPOPT
iterations, complementarity residual, active-set rounds, cost, the mode iteration's KKT
solves and whether IPOPT solved the sample — so that a closed-loop run keeps it per sample
in the trajectory's signal ``xc`` (:meth:`ContactMPC.signals` names its columns).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_matrix,
    as_vector,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import DimensionError, ModelError, SolverError
from ..systems.feedback import Jump, Measurement
from ..systems.lagrangian import LagrangianSystem
from ._casadi import require_casadi
from .contact import CONTACT_VARS, ContactProblem, Relaxation, _ContactNLP, active_sets
from .homotopy import SOLVED, _pair_constraints, casadi_ops, pair_keys, residual

__all__ = ["ContactMPC"]

#: The columns of the block's internal state (one record per sample).
RECORD = ("solve_time", "iterations", "residual", "rounds", "cost", "cpu_time",
          "mode_iterations", "ipopt")


@dataclass(eq=False)
class ContactMPC:
    """A sampled MPC block for a Lagrangian system with contacts and planar friction.

    At each sample ``t_k`` it minimises, over ``steps`` Moreau–Jean steps of length ``h``
    from the measured state ``x``,

    ``h Σ_k [(x_{k+1} - x*)ᵀ W (x_{k+1} - x*) + effort |u_k|²] + (x_N - x*)ᵀ P (x_N - x*)``,
    with ``x_N = x*`` where ``terminal`` is true (the NaN components of ``target`` free and
    unweighted),

    subject to the contact law of :class:`ContactProblem` and the input bounds, and returns
    the first input.

    Parameters
    ----------
    system : LagrangianSystem
        The model (constant mass, linear forces, affine gaps, at most planar friction).
    target : array_like (2 n,)
        The state ``x*`` to reach; NaN components are free.
    steps : int
        Horizon ``N`` (steps).
    h : float
        The model's step; the plant's integrator should use the same to be reproduced.
    period : float, optional
        Sampling period (default ``h``).
    state_weight : float or array_like (2 n,)
        Diagonal of ``W``, ``>= 0``.
    effort : float
        Weight of ``|u|²``, ``>= 0``.
    terminal : bool
        Constrain ``x_N = x*`` (the classical stabilising terminal constraint).
    terminal_weight : array_like (2 n, 2 n), optional
        ``P``, a symmetric positive semidefinite terminal cost (e.g. the cost-to-go of an LQR
        design, the classical alternative to the terminal constraint); default none.
    u_min, u_max : float or array_like (p,), optional
        Input bounds.
    relaxation : Relaxation, optional
        The first sample's homotopy; later samples solve at its ``sigma_min`` (and its
        ``tol``, ``max_iter``). Default: ``Relaxation(sigma_min=1e-6, tol=1e-8)``.
    theta, gamma : float
        θ and γ of the Moreau–Jean step.
    max_rounds : int
        Solves per sample while the active sets of the plan differ from those it was solved
        with.
    solver : {"auto", "ipopt"}
        ``"auto"``: the warm samples of a frictionless model by the mode iteration (the
        module docstring), IPOPT when it does not settle; ``"ipopt"``: every sample by IPOPT.
    max_mode_iterations : int
        KKT solves of the mode iteration per round before the sample falls back to IPOPT.

    Raises
    ------
    ModelError, DimensionError
        As :class:`ContactProblem` for the model, the target and the bounds.
    """

    system: LagrangianSystem
    target: Any
    steps: int
    h: float
    period: float | None = None
    state_weight: Any = 1.0
    effort: float = 1e-3
    terminal: bool = True
    terminal_weight: Any = None
    u_min: Any = None
    u_max: Any = None
    relaxation: Relaxation | None = None
    theta: float = 0.5
    gamma: float = 0.5
    max_rounds: int = 3
    solver: str = "auto"
    max_mode_iterations: int = 60
    problem: ContactProblem = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = check_type("system", self.system, LagrangianSystem)
        target = np.asarray(self.target, dtype=float).reshape(-1)
        self.problem = ContactProblem(
            s, np.where(np.isnan(target), 0.0, target) if target.size == s.n_states
            else target, self.steps, self.h, x_final=target if self.terminal else None,
            u_min=self.u_min, u_max=self.u_max, effort=self.effort, theta=self.theta,
            gamma=self.gamma)
        self.target = target
        self.period = self.h if self.period is None else check_positive("period", self.period)
        W = np.broadcast_to(np.asarray(self.state_weight, float), (s.n_states,)) \
            if np.ndim(self.state_weight) == 0 else np.asarray(self.state_weight, float)
        if W.shape != (s.n_states,):
            raise DimensionError(f"state_weight: expected a scalar or {s.n_states} values, "
                                 f"got shape {np.shape(self.state_weight)}")
        if np.any(~np.isfinite(W)) or np.any(W < 0):
            raise ModelError("state_weight: expected finite weights >= 0")
        self.state_weight = np.where(np.isnan(target), 0.0, W)
        if self.terminal_weight is not None:
            P = as_matrix("terminal_weight", self.terminal_weight, rows=s.n_states,
                          cols=s.n_states)
            if not np.allclose(P, P.T, rtol=0.0, atol=1e-12 * (1.0 + np.abs(P).max())) or \
                    np.linalg.eigvalsh(0.5 * (P + P.T)).min() < -1e-12 * np.abs(P).max():
                raise ModelError("terminal_weight: expected a symmetric positive "
                                 "semidefinite matrix")
            free = np.isnan(target)
            if np.any(P[free]) or np.any(P[:, free]):
                raise ModelError("terminal_weight: weighs a free (NaN) component of target")
            self.terminal_weight = 0.5 * (P + P.T)
        self.relaxation = self._relaxation = Relaxation(sigma_min=1e-6, tol=1e-8) \
            if self.relaxation is None else check_type("relaxation", self.relaxation, Relaxation)
        self._period = float(self.period)
        check_integer("max_rounds", self.max_rounds, minimum=1)
        check_integer("max_mode_iterations", self.max_mode_iterations, minimum=1)
        if self.solver not in ("auto", "ipopt"):
            raise ModelError(f"solver: expected 'auto' or 'ipopt', got {self.solver!r}")
        self._qp_built: _ModeQP | bool | None = None
        self._duals: tuple[FloatArray, FloatArray] | None = None
        self._nlp_built: _ParametricNLP | None = None
        self._guess: dict[str, Any] | None = None
        self._record = np.zeros(len(RECORD))
        self._at: float | None = None

    # -- the Controller protocol -----------------------------------------------------------
    @property
    def n_states(self) -> int:
        """The record of the last solve (:data:`RECORD`)."""
        return len(RECORD)

    @property
    def n_outputs(self) -> int:
        """The plant's inputs."""
        return self.problem.n_inputs

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """Solve from the measured state ``m.x`` and return the first planned input.

        Parameters
        ----------
        t : float
            The sampling instant.
        xc : ndarray
            The record of the last solve (unused).
        m : Measurement
            Its ``x``, the plant's state, is the horizon's initial state.

        Returns
        -------
        ndarray (p,)

        Raises
        ------
        SolverError
            IPOPT failed at this sample.
        """
        if self._at != t:
            self._record = self.solve(m.x, t)
            self._at = t
        assert self._guess is not None
        return np.array(self._guess["U"][:, 0], dtype=float)

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The record of the solve made at ``t``.

        Parameters
        ----------
        t : float
            The sampling instant.
        xc : ndarray
            The previous record.
        m : Measurement
            The plant's measurement.
        """
        if self._at != t:
            self.output(t, xc, m)
        return self._record.copy()

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        """A plant jump leaves the record as it is (the next sample measures the state).

        Parameters
        ----------
        t : float
            Time of the jump.
        xc : ndarray
            The record.
        jump : Jump
            The plant's jump.
        """
        return xc

    # -- solving ---------------------------------------------------------------------------
    def solve(self, x: ArrayLike, t: float = 0.0) -> FloatArray:
        """One sample: the plan from state ``x`` (kept for the next sample's warm start).

        Parameters
        ----------
        x : array_like (2 n,)
            The measured state.
        t : float
            Its time (for messages).

        Returns
        -------
        ndarray
            The record (:data:`RECORD`): wall time [s], IPOPT iterations (0 when the mode
            iteration solved the sample), complementarity residual, active-set rounds, cost,
            the process's CPU time [s] (on a loaded machine the wall time counts the waits
            for a core; the CPU time does not), the mode iteration's KKT solves, 1 when IPOPT
            solved the sample (the first one, a fallback, ``solver="ipopt"``) else 0.
        """
        x = as_vector("x", x, self.system.n_states)   # a measured state may penetrate by roundoff
        start, cpu = time.perf_counter(), time.process_time()
        cold = self._guess is None
        guess = self._cold_guess(x) if cold else self._shifted(x)
        active = active_sets(self.problem, guess["X"], self.h)
        modes = 0
        qp = None if cold or self.solver == "ipopt" else self._mode_qp()
        if qp is not None:
            found, active, rounds, modes = self._solve_modes(qp, x, guess, active)
            if found is not None:
                self._guess = found
                res = residual(_ContactNLP(self.problem, active), found)
                return np.array([time.perf_counter() - start, 0, res, rounds, found["cost"],
                                 time.process_time() - cpu, modes, 0.0], dtype=float)
        nlp = self._nlp()
        rel = self._relaxation
        iterations, rounds = 0, 0
        while True:
            rounds += 1
            for sigma in rel.sigmas() if cold else [rel.sigma_min]:
                start_from, duals = guess, self._duals
                stale = guess.get("lam_g") is None and duals is not None
                if stale and duals is not None:
                    # a fallback after mode-iteration samples: the last IPOPT multipliers
                    start_from = {**guess, "lam_g": duals[0], "lam_x": duals[1]}
                guess, its, status = nlp.solve(start_from, x, sigma, active)
                iterations += its
                if status not in SOLVED and stale:      # again without them
                    guess, its, status = nlp.solve({**start_from, "lam_g": None}, x, sigma,
                                                   active)
                    iterations += its
                if status not in SOLVED:
                    raise SolverError(f"ContactMPC: IPOPT failed at t = {t:.6g} (σ = "
                                      f"{sigma:.3g}, {status}); try a longer horizon, other "
                                      "weights or a smaller first relaxation", status=status)
            new = active_sets(self.problem, guess["X"], self.h)
            if np.array_equal(new, active) or rounds >= self.max_rounds:
                break
            active = new
        self._guess = guess
        self._duals = (guess["lam_g"], guess["lam_x"])
        if self.solver == "auto":
            self._mode_qp()                     # built at the first sample, not the second
        res = nlp.residual(guess, active)
        return np.array([time.perf_counter() - start, iterations, res, rounds,
                         guess["cost"], time.process_time() - cpu, modes, 1.0], dtype=float)

    def _solve_modes(self, qp: _ModeQP, x: FloatArray, guess: dict[str, Any],
                     active: np.ndarray) -> tuple[dict[str, Any] | None, np.ndarray, int, int]:
        """The mode iteration, its active sets re-derived from the plan until they agree
        (at most ``max_rounds``): the plan (``None`` when an iteration does not settle), the
        last active sets, the rounds and the KKT solves."""
        modes, rounds = 0, 0
        while True:
            rounds += 1
            found, its = qp.solve(x, guess, active, self._relaxation.tol,
                                  self.max_mode_iterations)
            modes += its
            if found is None:
                return None, active, rounds, modes
            new = active_sets(self.problem, found["X"], self.h)
            if np.array_equal(new, active) or rounds >= self.max_rounds:
                return found, active, rounds, modes
            active, guess = new, found

    def _mode_qp(self) -> _ModeQP | None:
        if self._qp_built is None:
            try:
                self._qp_built = _ModeQP(self)
            except ModelError:
                self._qp_built = False
        return self._qp_built if isinstance(self._qp_built, _ModeQP) else None

    @property
    def plan(self) -> dict[str, Any] | None:
        """The last plan's unknowns (``X``: states, ``U``: inputs, the contact forces), or
        ``None`` before the first sample."""
        return self._guess

    def signals(self, traj: Any) -> dict[str, FloatArray]:
        """The per-sample records of a closed-loop run, by name.

        Parameters
        ----------
        traj : Trajectory
            A run of ``closed_loop(plant, this block)``; its ``xc`` signal holds the record
            of the solve that produced the input acting over each step.

        Returns
        -------
        dict
            ``t`` (the sampling instants) and one array per :data:`RECORD` name, one entry
            per sample.
        """
        xc = np.asarray(traj.signals.get("xc"))
        if xc.ndim != 2 or xc.shape[1] != len(RECORD):
            raise ModelError(f"traj: expected the 'xc' signal of a ContactMPC ({len(RECORD)} "
                             f"columns), got shape {xc.shape}")
        t = np.asarray(traj.t, float)
        k = np.round((t[:-1] - t[0]) / self._period, 6)
        first = np.flatnonzero(np.r_[True, np.diff(np.floor(k)) > 0])
        rows = xc[1:][first]
        return {"t": t[:-1][first], **{name: rows[:, i] for i, name in enumerate(RECORD)}}

    def _cold_guess(self, x: FloatArray) -> dict[str, Any]:
        from .contact import initial_guess

        problem = ContactProblem(self.system, x, self.steps, self.h,
                                 x_final=np.where(np.isnan(self.target), x, self.target),
                                 theta=self.theta, gamma=self.gamma)
        return initial_guess(problem)

    def _shifted(self, x: FloatArray) -> dict[str, Any]:
        """The last plan moved one sample on (its last step repeated), from ``x``."""
        assert self._guess is not None
        k = max(1, int(round(self._period / self.h)))
        out = dict(self._guess)
        for name in ("X", "U", *CONTACT_VARS):
            if name in out and np.ndim(out[name]) == 2:
                a = out[name]
                out[name] = np.concatenate([a[:, k:], np.repeat(a[:, -1:], min(k, a.shape[1]),
                                                                axis=1)], axis=1)
        out["X"] = out["X"].copy()
        out["X"][:, 0] = x
        return out

    def _nlp(self) -> _ParametricNLP:
        if self._nlp_built is None:
            self._nlp_built = _ParametricNLP(self)
        return self._nlp_built


class _ParametricNLP:
    """The relaxed NLP with **every** contact of every step in it, built once: the initial
    state and ``σ`` are CasADi parameters, and the active sets are constraint bounds (an
    inactive entry's forces are fixed to zero and its velocity condition left free, the
    ``λ = 0`` of the Moreau–Jean step), so a change of active set costs no rebuild; solved
    by IPOPT through ``nlpsol`` (cold and warm-started solvers)."""

    def __init__(self, mpc: ContactMPC) -> None:
        ca = require_casadi()
        opti = ca.Opti()
        s, N = mpc.system, mpc.steps
        p_x0 = opti.parameter(s.n_states)
        builder = _TrackingNLP(mpc, np.ones((s.n_contacts, N), bool), p_x0)
        self.builder = builder
        var = builder.variables(opti)
        builder.constraints(opti, var)
        pairs = builder.pairs(var, casadi_ops())
        keys = pair_keys(builder, pairs)
        has_pairs = any(a.numel() for a, _ in pairs)
        sigma = opti.parameter() if has_pairs else None
        # each pair adds the rows a >= 0, b >= 0, a b <= σ (one per entry, in this order)
        self.pair_rows: list[tuple[int, int]] = []
        for pair, key in zip(pairs, keys[:len(pairs)], strict=True):
            first = opti.ng
            _pair_constraints(opti, [pair], sigma, None, [key])
            self.pair_rows.append((first, pair[0].numel()))
        cost = builder.cost(var)
        opti.minimize(cost)
        self.names, self.index, self.shapes = _layout(opti, var)
        params = [p_x0] if sigma is None else [p_x0, sigma]
        pw = ca.Function("pwhere", [opti.p], params)
        found = pw(np.arange(opti.np, dtype=float))
        self.p_index = [np.asarray(a, float).astype(int).ravel()
                        for a in (found if isinstance(found, (list, tuple)) else [found])]
        self.bounds = ca.Function("bounds", [opti.p], [opti.lbg, opti.ubg])
        self.nx, self.ng, self.np = opti.nx, opti.ng, opti.np
        self._rows: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        nlp = {"x": opti.x, "p": opti.p, "f": opti.f, "g": opti.g}
        rel = mpc._relaxation
        # MUMPS with the AMD ordering and no scaling: the KKT systems are small, and their
        # analysis is paid at every IPOPT call (15 % less CPU per sample on the cart-pole)
        base = {"print_level": 0, "sb": "yes", "tol": rel.tol,
                "acceptable_constr_viol_tol": rel.tol, "max_iter": int(rel.max_iter),
                "mumps_pivot_order": 0, "mumps_permuting_scaling": 0, "mumps_scaling": 0}
        opts = {"print_time": False, "error_on_fail": False, "expand": True}
        self.cold = ca.nlpsol("mpc_cold", "ipopt", nlp, {**opts, "ipopt": base})
        self.warm = ca.nlpsol("mpc_warm", "ipopt", nlp, {**opts, "ipopt": {
            **base, "warm_start_init_point": "yes", "mu_init": 1e-6}})

    def _parameters(self, x0: FloatArray, sigma: float) -> FloatArray:
        p = np.zeros(self.np)
        p[self.p_index[0]] = x0
        if len(self.p_index) > 1:
            p[self.p_index[1]] = sigma
        return p

    def constraint_bounds(self, p: FloatArray, active: np.ndarray
                          ) -> tuple[FloatArray, FloatArray]:
        """``lbg, ubg`` at the parameters ``p`` (Opti writes a parameter's equality, as
        ``X[:, 0] = x0``, into the bounds) and the active sets ``(m, N)``: on an inactive
        entry the first factor of each pair (a force, or the slip speed) is fixed at zero
        and the second (a velocity condition) is free."""
        lbg, ubg = (np.asarray(b, float).ravel() for b in self.bounds(p))
        key = np.asarray(active, bool).tobytes()
        if key not in self._rows:
            off = np.flatnonzero(~np.asarray(active, bool).ravel(order="F"))
            a_rows = np.concatenate([first + off for first, _ in self.pair_rows] or [off])
            b_rows = np.concatenate([first + k + off for first, k in self.pair_rows] or [off])
            if len(self._rows) > 256:
                self._rows.clear()
            self._rows[key] = (a_rows, b_rows)
        a_rows, b_rows = self._rows[key]
        finite = np.isfinite(lbg[a_rows])
        ubg[a_rows[finite]] = lbg[a_rows[finite]]
        lbg[a_rows[~finite]] = ubg[a_rows[~finite]]
        lbg[b_rows], ubg[b_rows] = -np.inf, np.inf
        return lbg, ubg

    def solve(self, guess: dict[str, Any], x0: FloatArray, sigma: float, active: np.ndarray
              ) -> tuple[dict[str, Any], int, str]:
        """One IPOPT solve from ``guess`` with the active sets ``active``; the solution, its
        iterations and status."""
        z = _pack(self.names, self.index, self.nx, guess)
        p = self._parameters(x0, sigma)
        lbg, ubg = self.constraint_bounds(p, active)
        lam = guess.get("lam_g")
        warm = lam is not None and lam.size == self.ng
        solver = self.warm if warm else self.cold
        args: dict[str, Any] = {"x0": z, "p": p, "lbg": lbg, "ubg": ubg}
        if warm:
            args |= {"lam_g0": lam, "lam_x0": guess["lam_x"]}
        sol = solver(**args)
        stats = solver.stats()
        out = _unpack(self.names, self.index, self.shapes, np.asarray(sol["x"], float).ravel(),
                      guess)
        out["cost"] = float(sol["f"])
        out["lam_g"] = np.asarray(sol["lam_g"], float).ravel()
        out["lam_x"] = np.asarray(sol["lam_x"], float).ravel()
        return out, int(stats.get("iter_count", 0)), str(stats.get("return_status", ""))

    def residual(self, sol: dict[str, Any], active: np.ndarray) -> float:
        """The largest ``|min(a, b)|`` over the active pairs."""
        return residual(_ContactNLP(self.builder.problem, active), sol)


class _TrackingNLP(_ContactNLP):
    """The contact transcription from a parametric initial state, with the tracking cost."""

    def __init__(self, mpc: ContactMPC, active: np.ndarray, x0: Any) -> None:
        super().__init__(mpc.problem, active, x0)
        self.mpc = mpc

    def cost(self, var: dict[str, Any]) -> Any:
        ca, mpc = require_casadi(), self.mpc
        J = super().cost(var)
        W = np.asarray(mpc.state_weight, float)
        ref = np.where(np.isnan(mpc.target), 0.0, mpc.target)
        err = var["X"][:, 1:] - ca.DM(np.tile(ref[:, None], (1, mpc.steps)))
        J = J + mpc.h * ca.sum1(ca.sum2(ca.DM(np.tile(W[:, None], (1, mpc.steps)))
                                         * err * err))
        if mpc.terminal_weight is not None:
            e_N = err[:, -1]
            J = J + ca.mtimes(e_N.T, ca.mtimes(ca.DM(mpc.terminal_weight), e_N))
        return J


def _layout(opti: Any, var: dict[str, Any]) -> tuple[list[str], list[np.ndarray], list[Any]]:
    """The names of the unknowns of an Opti problem, where each one's entries sit in
    ``opti.x`` (column-major) and their shapes."""
    ca = require_casadi()
    names = [name for name, sym in var.items() if isinstance(sym, ca.MX)]
    syms = [var[name] for name in names]
    where = ca.Function("where", [opti.x], [ca.vec(sym) for sym in syms])
    index = [np.asarray(a, float).astype(int).ravel()
             for a in where(np.arange(opti.nx, dtype=float))]
    return names, index, [sym.shape for sym in syms]


def _pack(names: list[str], index: list[np.ndarray], nx: int, guess: dict[str, Any]
          ) -> FloatArray:
    """The vector of unknowns of a plan."""
    z = np.zeros(nx)
    for name, idx in zip(names, index, strict=True):
        z[idx] = np.asarray(guess[name], float).ravel(order="F")
    return z


def _unpack(names: list[str], index: list[np.ndarray], shapes: list[Any], z: FloatArray,
            guess: dict[str, Any]) -> dict[str, Any]:
    """The plan of a vector of unknowns (the other entries of ``guess`` kept)."""
    out = dict(guess)
    for name, idx, shape in zip(names, index, shapes, strict=True):
        out[name] = z[idx].reshape(shape, order="F")
    return out


class _ModeQP:
    """A sample's problem as a QP with complementarity, solved by an active-set iteration
    over the contact modes and the bounds (the module docstring).

    It is the transcription of :class:`_TrackingNLP` (every contact of every step), each
    pair written as its two linear sides ``a >= 0`` (an unknown: a force or the slip speed)
    and ``b >= 0`` (a row) without the product; the model being linear, the cost's Hessian
    and the rows' Jacobian are constant, read off CasADi once. The states are eliminated by
    the steps and the initial state (``z = T y + t(x0)``, ``y`` the inputs and the contact
    unknowns), so that an iteration is one dense KKT solve of the free ``y`` and the rows
    held at a bound (a few dozen unknowns)."""

    def __init__(self, mpc: ContactMPC) -> None:
        if mpc.system.friction_dim:
            # sticking holds both friction rows and the slip speed at zero together; measured
            # on the pushed block, every sample fell back to IPOPT, after up to 36 KKT solves
            raise ModelError("system: the mode iteration covers frictionless contacts")
        opti, var, pair_rows, pair_vars = _qp_transcription(mpc)
        self.names, self.index, self.shapes = _layout(opti, var)
        A, H, c = self._read(opti, mpc.system.n_states)
        lb1, ub1 = self._bounds(np.random.default_rng(0).normal(size=mpc.system.n_states))
        b_rows = np.concatenate(pair_rows) if pair_rows else np.zeros(0, int)
        eq = (lb1 == ub1) & (self.lb0 == self.ub0)
        eq[b_rows] = False
        self._eliminate(A, np.flatnonzero(eq))
        self.Hy = self.T.T @ H @ self.T
        self.HT, self.cT = self.T.T @ H, self.T.T @ c
        self.H, self.c = H, c
        other = np.setdiff1d(np.arange(A.shape[0]), np.r_[self.rows_D, b_rows])
        pos, general = self._split_rows(A, other, lb1, ub1)
        self.n_general = int(general.size)
        self.rows = np.r_[general, b_rows]
        self.A_rows = A[self.rows]
        self.C = self.A_rows @ self.T
        # the pairs: y index of a, row (in self.rows) of b, per entry in the NLP's order
        self.pair_a = np.array([pos[self.index[self.names.index(name)][j]]
                                for keys_ in pair_vars for name, j in keys_], int)
        self.pair_b = self.n_general + np.arange(b_rows.size)

    def _read(self, opti: Any, n_states: int) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The rows' Jacobian ``A``, the cost's Hessian ``H`` and gradient at zero ``c``
        (constant: the model is linear), the cost at zero, and the rows' bounds
        ``lb(x0) <= A z <= ub(x0)``, affine in the initial state: read off at ``x0 = 0`` and
        at the unit vectors (an infinite bound stays so)."""
        ca = require_casadi()
        nx, ng, zero = opti.nx, opti.ng, np.zeros(opti.nx)
        A = np.asarray(ca.Function("A", [opti.x], [ca.jacobian(opti.g, opti.x)])(zero),
                       float).reshape(ng, nx)
        H = np.asarray(ca.Function("H", [opti.x], [ca.hessian(opti.f, opti.x)[0]])(zero),
                       float).reshape(nx, nx)
        c = np.asarray(ca.Function("c", [opti.x], [ca.gradient(opti.f, opti.x)])(zero),
                       float).ravel()
        self.f0 = float(ca.Function("f0", [opti.x], [opti.f])(zero))
        bounds = ca.Function("bounds", [opti.x, opti.p], [opti.lbg - opti.g, opti.ubg - opti.g])

        def at(x0: FloatArray) -> tuple[FloatArray, FloatArray]:
            lb, ub = bounds(zero, x0)
            return np.asarray(lb, float).ravel(), np.asarray(ub, float).ravel()

        self.lb0, self.ub0 = at(np.zeros(n_states))
        with np.errstate(invalid="ignore"):
            units = [at(e) for e in np.eye(n_states)]
            self.lb_x = np.nan_to_num(np.column_stack([lb - self.lb0 for lb, _ in units]))
            self.ub_x = np.nan_to_num(np.column_stack([ub - self.ub0 for _, ub in units]))
        return A, H, c

    def _eliminate(self, A: FloatArray, eq_rows: np.ndarray) -> None:
        """The states ``D`` from the equality rows that determine them (chosen by a pivoted
        QR): ``z = T y + t(x0)``, ``y`` the other unknowns ``Y``."""
        from scipy.linalg import qr

        D = self.index[self.names.index("X")]
        Y = np.setdiff1d(np.arange(A.shape[1]), D)
        if D.size > eq_rows.size:
            raise ModelError("system: the steps do not determine the states")
        _, R, piv = qr(A[eq_rows][:, D].T, pivoting=True)
        if np.abs(R[D.size - 1, D.size - 1]) <= 1e-10 * np.abs(R[0, 0]):
            raise ModelError("system: the steps do not determine the states")
        rows_D = eq_rows[np.sort(piv[:D.size])]
        Einv = np.linalg.inv(A[rows_D][:, D])
        T = np.zeros((A.shape[1], Y.size))
        T[D] = -Einv @ A[rows_D][:, Y]
        T[Y, np.arange(Y.size)] = 1.0
        self.D, self.Y, self.rows_D, self.Einv, self.T = D, Y, rows_D, Einv, T

    def _split_rows(self, A: FloatArray, other: np.ndarray, lb1: FloatArray,
                    ub1: FloatArray) -> tuple[np.ndarray, np.ndarray]:
        """Rows on one ``y`` alone with constant bounds become bounds of ``y`` (``lo``,
        ``hi``); the others stay rows. Returns each unknown's position in ``y`` (-1 for a
        state) and the rows that stay."""
        lb0, ub0 = self.lb0, self.ub0
        nnz = A[other] != 0.0
        single = (nnz.sum(axis=1) == 1) & ~nnz[:, self.D].any(axis=1) \
            & (lb0[other] == lb1[other]) & (ub0[other] == ub1[other]) \
            & (lb0[other] < ub0[other])
        self.lo, self.hi = np.full(self.Y.size, -np.inf), np.full(self.Y.size, np.inf)
        pos = np.full(A.shape[1], -1)
        pos[self.Y] = np.arange(self.Y.size)
        for r in other[single]:
            j = int(np.flatnonzero(A[r])[0])
            lo, hi = lb0[r] / A[r, j], ub0[r] / A[r, j]
            lo, hi = (hi, lo) if A[r, j] < 0 else (lo, hi)
            self.lo[pos[j]], self.hi[pos[j]] = max(self.lo[pos[j]], lo), min(self.hi[pos[j]], hi)
        return pos, other[~single]

    def _bounds(self, x0: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.lb0 + self.lb_x @ x0, self.ub0 + self.ub_x @ x0

    def solve(self, x0: FloatArray, guess: dict[str, Any], active: np.ndarray, tol: float,
              max_iter: int) -> tuple[dict[str, Any] | None, int]:
        """The plan from ``x0`` with the active sets ``active``, the modes and bounds held
        first where ``guess`` has them; ``(None, iterations)`` when the iteration does not
        settle within ``max_iter`` KKT solves or a KKT system has no solution."""
        lb, ub = self._bounds(x0)
        t = np.zeros(self.T.shape[0])
        t[self.D] = self.Einv @ lb[self.rows_D]
        g = self.HT @ t + self.cT
        off = self.A_rows @ t
        clo, chi = lb[self.rows] - off, ub[self.rows] - off
        on = np.tile(np.asarray(active, bool).ravel(order="F"),
                     self.pair_a.size // max(1, active.size))
        lo, hi = self.lo.copy(), self.hi.copy()
        pa, pb = self.pair_a, self.pair_b
        lo[pa], hi[pa] = 0.0, np.where(on, np.inf, 0.0)
        clo[pb], chi[pb] = np.where(on, clo[pb], -np.inf), np.inf
        # the first statuses (-1 at the lower bound, +1 at the upper, 0 free) from the guess;
        # they only choose where the iteration starts (a wrong one is corrected by it), so
        # the margin 1e-6 only needs to exceed IPOPT's distance to a bound it reached
        y = _pack(self.names, self.index, self.T.shape[0], guess)[self.Y]
        scale_y = 1.0 + np.abs(np.where(np.isfinite(lo), lo, 0.0)) \
            + np.abs(np.where(np.isfinite(hi), hi, 0.0))
        sv = np.where(y <= lo + 1e-6 * scale_y, -1, np.where(y >= hi - 1e-6 * scale_y, 1, 0))
        sv[lo == hi] = -1
        cy = self.C @ y
        sr = np.where(cy <= clo + 1e-6, -1, np.where(cy >= chi - 1e-6, 1, 0))
        sr[clo == chi] = -1
        sr[~np.isfinite(clo) & ~np.isfinite(chi)] = 0
        a_first = y[pa] <= cy[pb] - clo[pb]
        sv[pa] = np.where(on & ~a_first, 0, -1)
        sr[pb] = np.where(on & ~a_first, -1, 0)
        last: tuple[Any, ...] | None = None
        for it in range(1, max_iter + 1):
            solved = self._kkt(g, lo, hi, clo, chi, sv, sr)
            if solved is None and last is not None and not last[-1]:
                # too many rows held at once: back to the last iterate, one change only
                p_sv, p_sr, p_nv, p_nr, p_y, p_cy, p_mu, p_nu, _ = last
                sv, sr = _one_change(p_sv, p_sr, p_nv, p_nr, p_y, p_cy, p_mu, p_nu, lo, hi,
                                     clo, chi, pa, pb)
                solved = self._kkt(g, lo, hi, clo, chi, sv, sr)
            if solved is None:
                return None, it
            y, mu, nu = solved
            cy = self.C @ y
            tol_p = tol * (1.0 + np.abs(y).max(initial=0.0))
            tol_d = tol * (1.0 + np.abs(g).max(initial=0.0) + np.abs(mu).max(initial=0.0)
                           + np.abs(nu).max(initial=0.0))
            new_v, new_r = _update(sv, y, mu, lo, hi, tol_p, tol_d), \
                _update(sr, cy, nu, clo, chi, tol_p, tol_d)
            # a pair keeps at least one side at zero; a side whose multiplier asks to leave
            # zero hands it to the other (the contact's mode changes)
            sa, sb = sv[pa], sr[pb]
            a_v, b_v, mu_a, nu_b = y[pa], cy[pb] - clo[pb], mu[pa], nu[pb]
            na, nb = sa.copy(), sb.copy()
            only_a, only_b, both = on & (sa == -1) & (sb == 0), on & (sa == 0) & (sb == -1), \
                on & (sa == -1) & (sb == -1)
            na[only_a & (b_v >= -tol_p) & (mu_a < -tol_d)] = 0
            nb[only_a & ((b_v < -tol_p) | (mu_a < -tol_d))] = -1
            nb[only_b & (a_v >= -tol_p) & (nu_b < -tol_d)] = 0
            na[only_b & ((a_v < -tol_p) | (nu_b < -tol_d))] = -1
            release = both & (np.minimum(mu_a, nu_b) < -tol_d)
            na[release & (mu_a <= nu_b)] = 0
            nb[release & (mu_a > nu_b)] = 0
            new_v[pa], new_r[pb] = na, nb
            single = it > _ALL_AT_ONCE
            last = (sv, sr, new_v, new_r, y, cy, mu, nu, single)
            if single:
                new_v, new_r = _one_change(sv, sr, new_v, new_r, y, cy, mu, nu, lo, hi,
                                           clo, chi, pa, pb)
            if np.array_equal(new_v, sv) and np.array_equal(new_r, sr):
                z = self.T @ y + t
                out = _unpack(self.names, self.index, self.shapes, z, guess)
                out["cost"] = float(0.5 * z @ self.H @ z + self.c @ z + self.f0)
                out["lam_g"] = out["lam_x"] = None
                return out, it
            sv, sr = new_v, new_r
        return None, max_iter

    def _kkt(self, g: FloatArray, lo: FloatArray, hi: FloatArray, clo: FloatArray,
             chi: FloatArray, sv: np.ndarray, sr: np.ndarray
             ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """The equality-constrained QP of the statuses: ``y`` and the multipliers of the
        bounds (``mu``) and rows (``nu``) held, ``H y + g = mu + Cᵀ nu`` (zero where not
        held); ``None`` when the KKT system has no solution (its residual not small)."""
        F = sv == 0
        y = np.where(sv < 0, lo, np.where(sv > 0, hi, 0.0))
        W = np.flatnonzero(sr != 0)
        CW = self.C[W]
        cw = np.where(sr[W] < 0, clo[W], chi[W])
        nf = int(F.sum())
        K = np.zeros((nf + W.size, nf + W.size))
        K[:nf, :nf] = self.Hy[np.ix_(F, F)]
        K[:nf, nf:] = CW[:, F].T
        K[nf:, :nf] = CW[:, F]
        fixed = ~F
        rhs = np.r_[-(g[F] + self.Hy[np.ix_(F, fixed)] @ y[fixed]), cw - CW[:, fixed] @ y[fixed]]
        sol = _kkt_solve(K, rhs)
        if not np.all(np.isfinite(sol)) or np.abs(K @ sol - rhs).max(initial=0.0) > 1e-9 * (
                1.0 + np.abs(rhs).max(initial=0.0)
                + np.abs(K).max(initial=0.0) * np.abs(sol).max(initial=0.0)):
            return None
        y[F] = sol[:nf]
        nu = np.zeros(self.C.shape[0])
        nu[W] = -sol[nf:]
        mu = self.Hy @ y + g - CW.T @ nu[W]
        mu[F] = 0.0
        return y, mu, nu


def _kkt_solve(K: FloatArray, rhs: FloatArray) -> FloatArray:
    """``K s = rhs`` by LU; when a pivot is below ``1e-11`` of the largest (rows held that
    are dependent, e.g. a terminal equality the contact rows already imply), the least-norm
    solution of a pivoted QR instead (a consistent system keeps a small residual, which the
    caller checks)."""
    from scipy.linalg import LinAlgWarning, lstsq, lu_factor, lu_solve

    if K.size == 0:
        return np.zeros(0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LinAlgWarning)      # a zero pivot: handled below
        lu, piv = lu_factor(K, check_finite=False)
    d = np.abs(np.diag(lu))
    if np.all(np.isfinite(d)) and d.min() > 1e-11 * d.max():
        return np.asarray(lu_solve((lu, piv), rhs, check_finite=False))
    return np.asarray(lstsq(K, rhs, cond=1e-11, lapack_driver="gelsy", check_finite=False)[0])


def _update(status: np.ndarray, value: FloatArray, mult: FloatArray, lo: FloatArray,
            hi: FloatArray, tol_p: float, tol_d: float) -> np.ndarray:
    """The next statuses of bounds ``lo <= value <= hi`` (primal-dual active set): a held
    bound whose multiplier has the wrong sign is released, a violated one is held
    (equalities stay held)."""
    new = status.copy()
    new[(status == -1) & (mult < -tol_d) & (lo < hi)] = 0
    new[(status == 1) & (mult > tol_d) & (lo < hi)] = 0
    new[(status == 0) & (value < lo - tol_p)] = -1
    new[(status == 0) & (value > hi + tol_p)] = 1
    return new


#: Mode iterations that change every status found wrong at once (a primal-dual active set,
#: quick from a good start); later ones change the worst one only, which cycles less.
_ALL_AT_ONCE = 4


def _one_change(sv: np.ndarray, sr: np.ndarray, new_v: np.ndarray, new_r: np.ndarray,
                y: FloatArray, cy: FloatArray, mu: FloatArray, nu: FloatArray,
                lo: FloatArray, hi: FloatArray, clo: FloatArray, chi: FloatArray,
                pa: np.ndarray, pb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Of the changes ``new_v, new_r`` proposes, the one of the largest violation (of a
    bound, or of a multiplier's sign), with its pair's other side when it is a mode
    change."""
    viol_v = np.maximum.reduce([lo - y, y - hi, -mu * (sv < 0), mu * (sv > 0)])
    viol_r = np.maximum.reduce([clo - cy, cy - chi, -nu * (sr < 0), nu * (sr > 0)])
    viol_v = np.where(np.isfinite(viol_v), viol_v, 0.0)
    viol_r = np.where(np.isfinite(viol_r), viol_r, 0.0)
    cv, cr = new_v != sv, new_r != sr
    if not cv.any() and not cr.any():
        return new_v, new_r
    iv = int(np.argmax(np.where(cv, viol_v, -np.inf))) if cv.any() else -1
    ir = int(np.argmax(np.where(cr, viol_r, -np.inf))) if cr.any() else -1
    take_v = ir < 0 or (iv >= 0 and viol_v[iv] >= viol_r[ir])
    out_v, out_r = sv.copy(), sr.copy()
    k = np.flatnonzero(pa == iv) if take_v else np.flatnonzero(pb == ir)
    if take_v:
        out_v[iv] = new_v[iv]
    else:
        out_r[ir] = new_r[ir]
    out_v[pa[k]], out_r[pb[k]] = new_v[pa[k]], new_r[pb[k]]    # a mode changes both sides
    return out_v, out_r


def _qp_transcription(mpc: ContactMPC) -> tuple[Any, dict[str, Any], list[np.ndarray],
                                                list[list[Any]]]:
    """The tracking transcription with every contact of every step, each pair's second side
    a row ``b >= 0`` and no product: the Opti problem, its unknowns, the rows of the second
    sides and the unknowns of the first, per pair."""
    ca = require_casadi()
    opti = ca.Opti()
    s, N = mpc.system, mpc.steps
    builder = _TrackingNLP(mpc, np.ones((s.n_contacts, N), bool), opti.parameter(s.n_states))
    var = builder.variables(opti)
    builder.constraints(opti, var)
    pairs = builder.pairs(var, casadi_ops())
    keys = pair_keys(builder, pairs)
    pair_rows, pair_vars = [], []
    for (a, b), (a_keys, _) in zip(pairs, keys[:len(pairs)], strict=True):
        if a.numel() and a_keys is None:
            raise ModelError("system: a pair's first side is not an unknown")
        first = opti.ng
        if a.numel():
            opti.subject_to(b >= 0)
        pair_rows.append(first + np.arange(b.numel()))
        pair_vars.append(a_keys or [])
    opti.minimize(builder.cost(var))
    return opti, var, pair_rows, pair_vars
