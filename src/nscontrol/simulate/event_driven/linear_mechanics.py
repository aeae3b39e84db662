"""Exact event-driven run of a Lagrangian system that is linear between events: augmented
linear flow, persistent-contact modes, Newton's multi-contact law and accumulations."""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

import numpy as np

from ..._validation import FloatArray
from ...errors import SolverError
from ...laws.impact import NewtonImpactLaw
from ...numerics.lcp import solve_lcp
from ...numerics.lti import LTIFlow
from .._event_kernels import bounce_impulses, contact_state, open_and_finite
from ..loop import END, Stop
from ..trajectory import Recorder
from ._flight import _Flight, _Workspace, projection_stats
from ._options import _Options
from ._recording import _fail_budget, _fail_zeno, _Samples, append_events, recording
from ._zeno import _Zeno


class _LinearModel:
    """What every run of a linear Lagrangian system needs, prepared once: the augmented flow
    ``z = [q; v; 1; w]`` (gravity and the input generator inside), the free accelerations,
    the Delassus diagonal and the modes built so far. It depends on the (immutable) system
    and the input's generator only, so runs of the same system or closed loop (a state
    feedback is folded into the system) in sweeps and benchmarks share it."""

    _cache: weakref.WeakKeyDictionary[Any, dict[Any, _LinearModel]] = \
        weakref.WeakKeyDictionary()

    @classmethod
    def of(cls, system: Any, u: Any) -> _LinearModel:
        key = None if u is None else (u.S.shape, u.S.tobytes(), u.Cu.tobytes())
        models = cls._cache.get(system)
        if models is None:
            models = cls._cache[system] = {}
        model = models.get(key)
        if model is None:
            model = models[key] = cls(system, u)
        return model

    def __init__(self, s: Any, u: Any) -> None:
        n = s.n_dof
        self.M = s.mass_matrix()
        self.G = s.dense_gap_matrix()
        nw = 0 if u is None else u.n_states
        N = 2 * n + 1 + nw
        K = np.zeros((n, n)) if s.stiffness is None else s.stiffness
        D = np.zeros((n, n)) if s.damping is None else s.damping
        F = np.zeros((n, N))
        F[:, :n], F[:, n:2 * n], F[:, 2 * n] = -K, -D, s.constant_force
        S = np.eye(n) if s.actuation is None else s.actuation
        if u is not None:
            F[:, 2 * n + 1:] = S @ u.Cu
        self.Minv = np.linalg.inv(self.M)
        self.W_diag = np.einsum("jn,nm,jm->j", self.G, self.Minv, self.G)  # Delassus diagonal
        self.Afree = self.Minv @ F  # accelerations, (n, N)
        self.base = np.zeros((N, N))
        self.base[:n, n:2 * n] = np.eye(n)
        if u is not None:
            self.base[2 * n + 1:, 2 * n + 1:] = u.S
        self.n, self.N = n, N
        self.flows: dict[frozenset[int], tuple[_Flight, np.ndarray]] = {}
        self.workspaces: list[_Workspace] = []  # lent to one run at a time
        self.system = s

    def signals(self, X: FloatArray) -> dict[str, FloatArray]:
        """The recorded signals of states ``X = [q; v]`` (rows): ``gap`` and ``energy``."""
        return {"gap": X[:, :self.n] @ self.G.T + self.system.gap_offset,
                "energy": self.system.energy(X)}


