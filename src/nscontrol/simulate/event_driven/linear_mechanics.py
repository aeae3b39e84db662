"""Exact event-driven run of a Lagrangian system that is linear between events: augmented
linear flow, persistent-contact modes, Newton's multi-contact law and accumulations."""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..._progress import TimeProgress
from ..._validation import FloatArray
from ...errors import SolverError
from ...numerics.lti import LTIFlow
from ..trajectory import Trajectory
from ._flight import _Flight
from ._options import _Options
from ._recording import _fail_zeno, _Samples
from ._zeno import _Zeno


class _LinearModel:
    """What every run of a linear Lagrangian system needs, prepared once: the augmented flow
    ``z = [q; v; 1; w]`` (gravity and the input generator inside), the free accelerations,
    the Delassus diagonal and the modes built so far. It depends on the (immutable) system,
    the input's generator and the feedback gain only, so runs of the same closed loop
    (sweeps, benchmarks) share it."""

    _cache: weakref.WeakKeyDictionary[Any, dict[Any, _LinearModel]] = \
        weakref.WeakKeyDictionary()

    @classmethod
    def of(cls, system: Any, u: Any, gain: FloatArray | None) -> _LinearModel:
        key = (None if u is None else (u.S.shape, u.S.tobytes(), u.Cu.tobytes()),
               None if gain is None else gain.tobytes())
        models = cls._cache.setdefault(system, {})
        if key not in models:
            models[key] = cls(system, u, gain)
        return models[key]

    def __init__(self, s: Any, u: Any, gain: FloatArray | None) -> None:
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
        if gain is not None:  # u = -K [q; v]: still a linear flow
            F[:, :2 * n] -= S @ gain
        self.Minv = np.linalg.inv(self.M)
        self.W_diag = np.einsum("jn,nm,jm->j", self.G, self.Minv, self.G)  # Delassus diagonal
        self.Afree = self.Minv @ F  # accelerations, (n, N)
        self.base = np.zeros((N, N))
        self.base[:n, n:2 * n] = np.eye(n)
        if u is not None:
            self.base[2 * n + 1:, 2 * n + 1:] = u.S
        self.n, self.N = n, N
        self.flows: dict[frozenset[int], tuple[_Flight, np.ndarray]] = {}


