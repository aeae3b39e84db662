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

Speed: the flow between events, the event search and every event of a single guard with a
linear jump (a free contact bouncing with nothing else closed; a :class:`LinearHybridSystem`
whose ``jump`` is given as matrices, such as the chapter-2 plant with its observer) run in one
compiled loop (:mod:`nscontrol.simulate._event_kernels`); any other event — simultaneous,
grazing, a contact coming to rest, an accumulation — is handed back to the Python code below,
unchanged. Listeners are called for the compiled events too, in time order, once the loop
returns (they observe, they cannot alter the run).

Event kinds: ``"impact"``, ``"grazing"``, ``"accumulation"``, ``"contact_start"``,
``"contact_end"`` (mechanics), ``"jump"`` and ``"grazing"`` (linear hybrid systems).
"""

from __future__ import annotations

import warnings
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._progress import TimeProgress
from .._validation import FloatArray, as_matrix, check_integer, check_positive
from ..errors import (
    DimensionError,
    ModelError,
    NscontrolError,
    SolverError,
    ZenoError,
    ZenoWarning,
)
from ..numerics.lti import Exosystem, LTIFlow
from .trajectory import Recorder, Trajectory

__all__ = ["integrate"]


def integrate(system: Any, x0: Any, t_span: tuple[float, float], *, u: Any = None,
              controller: Any = None, dt: float | None = None, max_events: int = 100_000,
              min_interval: float = 1e-12, zeno_ratio_tol: float = 1e-3,
              zeno_horizon: float | None = None, zeno_rel: float = 1e-3,
              on_zeno: str = "raise", listeners: Sequence[Callable[..., None]] = (),
              rtol: float = 1e-10, atol: float = 1e-12, record_every: int = 1,
              signals: Sequence[str] | None = None, progress: bool | None = None
              ) -> Trajectory:
    """Event-driven simulation from ``x0`` over ``t_span`` (see the module docstring).

    Parameters
    ----------
    system : LinearHybridSystem, LagrangianSystem or ImpactingBodies
    x0 : array_like
        Admissible initial state (``[q; v]``, ``[x_a; x_b]`` or the hybrid state).
    t_span : (float, float)
    u : Exosystem, optional
        Input of a Lagrangian system or of :class:`ImpactingBodies` (through its actuation),
        ``u(t) = Cu w(t)`` with ``w(0) = w0`` (absolute time, as in every integrator); its
        state is propagated exactly with the plant.
    controller : (m, 2 n) array_like or callable ``(t, q, v) -> u``, optional
        State feedback added to ``u`` through the actuation. A matrix ``K`` means
        ``u = -K [q; v]``: linear, so the closed loop stays exact. A callable makes the flow
        nonlinear: the run uses DOP853 with event location (no persistent contact there).
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
        Accumulate once the predicted remaining time is below this many seconds. Default:
        relative, see ``zeno_rel``.
    zeno_rel : float
        Without ``zeno_horizon``, accumulate once the predicted remaining time is below
        ``zeno_rel`` times the duration of the bouncing sequence (from its first impact to
        the accumulation point): the same bounces are resolved whatever ``t_span``.
    on_zeno : {"raise", "warn"}
        An unresolvable accumulation raises :class:`ZenoError` or warns
        (:class:`ZenoWarning`) and returns the partial trajectory with ``status = -1``.
    listeners : sequence of callables ``(t, x_minus, x_plus, contacts, impulse)``
        Called after every jump / impact with the event's states, the indices of the guards
        or contacts involved and the contact impulses (``None`` for hybrid jumps). The same
        signature as :mod:`~nscontrol.simulate.moreau_jean`'s.
    rtol, atol : float
        Tolerances of DOP853 (nonlinear systems only).
    record_every : int
        Keep every ``record_every``-th sample (events, and the final state, are always kept).
    signals : sequence of str, optional
        Signals to record (default all: the system's outputs for a hybrid system, ``gap`` and
        ``energy`` for mechanics); an empty sequence records states only.
    progress : bool, optional
        Progress bar (default: shown after 2 s).

    Returns
    -------
    Trajectory
        ``signals``: the system's outputs (hybrid), ``gap`` and ``energy`` (mechanics);
        ``stats["impulses"]`` (mechanics): one row of contact impulses per ``"impact"``
        event, in the order of ``traj.events_of("impact")``.

    Raises
    ------
    ModelError
        Unsupported system or option.
    InadmissibleStateError
        ``x0`` violates a constraint.
    ZenoError
        Unresolvable accumulation of events; ``err.trajectory`` holds the run so far (every
        error raised during the run carries it).

    Notes
    -----
    Exact for flows that are linear between events: the state is propagated by the matrix
    exponential and events are the first zeros of the guards on the exact solution
    (:func:`nscontrol.numerics.lti.first_event`); impacts apply Newton's law on all closed
    contacts at once. Accumulations are resolved as described in the module docstring.

    References
    ----------
    Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer 2008,
    ch. 8 (event-driven schemes); D5.3 chapter 2, section 5.

    Examples
    --------
    >>> import nscontrol as nsc
    >>> from nscontrol.testing.mechanics_problems import BouncingBall
    >>> ball = BouncingBall(restitution=0.9)
    >>> traj = nsc.simulate(ball.system(), ball.x0, (0.0, 10.0))
    >>> bool(abs(traj.event_times("accumulation")[0] - ball.accumulation_time) < 1e-9)
    True
    """
    from ..systems.impacting_bodies import ImpactingBodies
    from ..systems.lagrangian import LagrangianSystem
    from .hybrid import LinearHybridSystem

    if on_zeno not in ("raise", "warn"):
        raise ModelError(f"on_zeno: expected 'raise' or 'warn', got {on_zeno!r}")
    t0, tf = (float(t) for t in t_span)
    for i, fn in enumerate(listeners):
        if not callable(fn):
            raise ModelError(f"listeners[{i}]: expected a callable (t, x_minus, x_plus, "
                             f"contacts, impulse), got {type(fn).__name__}")
    opts = _Options(t0=t0, dt=check_positive("dt", dt) if dt is not None else (tf - t0) / 1000,
                    max_events=check_integer("max_events", max_events, minimum=1),
                    min_interval=check_positive("min_interval", min_interval, allow_zero=True),
                    ratio_tol=check_positive("zeno_ratio_tol", zeno_ratio_tol),
                    horizon=(check_positive("zeno_horizon", zeno_horizon)
                             if zeno_horizon is not None else -1.0),
                    rel=check_positive("zeno_rel", zeno_rel),
                    on_zeno=on_zeno, listeners=tuple(listeners),
                    rtol=check_positive("rtol", rtol), atol=check_positive("atol", atol),
                    every=record_every, signals=signals, progress=progress)
    if isinstance(system, LinearHybridSystem):
        for name, value in (("u", u), ("controller", controller)):
            if value is not None:
                raise ModelError(f"{name}: a LinearHybridSystem carries its input generator "
                                 "and controller in its state; stack them into A instead")
        return _guarded(_HybridRun(system, system.check_state(x0), t0, tf, opts))
    if isinstance(system, ImpactingBodies):
        x0 = system.check_state(x0)
        perm = system.lagrangian_permutation()
        back = np.argsort(perm)
        try:
            traj = integrate(system.lagrangian(), x0[perm], t_span, u=u,
                             controller=_permuted_gain(controller, perm), dt=dt,
                             max_events=max_events, min_interval=min_interval,
                             zeno_ratio_tol=zeno_ratio_tol, zeno_horizon=zeno_horizon,
                             zeno_rel=zeno_rel, on_zeno=on_zeno,
                             listeners=reorder_listeners(listeners, back), rtol=rtol,
                             atol=atol, record_every=record_every, signals=signals,
                             progress=progress)
        except NscontrolError as err:  # the partial run in the chapter's state order too
            if isinstance(err.trajectory, Trajectory):
                err.trajectory = reorder_states(err.trajectory, back, system.state_names)
            raise
        return reorder_states(traj, back, system.state_names)
    if isinstance(system, LagrangianSystem):
        x0 = system.check_state(x0)
        u = _check_input(system, u)
        if controller is not None and not callable(controller):
            return _guarded(_LinearMechanicsRun(system, x0, t0, tf, u, opts,
                                                gain=_check_gain(system, controller))
                            if system.is_linear else _NonlinearMechanicsRun(
                                system, x0, t0, tf, u, opts,
                                controller=_linear_controller(system, controller)))
        if system.is_linear and controller is None:
            return _guarded(_LinearMechanicsRun(system, x0, t0, tf, u, opts))
        return _guarded(_NonlinearMechanicsRun(system, x0, t0, tf, u, opts,
                                               controller=controller))
    raise ModelError(f"event_driven: integrates LinearHybridSystem, LagrangianSystem and "
                     f"ImpactingBodies, got {type(system).__name__}")


def _guarded(run: Any) -> Trajectory:
    """Run; an error raised mid-run carries the trajectory computed so far."""
    try:
        return run.run()
    except NscontrolError as err:
        if err.trajectory is None:
            err.trajectory = run.samples.finish(status=-1, message=str(err),
                                                method="event_driven",
                                                state_names=run.s.state_names)
        raise


def _check_input(system: Any, u: Any) -> Any:
    """``u`` must be an :class:`Exosystem` with one output per actuator column."""
    if u is None:
        return None
    if not isinstance(u, Exosystem):
        raise ModelError(f"u: event_driven needs the input as an Exosystem (constant, "
                         f"polynomial, sinusoid or a sum: exact flow), got "
                         f"{type(u).__name__}; for another function of time use "
                         f"method='moreau_jean', or write it as a time-dependent force")
    m = system.n_dof if system.actuation is None else system.actuation.shape[1]
    if u.n_inputs != m:
        raise DimensionError(f"u: expected an Exosystem with {m} input(s) (the actuation's "
                             f"columns), got {u.n_inputs}")
    return u


def _check_gain(system: Any, K: Any) -> FloatArray:
    """A state-feedback gain ``K`` (``u = -K [q; v]``) of the right shape."""
    m = system.n_dof if system.actuation is None else system.actuation.shape[1]
    return as_matrix("controller", K, rows=m, cols=2 * system.n_dof)


def _linear_controller(system: Any, K: Any) -> Callable[..., FloatArray]:
    K = _check_gain(system, K)
    return lambda t, q, v: -K @ np.concatenate([q, v])


def _permuted_gain(controller: Any, perm: np.ndarray) -> Any:
    """A gain on ``[x_a; x_b]`` as a gain on the Lagrangian ``[q; v]`` (callables pass)."""
    if controller is None or callable(controller):
        return controller
    K = np.atleast_2d(np.asarray(controller, dtype=float))
    if K.shape[-1] != perm.size:
        raise DimensionError(f"controller: expected {perm.size} columns (the state), got "
                             f"shape {K.shape}")
    out = np.empty_like(K)
    out[:, np.arange(perm.size)] = K[:, perm]
    return out


class _Options:
    def __init__(self, **kw: Any) -> None:
        self.__dict__.update(kw)


class _Samples:
    """The run's :class:`Recorder` (``record_every``, selected signals) and the last sample
    offered, so that the final state is kept whatever ``record_every`` drops.

    The signals of these integrators are functions of the state (outputs, gaps, energy):
    ``derive(X) -> {name: values}`` computes them once, on the recorded samples, at the end.
    """

    def __init__(self, n: int, opts: _Options, offered: Sequence[str],
                 derive: Callable[[FloatArray], dict[str, FloatArray]]) -> None:
        self.rec = Recorder(n, every=opts.every, signals=opts.signals, offered=offered)
        self.derive = derive
        self.last: tuple[float, FloatArray] | None = None

    def extend(self, times: FloatArray, X: FloatArray) -> None:
        self.rec.extend(times, X)
        self.last = (float(times[-1]), X[-1])

    def finish(self, **kw: Any) -> Trajectory:
        from dataclasses import replace

        if self.last is not None and self.rec.last_time < self.last[0]:
            self.rec.sample(*self.last, force=True)
        traj = self.rec.finish(**kw)
        wanted = [k for k in self.rec.offered or () if self.rec.wants(k)]
        if not wanted:
            return traj
        signals = self.derive(traj.x)
        return replace(traj, signals={k: signals[k] for k in wanted})


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
    """Per-slot (contact or guard) event times and the accumulation tests, on arrays shared
    with the compiled event loop (:func:`._event_kernels.zeno_status` is the one test)."""

    def __init__(self, opts: _Options, n_slots: int) -> None:
        self.opts = opts
        self.hist = np.zeros((max(n_slots, 1), 6))
        self.count = np.zeros(max(n_slots, 1), dtype=np.int64)
        self.first = np.zeros(max(n_slots, 1))
        self.n_events = 0

    def reset(self, j: int) -> None:
        self.count[j] = 0

    def _status(self, j: int, t: float, geometric: bool) -> tuple[int, float]:
        from ._event_kernels import zeno_status

        o = self.opts
        return zeno_status(self.hist, self.count, self.first, j, t, geometric, o.ratio_tol,
                           o.horizon, o.rel, o.min_interval)

    def too_close(self, j: int, t: float) -> bool:
        from ._event_kernels import ZENO_CLOSE

        return self._status(j, t, False)[0] == ZENO_CLOSE

    def push(self, j: int, t: float) -> None:
        from ._event_kernels import zeno_push

        zeno_push(self.hist, self.count, self.first, j, t)

    def add(self, j: int, t: float) -> float | None:
        """Record an impact; return the accumulation time when it is due."""
        from ._event_kernels import ZENO_DUE

        code, t_acc = self._status(j, t, True)
        self.push(j, t)
        return t_acc if code == ZENO_DUE else None


def _caller_level() -> int:
    """``stacklevel`` pointing at the first frame outside nscontrol (the user's call)."""
    import sys

    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith("nscontrol"):
        frame, level = frame.f_back, level + 1
    return level


def _fail_zeno(opts: _Options, rec: _Samples, message: str, t: float, **finish: Any
               ) -> Trajectory:
    traj = rec.finish(status=-1, message=message, **finish)
    if opts.on_zeno == "warn":
        warnings.warn(message, ZenoWarning, stacklevel=_caller_level())
        return traj
    raise ZenoError(message + "; pass on_zeno='warn' to keep the partial trajectory, or use "
                    "method='moreau_jean' which passes through accumulations", time=t,
                    trajectory=traj)


class _Flight:
    """One flow (mode) prepared for the compiled event loop: guards, and the linear jump
    ``x+ = J_i x`` of each guard that has one (``jump_ok``); others are handed back.

    :meth:`run` flows from ``(t, x)``, settles the simple events in compiled code (see
    :mod:`._event_kernels`), passes their samples and events to the callbacks and returns
    ``(t, x, event)`` at ``tf`` (``event`` None) or at the first event Python must handle.
    """

    SAMPLES, EVENTS = 4096, 512

    def __init__(self, flow: LTIFlow, G: FloatArray, g0: FloatArray, J: FloatArray | None,
                 jump_ok: np.ndarray, slots: np.ndarray) -> None:
        from ..numerics.lti import TAYLOR_DEGREE

        self.flow = flow
        self.ctx = ctx = flow.guard_context()
        n, p = flow.n, len(g0)
        self.G, self.g0 = np.ascontiguousarray(G, dtype=float).reshape(p, n), np.asarray(g0,
                                                                                    float)
        if p:
            self.W, self.row_norm = ctx.guard_data(self.G)
        else:
            self.W, self.row_norm = np.zeros((TAYLOR_DEGREE + 1, 0, n)), np.zeros(0)
        self.J = np.zeros((max(p, 1), n, n)) if J is None else np.ascontiguousarray(J, float)
        self.jump_ok = np.asarray(jump_ok, dtype=np.bool_).reshape(p)
        self.slots = np.asarray(slots, dtype=np.int64).reshape(p)

    def run(self, x: FloatArray, t: float, tf: float, zeno: _Zeno, geometric: bool,
            opts: _Options, *, sample_pre: bool, on_samples: Callable[..., None],
            on_events: Callable[..., None]) -> tuple[float, FloatArray, Any]:
        from ..numerics.lti import _REMAINDER, GuardEvent
        from ._event_kernels import DONE, FULL, HANDOFF, INADMISSIBLE, run_linear_jumps

        ctx, n, p = self.ctx, self.flow.n, len(self.g0)
        x = np.array(x, dtype=float)
        s_t, s_x = np.empty(self.SAMPLES), np.empty((self.SAMPLES, n))
        e_t, e_i = np.empty(self.EVENTS), np.empty(self.EVENTS, dtype=np.int64)
        e_pre, e_post = np.empty((self.EVENTS, n)), np.empty((self.EVENTS, n))
        hit, graze = np.zeros(max(p, 1), dtype=np.int8), np.zeros(max(p, 1), dtype=np.int8)
        while True:
            budget = opts.max_events - zeno.n_events
            code, t, n_s, n_e = run_linear_jumps(
                self.W, self.g0, self.row_norm, 1e-12, 1e-12, _REMAINDER, ctx.phi, ctx.bern,
                ctx.kind, ctx.lam, ctx.V, ctx.Vinv, ctx.taylor, ctx.d, ctx.h,
                self.J, self.jump_ok, self.slots, zeno.hist, zeno.count, zeno.first, geometric,
                opts.ratio_tol, opts.horizon, opts.rel, opts.min_interval, budget,
                x, t, tf, opts.dt, opts.t0, sample_pre,
                s_t, s_x, e_t, e_i, e_pre, e_post, hit, graze)
            zeno.n_events += n_e
            if n_s:
                on_samples(s_t[:n_s].copy(), s_x[:n_s].copy())
            if n_e:  # views: the callbacks copy what they keep
                on_events(e_t[:n_e], e_i[:n_e], e_pre[:n_e], e_post[:n_e])
            if code == FULL:
                continue
            if code == DONE:
                return t, x, None
            if code == INADMISSIBLE:
                from ..errors import InadmissibleStateError

                g = self.G @ x + self.g0
                raise InadmissibleStateError(
                    f"event_driven: guard {int(np.argmin(g))} is negative at t = {t:.12g} "
                    f"(g = {g.min():.3g}); the state left the admissible set")
            if code != HANDOFF:
                raise SolverError(f"event_driven: unexpected event-loop status {code}")
            idx = tuple(int(i) for i in np.flatnonzero(hit[:p]))
            return t, x, GuardEvent(0.0, idx, bool(graze[list(idx)].all()))


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
        self.flow = LTIFlow.shared(system.A)
        p = system.n_guards
        J = system.jump_matrices
        self.flight = _Flight(self.flow, system.G, system.g0, J,
                              np.full(p, J is not None), np.arange(p))
        self.samples = _Samples(system.n_states, opts, tuple(system.outputs), lambda X: {
            k: X @ C.T for k, C in system.outputs.items()})
        self.rec = self.samples.rec
        self.zeno = _Zeno(opts, p)

    def _sample(self, times: FloatArray, X: FloatArray) -> None:
        self.samples.extend(times, X)

    def _jumped(self, times: FloatArray, idx: np.ndarray, pre: FloatArray,
                post: FloatArray) -> None:
        for t, i, xm, xp in zip(times, idx, pre, post, strict=True):
            self.rec.event(float(t), "jump", int(i), xm, xp)
            for listener in self.opts.listeners:
                listener(float(t), xm.copy(), xp.copy(), np.array([i]), None)

    def run(self) -> Trajectory:
        s, t, x = self.s, self.t0, self.x
        self._sample(np.array([t]), x[None])
        finish = dict(method="event_driven", state_names=s.state_names)
        with TimeProgress(self.t0, self.tf, desc="event_driven",
                          enable=self.opts.progress) as bar:
            while t < self.tf:
                t, x, ev = self.flight.run(x, t, self.tf, self.zeno, False, self.opts,
                                           sample_pre=True, on_samples=self._sample,
                                           on_events=self._jumped)
                bar.update(t)
                if ev is None:
                    break
                if ev.grazing:
                    for i in ev.indices:
                        self.rec.event(t, "grazing", i, x, x)
                    continue
                idx = np.asarray(ev.indices, dtype=np.int64)
                self.zeno.n_events += 1
                if self.zeno.n_events > self.opts.max_events or any(
                        self.zeno.too_close(int(i), t) for i in idx):
                    return _fail_zeno(self.opts, self.samples, f"event_driven: accumulation of "
                                      f"events of guards {idx.tolist()} near t = {t:.12g}",
                                      t, **finish)
                for i in idx:
                    self.zeno.push(int(i), t)
                x_plus = np.asarray(s.apply_jump(t, x, idx), float)
                for i in idx:
                    self.rec.event(t, "jump", int(i), x, x_plus)
                for listener in self.opts.listeners:
                    listener(t, x.copy(), x_plus.copy(), idx, None)
                x = x_plus
                self._sample(np.array([t]), x[None])
        return self.samples.finish(status=0, stats={"events": self.zeno.n_events}, **finish)


# ------------------------------------------------------------------------------ mechanics
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


class _LinearMechanicsRun:
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
        from ..numerics.lcp import solve_lcp

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
            from ..laws.impact import NewtonImpactLaw

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


class _NonlinearMechanicsRun:
    """DOP853 with event location for ``M(q)``, nonlinear forces or gaps."""

    def __init__(self, system: Any, x0: FloatArray, t0: float, tf: float, u: Any,
                 opts: _Options, controller: Callable[..., Any] | None = None) -> None:
        from ..laws.impact import NewtonImpactLaw

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
                sol = solve_ivp(self._rhs, (t, t_stop), x, method="DOP853",
                                rtol=self.opts.rtol, atol=self.opts.atol,
                                events=events or None, dense_output=True)
                if not sol.success:
                    raise SolverError(f"event_driven: DOP853 failed at t = {sol.t[-1]:.6g}: "
                                      f"{sol.message}")
                t_end = float(sol.t[-1])
                grid = grid[grid < t_end]
                if grid.size:
                    self._sample(grid, sol.sol(grid).T)
                x = sol.y[:, -1].copy()
                t = t_end
                self._sample(np.array([t]), x[None])
                bar.update(t)
                if sol.status != 1:
                    continue
                out = self._impact(t, x)
                if isinstance(out, Trajectory):
                    return out
                x = out
        stats = {"events": self.zeno.n_events,
                 "impacts": sum(e.kind == "impact" for e in self.rec.events),
                 "impulses": np.array(self.impulses).reshape(-1, s.n_contacts)}
        return self.samples.finish(status=0, stats=stats, **finish)

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
            return _fail_zeno(self.opts, self.samples, f"event_driven: contacts {closed.tolist()} "
                              f"are closed at t = {t:.12g} with zero normal velocity and pushed "
                              "inwards (persistent contact), which is supported for linear "
                              "systems only", t, **finish)
        if self.zeno.n_events > self.opts.max_events or any(
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
