"""Event-driven run of a nonlinear Lagrangian system (``M(q)``, nonlinear forces or gaps, a
callable controller): scipy's DOP853 with gap events and Newton's impact law.

With ``sensitivity=True`` the variational equation is integrated with the state and every
impact multiplies the transition by its saltation matrix (:mod:`._variational`); the run
returns ``stats["state_transition"]`` (``∂x(tf)/∂x0``) and ``stats["saltation_matrices"]``
(one per impact, in the order of ``traj.events_of("impact")``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..._progress import TimeProgress
from ..._validation import FloatArray
from ...errors import ModelError, SolverError
from ..trajectory import Trajectory
from ._flight import _sample_times
from ._options import _Options
from ._recording import _fail_budget, _fail_zeno, _Samples
from ._variational import Variational
from ._zeno import _Zeno


class NonlinearMechanicsRun:
    """DOP853 with event location for ``M(q)``, nonlinear forces or gaps."""

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options, controller: Callable[..., Any] | None = None,
                 sensitivity: bool = False) -> None:
        from ...laws.impact import NewtonImpactLaw

        self.s, self.x, self.t0, self.tf, self.u, self.opts = system, x0, t0, tf, u, opts
        self.controller = controller
        self.m = system.n_dof if system.actuation is None else system.actuation.shape[1]
        self.law = NewtonImpactLaw(system.restitution)
        n = system.n_dof
        self.samples = _Samples(system.n_states, opts, ("gap", "energy"), lambda X: {
            "gap": np.array([system.gaps(x[:n]) for x in X]).reshape(len(X), -1),
            "energy": system.energy(X)})
        self.rec = self.samples.rec
        self.zeno = _Zeno(opts, system.n_contacts)
        self.impulses: list[FloatArray] = []
        self.var = Variational(system, self._rhs, controller is not None) if sensitivity \
            else None
        self.saltations: list[FloatArray] = []
        self.closed: list[int] = []   # the contacts of the last impact

    def _input(self, t: float, q: FloatArray, v: FloatArray) -> FloatArray | None:
        uu = None if self.u is None else self.u.u(t)
        if self.controller is not None:
            c = np.asarray(self.controller(t, q, v), dtype=float).reshape(-1)
            if c.shape != (self.m,) or not np.all(np.isfinite(c)):
                raise ModelError(f"controller: expected a finite input of length {self.m} "
                                 f"from controller(t, q, v), got {c!r} at t = {t:.6g}")
            uu = c if uu is None else uu + c
        return uu

    def _rhs(self, t: float, x: FloatArray) -> FloatArray:
        s, n = self.s, self.s.n_dof
        q, v = x[:n], x[n:]
        M = s.mass_matrix(q)
        try:  # M(q) must stay positive definite along the motion, not only at q0
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise ModelError(f"mass: M(q) is not positive definite at t = {t:.6g}, q = {q!r}; "
                             "the model is only valid where the mass matrix is") from None
        y = np.linalg.solve(L, s.forces(t, q, v, self._input(t, q, v)))
        return np.concatenate([v, np.linalg.solve(L.T, y)])

    def _sample(self, times: FloatArray, X: FloatArray) -> None:
        self.samples.extend(times, X)

    def run(self) -> Trajectory:
        from scipy.integrate import solve_ivp

        s = self.s
        t, x = self.t0, self.x.copy()
        finish = dict(method="event_driven", state_names=s.state_names)
        self._sample(np.array([t]), x[None])
        events = [self._gap_event(j) for j in range(s.n_contacts)]
        N = s.n_states
        # with sensitivity the integrated vector is [x; vec Φ] (events read its first n)
        z = x if self.var is None else self.var.augment(x, np.eye(N))
        rhs = self._rhs if self.var is None else self.var.rhs
        # windows of at most 1/50 of the span: an error raised inside the model (a controller
        # returning NaN, M(q) losing definiteness) loses one window, never the run
        window = max(self.opts.dt, (self.tf - self.t0) / 50)
        with TimeProgress(self.t0, self.tf, desc="event_driven",
                          enable=self.opts.progress) as bar:
            while t < self.tf:
                # a contact closed and separating at t is not re-detected: only falling
                # crossings (direction -1) count
                t_stop = min(self.tf, t + window)
                grid = _sample_times(t, t_stop, self.opts.dt, self.t0)
                sol = solve_ivp(rhs, (t, t_stop), z, method="DOP853",
                                rtol=self.opts.rtol, atol=self.opts.atol,
                                events=events or None, dense_output=True)
                if not sol.success:
                    raise SolverError(f"event_driven: DOP853 failed at t = {sol.t[-1]:.6g}: "
                                      f"{sol.message}")
                t_end = float(sol.t[-1])
                grid = grid[grid < t_end]
                if grid.size:
                    self._sample(grid, sol.sol(grid).T[:, :N])
                z = sol.y[:, -1].copy()
                x = z[:N]
                t = t_end
                self._sample(np.array([t]), x[None])
                bar.update(t)
                if sol.status != 1:
                    continue
                out = self._impact(t, x)
                if isinstance(out, Trajectory):
                    return out
                z = out if self.var is None else self._carry_transition(self.var, t, x, out, z)
        stats = {"events": self.zeno.n_events,
                 "impacts": sum(e.kind == "impact" for e in self.rec.events),
                 "impulses": np.array(self.impulses).reshape(-1, s.n_contacts)}
        if self.var is not None:
            stats["state_transition"] = self.var.transition(z).copy()
            stats["saltation_matrices"] = np.array(self.saltations).reshape(-1, N, N)
        return self.samples.finish(status=0, stats=stats, **finish)

    def _carry_transition(self, var: Variational, t: float, x_minus: FloatArray,
                          x_plus: FloatArray, z: FloatArray) -> FloatArray:
        """``[x+; vec(S Φ)]``: the transition carried through the impact just applied (on
        the contacts Newton's law closed, ``self.closed``)."""
        S = var.impact_saltation(t, x_minus, x_plus, self.closed)
        self.saltations.append(S)
        return var.augment(x_plus, S @ var.transition(z))

    def _gap_event(self, j: int) -> Callable[[float, FloatArray], float]:
        def event(t: float, x: FloatArray) -> float:
            return float(self.s.gaps(x[: self.s.n_dof])[j])

        event.terminal = True  # type: ignore[attr-defined]  # solve_ivp reads it
        event.direction = -1  # type: ignore[attr-defined]  # solve_ivp reads it
        return event

    def _impact(self, t: float, x: FloatArray) -> Any:
        s, n = self.s, self.s.n_dof
        finish = dict(method="event_driven", state_names=s.state_names)
        q, v = x[:n], x[n:]
        g = s.gaps(q)
        closed = np.flatnonzero(np.abs(g) <= 1e-9 * (1.0 + np.max(np.abs(q))))
        self.closed = [int(j) for j in closed]
        self.zeno.n_events += 1
        J = s.gap_jacobian(q)
        hitting = [int(j) for j in closed if J[j] @ v < 0]
        if not hitting:
            return _fail_zeno(self.opts, self.samples, f"event_driven: contacts {closed.tolist()} "
                              f"are closed at t = {t:.12g} with zero normal velocity and pushed "
                              "inwards (persistent contact), which is supported for linear "
                              "systems only", t, **finish)
        if self.zeno.n_events > self.opts.max_events:
            return _fail_budget(self.opts, self.samples, t, self.zeno.n_events, **finish)
        if any(
                self.zeno.too_close(j, t) or self.zeno.add(j, t) is not None for j in hitting):
            return _fail_zeno(self.opts, self.samples, f"event_driven: impacts of contacts "
                              f"{hitting} accumulate near t = {t:.12g}; persistent contact "
                              "is supported for linear systems only", t, **finish)
        res = self.law.apply(s.mass_matrix(q), J.T, v, closed)
        xp = np.concatenate([q, res.v_plus])
        for j in hitting:
            self.rec.event(t, "impact", j, x, xp)
            self.impulses.append(res.impulse)
        for listener in self.opts.listeners:
            listener(t, x.copy(), xp.copy(), np.array(hitting), res.impulse.copy())
        self._sample(np.array([t]), xp[None])
        return xp
