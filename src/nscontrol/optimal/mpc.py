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
the block's :class:`~nscontrol.optimal.Relaxation` from a cold start; each later sample solves
**one** relaxed problem at ``σ = relaxation.sigma_min``, warm-started from the shifted plan
(primal and dual), and no polish. The block's internal state is the record of its last
solve — wall and CPU time, IPOPT iterations, complementarity residual, active-set rounds,
cost — so that a closed-loop run keeps it per sample in the trajectory's signal ``xc``
(:meth:`ContactMPC.signals` names its columns).
"""

from __future__ import annotations

import time
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
RECORD = ("solve_time", "iterations", "residual", "rounds", "cost", "cpu_time")


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
            The record (:data:`RECORD`): wall time [s], IPOPT iterations, complementarity
            residual, active-set rounds, cost, the process's CPU time [s] (on a loaded
            machine the wall time counts the waits for a core; the CPU time does not).
        """
        x = as_vector("x", x, self.system.n_states)   # a measured state may penetrate by roundoff
        start, cpu = time.perf_counter(), time.process_time()
        cold = self._guess is None
        guess = self._cold_guess(x) if cold else self._shifted(x)
        active = active_sets(self.problem, guess["X"], self.h)
        nlp = self._nlp()
        rel = self._relaxation
        iterations, rounds = 0, 0
        while True:
            rounds += 1
            for sigma in rel.sigmas() if cold else [rel.sigma_min]:
                guess, its, status = nlp.solve(guess, x, sigma, active)
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
        res = nlp.residual(guess, active)
        return np.array([time.perf_counter() - start, iterations, res, rounds,
                         guess["cost"], time.process_time() - cpu], dtype=float)

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
        self.names = [name for name, sym in var.items() if isinstance(sym, ca.MX)]
        syms = [var[name] for name in self.names]
        # where each unknown's entries sit in opti.x, and the parameters in opti.p
        where = ca.Function("where", [opti.x], [ca.vec(sym) for sym in syms])
        self.index = [np.asarray(a, float).astype(int).ravel()
                      for a in where(np.arange(opti.nx, dtype=float))]
        self.shapes = [sym.shape for sym in syms]
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
        z = np.zeros(self.nx)
        for name, idx in zip(self.names, self.index, strict=True):
            z[idx] = np.asarray(guess[name], float).ravel(order="F")
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
        zx = np.asarray(sol["x"], float).ravel()
        out = dict(guess)
        for name, idx, shape in zip(self.names, self.index, self.shapes, strict=True):
            out[name] = zx[idx].reshape(shape, order="F")
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
