r"""Model predictive control through contact and friction, as a sampled block.

:class:`ContactMPC` is a sampled :class:`~nscontrol.systems.feedback.Controller`: at every
sampling instant it reads the plant's state, solves the contact transcription of
:class:`~nscontrol.optimal.ContactProblem` over a receding horizon from that state (the same
Moreau–Jean steps, the same complementarity pairs), applies the first planned input (held
over the sample) and keeps the plan, shifted by one step, as the next sample's initial guess.

The NLP is built once per active set (the contacts each step closes), with the initial state
and the relaxation ``σ`` as CasADi parameters, and solved by IPOPT through ``nlpsol``: a
sample costs the IPOPT iterations alone. The first sample runs the whole Scholtes homotopy of
the block's :class:`~nscontrol.optimal.Relaxation` from a cold start; each later sample solves
**one** relaxed problem at ``σ = relaxation.sigma_min``, warm-started from the shifted plan
(primal and dual), and no polish. The block's internal state is the record of its last
solve — wall time, IPOPT iterations, complementarity residual, active-set rounds — so that a
closed-loop run keeps it per sample in the trajectory's signal ``xc``
(:meth:`ContactMPC.signals` names its columns).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector, check_integer, check_positive, check_type
from ..errors import DimensionError, ModelError, SolverError
from ..systems.feedback import Jump, Measurement
from ..systems.lagrangian import LagrangianSystem
from ._casadi import require_casadi
from .contact import CONTACT_VARS, ContactProblem, Relaxation, _ContactNLP, active_sets
from .homotopy import SOLVED, _pair_constraints, casadi_ops, pair_keys, residual

__all__ = ["ContactMPC"]

#: The columns of the block's internal state (one record per sample).
RECORD = ("solve_time", "iterations", "residual", "rounds", "cost")


@dataclass(eq=False)
class ContactMPC:
    """A sampled MPC block for a Lagrangian system with contacts and planar friction.

    At each sample ``t_k`` it minimises, over ``steps`` Moreau–Jean steps of length ``h``
    from the measured state ``x``,

    ``h Σ_k [(x_{k+1} - x*)ᵀ W (x_{k+1} - x*) + effort |u_k|²]``, with ``x_N = x*``
    where ``terminal`` is true (the NaN components of ``target`` free and unweighted),

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
        self.relaxation = self._relaxation = Relaxation(sigma_min=1e-6, tol=1e-8) \
            if self.relaxation is None else check_type("relaxation", self.relaxation, Relaxation)
        self._period = float(self.period)
        check_integer("max_rounds", self.max_rounds, minimum=1)
        self._nlps: dict[bytes, _ParametricNLP] = {}
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
            residual, active-set rounds, cost.
        """
        x = as_vector("x", x, self.system.n_states)   # a measured state may penetrate by roundoff
        start = time.perf_counter()
        cold = self._guess is None
        guess = self._cold_guess(x) if cold else self._shifted(x)
        active = active_sets(self.problem, guess["X"], self.h)
        iterations, rounds = 0, 0
        while True:
            rounds += 1
            nlp = self._nlp(active)
            if guess.get("lam_g") is not None and guess["lam_g"].size != nlp.ng:
                guess = {**guess, "lam_g": None}
            rel = self._relaxation
            sigmas = rel.sigmas() if cold else [rel.sigma_min]
            for sigma in sigmas:
                guess, its, status = nlp.solve(guess, x, sigma)
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
        res = nlp.residual(guess)
        return np.array([time.perf_counter() - start, iterations, res, rounds,
                         guess["cost"]], dtype=float)

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

    def _nlp(self, active: np.ndarray) -> _ParametricNLP:
        key = np.asarray(active, bool).tobytes()
        if key not in self._nlps:
            self._nlps[key] = _ParametricNLP(self, active)
        return self._nlps[key]


class _ParametricNLP:
    """The relaxed NLP of one active set, built once, with the initial state and ``σ`` as
    parameters, solved by IPOPT through ``nlpsol`` (cold and warm-started solvers)."""

    def __init__(self, mpc: ContactMPC, active: np.ndarray) -> None:
        ca = require_casadi()
        opti = ca.Opti()
        p_x0 = opti.parameter(mpc.system.n_states)
        self.sigma = opti.parameter()
        builder = _TrackingNLP(mpc, active, p_x0)
        self.builder = builder
        var = builder.variables(opti)
        builder.constraints(opti, var)
        pairs = builder.pairs(var, casadi_ops())
        _pair_constraints(opti, pairs, self.sigma, None, pair_keys(builder, pairs))
        cost = builder.cost(var)
        opti.minimize(cost)
        self.names = [name for name, sym in var.items() if isinstance(sym, ca.MX)]
        syms = [var[name] for name in self.names]
        # where each unknown's entries sit in opti.x, and the parameters in opti.p
        where = ca.Function("where", [opti.x], [ca.vec(s) for s in syms])
        self.index = [np.asarray(a, float).astype(int).ravel()
                      for a in where(np.arange(opti.nx, dtype=float))]
        self.shapes = [s.shape for s in syms]
        pw = ca.Function("pwhere", [opti.p], [p_x0, self.sigma])
        self.p_index = [np.asarray(a, float).astype(int).ravel()
                        for a in pw(np.arange(opti.np, dtype=float))]
        self.bounds = ca.Function("bounds", [opti.p], [opti.lbg, opti.ubg])
        self.cost = ca.Function("cost", [opti.x, opti.p], [cost])
        self.nx, self.ng, self.np = opti.nx, opti.ng, opti.np
        nlp = {"x": opti.x, "p": opti.p, "f": opti.f, "g": opti.g}
        rel = mpc._relaxation
        base = {"print_level": 0, "sb": "yes", "tol": rel.tol,
                "acceptable_constr_viol_tol": rel.tol, "max_iter": int(rel.max_iter)}
        opts = {"print_time": False, "error_on_fail": False, "expand": True}
        self.cold = ca.nlpsol("mpc_cold", "ipopt", nlp, {**opts, "ipopt": base})
        self.warm = ca.nlpsol("mpc_warm", "ipopt", nlp, {**opts, "ipopt": {
            **base, "warm_start_init_point": "yes", "mu_init": 1e-6}})

    def solve(self, guess: dict[str, Any], x0: FloatArray, sigma: float
              ) -> tuple[dict[str, Any], int, str]:
        """One IPOPT solve from ``guess``; the solution, its iterations and status."""
        z = np.zeros(self.nx)
        for name, idx in zip(self.names, self.index, strict=True):
            z[idx] = np.asarray(guess[name], float).ravel(order="F")
        p = np.zeros(self.np)
        p[self.p_index[0]] = x0
        p[self.p_index[1]] = sigma
        lbg, ubg = (np.asarray(b, float).ravel() for b in self.bounds(p))
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

    def residual(self, sol: dict[str, Any]) -> float:
        """The largest ``|min(a, b)|`` over the active pairs."""
        return residual(self.builder, sol)


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
        return J + mpc.h * ca.sum1(ca.sum2(ca.DM(np.tile(W[:, None], (1, mpc.steps)))
                                            * err * err))
