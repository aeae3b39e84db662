"""Exact event-driven run of one planar frictional contact held closed: the modes "slip +",
"slip −" and "stick" are each a linear flow of ``z = [q; v; 1; w]``, switched at events
located on the exact solution (:func:`nscontrol.numerics.lti.first_event`).

In every mode the contact forces are linear in ``z`` (rows ``L``: ``[λ_N; λ_T] = L z``):

* slip with direction ``s = ±1`` (``u_T = T v`` of sign ``s``): ``λ_T = -s μ λ_N`` and
  ``λ_N`` from ``G a = 0``, i.e. ``λ_N = -G a_free / (G M⁻¹ (G - s μ T)ᵀ)``; guards
  ``s u_T >= 0`` (the slip stops) and ``λ_N >= 0``;
* stick: ``(λ_N, λ_T)`` from ``G a = 0`` and ``T a = 0`` (the 2 x 2 Delassus system);
  guards ``μ λ_N ∓ λ_T >= 0`` (the friction needed reaches the cone's edge) and ``λ_N >= 0``.

When the slip stops, the stick forces decide: ``|λ_T| <= μ λ_N`` sticks, otherwise the slip
reverses (direction ``-sign(λ_T)``). ``λ_N`` reaching zero (lift-off) is refused.
"""

from __future__ import annotations

from typing import Any, NoReturn

import numpy as np

from ..._validation import FloatArray
from ...errors import BudgetExceededError, ModelError, ZenoError
from ...numerics.lti import LTIFlow, first_event, project_restart
from ..loop import END, Stop
from ..trajectory import Recorder
from ._flight import projection_stats
from ._options import _Options
from ._recording import recording
from .linear_mechanics import _LinearModel

#: Mode codes (``Event.mode_from`` / ``mode_to``): stick, slip forward (``u_T > 0``),
#: slip backward (``u_T < 0``).
STICK, SLIP_FORWARD, SLIP_BACKWARD = 0, 1, 2
_DIRECTION = {SLIP_FORWARD: 1.0, SLIP_BACKWARD: -1.0}
OFFERED = ("gap", "energy", "contact_state", "friction", "normal_force")
_USE_MJ = "simulate it with method='moreau_jean' and a step h"


def check_frictional_system(system: Any, blocks: Any, listeners: Any) -> None:
    """Refuse what the exact frictional runner does not cover (a :class:`ModelError` that
    points to Moreau–Jean)."""
    if system.friction_dim != 1 or system.n_contacts != 1:
        raise ModelError(f"system: event_driven handles friction at exactly one planar contact "
                         f"(got {system.n_contacts} contacts, friction_dim "
                         f"{system.friction_dim}); {_USE_MJ}")
    if not system.is_linear:
        raise ModelError(f"system: event_driven with friction needs a constant mass matrix and "
                         f"linear forces; {_USE_MJ}")
    if blocks is not None:
        raise ModelError(f"controller: event_driven with friction takes linear state feedback "
                         f"only, folded into the model (closed_loop(plant, StateFeedback(K)): "
                         f"a linear flow), not a law written in Python; {_USE_MJ}")
    if listeners:
        raise ModelError(f"listeners: not supported with friction (no impacts to report); "
                         f"{_USE_MJ}")