class LinearMechanicsRun:
    """Exact simulation of a Lagrangian system that is linear between events."""

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options, gain: FloatArray | None = None) -> None:
        s = system
        self.s, self.t0, self.tf, self.opts = s, t0, tf, opts
        self.model = model = _LinearModel.of(s, u, gain)
        self.M, self.G, self.Minv = model.M, model.G, model.Minv
        self.W_diag, self.Afree, self.base = model.W_diag, model.Afree, model.base
        self.n, self.N = model.n, model.N
        self.flows = model.flows
        # the exosystem runs in absolute time, w(0) = w0, like every integrator's input
        self.z = np.concatenate([x0, [1.0], [] if u is None else u.w(t0)])
        G, g0 = self.G, s.gap_offset
        self.samples = _Samples(2 * self.n, opts, ("gap", "energy"), lambda X: {
            "gap": X[:, :self.n] @ G.T + g0, "energy": s.energy(X)})
        self.rec = self.samples.rec
        self.zeno = _Zeno(opts, s.n_contacts)
        self.contact: set[int] = set()
        self.n_impacts = 0
        self.impulses: list[FloatArray] = []  # one row per "impact" event

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
        # a free contact hit alone, with nothing else closed, bounces by a linear map
        J = np.tile(np.eye(N), (len(guard_ids), 1, 1))
        for k, j in enumerate(free):
            Gj = self.G[j]
            MinvG = self.Minv @ Gj
            J[k, n:2 * n, n:2 * n] -= (1.0 + self.s.restitution[j]) * np.outer(
                MinvG, Gj) / float(Gj @ MinvG)
        jump_ok = (guard_ids >= 0) & (not C)
        slots = np.where(guard_ids >= 0, guard_ids, 0)
        self.flows[C] = (_Flight(LTIFlow.shared(A), gmat, g0, J, jump_ok, slots), guard_ids)
        return self.flows[C]

    def _sample(self, times: FloatArray, Z: FloatArray) -> None:
        self.samples.extend(times, Z[:, :2 * self.n])

    def _bounced(self, ids: np.ndarray) -> Callable[..., None]:
        """Record the impacts settled by the compiled loop (``ids``: guard -> contact)."""
        n, m = self.n, 2 * self.n

        def record(times: FloatArray, idx: np.ndarray, pre: FloatArray,
                   post: FloatArray) -> None:
            js = ids[idx]
            P = np.zeros((times.size, self.s.n_contacts))  # G_j (v+ - v-) = W_jj P_j
            P[np.arange(times.size), js] = np.einsum(
                "kn,kn->k", self.G[js], post[:, n:m] - pre[:, n:m]) / self.W_diag[js]
            self.rec.events_block(times, "impact", js, pre[:, :m], post[:, :m])
            self.impulses.extend(P)
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
            self.impulses.append(impulse)
        if self.opts.listeners:
            for listener in self.opts.listeners:
                listener(t, x_minus.copy(), x_plus.copy(), np.array(contacts),
                         impulse.copy())
        self.n_impacts += len(contacts)

    def _persistent(self, z: FloatArray, candidates: Sequence[int]) -> set[int]:
        """Contacts among ``candidates`` (closed, zero normal velocity) with a positive
        contact force: the LCP ``0 <= λ ⟂ W λ + G a_free >= 0``."""
        if not candidates:
            return set()
        from ...numerics.lcp import solve_lcp

        idx = list(candidates)
        Gc = self.G[idx]
        q = Gc @ (self.Afree @ z)
        if len(idx) == 1:  # the one-dimensional LCP: λ = max(0, -q / W)
            lam = np.maximum(0.0, -q / self.W_diag[idx])
        else:
            lam = solve_lcp(Gc @ self.Minv @ Gc.T, q, strict=True).z
        scale = 1e-12 * (1.0 + float(np.max(np.abs(lam), initial=0.0)))
        return {j for j, lj in zip(idx, lam, strict=True) if lj > scale}

    def _closed(self, z: FloatArray) -> np.ndarray:
        q = z[: self.n]
        g = self.G @ q + self.s.gap_offset
        return np.flatnonzero(np.abs(g) <= 1e-12 * (1.0 + np.max(np.abs(q), initial=0.0)))

    def _resting(self, z: FloatArray, closed: np.ndarray) -> list[int]:
        v = z[self.n:2 * self.n]
        un = self.G[closed] @ v
        tol = 1e-12 * (1.0 + float(np.max(np.abs(v), initial=0.0)))
        return [int(j) for j, uj in zip(closed, un, strict=True) if abs(uj) <= tol]

    def _set_mode(self, t: float, z: FloatArray, new: set[int]) -> None:
        x = z[:2 * self.n]
        for j in sorted(self.contact - new):
            self.rec.event(t, "contact_end", j, x, x)
        for j in sorted(new - self.contact):
            self.rec.event(t, "contact_start", j, x, x)
            self.zeno.reset(j)
        self.contact = new

    # -- main loop -----------------------------------------------------------------------
    def run(self) -> Trajectory:
        t, z = self.t0, self.z
        finish = dict(method="event_driven", state_names=self.s.state_names)
        self._sample(np.array([t]), z[None])
        closed = self._closed(z)
        self._set_mode(t, z, self._persistent(z, self._resting(z, closed)))
        with TimeProgress(self.t0, self.tf, desc="event_driven",
                          enable=self.opts.progress) as bar:
            while t < self.tf:
                flight, ids = self._mode(frozenset(self.contact))
                t, z, ev = flight.run(z, t, self.tf, self.zeno, True, self.opts,
                                      sample_pre=True, on_samples=self._sample,
                                      on_events=self._bounced(ids))
                bar.update(t)
                if ev is None:
                    break
                hit = ids[list(ev.indices)]
                if ev.grazing:  # a gap or a contact force touching zero: nothing changes
                    for j in hit:
                        self.rec.event(t, "grazing", int(j if j >= 0 else -1 - j),
                                       z[:2 * self.n], z[:2 * self.n])
                    continue
                self.zeno.n_events += 1
                if self.zeno.n_events > self.opts.max_events:
                    return _fail_zeno(self.opts, self.samples, f"event_driven: more than "
                                      f"{self.opts.max_events} events by t = {t:.12g}", t,
                                      **finish)
                ended = [int(-1 - j) for j in hit if j < 0]
                impacts = [int(j) for j in hit if j >= 0]
                if impacts:
                    out = self._impact(t, z, impacts)
                    if isinstance(out, Trajectory):
                        return out
                    t, z = out
                else:
                    remaining = self.contact - set(ended)
                    self._set_mode(t, z, self._persistent(z, sorted(remaining)))
        stats = {"events": self.zeno.n_events, "impacts": self.n_impacts,
                 "impulses": np.array(self.impulses).reshape(-1, self.s.n_contacts)}
        return self.samples.finish(status=0, stats=stats, **finish)

    def _impact(self, t: float, z: FloatArray, impacts: list[int]) -> Any:
        """Apply Newton's law at ``t``; handle accumulations. Returns ``(t, z)`` or a failed
        trajectory."""
        n = self.n
        finish = dict(method="event_driven", state_names=self.s.state_names)
        closed = sorted(set(self._closed(z).tolist()) | set(impacts) | self.contact)
        for j in impacts:
            if self.zeno.too_close(j, t):
                return _fail_zeno(self.opts, self.samples, f"event_driven: impacts of contact "
                                  f"{j} accumulate near t = {t:.12g} without a geometric "
                                  "pattern", t, **finish)
        due = [self.zeno.add(j, t) for j in impacts]
        t_acc = min((ta for ta in due if ta is not None), default=None)
        e = self.s.restitution.copy()
        if t_acc is not None:
            e[impacts] = 0.0  # close the accumulating contact plastically
        z_minus = z.copy()
        z = z.copy()
        v = z[n:2 * n]
        if len(closed) == 1:  # one contact: Newton's law in closed form, P = -(1+e) u- / W
            j = closed[0]
            P = np.zeros(self.s.n_contacts)
            P[j] = max(0.0, -(1.0 + e[j]) * float(self.G[j] @ v) / self.W_diag[j])
            v += self.Minv @ (self.G[j] * P[j])
        else:
            from ...laws.impact import NewtonImpactLaw

            res = NewtonImpactLaw(e).apply(self.M, self.G.T, v, closed)
            v[:], P = res.v_plus, res.impulse
        self._impacted(t, impacts, z_minus[:2 * n], z[:2 * n], P)
        new = self._persistent(z, self._resting(z, np.array(closed, dtype=np.int64)))
        self._sample(np.array([t]), z[None])
        if t_acc is not None:
            if not set(impacts) <= new:
                return _fail_zeno(self.opts, self.samples, f"event_driven: impacts of contacts "
                                  f"{impacts} accumulate at t = {t_acc:.12g} but the contact "
                                  "force there would be negative", t, **finish)
            # the remaining bounces (shorter than the horizon) are replaced by the contact held
            # closed; that flow is still watched by every other guard up to t_acc
            flight, ids = self._mode(frozenset(new))
            t_end, z, ev = flight.run(z, t, min(t_acc, self.tf), self.zeno, True, self.opts,
                                      sample_pre=True, on_samples=self._sample,
                                      on_events=self._bounced(ids))
            if ev is None and t_end == t_acc:
                for j in impacts:
                    self.rec.event(t_end, "accumulation", j, z[:2 * n], z[:2 * n])
            t = t_end
        self._set_mode(t, z, new)
        return t, z