class LinearMechanicsRun:
    """Exact simulation of a Lagrangian system that is linear between events (a
    :class:`~nscontrol.simulate.loop.Stepper`)."""

    samples: _Samples
    rec: Recorder

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options) -> None:
        s = system
        self.s, self.t0, self.tf, self.opts = s, t0, tf, opts
        self.model = model = _LinearModel.of(s, u)
        self.M, self.G, self.Minv = model.M, model.G, model.Minv
        self.W_diag, self.Afree, self.base = model.W_diag, model.Afree, model.base
        self.n, self.N = model.n, model.N
        self.flows = model.flows
        # the exosystem runs in absolute time, w(0) = w0, like every integrator's input
        self.z = z = np.empty(self.N)
        z[:2 * self.n], z[2 * self.n] = x0, 1.0
        if u is not None:
            z[2 * self.n + 1:] = u.w(t0)
        self.ws = _Workspace.lend(model.workspaces, self.N, s.n_contacts, s.n_contacts)
        self.recording = recording(opts, 2 * self.n, ("gap", "energy"), s.state_names)
        self.zeno = _Zeno(opts, s.n_contacts, self.ws.zeno)
        self.contact: set[int] = set()
        self.n_impacts = 0
        self.impulses: list[FloatArray] = []  # blocks of rows, one row per "impact" event
        self.t = t0
        self.restart = False  # the first flight starts from the user's x0
        self.ended = False

    def start(self, rec: Recorder) -> None:
        """The first sample into ``rec``, the run's record (behind the sample buffer), and
        the contacts in persistent contact at ``x0``."""
        ws, z, t0 = self.ws, self.z, self.t0
        self.rec = rec
        self.samples = _Samples(rec, self.model.signals, buffer=(ws.s_t, ws.s_x))
        self.samples.add(t0, z)
        self._set_mode(t0, z, self._persistent(z, self._resting(z, self._contacts(z)[0])))

    # -- modes ---------------------------------------------------------------------------
    def _mode(self, C: frozenset[int]) -> tuple[_Flight, np.ndarray]:
        """The flight (flow, guards, linear impact maps) of the mode ``C`` and its guard ids
        (contact ``j >= 0`` for a free gap, ``-1 - j`` for the force of a closed contact)."""
        if C in self.flows:
            return self.flows[C]
        n, N = self.n, self.N
        A = self.base.copy()
        acc = self.Afree
        L = np.zeros((0, N))
        if C:
            idx = sorted(C)
            Gc = self.G[idx]
            Wc = Gc @ self.Minv @ Gc.T
            try:
                L = -np.linalg.solve(Wc, Gc @ self.Afree)  # contact forces λ = L z
            except np.linalg.LinAlgError:
                raise SolverError(f"event_driven: the contacts {idx} in persistent contact "
                                  "are dependent (singular Delassus matrix)") from None
            acc = self.Afree + self.Minv @ Gc.T @ L
        A[n:2 * n] = acc
        free = [j for j in range(self.s.n_contacts) if j not in C]
        rows = [np.concatenate([self.G[j], np.zeros(N - n)]) for j in free]
        rows += [L[k] for k in range(len(C))]
        gmat = np.array(rows).reshape(-1, N)
        g0 = np.concatenate([self.s.gap_offset[free], np.zeros(len(C))])
        guard_ids = np.array(free + [-1 - j for j in sorted(C)], dtype=np.int64)
        jump_ok = (guard_ids >= 0) & (not C)
        slots = np.where(guard_ids >= 0, guard_ids, 0)
        flight = _Flight(LTIFlow.shared(A), gmat, g0, self._bounce_maps(free, len(guard_ids)),
                         jump_ok, slots, n_free=2 * n)
        self.flows[C] = (flight, guard_ids)
        return self.flows[C]

    def _bounce_maps(self, free: list[int], p: int) -> FloatArray:
        """``J[k]``: the linear map of a bounce of the ``k``-th free contact hit alone, with
        nothing else closed, ``v+ = v- - (1+e) M⁻¹Gⱼᵀ Gⱼ v- / Wⱼⱼ`` (identity for the others)."""
        n, N = self.n, self.N
        J = np.tile(np.eye(N), (p, 1, 1))
        for k, j in enumerate(free):
            Gj = self.G[j]
            MinvG = self.Minv @ Gj
            J[k, n:2 * n, n:2 * n] -= (1.0 + self.s.restitution[j]) * np.outer(
                MinvG, Gj) / float(Gj @ MinvG)
        return J

    # -- recording -----------------------------------------------------------------------
    def _bounced(self, ids: np.ndarray) -> Callable[..., None]:
        """Record the impacts settled by the compiled loop (``ids``: guard -> contact)."""
        n, m = self.n, 2 * self.n

        def record(times: FloatArray, idx: np.ndarray, pre: FloatArray,
                   post: FloatArray) -> None:
            k = times.size
            js, P = self.ws.contacts[:k], self.ws.impulses[:k]
            bounce_impulses(self.G, self.W_diag, ids, idx, pre, post, n, js, P)
            P = P.copy()
            append_events(self.rec, times, "impact", js, pre[:, :m], post[:, :m])
            self.impulses.append(P)
            self.n_impacts += times.size
            for k in range(times.size) if self.opts.listeners else ():
                for listener in self.opts.listeners:
                    listener(float(times[k]), pre[k, :m].copy(), post[k, :m].copy(),
                             np.array([js[k]]), P[k].copy())
        return record

    def _impacted(self, t: float, contacts: list[int], x_minus: FloatArray,
                  x_plus: FloatArray, impulse: FloatArray) -> None:
        for j in contacts:
            self.rec.event(t, "impact", j, x_minus, x_plus)
        self.impulses.append(impulse[None] if len(contacts) == 1  # impulse: a fresh array
                             else np.repeat(impulse[None], len(contacts), axis=0))
        if self.opts.listeners:
            for listener in self.opts.listeners:
                listener(t, x_minus.copy(), x_plus.copy(), np.array(contacts),
                         impulse.copy())
        self.n_impacts += len(contacts)

    def _set_mode(self, t: float, z: FloatArray, new: set[int]) -> None:
        x = z[:2 * self.n]
        for j in sorted(self.contact - new):
            self.rec.event(t, "contact_end", j, x, x)
        for j in sorted(new - self.contact):
            self.rec.event(t, "contact_start", j, x, x)
            self.zeno.reset(j)
        self.contact = new

    def _fail(self, message: str, t: float) -> NoReturn:
        _fail_zeno(message, t)

    # -- contact state -------------------------------------------------------------------
    def _persistent(self, z: FloatArray, candidates: Sequence[int]) -> set[int]:
        """Contacts among ``candidates`` (closed, zero normal velocity) with a positive
        contact force: the LCP ``0 <= λ ⟂ W λ + G a_free >= 0``."""
        if not candidates:
            return set()
        a_free = self.Afree @ z
        if len(candidates) == 1:  # the one-dimensional LCP: λ = max(0, -G a_free / W)
            j = int(candidates[0])
            lam_j = max(0.0, -float(self.G[j] @ a_free) / float(self.W_diag[j]))
            return {j} if lam_j > 1e-12 * (1.0 + lam_j) else set()
        idx = list(candidates)
        Gc = self.G[idx]
        lam = solve_lcp(Gc @ self.Minv @ Gc.T, Gc @ a_free, strict=True).z
        scale = 1e-12 * (1.0 + float(np.max(np.abs(lam), initial=0.0)))
        return {j for j, lj in zip(idx, lam, strict=True) if lj > scale}

    def _contacts(self, z: FloatArray) -> tuple[list[int], np.ndarray]:
        """At the state ``z``: the closed contacts (gap zero to rounding), ascending, and
        per contact whether its normal velocity is zero."""
        k = contact_state(self.G, self.s.gap_offset, z, self.n, self.ws.closed, self.ws.still)
        return self.ws.closed[:k].tolist(), self.ws.still

    def _resting(self, z: FloatArray, closed: Sequence[int]) -> list[int]:
        """Contacts among ``closed`` with zero normal velocity at ``z``."""
        still = self._contacts(z)[1]
        return [j for j in closed if still[j]]

    # -- the stepper (driven by nscontrol.simulate.loop.drive) ----------------------------
    def advance(self) -> float | Stop:
        """One flight of the current mode (the events the compiled loop settles included)
        and the event it hands back; a :class:`Stop` once ``tf`` is reached."""
        if self.ended or self.t >= self.tf:
            return END
        flight, ids = self._mode(frozenset(self.contact))
        t, z, ev = self._fly(flight, ids, self.z, self.t, self.tf, self.restart)
        self.restart = True
        self.t, self.z = t, z
        if ev is None:
            self.ended = True
            return t
        self.t, self.z = self._event(t, z, [int(ids[i]) for i in ev.indices], ev.grazing)
        return self.t

    def settle(self) -> None:
        """The buffered samples to the record."""
        self.samples.settle()

    def end(self, stop: Stop) -> dict[str, Any]:
        """The run's statistics; the workspace goes back to the model for the next run."""
        stats = {"events": self.zeno.n_events, "impacts": self.n_impacts,
                 "impulses": (np.concatenate(self.impulses) if self.impulses
                              else np.zeros((0, self.s.n_contacts))),
                 **projection_stats(self.ws.proj)}
        self.ws.give_back(self.model.workspaces)
        return stats

    def _fly(self, flight: _Flight, ids: np.ndarray, z: FloatArray, t: float, t_end: float,
             restart: bool = True) -> tuple[float, FloatArray, Any]:
        return flight.run(z, t, t_end, self.zeno, True, self.opts, self.samples, self.ws,
                          sample_pre=True, on_events=self._bounced(ids), restart=restart)

    def _event(self, t: float, z: FloatArray, hit: list[int], grazing: bool
               ) -> tuple[float, FloatArray]:
        """An event handed back by the compiled loop (``hit``: guard ids). Returns
        ``(t, z)`` to go on from; a spent budget or an accumulation raises."""
        self.zeno.n_events += 1   # every event spends the budget, a touch too
        if self.zeno.n_events > self.opts.max_events:
            _fail_budget(self.opts, t, self.zeno.n_events)
        if grazing:  # a gap or a contact force touching zero: nothing changes
            for j in hit:
                self.rec.event(t, "grazing", j if j >= 0 else -1 - j,
                               z[:2 * self.n], z[:2 * self.n])
            return t, z
        impacts = [j for j in hit if j >= 0]
        if impacts:
            return self._impact(t, z, impacts)
        ended = {-1 - j for j in hit if j < 0}
        self._set_mode(t, z, self._persistent(z, sorted(self.contact - ended)))
        return t, z

    def _impact(self, t: float, z: FloatArray, impacts: list[int]
                ) -> tuple[float, FloatArray]:
        """Apply Newton's law at ``t``; handle accumulations. Returns ``(t, z)``; an
        accumulation that cannot be resolved raises."""
        closed = sorted(set(self._contacts(z)[0]) | set(impacts) | self.contact)
        checks = [self.zeno.check(j, t) for j in impacts]
        for j, (too_close, _) in zip(impacts, checks, strict=True):
            if too_close:
                self._fail(f"event_driven: impacts of contact {j} accumulate near "
                                  f"t = {t:.12g} without a geometric pattern", t)
        for j in impacts:
            self.zeno.push(j, t)
        t_acc = min((ta for _, ta in checks if ta is not None), default=None)
        e = self.s.restitution
        if t_acc is not None:
            e = e.copy()
            e[impacts] = 0.0  # close the accumulating contact plastically
        z_minus, (z, P) = z, self._newton(z, closed, e)
        self._impacted(t, impacts, z_minus[:2 * self.n], z[:2 * self.n], P)
        new = self._persistent(z, self._resting(z, closed))
        self.samples.add(t, z)
        if t_acc is not None:
            if not set(impacts) <= new:
                self._fail(f"event_driven: impacts of contacts {impacts} accumulate "
                                  f"at t = {t_acc:.12g} but the contact force there would be "
                                  "negative", t)
            t, z = self._hold_closed(t, z, new, impacts, t_acc)
        self._set_mode(t, z, new)
        return t, z

    def _newton(self, z: FloatArray, closed: list[int], e: FloatArray
                ) -> tuple[FloatArray, FloatArray]:
        """The state after Newton's law on the ``closed`` contacts with restitutions ``e``,
        and the contact impulses."""
        n = self.n
        z = z.copy()
        v = z[n:2 * n]
        if len(closed) == 1:  # one contact: Newton's law in closed form, P = -(1+e) u- / W
            j = closed[0]
            P = np.zeros(self.s.n_contacts)
            P[j] = max(0.0, -(1.0 + e[j]) * float(self.G[j] @ v) / self.W_diag[j])
            v += self.Minv @ (self.G[j] * P[j])
        else:
            res = NewtonImpactLaw(e).apply(self.M, self.G.T, v, closed)
            v[:], P = res.v_plus, res.impulse
        return z, P

    def _hold_closed(self, t: float, z: FloatArray, new: set[int], impacts: list[int],
                     t_acc: float) -> tuple[float, FloatArray]:
        """The remaining bounces (shorter than the horizon) replaced by the contact held
        closed up to ``t_acc``; that flow is still watched by every other guard."""
        flight, ids = self._mode(frozenset(new))
        t_end, z, ev = self._fly(flight, ids, z, t, min(t_acc, self.tf))
        if ev is None and t_end == t_acc:
            for j in impacts:
                self.rec.event(t_end, "accumulation", j, z[:2 * self.n], z[:2 * self.n])
        return t_end, z


def checked_state(system: Any, x0: Any) -> FloatArray:
    """``system.check_state(x0)``, skipped for a finite float vector of the right length with
    every gap open (admissible whatever its velocity: the check would only copy it)."""
    if (system.is_linear and isinstance(x0, np.ndarray) and x0.dtype == np.float64
            and x0.shape == (system.n_states,)):
        G, g0 = _dense_gaps(system)
        if open_and_finite(G, g0, x0, system.n_dof):
            return x0
    return system.check_state(x0)


_GAPS: weakref.WeakKeyDictionary[Any, tuple[FloatArray, FloatArray]] = \
    weakref.WeakKeyDictionary()


def _dense_gaps(system: Any) -> tuple[FloatArray, FloatArray]:
    """The affine gaps ``(G, g0)`` of a linear system, ``G`` dense (computed once)."""
    gaps = _GAPS.get(system)
    if gaps is None:
        gaps = _GAPS[system] = (np.ascontiguousarray(system.dense_gap_matrix(), dtype=float),
                                np.ascontiguousarray(system.gap_offset, dtype=float))
    return gaps