class FrictionalContactRun:
    """Exact simulation of a linear Lagrangian system resting on its one frictional contact
    (gap and normal velocity zero throughout); a :class:`~nscontrol.simulate.loop.Stepper`
    that appends every piece to the run's record at once."""

    rec: Recorder

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options) -> None:
        self.s, self.t0, self.tf, self.opts = system, t0, tf, opts
        model = _LinearModel.of(system, u)
        self.n, self.N, self.model = model.n, model.N, model
        self.Gn = model.G[0]
        self.Tt = np.asarray(system.tangent_matrix.todense()
                             if hasattr(system.tangent_matrix, "todense")
                             else system.tangent_matrix, dtype=float).reshape(-1)
        self.mu = float(system.friction[0])
        self.z = z = np.empty(self.N)
        z[:2 * self.n], z[2 * self.n] = x0, 1.0
        if u is not None:
            z[2 * self.n + 1:] = u.w(t0)
        self.recording = recording(opts, system.n_states, OFFERED, system.state_names)
        self.flows: dict[int, tuple[LTIFlow, FloatArray, FloatArray]] = {}
        self.n_events = 0
        self._check_closed(x0)
        self.t = t0
        self.mode = self._initial_mode(z)
        L = self._mode(self.mode)[2]
        if float(L[0] @ z) <= 0.0:
            self._fail(f"x0: the normal force would be {float(L[0] @ z):.3g} <= 0 (the body "
                       f"leaves the contact); {_USE_MJ}", t0)
        self.proj = np.zeros(5)  # round-off projections at restarts (lti.project_restart)
        self.restart = False     # the first piece starts from the user's x0
        self.ended = False

    def start(self, rec: Recorder) -> None:
        """The first sample into ``rec``, the run's record."""
        self.rec = rec
        self._record(np.array([self.t0]), self.z[None], self.mode, self._mode(self.mode)[2])

    def settle(self) -> None:
        """Nothing is held back: every sample goes to the record at once."""

    def _check_closed(self, x0: FloatArray) -> None:
        """The contact must start closed with zero normal velocity."""
        n, q, v = self.n, x0[:self.n], x0[self.n:]
        gap = float(self.Gn @ q + self.s.gap_offset[0])
        u_n = float(self.Gn @ v)
        scale = 1e-12 * (1.0 + float(np.abs(self.Gn).sum()) * max(
            1.0, float(np.max(np.abs(x0[:n]), initial=0.0)), float(np.max(np.abs(v),
                                                                           initial=0.0))))
        if abs(gap) > scale or abs(u_n) > scale:
            raise ModelError(f"x0: event_driven with friction needs the contact closed with "
                             f"zero normal velocity (gap {gap:.3g}, normal velocity {u_n:.3g}); "
                             f"for impacts with friction {_USE_MJ}")

    # -- modes ---------------------------------------------------------------------------
    def _mode(self, mode: int) -> tuple[LTIFlow, FloatArray, FloatArray]:
        """The flow of ``mode``, its guard rows (``λ_N`` first) and the force rows ``L``."""
        if mode in self.flows:
            return self.flows[mode]
        n, N, m = self.n, self.N, self.model
        G, T, mu = self.Gn, self.Tt, self.mu
        pad = np.zeros(N - n)
        if mode == STICK:
            C = np.vstack([G, T])
            L = -np.linalg.solve(C @ m.Minv @ C.T, C @ m.Afree)
            acc = m.Afree + m.Minv @ C.T @ L
            guards = np.vstack([L[0], mu * L[0] - L[1], mu * L[0] + L[1]])
        else:
            s = _DIRECTION[mode]
            w = G - s * mu * T  # the contact force per unit λ_N
            den = float(G @ m.Minv @ w)
            if den <= 0.0:
                raise ModelError(f"system: with μ = {mu:g} slipping in direction {s:+g} the "
                                 f"normal force is undetermined (G M⁻¹ (G - s μ T)ᵀ = "
                                 f"{den:.3g} <= 0, Painlevé's paradox); {_USE_MJ}")
            Ln = -(G @ m.Afree) / den
            L = np.vstack([Ln, -s * mu * Ln])
            acc = m.Afree + np.outer(m.Minv @ w, Ln)
            guards = np.vstack([Ln, s * np.concatenate([np.zeros(n), T, pad[n:]])])
        A = m.base.copy()
        A[n:2 * n] = acc
        self.flows[mode] = out = (LTIFlow.shared(A), np.ascontiguousarray(guards), L)
        return out

    def _settle(self, z: FloatArray) -> int:
        """The mode at a state of zero slip velocity: stick when the friction that stick
        needs lies in the cone, otherwise slip against it."""
        L = self._mode(STICK)[2]
        lam_n, lam_t = L @ z
        if abs(lam_t) <= self.mu * lam_n + 1e-12 * (abs(lam_t) + abs(lam_n)):
            return STICK
        return SLIP_BACKWARD if lam_t > 0.0 else SLIP_FORWARD

    def _initial_mode(self, z: FloatArray) -> int:
        v = z[self.n:2 * self.n]
        u_t = float(self.Tt @ v)
        tol = 1e-12 * (1.0 + float(np.abs(self.Tt).sum()) * float(np.max(np.abs(v),
                                                                         initial=0.0)))
        if abs(u_t) <= tol:
            return self._settle(z)
        return SLIP_FORWARD if u_t > 0.0 else SLIP_BACKWARD

    # -- recording -----------------------------------------------------------------------
    def _record(self, times: FloatArray, Z: FloatArray, mode: int, L: FloatArray) -> None:
        X = Z[:, :2 * self.n]
        rows: dict[str, FloatArray] = {}
        if self.rec.wants("gap"):
            rows["gap"] = X[:, :self.n] @ self.Gn + self.s.gap_offset[0]
        if self.rec.wants("energy"):
            rows["energy"] = self.s.energy(X)
        forces = Z @ L.T
        rows.update(contact_state=np.full(len(times), 1.0 if mode == STICK else 2.0),
                    friction=forces[:, 1], normal_force=forces[:, 0])
        self.rec.extend(times, X, **rows)

    def _grid(self, t: float, t_end: float) -> FloatArray:
        """The regular sample times ``t0 + k dt`` in ``(t, t_end)``, then ``t_end``."""
        dt, t0 = self.opts.dt, self.opts.t0
        k0, k1 = int(np.floor((t - t0) / dt)) + 1, int(np.ceil((t_end - t0) / dt))
        grid = t0 + dt * np.arange(k0, k1)
        grid = grid[(grid > t) & (grid < t_end)]
        return np.append(grid, t_end)

    def _fail(self, message: str, t: float, error: type[Exception] = ModelError
              ) -> NoReturn:
        """Raise ``error`` (the loop attaches the part computed)."""
        if error is BudgetExceededError:
            raise BudgetExceededError(message, budget="max_events", limit=self.opts.max_events,
                                      used=self.n_events)
        if error is ZenoError:
            raise ZenoError(message, time=t)
        raise ModelError(message)

    # -- the stepper (driven by nscontrol.simulate.loop.drive) ----------------------------
    def advance(self) -> float | Stop:
        """The flow of the current mode up to its first event (or ``tf``) and that event;
        a :class:`Stop` once ``tf`` is reached."""
        if self.ended or self.t >= self.tf:
            return END
        t, z, mode = self.t, self.z, self.mode
        flow, guards, L = self._mode(mode)
        if self.restart:
            z = project_restart(flow, z, guards, np.zeros(len(guards)), t, self.proj,
                                n_free=2 * self.n)
        self.restart = True
        ev = first_event(flow, z, guards, np.zeros(len(guards)), self.tf - t)
        t_end = self.tf if ev is None else t + ev.t
        times = self._grid(t, t_end)
        offsets = times - t
        # the piece ends at the event's own offset, not at (t + τ) - t, which rounds by
        # eps·t and would leave the state past its guard in a long run
        offsets[-1] = self.tf - t if ev is None else ev.t
        Z = flow.propagate(z, offsets)
        self._record(times, Z, mode, L)
        self.t, self.z = t_end, Z[-1].copy()
        if ev is None:
            self.ended = True
        else:
            self._switch(ev)
        return self.t

    def _switch(self, ev: Any) -> None:
        """The event ``ev`` at ``self.t``: a grazing, or the next mode (stick, slip or its
        reversal); lift-off and a spent budget raise."""
        t, z, mode = self.t, self.z, self.mode
        x = z[:2 * self.n]
        self.n_events += 1   # every event spends the budget, a touch too
        if self.n_events > self.opts.max_events:
            self._fail(f"max_events: the run spent its budget of {self.opts.max_events} "
                       f"stick-slip events by t = {t:.12g}; raise max_events", t,
                       BudgetExceededError)
        if ev.grazing:
            self.rec.event(t, "grazing", 0, x, x, mode, mode)
            return
        if 0 in ev.indices:
            self._fail(f"event_driven: the normal force reaches zero at t = {t:.12g} (the "
                       f"body would leave the contact); {_USE_MJ}", t)
        new = self._settle(z) if mode != STICK else (
            SLIP_BACKWARD if 1 in ev.indices else SLIP_FORWARD)
        kind = ("slip" if mode == STICK else "stick" if new == STICK else "slip_reversal")
        self.rec.event(t, kind, 0, x, x, mode, new)
        self.mode = new
        self._record(np.array([t]), z[None], new, self._mode(new)[2])

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics."""
        return {"events": self.n_events, "impacts": 0,
                "impulses": np.zeros((0, self.s.n_contacts)), **projection_stats(self.proj)}
