"""Event-driven integration: flow until the next event, apply the jump, repeat.

Integrates

* :class:`~nscontrol.simulate.hybrid.LinearHybridSystem` — exact: ``e^{At}`` between events,
  events located on the exact solution by :func:`nscontrol.numerics.lti.first_event`;
* :class:`~nscontrol.systems.LagrangianSystem` that is linear between events (constant ``M``,
  linear forces, affine gaps), optionally driven by an exosystem input — exact as well: the
  state is augmented by ``[1; w]`` so that constant forces (gravity) and the input are part
  of one linear flow. Contacts in *persistent contact* change the flow (the constrained
  acceleration is again linear in the state) and are left when their contact force, also
  linear in the state, reaches zero;
* :class:`~nscontrol.systems.ImpactingBodies` through its Lagrangian form (state order
  ``[x_a; x_b]`` kept);
* any other :class:`~nscontrol.systems.LagrangianSystem` (``M(q)``, nonlinear forces or gaps)
  with scipy's DOP853 and event location (no persistent contact: an accumulation of impacts
  there is reported as Zeno).

Impacts go through Newton's multi-contact law (:class:`nscontrol.laws.NewtonImpactLaw`, one
LCP on the Delassus matrix of the closed contacts), so simultaneous impacts are resolved
together. After an impact the contacts that stay closed with zero normal velocity enter
persistent contact when the contact-force LCP gives them a positive force.

Accumulations (Zeno): when the impact intervals of a contact shrink geometrically (three
successive ratios equal to ``zeno_ratio_tol``) and the remaining time ``Δ r / (1 - r)`` is
below ``zeno_horizon``, the accumulation point ``t∞ = t_k + Δ_k r / (1 - r)`` is computed, the
contact is closed plastically at ``t_k`` and the run continues in persistent contact; the
event ``"accumulation"`` is recorded at ``t∞`` (our choice: the samples in ``[t_k, t∞]``
follow the constrained flow, an error of the order of the remaining bounce heights). An
accumulation that cannot be resolved that way (no geometric pattern, a contact force that
would be negative, more than ``max_events`` events) raises :class:`ZenoError` with the
trajectory computed so far (or warns and returns it, ``on_zeno="warn"``).

Event kinds: ``"impact"``, ``"grazing"``, ``"accumulation"``, ``"contact_start"``,
``"contact_end"`` (mechanics), ``"jump"`` and ``"grazing"`` (linear hybrid systems).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._progress import TimeProgress
from .._validation import FloatArray, check_positive
from ..errors import ModelError, SolverError, ZenoError, ZenoWarning
from ..numerics.lti import LTIFlow, first_event
from .trajectory import Recorder, Trajectory

__all__ = ["integrate"]


def integrate(system: Any, x0: Any, t_span: tuple[float, float], *, u: Any = None,
              dt: float | None = None, max_events: int = 100_000,
              min_interval: float = 1e-12, zeno_ratio_tol: float = 1e-3,
              zeno_horizon: float | None = None, on_zeno: str = "raise",
              listeners: Sequence[Callable[..., None]] = (), rtol: float = 1e-10,
              atol: float = 1e-12, progress: bool | None = None) -> Trajectory:
    """Event-driven simulation from ``x0`` over ``t_span`` (see the module docstring).

    Parameters
    ----------
    system : LinearHybridSystem, LagrangianSystem or ImpactingBodies
    x0 : array_like
        Admissible initial state (``[q; v]``, ``[x_a; x_b]`` or the hybrid state).
    t_span : (float, float)
    u : Exosystem, optional
        Input of a Lagrangian system or of :class:`ImpactingBodies` (through its actuation);
        its state is propagated exactly with the plant.
    dt : float, optional
        Spacing of the regular samples between events (default ``(tf - t0) / 1000``); every
        event adds its pre- and post-event samples.
    max_events : int
        More events than this is reported as Zeno.
    min_interval : float
        Two events of the same guard closer than this (without a geometric pattern) is Zeno.
    zeno_ratio_tol : float
        Tolerance on successive interval ratios to call the shrinking geometric.
    zeno_horizon : float, optional
        Accumulate once the predicted remaining time is below this (default
        ``1e-3 (tf - t0)``).
    on_zeno : {"raise", "warn"}
        An unresolvable accumulation raises :class:`ZenoError` or warns
        (:class:`ZenoWarning`) and returns the partial trajectory with ``status = -1``.
    listeners : sequence of callables ``(t, x_minus, x_plus, indices)``
        Called after every jump / impact.
    rtol, atol : float
        Tolerances of DOP853 (nonlinear systems only).
    progress : bool, optional
        Progress bar (default: shown after 2 s).

    Returns
    -------
    Trajectory
        ``signals``: the system's outputs (hybrid), ``gap`` and ``energy`` (mechanics).

    Raises
    ------
    ModelError
        Unsupported system or option.
    InadmissibleStateError
        ``x0`` violates a constraint.
    ZenoError
        Unresolvable accumulation of events; ``err.trajectory`` holds the run so far.
    """
    from ..systems.impacting_bodies import ImpactingBodies
    from ..systems.lagrangian import LagrangianSystem
    from .hybrid import LinearHybridSystem

    if on_zeno not in ("raise", "warn"):
        raise ModelError(f"on_zeno: expected 'raise' or 'warn', got {on_zeno!r}")
    t0, tf = t_span
    opts = _Options(dt=check_positive("dt", dt) if dt is not None else (tf - t0) / 1000,
                    max_events=int(max_events), min_interval=float(min_interval),
                    ratio_tol=check_positive("zeno_ratio_tol", zeno_ratio_tol),
                    horizon=(check_positive("zeno_horizon", zeno_horizon)
                             if zeno_horizon is not None else 1e-3 * (tf - t0)),
                    on_zeno=on_zeno, listeners=tuple(listeners), rtol=rtol, atol=atol,
                    progress=progress)
    if isinstance(system, LinearHybridSystem):
        if u is not None:
            raise ModelError("u: a LinearHybridSystem carries its input generator in its state; "
                             "stack the exosystem into A instead of passing u")
        return _HybridRun(system, system.check_state(x0), t0, tf, opts).run()
    if isinstance(system, ImpactingBodies):
        x0 = system.check_state(x0)
        perm = system.lagrangian_permutation()
        back = np.argsort(perm)
        traj = integrate(system.lagrangian(), x0[perm], t_span, u=u, dt=dt,
                         max_events=max_events, min_interval=min_interval,
                         zeno_ratio_tol=zeno_ratio_tol, zeno_horizon=zeno_horizon,
                         on_zeno=on_zeno, listeners=reorder_listeners(listeners, back),
                         rtol=rtol, atol=atol, progress=progress)
        return reorder_states(traj, back, system.state_names)
    if isinstance(system, LagrangianSystem):
        x0 = system.check_state(x0)
        if system.is_linear:
            return _LinearMechanicsRun(system, x0, t0, tf, u, opts).run()
        return _NonlinearMechanicsRun(system, x0, t0, tf, u, opts).run()
    raise ModelError(f"event_driven: integrates LinearHybridSystem, LagrangianSystem and "
                     f"ImpactingBodies, got {type(system).__name__}")


class _Options:
    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


def reorder_listeners(listeners: Sequence[Callable[..., None]], order: np.ndarray
                      ) -> list[Callable[..., None]]:
    """Listeners that receive ``x_minus, x_plus`` permuted by ``order`` (the caller's state
    convention, e.g. ``[x_a; x_b]`` of :class:`ImpactingBodies`)."""
    def wrap(fn: Callable[..., None]) -> Callable[..., None]:
        def call(t: float, x_minus: FloatArray, x_plus: FloatArray, *rest: Any) -> None:
            fn(t, x_minus[order], x_plus[order], *rest)
        return call
    return [wrap(fn) for fn in listeners]


def reorder_states(traj: Trajectory, order: np.ndarray, names: Sequence[str]) -> Trajectory:
    """The same trajectory with its state columns (and event states) permuted by ``order``."""
    from dataclasses import replace

    from .trajectory import Event

    events = tuple(Event(e.time, e.kind, e.index,
                         e.pre[order] if e.pre.size == order.size else e.pre,
                         e.post[order] if e.post.size == order.size else e.post,
                         e.mode_from, e.mode_to) for e in traj.events)
    return replace(traj, x=traj.x[:, order], events=events, state_names=tuple(names))


# ------------------------------------------------------------------------------ shared
class _Zeno:
    """Per-contact impact times and the geometric-shrinking test."""

    def __init__(self, opts: _Options) -> None:
        self.opts = opts
        self.times: dict[int, list[float]] = {}
        self.n_events = 0

    def reset(self, j: int) -> None:
        self.times.pop(j, None)

    def add(self, j: int, t: float) -> float | None:
        """Record an impact; return the accumulation time when it is due."""
        ts = self.times.setdefault(j, [])
        ts.append(t)
        del ts[:-6]
        if len(ts) < 5:
            return None
        d = np.diff(ts)
        if np.any(d <= 0.0):
            return None
        r = d[1:] / d[:-1]
        if not (np.all(r < 1.0) and np.ptp(r) <= self.opts.ratio_tol * r[-1]):
            return None
        remaining = d[-1] * r[-1] / (1.0 - r[-1])
        return t + remaining if remaining <= self.opts.horizon else None

    def too_close(self, j: int, t: float) -> bool:
        ts = self.times.get(j)
        return bool(ts) and t - ts[-1] < self.opts.min_interval


def _fail_zeno(opts: _Options, rec: Recorder, message: str, t: float, **finish: Any
               ) -> Trajectory:
    traj = rec.finish(status=-1, message=message, **finish)
    if opts.on_zeno == "warn":
        warnings.warn(message, ZenoWarning, stacklevel=4)
        return traj
    raise ZenoError(message + "; pass on_zeno='warn' to keep the partial trajectory, or use "
                    "method='moreau_jean' which passes through accumulations", time=t,
                    trajectory=traj)


def _make_flow(A: FloatArray) -> LTIFlow:
    """An :class:`~nscontrol.numerics.lti.LTIFlow` of ``A``, exact series when nilpotent."""
    powers = [np.eye(A.shape[0])]
    while len(powers) <= A.shape[0] and np.any(powers[-1]):
        powers.append(powers[-1] @ A)
    if np.any(powers[-1]):
        return LTIFlow(A)
    return _NilpotentFlow(A, powers[:-1])


class _NilpotentFlow(LTIFlow):
    """The flow of a nilpotent ``A`` (free flight under constant forces: ``A^3 = 0``): its
    exponential is the finite series ``Σ A^k t^k / k!`` — exact, and free of Padé's cost
    (which multi-threaded BLAS makes ~400x slower for 3x3 matrices on a loaded machine)."""

    def __init__(self, A: FloatArray, powers: list[FloatArray]) -> None:
        super().__init__(A)
        fact = np.cumprod([1.0] + list(range(1, len(powers))))
        self._terms = np.array(powers) / fact[:, None, None]  # A^k / k!

    def _monomials(self, t: Any) -> FloatArray:
        return np.power.outer(np.atleast_1d(np.asarray(t, float)), np.arange(len(self._terms)))

    def expm(self, t: Any) -> FloatArray:
        out = np.einsum("tk,kij->tij", self._monomials(t), self._terms)
        return out[0] if np.ndim(t) == 0 else out

    def propagate(self, x0: Any, t: Any) -> FloatArray:
        out = self._monomials(t) @ (self._terms @ np.asarray(x0, float))
        return out[0] if np.ndim(t) == 0 else out

    def state_at(self, x0: FloatArray, t: float) -> FloatArray:
        return self.propagate(x0, t)


class _Propagator:
    """``e^{At} x`` on a regular grid of sample times: one exponential per step size, then
    matrix products, when the flow has no cheap closed form (sampling only; event states
    always come from a direct propagation)."""

    def __init__(self, flow: LTIFlow) -> None:
        self.flow = flow

    def __call__(self, x: FloatArray, t: Any) -> FloatArray:
        ts = np.atleast_1d(np.asarray(t, float))
        cheap = isinstance(self.flow, _NilpotentFlow) or self.flow.method == "eig"
        if cheap or ts.size < 3:
            return self.flow.propagate(x, t)
        Phi = self.flow.expm(ts[1] - ts[0])
        out = np.empty((ts.size, x.size))
        out[0] = self.flow.propagate(x, ts[0])
        for k in range(1, ts.size):
            out[k] = Phi @ out[k - 1]
        return out


def _sample_times(t: float, t_next: float, dt: float, t0: float) -> FloatArray:
    """Regular grid points strictly inside ``(t, t_next)``."""
    k0 = int(np.floor((t - t0) / dt)) + 1
    k1 = int(np.ceil((t_next - t0) / dt))
    grid = t0 + dt * np.arange(k0, k1)
    return grid[(grid > t) & (grid < t_next)]


# ------------------------------------------------------------------------------ hybrid
class _HybridRun:
    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float,
                 opts: _Options) -> None:
        self.s, self.x, self.t0, self.tf, self.opts = system, x0.copy(), t0, tf, opts
        self.flow = _make_flow(system.A)
        self.prop = _Propagator(self.flow)
        self.rec = Recorder(system.n_states)
        self.zeno = _Zeno(opts)

    def _sample(self, times: FloatArray, X: FloatArray) -> None:
        sig = {k: X @ C.T for k, C in self.s.outputs.items()}
        self.rec.extend(times, X, **sig)

    def run(self) -> Trajectory:
        s, t, x = self.s, self.t0, self.x
        self._sample(np.array([t]), x[None])
        finish = dict(method="event_driven", state_names=s.state_names)
        with TimeProgress(self.t0, self.tf, desc="event_driven",
                          enable=self.opts.progress) as bar:
            while t < self.tf:
                ev = first_event(self.flow, x, s.G, s.g0, self.tf - t) if s.n_guards else None
                t_next = self.tf if ev is None else t + ev.t
                grid = _sample_times(t, t_next, self.opts.dt, self.t0)
                if grid.size:
                    self._sample(grid, self.prop(x, grid - t))
                x_minus = self.prop(x, t_next - t)
                self._sample(np.array([t_next]), x_minus[None])
                t = t_next
                bar.update(t)
                if ev is None:
                    break
                x = x_minus
                if ev.grazing:
                    for i in ev.indices:
                        self.rec.event(t, "grazing", i, x, x)
                    continue
                idx = np.asarray(ev.indices, dtype=np.int64)
                self.zeno.n_events += 1
                if self.zeno.n_events > self.opts.max_events or any(
                        self.zeno.too_close(int(i), t) for i in idx):
                    return _fail_zeno(self.opts, self.rec, f"event_driven: accumulation of "
                                      f"events of guards {idx.tolist()} near t = {t:.12g}",
                                      t, **finish)
                for i in idx:
                    self.zeno.times.setdefault(int(i), []).append(t)
                x_plus = np.asarray(s.jump(t, x, idx), float)
                for i in idx:
                    self.rec.event(t, "jump", int(i), x, x_plus)
                for listener in self.opts.listeners:
                    listener(t, x.copy(), x_plus.copy(), idx)
                x = x_plus
                self._sample(np.array([t]), x[None])
        return self.rec.finish(status=0, stats={"events": self.zeno.n_events}, **finish)


# ------------------------------------------------------------------------------ mechanics
class _LinearMechanicsRun:
    """Exact simulation of a Lagrangian system that is linear between events."""

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options) -> None:
        from ..laws.impact import NewtonImpactLaw

        s = system
        n = s.n_dof
        self.s, self.t0, self.tf, self.opts = s, t0, tf, opts
        self.M = s.mass_matrix()
        self.G = s.dense_gap_matrix()
        self.law = NewtonImpactLaw(s.restitution)
        # augmented state z = [q; v; 1; w]
        nw = 0 if u is None else u.n_states
        N = 2 * n + 1 + nw
        K = np.zeros((n, n)) if s.stiffness is None else s.stiffness
        D = np.zeros((n, n)) if s.damping is None else s.damping
        F = np.zeros((n, N))
        F[:, :n], F[:, n:2 * n], F[:, 2 * n] = -K, -D, s.constant_force
        if u is not None:
            S = np.eye(n) if s.actuation is None else s.actuation
            F[:, 2 * n + 1:] = S @ u.Cu
        self.Minv = np.linalg.inv(self.M)
        self.Afree = self.Minv @ F  # accelerations, (n, N)
        self.base = np.zeros((N, N))
        self.base[:n, n:2 * n] = np.eye(n)
        if u is not None:
            self.base[2 * n + 1:, 2 * n + 1:] = u.S
        self.z = np.concatenate([x0, [1.0], [] if u is None else u.w0])
        self.n, self.N = n, N
        self.flows: dict[frozenset[int], tuple[Any, FloatArray, FloatArray, FloatArray,
                                               _Propagator]] = {}
        self.rec = Recorder(2 * n)
        self.zeno = _Zeno(opts)
        self.contact: set[int] = set()

    # -- modes ---------------------------------------------------------------------------
    def _mode(self, C: frozenset[int]) -> tuple[Any, FloatArray, FloatArray, FloatArray]:
        """Flow, guard matrix, guard offsets and contact-force map of the mode ``C``."""
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
        flow = _make_flow(A)
        self.flows[C] = (flow, gmat, g0, guard_ids, _Propagator(flow))
        return self.flows[C]

    def _signals(self, Z: FloatArray) -> dict[str, FloatArray]:
        q = Z[:, : self.n]
        return {"gap": q @ self.G.T + self.s.gap_offset, "energy": self.s.energy(Z[:, :2 * self.n])}

    def _sample(self, times: FloatArray, Z: FloatArray) -> None:
        self.rec.extend(times, Z[:, :2 * self.n], **self._signals(Z))

    def _persistent(self, z: FloatArray, candidates: Sequence[int]) -> set[int]:
        """Contacts among ``candidates`` (closed, zero normal velocity) with a positive
        contact force: the LCP ``0 <= λ ⟂ W λ + G a_free >= 0``."""
        if not candidates:
            return set()
        from ..numerics.lcp import solve_lcp

        idx = list(candidates)
        Gc = self.G[idx]
        W = Gc @ self.Minv @ Gc.T
        res = solve_lcp(W, Gc @ (self.Afree @ z), strict=True)
        scale = 1e-12 * (1.0 + float(np.max(np.abs(res.z), initial=0.0)))
        return {j for j, lam in zip(idx, res.z, strict=True) if lam > scale}

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
        n_impacts = 0
        with TimeProgress(self.t0, self.tf, desc="event_driven",
                          enable=self.opts.progress) as bar:
            while t < self.tf:
                flow, gmat, g0, ids, prop = self._mode(frozenset(self.contact))
                ev = first_event(flow, z, gmat, g0, self.tf - t) if len(ids) else None
                t_next = self.tf if ev is None else t + ev.t
                grid = _sample_times(t, t_next, self.opts.dt, self.t0)
                if grid.size:
                    self._sample(grid, prop(z, grid - t))
                z = prop(z, t_next - t) if t_next > t else z
                t = t_next
                bar.update(t)
                if ev is None:
                    self._sample(np.array([t]), z[None])
                    break
                hit = ids[list(ev.indices)]
                if ev.grazing and np.all(hit >= 0):
                    for j in hit:
                        self.rec.event(t, "grazing", int(j), z[:2 * self.n], z[:2 * self.n])
                    continue
                self.zeno.n_events += 1
                if self.zeno.n_events > self.opts.max_events:
                    return _fail_zeno(self.opts, self.rec, f"event_driven: more than "
                                      f"{self.opts.max_events} events by t = {t:.12g}", t,
                                      **finish)
                ended = [int(-1 - j) for j in hit if j < 0]
                impacts = [int(j) for j in hit if j >= 0]
                if impacts:
                    out = self._impact(t, z, impacts)
                    if isinstance(out, Trajectory):
                        return out
                    t, z = out
                    n_impacts += len(impacts)
                else:
                    remaining = self.contact - set(ended)
                    self._sample(np.array([t]), z[None])
                    self._set_mode(t, z, self._persistent(z, sorted(remaining)))
        stats = {"events": self.zeno.n_events, "impacts": n_impacts}
        return self.rec.finish(status=0, stats=stats, **finish)

    def _impact(self, t: float, z: FloatArray, impacts: list[int]) -> Any:
        """Apply Newton's law at ``t``; handle accumulations. Returns ``(t, z)`` or a failed
        trajectory."""
        n = self.n
        finish = dict(method="event_driven", state_names=self.s.state_names)
        closed = sorted(set(self._closed(z).tolist()) | set(impacts) | self.contact)
        for j in impacts:
            if self.zeno.too_close(j, t):
                return _fail_zeno(self.opts, self.rec, f"event_driven: impacts of contact {j} "
                                  f"accumulate near t = {t:.12g} without a geometric pattern",
                                  t, **finish)
        t_acc = None
        for j in impacts:
            t_acc = self.zeno.add(j, t) if t_acc is None else t_acc
        law = self.law
        if t_acc is not None:
            from ..laws.impact import NewtonImpactLaw

            e = self.s.restitution.copy()
            e[impacts] = 0.0  # close the accumulating contact plastically
            law = NewtonImpactLaw(e)
        res = law.apply(self.M, self.G.T, z[n:2 * n], closed)
        z_minus = z.copy()
        z = z.copy()
        z[n:2 * n] = res.v_plus
        for j in impacts:
            self.rec.event(t, "impact", j, z_minus[:2 * n], z[:2 * n])
        for listener in self.opts.listeners:
            listener(t, z_minus[:2 * n].copy(), z[:2 * n].copy(), np.array(impacts))
        new = self._persistent(z, self._resting(z, np.array(closed, dtype=np.int64)))
        if t_acc is not None:
            if not set(impacts) <= new:
                return _fail_zeno(self.opts, self.rec, f"event_driven: impacts of contacts "
                                  f"{impacts} accumulate at t = {t_acc:.12g} but the contact "
                                  "force there would be negative", t, **finish)
            self._sample(np.array([t]), z[None])
            self.contact = new - set(impacts) | (self.contact & new)
            prop = self._mode(frozenset(new))[4]
            grid = _sample_times(t, t_acc, self.opts.dt, self.t0)
            if grid.size:
                self._sample(grid, prop(z, grid - t))
            z = prop(z, t_acc - t)
            t = t_acc
            for j in impacts:
                self.rec.event(t, "accumulation", j, z[:2 * n], z[:2 * n])
        self._sample(np.array([t]), z[None])
        self._set_mode(t, z, new)
        return t, z


class _NonlinearMechanicsRun:
    """DOP853 with event location for ``M(q)``, nonlinear forces or gaps."""

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options) -> None:
        from ..laws.impact import NewtonImpactLaw

        self.s, self.x, self.t0, self.tf, self.u, self.opts = system, x0, t0, tf, u, opts
        self.law = NewtonImpactLaw(system.restitution)
        self.rec = Recorder(system.n_states)
        self.zeno = _Zeno(opts)

    def _rhs(self, t: float, x: FloatArray) -> FloatArray:
        s, n = self.s, self.s.n_dof
        q, v = x[:n], x[n:]
        uu = None if self.u is None else self.u.u(t)
        return np.concatenate([v, np.linalg.solve(s.mass_matrix(q), s.forces(t, q, v, uu))])

    def _sample(self, times: FloatArray, X: FloatArray) -> None:
        n = self.s.n_dof
        gaps = np.array([self.s.gaps(x[:n]) for x in X])
        self.rec.extend(times, X, gap=gaps, energy=self.s.energy(X))

    def run(self) -> Trajectory:
        from scipy.integrate import solve_ivp

        s = self.s
        t, x = self.t0, self.x.copy()
        finish = dict(method="event_driven", state_names=s.state_names)
        self._sample(np.array([t]), x[None])
        events = [self._gap_event(j) for j in range(s.n_contacts)]
        while t < self.tf:
            # a contact closed and separating at t is not re-detected: only falling crossings
            # (direction -1) count
            watch = events
            grid = _sample_times(t, self.tf, self.opts.dt, self.t0)
            sol = solve_ivp(self._rhs, (t, self.tf), x, method="DOP853", rtol=self.opts.rtol,
                            atol=self.opts.atol, events=watch or None, dense_output=True)
            if not sol.success:
                raise SolverError(f"event_driven: DOP853 failed at t = {sol.t[-1]:.6g}: "
                                  f"{sol.message}", trajectory=self.rec.finish(
                                      status=-1, **finish))
            t_end = float(sol.t[-1])
            grid = grid[grid < t_end]
            if grid.size:
                self._sample(grid, sol.sol(grid).T)
            x = sol.y[:, -1].copy()
            t = t_end
            self._sample(np.array([t]), x[None])
            if sol.status != 1:
                break
            out = self._impact(t, x)
            if isinstance(out, Trajectory):
                return out
            x = out
        return self.rec.finish(status=0, stats={"events": self.zeno.n_events}, **finish)

    def _gap_event(self, j: int) -> Callable[[float, FloatArray], float]:
        def event(t: float, x: FloatArray) -> float:
            return float(self.s.gaps(x[: self.s.n_dof])[j])

        event.terminal = True  # type: ignore[attr-defined]
        event.direction = -1  # type: ignore[attr-defined]
        return event

    def _impact(self, t: float, x: FloatArray) -> Any:
        s, n = self.s, self.s.n_dof
        finish = dict(method="event_driven", state_names=s.state_names)
        q, v = x[:n], x[n:]
        g = s.gaps(q)
        closed = np.flatnonzero(np.abs(g) <= 1e-9 * (1.0 + np.max(np.abs(q))))
        self.zeno.n_events += 1
        J = s.gap_jacobian(q)
        hitting = [int(j) for j in closed if J[j] @ v < 0]
        if not hitting:
            return _fail_zeno(self.opts, self.rec, f"event_driven: contacts {closed.tolist()} "
                              f"are closed at t = {t:.12g} with zero normal velocity and pushed "
                              "inwards (persistent contact), which is supported for linear "
                              "systems only", t, **finish)
        if self.zeno.n_events > self.opts.max_events or any(
                self.zeno.too_close(j, t) or self.zeno.add(j, t) is not None for j in hitting):
            return _fail_zeno(self.opts, self.rec, f"event_driven: impacts of contacts "
                              f"{hitting} accumulate near t = {t:.12g}; persistent contact "
                              "is supported for linear systems only", t, **finish)
        res = self.law.apply(s.mass_matrix(q), J.T, v, closed)
        xp = np.concatenate([q, res.v_plus])
        for j in hitting:
            self.rec.event(t, "impact", j, x, xp)
        for listener in self.opts.listeners:
            listener(t, x.copy(), xp.copy(), np.array(hitting))
        self._sample(np.array([t]), xp[None])
        return xp
