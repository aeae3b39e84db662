"""Event-driven run of a nonlinear Lagrangian system (``M(q)``, nonlinear forces or gaps, a
law evaluated along the flow): scipy's DOP853 with gap events and Newton's impact law.

With ``sensitivity=True`` the variational equation is integrated with the state and every
impact multiplies the transition by its saltation matrix (:mod:`._variational`); the run
returns ``stats["state_transition"]`` (``∂x(tf)/∂x0``) and ``stats["saltation_matrices"]``
(one per impact, in the order of ``traj.events_of("impact")``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError, SolverError
from ..loop import END, Stop
from ..trajectory import Recorder
from ._flight import _sample_times
from ._options import _Options
from ._recording import _fail_budget, _fail_zeno, _Samples, recording
from ._variational import Variational
from ._zeno import _Zeno


class NonlinearMechanicsRun:
    """DOP853 with event location for ``M(q)``, nonlinear forces or gaps (a
    :class:`~nscontrol.simulate.loop.Stepper`)."""

    samples: _Samples
    rec: Recorder

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options, controller: Callable[..., Any] | None = None,
                 sensitivity: bool = False) -> None:
        from ...laws.impact import NewtonImpactLaw

        self.s, self.x, self.t0, self.tf, self.u, self.opts = system, x0, t0, tf, u, opts
        self.controller = controller   # a closed loop's law (t, q, v) -> u, or None
        self.law = NewtonImpactLaw(system.restitution)
        self.recording = recording(opts, system.n_states, ("gap", "energy"),
                                   system.state_names)
        self.zeno = _Zeno(opts, system.n_contacts)
        self.impulses: list[FloatArray] = []
        self.var = Variational(system, self._rhs, controller is not None) if sensitivity \
            else None
        self.saltations: list[FloatArray] = []
        self.closed: list[int] = []   # the contacts of the last impact

    def _input(self, t: float, q: FloatArray, v: FloatArray) -> FloatArray | None:
        """The input at ``(t, q, v)``: the exosystem's, plus the law's (the block runner
        checks its length and finiteness)."""
        uu = None if self.u is None else self.u.u(t)
        if self.controller is not None:
            c = self.controller(t, q, v)
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

    def start(self, rec: Recorder) -> None:
        """The first sample into ``rec``, the run's record (behind the sample buffer), the
        gap events and the integrated vector (with sensitivity ``[x; vec Φ]``, whose first
        ``n`` entries the events read)."""
        s, t, x = self.s, self.t0, self.x.copy()
        n = s.n_dof
        self.rec = rec
        self.samples = _Samples(rec, lambda X: {
            "gap": np.array([s.gaps(x[:n]) for x in X]).reshape(len(X), -1),
            "energy": s.energy(X)})
        self._sample(np.array([t]), x[None])
        self.events = [self._gap_event(j) for j in range(s.n_contacts)]
        self.z = x if self.var is None else self.var.augment(x, np.eye(s.n_states))
        self.rhs = self._rhs if self.var is None else self.var.rhs
        # windows of at most 1/50 of the span: an error raised inside the model (a law that
        # returns NaN, M(q) losing definiteness) loses one window, never the run
        self.window = max(self.opts.dt, (self.tf - self.t0) / 50)
        self.t = t

    def advance(self) -> float | Stop:
        """DOP853 over one window or up to the first impact, and that impact; a
        :class:`Stop` once ``tf`` is reached."""
        from scipy.integrate import solve_ivp

        if self.t >= self.tf:
            return END
        t, N = self.t, self.s.n_states
        # a contact closed and separating at t is not re-detected: only falling crossings
        # (direction -1) count
        t_stop = min(self.tf, t + self.window)
        grid = _sample_times(t, t_stop, self.opts.dt, self.t0)
        sol = solve_ivp(self.rhs, (t, t_stop), self.z, method="DOP853", rtol=self.opts.rtol,
                        atol=self.opts.atol, events=self.events or None, dense_output=True)
        if not sol.success:
            raise SolverError(f"event_driven: DOP853 failed at t = {sol.t[-1]:.6g}: "
                              f"{sol.message}")
        t_end = float(sol.t[-1])
        grid = grid[grid < t_end]
        if grid.size:
            self._sample(grid, sol.sol(grid).T[:, :N])
        z = sol.y[:, -1].copy()
        x = z[:N]
        self.t, self.z = t_end, z
        self._sample(np.array([t_end]), x[None])
        if sol.status == 1:
            xp = self._impact(t_end, x)
            self.z = xp if self.var is None else self._carry_transition(self.var, t_end, x,
                                                                        xp, z)
        return t_end

    def settle(self) -> None:
        """The buffered samples to the record."""
        self.samples.settle()

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics (with the state transition when asked)."""
        s, N = self.s, self.s.n_states
        stats: dict[str, Any] = {"events": self.zeno.n_events,
                 "impacts": sum(e.kind == "impact" for e in self.rec.events),
                 "impulses": np.array(self.impulses).reshape(-1, s.n_contacts)}
        if self.var is not None:
            stats["state_transition"] = self.var.transition(self.z).copy()
            stats["saltation_matrices"] = np.array(self.saltations).reshape(-1, N, N)
        return stats

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

    def _impact(self, t: float, x: FloatArray) -> FloatArray:
        s, n = self.s, self.s.n_dof
        q, v = x[:n], x[n:]
        g = s.gaps(q)
        closed = np.flatnonzero(np.abs(g) <= 1e-9 * (1.0 + np.max(np.abs(q))))
        self.closed = [int(j) for j in closed]
        self.zeno.n_events += 1
        J = s.gap_jacobian(q)
        hitting = [int(j) for j in closed if J[j] @ v < 0]
        if not hitting:
            _fail_zeno(f"event_driven: contacts {closed.tolist()} are closed at t = {t:.12g} "
                       "with zero normal velocity and pushed inwards (persistent contact), "
                       "which is supported for linear systems only", t)
        if self.zeno.n_events > self.opts.max_events:
            _fail_budget(self.opts, t, self.zeno.n_events)
        if any(
                self.zeno.too_close(j, t) or self.zeno.add(j, t) is not None for j in hitting):
            _fail_zeno(f"event_driven: impacts of contacts {hitting} accumulate near "
                       f"t = {t:.12g}; persistent contact is supported for linear systems "
                       "only", t)
        res = self.law.apply(s.mass_matrix(q), J.T, v, closed)
        xp = np.concatenate([q, res.v_plus])
        for j in hitting:
            self.rec.event(t, "impact", j, x, xp)
            self.impulses.append(res.impulse)
        for listener in self.opts.listeners:
            listener(t, x.copy(), xp.copy(), np.array(hitting), res.impulse.copy())
        self._sample(np.array([t]), xp[None])
        return xp
