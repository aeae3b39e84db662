"""Periodic orbits of forced non-smooth systems by multiple shooting, with saltation matrices.

* :class:`Forced` — a system, its ``T``-periodic input and ``T`` (what a continuation factory
  returns).
* :func:`stroboscopic_map` — ``P(x0) = x(T)`` (or ``x(kT)``) and its Jacobian, the state
  transition through every event: flows' transition matrices times saltation matrices
  (:mod:`~nscontrol.analysis.saltation`).
* :func:`find_orbit` — Newton on the multiple-shooting equations ``P(x_i) = x_{i+1}``
  (``i = 0..k-1``, ``x_k = x_0``) for a ``kT``-periodic orbit; the monodromy is the product
  of the nodes' Jacobians and its eigenvalues are the Floquet multipliers.

Where the Jacobian comes from
-----------------------------
* Methods with the ``sensitivity`` capability (``switching``: PWA, Filippov with sliding
  segments, PWM) return ``stats["state_transition"]``, assembled by the integrator from the
  flows and the saltation matrices of facet crossings and sliding entry/exit (and, for PWM,
  the terms of the instants set by the sampled state). ``implicit_euler`` (Lur'e systems)
  returns the Jacobian of its discrete map: the orbit is then the fixed point of the discrete
  stroboscopic map (``T`` a multiple of the step ``h``).
* Linear mechanical systems (:class:`~nscontrol.systems.lagrangian.LagrangianSystem` with
  constant mass, linear forces and affine gaps) integrated by ``event_driven``: between
  events the flow is ``x' = A x + B u(t) + c``, so the transition over a free-flight interval
  ``Δ`` is ``e^{AΔ}`` (:class:`~nscontrol.numerics.lti.LTIFlow`); at each impact of the event
  table the saltation matrix of Newton's law is applied. Nothing is differentiated
  numerically.
* Nonlinear mechanical systems (``M(q)``, nonlinear forces or gaps, a callable controller)
  under ``event_driven``: the integrator's ``sensitivity`` (DOP853 with the variational
  equation, the saltation matrix of Newton's law with ``M(q)`` and ``g(q)`` at each impact);
  the smallest impact speed is read from the event table.

Grazing monitors
----------------
An orbit records its **event signature** (the kinds and contacts of its events in order) and
two distances to a grazing: the smallest approach speed at its impacts and, for mechanical
systems, the smallest gap over its free flight (refined on the exact flow, or for nonlinear
mechanics by Brent's method on ``ġ = 0`` with short runs: :func:`nonlinear_min_gap`).
Continuation locates a grazing where the signature changes and these distances go to zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_float_array,
    as_vector,
    check_integer,
    check_positive,
)
from ..errors import (
    BudgetExceededError,
    DimensionError,
    InadmissibleStateError,
    ModelError,
    SolverError,
)
from .saltation import impact_jump_jacobian, saltation_matrix

__all__ = ["Forced", "MapResult", "Orbit", "stroboscopic_map", "find_orbit", "Cycle",
           "find_cycle", "Autonomous", "SectionReturn", "hyperplane_map",
           "floquet_multipliers"]


@dataclass(frozen=True, eq=False)
class Forced:
    """A ``period``-periodically forced system: what a continuation factory returns.

    Attributes
    ----------
    system
        The model (any system :func:`nscontrol.simulate` integrates).
    u
        The periodic input passed as ``simulate(..., u=u)`` (``None``: no input; the orbit
        is then a fixed point of the time-``period`` map).
    period
        The input's period ``T``.
    method
        Integrator name (``None``: the system's default).
    options
        Extra ``simulate`` options, as a tuple of ``(name, value)`` pairs (hashable).
    """

    system: Any
    u: Any
    period: float
    method: Any = None
    options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        _n_states(self.system)
        check_positive("period", self.period)

    @property
    def n_states(self) -> int:
        return int(self.system.n_states)

    def simulate(self, x0: Any, t_span: tuple[float, float], **extra: Any) -> Any:
        """``simulate(system, x0, t_span, method=..., u=..., **options, **extra)``."""
        from ..simulate import simulate

        opts = dict(self.options)
        opts.update(extra)
        if self.u is not None:
            opts["u"] = self.u
        return simulate(self.system, x0, t_span, method=self.method, **opts)


@dataclass(frozen=True, eq=False)
class MapResult:
    """``P(x0)``, its Jacobian and what happened on the way.

    Attributes
    ----------
    x
        The state after ``n_periods`` periods.
    jacobian
        ``∂x/∂x0``.
    trajectory
        The run (:class:`~nscontrol.simulate.Trajectory`).
    signature
        ``((kind, index), ...)`` of the events in order.
    min_impact_speed
        Smallest approach speed at an impact (``inf`` when none).
    """

    x: FloatArray
    jacobian: FloatArray
    trajectory: Any
    signature: tuple[tuple[str, int], ...]
    min_impact_speed: float


def _is_linear_mechanics(system: Any) -> bool:
    from ..systems.lagrangian import LagrangianSystem

    return isinstance(system, LagrangianSystem) and system.is_linear


def _is_mechanics(system: Any) -> bool:
    from ..systems.lagrangian import LagrangianSystem

    return isinstance(system, LagrangianSystem)


def _has_sensitivity(forced: Forced) -> bool:
    from ..simulate.driver import integrator_for

    return "sensitivity" in integrator_for(forced.system, forced.method).capabilities


@dataclass(frozen=True, eq=False)
class _LinearMechanics:
    """``x' = A x + B u + c`` of a linear :class:`LagrangianSystem` and its exact flow."""

    A: FloatArray
    B: FloatArray | None
    c: FloatArray
    M: FloatArray
    G: FloatArray
    g0: FloatArray
    restitution: FloatArray
    flow: Any

    @classmethod
    def of(cls, system: Any) -> _LinearMechanics:
        from ..numerics.lti import LTIFlow

        n = system.n_dof
        M = system.mass_matrix()
        Minv = np.linalg.inv(M)
        K = system.stiffness if system.stiffness is not None else np.zeros((n, n))
        C = system.damping if system.damping is not None else np.zeros((n, n))
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ K, -Minv @ C]])
        B = None if system.actuation is None else np.vstack([np.zeros_like(system.actuation),
                                                             Minv @ system.actuation])
        c = np.concatenate([np.zeros(n), Minv @ system.constant_force])
        return cls(A, B, c, M, system.dense_gap_matrix(), np.asarray(system.gap_offset, float),
                   system.restitution, LTIFlow(A))

    def field(self, x: FloatArray, t: float, u: Any) -> FloatArray:
        f = self.A @ x + self.c
        if self.B is not None and u is not None:
            f = f + self.B @ np.atleast_1d(u.u(t) if hasattr(u, "u") else u)
        return f

    def impact_saltation(self, event: Any, u: Any) -> tuple[FloatArray, float]:
        n = self.M.shape[0]
        w = self.G[event.index]
        J = impact_jump_jacobian(self.M, w, self.restitution[event.index])
        grad = np.concatenate([w, np.zeros(n)])
        fm = self.field(np.asarray(event.pre, float), event.time, u)
        fp = self.field(np.asarray(event.post, float), event.time, u)
        speed = -float(w @ np.asarray(event.pre, float)[n:])
        return saltation_matrix(J, fm, fp, grad), speed


def _mechanics_transition(model: _LinearMechanics, tr: Any, t0: float, tf: float,
                          u: Any) -> tuple[FloatArray, float]:
    """Product of flow exponentials and impact saltation matrices along ``tr``."""
    Phi = np.eye(model.A.shape[0])
    t_last, min_speed = t0, np.inf
    for ev in tr.events:
        if ev.kind == "grazing":
            # a tangential touch without impact: the map's one-sided derivative on the
            # non-impacting side is the flow's; the orbit is exactly at a grazing
            min_speed = 0.0
            continue
        if ev.kind != "impact":
            raise ModelError(f"system: the orbit has a {ev.kind!r} event at t = {ev.time:.6g}; "
                             f"saltation through it is implemented for impacts only (a "
                             f"sustained contact has no isolated event)")
        S, speed = model.impact_saltation(ev, u)
        Phi = S @ model.flow.expm(ev.time - t_last) @ Phi
        t_last, min_speed = ev.time, min(min_speed, speed)
    return model.flow.expm(tf - t_last) @ Phi, min_speed


def stroboscopic_map(forced: Forced, x0: Any, *, n_periods: int = 1,
                     t0: float = 0.0) -> MapResult:
    """``x(t0 + kT)`` from ``x(t0) = x0`` and its Jacobian ``∂x(t0 + kT)/∂x0``.

    Parameters
    ----------
    forced : Forced
        The periodically forced system and its period ``T``.
    x0 : array_like
        Initial state.
    n_periods : int
        ``k``, the number of periods.
    t0 : float
        Initial time.

    Raises
    ------
    ModelError
        A system whose transition can be neither asked from its integrator (capability
        ``sensitivity``) nor assembled from an event table (linear mechanics).
    SolverError
        A grazing impact on the way (no saltation matrix), or the integrator's failure.
    """
    k = check_integer("n_periods", n_periods, minimum=1)
    x0 = as_vector("x0", x0, forced.n_states)
    tf = t0 + k * forced.period
    if _is_linear_mechanics(forced.system):   # exact: nothing integrated numerically
        tr = forced.simulate(x0, (t0, tf), t_eval=np.array([t0, tf]))
        J, speed = _mechanics_transition(_model_of(forced.system), tr, t0, tf, forced.u)
    elif _has_sensitivity(forced):
        tr = _transition_over(forced, x0, t0, tf)
        J = np.asarray(tr.stats["state_transition"], float)
        speed = _min_impact_speed(forced.system, tr)
    else:
        raise ModelError(f"system: no state transition for {type(forced.system).__name__} "
                         f"with method {forced.method!r}; use a method with the "
                         f"'sensitivity' capability or a linear LagrangianSystem")
    sig = tuple((e.kind, int(e.index)) for e in tr.events)
    return MapResult(np.asarray(tr.x[-1], float), J, tr, sig, speed)


def _transition_over(forced: Forced, x0: FloatArray, t0: float, tf: float) -> Any:
    """The run with ``sensitivity=True``, sampled at ``t0, tf``: on the coarsest grid
    (``dt = tf - t0``) by a method without ``t_eval`` that has a sampling grid
    (``event_driven``, whose ``t_eval`` would interpolate), by ``t_eval`` otherwise."""
    from ..simulate.driver import integrator_for

    cls = integrator_for(forced.system, forced.method)
    grid = ({"dt": tf - t0} if "t_eval" not in cls.capabilities
            and "dt" in getattr(cls, "options", ()) else {"t_eval": np.array([t0, tf])})
    return forced.simulate(x0, (t0, tf), sensitivity=True, **grid)


def _min_impact_speed(system: Any, tr: Any) -> float:
    """Smallest approach speed ``-∇g_j(q)·v-`` over the impacts of a mechanical run
    (``inf`` for another system or no impact)."""
    if not hasattr(system, "gap_jacobian"):
        return np.inf
    n = system.n_dof
    speeds = [-float(system.gap_jacobian(ev.pre[:n])[ev.index] @ ev.pre[n:])
              for ev in tr.events if ev.kind == "impact"]
    return min(speeds, default=np.inf)


_MODELS: dict[int, tuple[Any, _LinearMechanics]] = {}


def _model_of(system: Any) -> _LinearMechanics:
    """Cache the flow per system object (continuation calls the map many times)."""
    hit = _MODELS.get(id(system))
    if hit is None or hit[0] is not system:
        if len(_MODELS) > 64:
            _MODELS.clear()
        hit = (system, _LinearMechanics.of(system))
        _MODELS[id(system)] = hit
    return hit[1]


def sample_on_grid(forced: Forced, x0: Any, dt: float, n: int) -> Any:
    """Run ``(0, n·dt)`` with samples exactly at ``k·dt``: requested times for methods with
    the ``t_eval`` capability, the ``dt`` sampling grid of ``event_driven`` (whose samples are
    computed by the exact flow; ``t_eval`` there would interpolate linearly)."""
    from ..simulate.driver import integrator_for

    grid = dt * np.arange(n + 1, dtype=float)
    cls = integrator_for(forced.system, forced.method)
    if "t_eval" in cls.capabilities:
        return forced.simulate(x0, (0.0, grid[-1]), t_eval=grid)
    if "dt" in getattr(cls, "options", ()):
        return forced.simulate(x0, (0.0, grid[-1]), dt=dt)
    raise ModelError(f"system: method {cls.name!r} can sample neither at requested times nor "
                     f"on a grid; use an exact-flow method")


def at_times(tr: Any, times: Any) -> FloatArray:
    """Rows of ``tr`` at ``times`` (right-continuous: the post-event state when an event falls
    on a sample time); the times must be sample times of ``tr``."""
    times = np.asarray(times, float)
    tol = 1e-12 * max(1.0, float(np.max(np.abs(times))))   # roundoff of k·dt
    idx = np.searchsorted(tr.t, times + tol, side="right") - 1
    return np.asarray(tr.x[np.clip(idx, 0, len(tr.t) - 1)], float)


def floquet_multipliers(monodromy: Any) -> np.ndarray:
    """Eigenvalues of the monodromy matrix, by decreasing modulus.

    Parameters
    ----------
    monodromy : (n, n) array_like
        The monodromy matrix.
    """
    mu = np.linalg.eigvals(np.asarray(monodromy, float))
    return mu[np.argsort(-np.abs(mu), kind="stable")]


@dataclass(frozen=True, eq=False)
class Orbit:
    """A ``kT``-periodic orbit of a forced system.

    Attributes
    ----------
    nodes
        ``(k, n)`` shooting nodes: the state at ``t = 0, T, ..., (k-1)T``.
    period
        ``T`` of the input (the orbit's period is ``n_periods·T``).
    n_periods
        ``k``.
    monodromy
        ``∂x(kT)/∂x(0)``.
    multipliers
        Its eigenvalues by decreasing modulus.
    signature
        Events of one orbit period, ``((kind, index), ...)``.
    min_impact_speed, min_gap
        Distances to a grazing (``inf`` when not applicable).
    iterations
        Newton iterations used.
    residual
        Final ``max_i |P(x_i) - x_{i+1}|``.
    node_jacobians
        ``J_i = ∂P(x_i)/∂x_i``, the one-period Jacobians at the nodes (their product is the
        monodromy).
    """

    nodes: FloatArray
    period: float
    n_periods: int
    monodromy: FloatArray
    multipliers: np.ndarray
    signature: tuple[tuple[str, int], ...]
    min_impact_speed: float = np.inf
    min_gap: float = np.inf
    iterations: int = 0
    residual: float = 0.0
    node_jacobians: tuple[FloatArray, ...] = field(default=(), repr=False)

    @property
    def x0(self) -> FloatArray:
        """State at ``t = 0``."""
        return self.nodes[0]

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle."""
        return bool(np.all(np.abs(self.multipliers) < 1.0))

    @property
    def n_impacts(self) -> int:
        return sum(1 for k, _ in self.signature if k == "impact")


def _shooting_system(forced: Forced, X: FloatArray
                     ) -> tuple[FloatArray, FloatArray, list[MapResult]]:
    """Residual ``P(x_i) - x_{i+1}`` and its block-bidiagonal Jacobian over all nodes."""
    if isinstance(forced, Autonomous):
        return _cycle_shooting_system(forced, X)
    k, n = X.shape
    maps = [stroboscopic_map(forced, X[i]) for i in range(k)]
    R = np.concatenate([maps[i].x - X[(i + 1) % k] for i in range(k)])
    J = np.zeros((k * n, k * n))
    for i in range(k):
        j = (i + 1) % k
        J[i * n:(i + 1) * n, i * n:(i + 1) * n] += maps[i].jacobian
        J[i * n:(i + 1) * n, j * n:(j + 1) * n] -= np.eye(n)
    return R, J, maps


def find_orbit(forced: Forced, x0: Any, *, n_periods: int = 1, tol: float = 1e-11,
               max_iter: int = 30) -> Orbit:
    """Newton on the multiple-shooting equations of a ``kT``-periodic orbit.

    Parameters
    ----------
    forced
        System, input and period.
    x0 : (n,) or (k, n) array_like
        Initial guess: one state (the other nodes are generated by the map) or all nodes.
    n_periods
        ``k``: look for an orbit of period ``kT``.
    tol
        Stop when ``max_i |P(x_i) - x_{i+1}| <= tol·max(1, |x|)`` (``> 0``).
    max_iter
        Newton iterations at most (each a damped step: halved, at most
        :data:`DAMPING_HALVINGS` times, until the residual decreases and the trial is
        admissible).

    Raises
    ------
    ModelError
        ``forced`` not a :class:`Forced`, or a tolerance that is not a positive number.
    BudgetExceededError
        ``max_iter`` iterations spent (a :class:`SolverError`; message with the last
        residual, the last Newton iterate's nodes in ``err.partial``).
    InadmissibleStateError
        A Newton iterate left the admissible set (a penetrated contact, a state outside the
        partition) and no damped step stayed inside; the message names the iterate and the
        start it came from.
    SolverError
        A singular shooting Jacobian, or an integrator's failure.
    """
    if not isinstance(forced, Forced):
        raise ModelError(f"forced: expected a Forced (system, periodic input, period), got "
                         f"{type(forced).__name__}; wrap the model as Forced(system, u, period)")
    k = check_integer("n_periods", n_periods, minimum=1)
    tol = check_positive("tol", tol)
    max_iter = check_integer("max_iter", max_iter, minimum=0)
    n = forced.n_states
    X = _initial_nodes(forced, x0, k, n)
    start = X.copy()
    for it in range(max_iter + 1):
        R, J, maps = _iterate_system(forced, X, it, start)
        res = float(np.max(np.abs(R)))
        if res <= tol * max(1.0, float(np.max(np.abs(X)))):
            return make_orbit(forced, X, maps, it, res)
        if it == max_iter:
            break
        X = _damped_step(forced, X, R, J, res, it, start)
    raise BudgetExceededError(
        f"max_iter: shooting did not converge in {max_iter} Newton iterations (residual "
        f"{res:.3g} > tol = {tol:g}); raise max_iter, start closer to the orbit (e.g. from a "
        f"brute-force run) or check that a {k}T-periodic orbit exists; the last iterate's "
        f"nodes are in err.partial", budget="max_iter", limit=max_iter, used=max_iter,
        partial=X.copy())


#: Halvings of a Newton step in :func:`find_orbit` before the smallest step is taken as it is.
DAMPING_HALVINGS = 8


def _iterate_system(forced: Forced, X: FloatArray, it: int, start: FloatArray
                    ) -> tuple[FloatArray, FloatArray, list[MapResult]]:
    """:func:`_shooting_system` at Newton iterate ``it``; an inadmissible iterate (``it >
    0``: the user's start was admissible) is reported as the iterate's, not as ``x0``'s."""
    try:
        return _shooting_system(forced, X)
    except InadmissibleStateError as exc:
        if it == 0:
            raise
        raise _left_admissible_set(it, start, X, exc) from exc


def _left_admissible_set(it: int, start: FloatArray, X: FloatArray,
                         exc: Exception) -> InadmissibleStateError:
    first = np.array2string(start[0], precision=6)
    here = np.array2string(X[0], precision=6)
    cause = str(exc).removeprefix("x0: ")     # the iterate's state, not the user's x0
    return InadmissibleStateError(
        f"x0: Newton iterate {it} of the shooting from x0 = {first} left the admissible set "
        f"(at {here}; even the step damped {DAMPING_HALVINGS} times): {cause}; start closer to "
        f"the orbit (e.g. from the end of a brute-force run), or with n_periods nodes "
        f"taken from a run, so that smaller Newton steps reach it")


def _initial_nodes(forced: Forced, x0: Any, k: int, n: int) -> FloatArray:
    if isinstance(forced, Autonomous):
        return _cycle_node(forced, x0, k)
    arr = as_float_array("x0", x0)
    if arr.ndim == 2:
        if arr.shape != (k, n):
            raise DimensionError(f"x0: expected shape ({k}, {n}) for {k} nodes, got {arr.shape}")
        return arr.copy()
    X = [as_vector("x0", x0, n)]
    for _ in range(k - 1):
        X.append(stroboscopic_map(forced, X[-1]).x)
    return np.array(X)


def _damped_step(forced: Forced, X: FloatArray, R: FloatArray, J: FloatArray,
                 res: float, it: int, start: FloatArray) -> FloatArray:
    """The Newton step from iterate ``it``, halved until the residual decreases (a trial the
    integrator refuses — a grazing, a penetrated contact — counts as no decrease); after
    :data:`DAMPING_HALVINGS` halvings the smallest step is taken as it is, unless it left
    the admissible set (:class:`InadmissibleStateError` naming iterate ``it + 1``)."""
    try:
        dx = np.linalg.solve(J, -R).reshape(X.shape)
    except np.linalg.LinAlgError as exc:
        raise SolverError(f"x0: singular shooting Jacobian at Newton iterate {it} ({exc}); "
                          f"the orbit is at a fold or a multiplier is 1") from exc
    lam = 1.0
    outside: InadmissibleStateError | None = None
    for _ in range(DAMPING_HALVINGS):
        trial = X + lam * dx
        try:
            R2 = _shooting_system(forced, trial)[0]
            if float(np.max(np.abs(R2))) < res:
                return trial
            outside = None
        except InadmissibleStateError as exc:
            outside = exc
        except SolverError:
            outside = None
        lam /= 2
    if outside is not None:
        raise _left_admissible_set(it + 1, start, X + 2 * lam * dx, outside) from outside
    return X + lam * dx


def make_orbit(forced: Forced, X: FloatArray, maps: list[MapResult], iterations: int,
               residual: float) -> Orbit:
    """Assemble an :class:`Orbit` from converged nodes and their maps."""
    if isinstance(forced, Autonomous):
        return _cycle_orbit(forced, X, maps, iterations, residual)
    Mono = np.eye(X.shape[1])
    for m in maps:
        Mono = m.jacobian @ Mono
    sig = tuple(s for m in maps for s in m.signature)
    speed = min((m.min_impact_speed for m in maps), default=np.inf)
    gap = (min_gap(forced, X, maps) if _is_linear_mechanics(forced.system)
           else nonlinear_min_gap(forced, X) if _is_mechanics(forced.system) else np.inf)
    return Orbit(X.copy(), float(forced.period), X.shape[0], Mono, floquet_multipliers(Mono),
                 sig, float(speed), float(gap), iterations, residual,
                 tuple(m.jacobian for m in maps))


def min_gap(forced: Forced, X: FloatArray, maps: list[MapResult] | None = None,
            samples: int = 64) -> float:
    """Smallest local minimum of the gaps over the free flight of the orbit through nodes
    ``X`` (linear mechanics; minima at impacts excluded, ``inf`` when there is none).

    The gaps are sampled on ``samples`` points per period of the exact flow, and each sampled
    local minimum is refined by Newton on ``ġ(t) = 0`` (state propagated exactly by the
    augmented flow of plant and input), so a grazing distance is exact to rounding.
    """
    from ..numerics.lti import LTIFlow, augment

    model = _model_of(forced.system)
    sysm = forced.system
    n = sysm.n_dof
    u = forced.u
    A_aug = augment(model.A, model.B, u) if (u is not None and model.B is not None) else model.A
    flow = LTIFlow(A_aug)
    best = np.inf
    T = forced.period
    for x_node in X:
        tr = sample_on_grid(forced, x_node, T / samples, samples)
        for j in range(sysm.n_contacts):
            best = min(best, _min_gap_contact(tr, j, model, flow, u, n))
    return best


def _min_gap_contact(tr: Any, j: int, model: _LinearMechanics, flow: Any, u: Any,
                     n: int) -> float:
    w, g0 = model.G[j], float(model.g0[j])
    t, x = tr.t, tr.x
    g = x[:, :n] @ w + g0
    t_imp = tr.event_times()
    best = np.inf
    for i in range(1, len(t) - 1):
        lo, hi = t[i - 1], t[i + 1]
        if g[i] <= g[i - 1] and g[i] <= g[i + 1] and not np.any((t_imp >= lo) & (t_imp <= hi)):
            best = min(best, _refine_min(t[i], x[i], w, g0, model, flow, u, n, hi - lo))
    return best


def _refine_min(ts: float, xs: FloatArray, w: FloatArray, g0: float, model: _LinearMechanics,
                flow: Any, u: Any, n: int, width: float) -> float:
    """Newton on ``ġ(t) = wᵀv(t) = 0`` near a sampled minimum, on the exact flow (kept
    within ``width`` of the sample; the sampled value when Newton leaves it)."""
    X0 = np.concatenate([xs, u.w(ts)]) if flow.n > xs.shape[0] else xs.copy()
    s = 0.0
    for _ in range(20):
        X = flow.propagate(X0, s)
        x = X[: 2 * n]
        gd = float(w @ x[n:])
        gdd = float(w @ model.field(x, ts + s, u)[n:])
        if gdd == 0.0:
            break
        ds = -gd / gdd
        s += ds
        if abs(ds) <= 4 * np.finfo(float).eps * max(1.0, abs(ts)):
            break
    if not abs(s) <= width:
        return float(w @ xs[:n] + g0)
    X = flow.propagate(X0, s)
    return float(w @ X[:n] + g0)


def nonlinear_min_gap(forced: Forced, X: FloatArray, samples: int = 64) -> float:
    """Smallest local minimum of the gaps over the free flight of the orbit through nodes
    ``X`` of a nonlinear mechanical system (minima at impacts excluded; ``inf`` if none).

    The gaps are sampled on the run's grid of ``samples`` points per period; each sampled
    local minimum of contact ``j`` is refined by Brent's method on ``ġ_j = ∇g_j(q)·v = 0``
    between its neighbouring samples (each evaluation a short run from the left one), so the
    grazing distance is as accurate as the integrator, not the sampling.

    Parameters
    ----------
    forced : Forced
        The forced :class:`~nscontrol.systems.lagrangian.LagrangianSystem`.
    X : (k, n) array_like
        The orbit's shooting nodes (at ``t = 0, T, ...``).
    samples : int
        Samples per period.
    """
    sysm, T = forced.system, forced.period
    best = np.inf
    for x_node in np.atleast_2d(np.asarray(X, float)):
        tr = sample_on_grid(forced, x_node, T / samples, samples)
        g = np.array([sysm.gaps(x[: sysm.n_dof]) for x in tr.x]).reshape(len(tr.t), -1)
        t_imp = tr.event_times()
        for j in range(g.shape[1]):
            for i in range(1, len(tr.t) - 1):
                lo, hi = tr.t[i - 1], tr.t[i + 1]
                if (g[i, j] <= g[i - 1, j] and g[i, j] <= g[i + 1, j] and hi > lo
                        and not np.any((t_imp >= lo) & (t_imp <= hi))):
                    best = min(best, _refine_gap_min(forced, tr.x[i - 1], lo, hi, j))
    return float(best)


def _refine_gap_min(forced: Forced, x_lo: FloatArray, t_lo: float, t_hi: float,
                    j: int) -> float:
    """``g_j`` where ``ġ_j = 0`` in ``(t_lo, t_hi)`` (``g_j`` decreasing at ``t_lo``,
    increasing at ``t_hi``), the state run from ``x_lo`` at ``t_lo``; the smaller end value
    when ``ġ_j`` does not change sign there."""
    import scipy.optimize

    sysm, n = forced.system, forced.system.n_dof

    def state(s: float) -> FloatArray:
        if s == 0.0:
            return x_lo
        return np.asarray(forced.simulate(x_lo, (t_lo, t_lo + s), dt=s).x[-1], float)

    def rate(s: float) -> float:
        x = state(s)
        return float(sysm.gap_jacobian(x[:n])[j] @ x[n:])

    width = t_hi - t_lo
    r0, r1 = rate(0.0), rate(width)
    if not r0 < 0.0 < r1:
        return float(min(sysm.gaps(state(0.0)[:n])[j], sysm.gaps(state(width)[:n])[j]))
    s = scipy.optimize.brentq(rate, 0.0, width, xtol=4 * np.finfo(float).eps * max(1.0, t_hi))
    return float(sysm.gaps(state(s)[:n])[j])


# -- autonomous orbits and hyperplane sections -------------------------------------------------

def _transition_run(system: Any, x0: FloatArray, tf: float, method: Any,
                    t_eval: FloatArray | None = None) -> Any:
    """``simulate`` over ``(0, tf)`` with the state transition (capability ``sensitivity``)."""
    from ..simulate import simulate
    from ..simulate.driver import METHODS, integrator_for

    cls = integrator_for(system, method)
    if "sensitivity" not in cls.capabilities:
        able = sorted(k for k in METHODS if "sensitivity" in METHODS[k].capabilities)
        raise ModelError(f"method: autonomous orbits need the state transition, which "
                         f"{cls.name!r} does not compute; use one of {able}")
    te = np.array([0.0, tf]) if t_eval is None else t_eval
    return simulate(system, x0, (0.0, tf), method=method, t_eval=te, sensitivity=True)


def _velocity_samples(tf: float) -> FloatArray:
    """The ``t_eval`` a run to ``tf`` needs for :func:`_flow_velocity`: ``0, tf - δ, tf``."""
    return np.array([0.0, tf - _velocity_step(tf), tf])


def _velocity_step(tf: float) -> float:
    """``δ = ε^{1/3}·tf``: truncation ``O(δ²)`` against rounding ``O(ε/δ)``."""
    return float(np.finfo(float).eps) ** (1 / 3) * tf


def _flow_velocity(system: Any, tr: Any, tf: float, method: Any) -> FloatArray:
    """``ẋ(tf)`` by central differences of the flow (step :func:`_velocity_step`):
    ``x(tf - δ)`` from the run's samples (run with :func:`_velocity_samples`), ``x(tf + δ)``
    from a short continuation."""
    from ..simulate import simulate

    delta = _velocity_step(tf)
    x_minus = at_times(tr, [tf - delta])[0]
    after = simulate(system, tr.x[-1], (0.0, delta), method=method,
                     t_eval=np.array([0.0, delta]))
    return (after.x[-1] - x_minus) / (2 * delta)


@dataclass(frozen=True, eq=False)
class Cycle:
    """A periodic orbit of an autonomous system (period unknown).

    Attributes
    ----------
    x0
        A point of the orbit on the phase-condition hyperplane.
    period
        ``T``.
    monodromy
        ``∂φ_T/∂x0``.
    multipliers
        All eigenvalues of the monodromy by decreasing modulus.
    trivial_index
        Index in ``multipliers`` of the trivial multiplier 1 (eigenvector along the flow).
    signature
        Events of one period.
    iterations, residual
        Newton iterations and final ``|φ_T(x0) - x0|``.
    """

    x0: FloatArray
    period: float
    monodromy: FloatArray
    multipliers: np.ndarray
    trivial_index: int
    signature: tuple[tuple[str, int], ...]
    iterations: int
    residual: float

    @property
    def nontrivial(self) -> np.ndarray:
        """The multipliers without the trivial one."""
        return np.delete(self.multipliers, self.trivial_index)

    @property
    def stable(self) -> bool:
        """All non-trivial multipliers strictly inside the unit circle."""
        return bool(np.all(np.abs(self.nontrivial) < 1.0))


def _trivial_index(M: FloatArray, f: FloatArray) -> tuple[np.ndarray, int]:
    """Multipliers by decreasing modulus and the index of the one whose eigenvector is most
    nearly parallel to the flow ``f`` (``M f = f`` on a periodic orbit)."""
    mu, V = np.linalg.eig(M)
    order = np.argsort(-np.abs(mu), kind="stable")
    mu, V = mu[order], V[:, order]
    fn = f / np.linalg.norm(f)
    align = np.abs(fn @ V) / np.linalg.norm(V, axis=0)
    return mu, int(np.argmin(np.abs(mu - 1.0) + (1.0 - align)))


def find_cycle(system: Any, x0: Any, period: float, *, normal: Any, offset: float | None = None,
               method: Any = None, tol: float = 1e-9, max_iter: int = 30) -> Cycle:
    """Newton on ``φ_T(x0) = x0``, ``normal·x0 = offset`` for ``(x0, T)`` (single shooting).

    The phase condition pins the point on a hyperplane the orbit crosses transversally
    (default offset: ``normal·x0`` of the guess). The bordered Jacobian is
    ``[[M - I, ẋ(T)], [normalᵀ, 0]]`` with ``M`` the integrator's state transition and
    ``ẋ(T)`` a central difference of the flow in time. At the solution ``M ẋ(0) = ẋ(0)``:
    the multiplier 1 with the flow as eigenvector is the trivial one (``trivial_index``).
    The default ``tol = 1e-9`` sits above the residual floor of event-located flows (switch
    instants found to ~1e-11 relative, times the field's jump).

    An equilibrium solves the same equations for every ``T`` (it is no cycle) and is
    refused: the point found must move, over its period, by more than the tolerance, and
    cross the hyperplane (``normal·ẋ ≠ 0``).

    Parameters
    ----------
    system
        An autonomous model whose integrator offers the ``sensitivity`` capability.
    x0 : array_like
        Initial guess of a point of the cycle.
    period : float
        Initial guess of its period.
    normal : array_like
        Normal of the phase-condition hyperplane (nonzero).
    offset : float, optional
        Its offset (default ``normal·x0`` of the guess).
    method : str or Integrator subclass, optional
        The integrator (default: the system's).
    tol : float
        Newton's tolerance on the residual (``> 0``).
    max_iter : int
        Newton iterations at most.

    Raises
    ------
    ModelError
        A method without the ``sensitivity`` capability, a zero ``normal``, a bad tolerance.
    BudgetExceededError
        ``max_iter`` iterations spent (message with the residual; the last iterate
        ``(x0, T)`` in ``err.partial``).
    SolverError
        Newton ended on an equilibrium or on a point whose flow does not cross the
        hyperplane, drove the period to ``<= 0``, or met a singular bordered Jacobian.
    """
    n = _n_states(system)
    x = as_vector("x0", x0, n).copy()
    T = check_positive("period", period)
    nv = _section_normal(normal, n)
    c = float(nv @ x) if offset is None else as_finite_scalar("offset", offset)
    tol = check_positive("tol", tol)
    max_iter = check_integer("max_iter", max_iter, minimum=0)
    for it in range(max_iter + 1):
        r, J, M, f, tr = _cycle_equations(system, x, T, nv, c, method)
        res = float(np.max(np.abs(r)))
        if res <= tol * max(1.0, float(np.max(np.abs(x)))):
            _check_crossing(x, T, f, nv, tol, it)
            mu, k = _trivial_index(M, f)
            sig = tuple((e.kind, int(e.index)) for e in tr.events)
            return Cycle(x, T, M, mu, k, sig, it, res)
        if it == max_iter:
            break
        try:
            step = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError as exc:
            raise SolverError(f"normal: singular bordered Jacobian at Newton iterate {it}: the "
                              f"flow at x = {x} does not cross normal·x = {c:g} (normal·ẋ = "
                              f"{float(nv @ f):.3g}), or the cycle has a second multiplier 1; "
                              f"choose a normal along the flow at x0") from exc
        x, T = x + step[:n], T + float(step[n])
        if T <= 0:
            raise SolverError(f"period: Newton drove the period to {T:.3g} <= 0; start from a "
                              f"better period guess")
    raise BudgetExceededError(
        f"max_iter: cycle shooting did not converge in {max_iter} iterations (residual "
        f"{res:.3g} > tol = {tol:g}); raise max_iter or improve the guesses of x0 and period; "
        f"the last iterate (x0, T) is in err.partial", budget="max_iter", limit=max_iter,
        used=max_iter, partial=np.append(x, T))


def _n_states(system: Any) -> int:
    """``system.n_states`` of a model (``ModelError`` for anything else)."""
    n = getattr(system, "n_states", None)
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 1:
        raise ModelError(f"system: expected a model with n_states (a system simulate "
                         f"integrates), got {type(system).__name__}")
    return int(n)


def _section_normal(normal: Any, n: int) -> FloatArray:
    """The normal of a hyperplane ``normal·x = offset`` in ``R^n``: a finite nonzero vector
    (a zero one defines no hyperplane and makes the phase condition vacuous).

    Parameters
    ----------
    normal : array_like
        The normal.
    n : int
        The state dimension.
    """
    nv = as_vector("normal", normal, n)
    if not np.any(nv):
        raise ModelError(f"normal: expected a nonzero normal of the hyperplane normal·x = "
                         f"offset, got {nv.tolist()}; take e.g. the flow's direction at x0")
    return nv


def _check_crossing(x: FloatArray, T: float, f: FloatArray, normal: FloatArray, tol: float,
                    it: int) -> None:
    """Refuse an equilibrium (the flow moves less than the tolerance over the period: the
    shooting residual cannot tell it from a cycle) and a point whose flow is tangent to the
    section (``normal·ẋ = 0`` to rounding: no crossing to pin the phase)."""
    scale = max(1.0, float(np.max(np.abs(x))))
    travel = float(np.max(np.abs(f))) * T
    if not travel > tol * scale:
        raise SolverError(f"x0: Newton iterate {it} is an equilibrium, not a point of a cycle: "
                          f"the flow there moves |ẋ|·T = {travel:.3g} over the period (<= tol "
                          f"= {tol:g}); start from a point on the cycle (e.g. the end of a "
                          f"long run) away from the equilibria")
    # normal·ẋ against the rounding of the central difference ẋ (ε^{2/3} relative) times a
    # factor 1e3 for the event location inside the difference's window
    eps23 = float(np.finfo(float).eps) ** (2 / 3)
    cross = abs(float(normal @ f))
    if not cross > 1e3 * eps23 * float(np.linalg.norm(normal)) * float(np.linalg.norm(f)):
        raise SolverError(f"normal: the flow at the point found, {x}, does not cross "
                          f"normal·x = offset (normal·ẋ = {float(normal @ f):.3g}): no "
                          f"phase condition; choose a normal along the flow there")


def _cycle_equations(system: Any, x: FloatArray, T: float, normal: FloatArray, offset: float,
                     method: Any) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, Any]:
    """The single-shooting equations of a cycle, ``(φ_T(x) - x, normal·x - offset)``, their
    bordered Jacobian ``[[M - I, ẋ(T)], [normalᵀ, 0]]``, the monodromy ``M``, the velocity
    ``ẋ(T)`` and the run."""
    n = x.shape[0]
    tr = _transition_run(system, x, T, method, t_eval=_velocity_samples(T))
    M = np.asarray(tr.stats["state_transition"], float)
    r = np.append(tr.x[-1] - x, normal @ x - offset)
    f = _flow_velocity(system, tr, T, method)
    J = np.block([[M - np.eye(n), f[:, None]], [normal[None, :], np.zeros((1, 1))]])
    return r, J, M, f, tr


@dataclass(frozen=True, eq=False, init=False)
class Autonomous(Forced):
    """An autonomous system and the phase condition of its cycles: what a continuation factory
    returns to follow a limit cycle (:func:`nscontrol.analysis.continuation.continue_orbit`).

    The shooting unknowns are ``(x0, T)``, one node: a state on the hyperplane
    ``normal·x0 = offset`` and the period (the start of a continuation may give ``x0``
    alone: ``period`` is then the guess of ``T``). So that the continuation engine of forced orbits
    runs unchanged, this is a :class:`Forced` (no input; ``period`` the guess of ``T``) whose
    ``n_states`` counts the unknowns, ``system.n_states + 1``; its orbits' ``multipliers``
    are the non-trivial ones (the trivial 1 would zero the fold test everywhere).

    Parameters
    ----------
    system
        The autonomous model; its integrator must offer the ``sensitivity`` capability.
    period : float
        A guess of the cycle's period.
    normal : array_like
        Normal of the phase-condition hyperplane (crossed transversally by the cycles).
    offset : float
        Its offset.
    method : str or Integrator subclass, optional
        The integrator (default: the system's).
    options : tuple of (name, value) pairs
        Extra ``simulate`` options.

    Examples
    --------
    Continuation in ``μ`` of the Hopf normal form's cycle (``r' = r(μ - r²)``, ``θ' = 1``)
    starts from ``continue_orbit(factory, 0.25, [0.5, 0.0], p_range=(0.1, 1.0))`` with
    ``factory = lambda mu: Autonomous(system_at(mu), 2π, normal=[0, 1])``.
    """

    normal: Any = None
    offset: float = 0.0

    def __init__(self, system: Any, period: float, *, normal: Any, offset: float = 0.0,
                 method: Any = None, options: tuple[tuple[str, Any], ...] = ()) -> None:
        nv = _section_normal(normal, _n_states(system))
        values = {"system": system, "u": None, "period": period, "method": method,
                  "options": tuple(options), "normal": nv, "offset": float(offset)}
        for key, value in values.items():
            object.__setattr__(self, key, value)
        self.__post_init__()

    @property
    def n_states(self) -> int:
        """Number of shooting unknowns: the state and the period."""
        return int(self.system.n_states) + 1


def _cycle_node(problem: Autonomous, x0: Any, k: int) -> FloatArray:
    """The one shooting node ``(x0, T)`` of a cycle: ``x0`` with the period guess appended,
    or ``(x0, T)`` as given."""
    if k != 1:
        raise ModelError(f"n_periods: a cycle is shot from one node (n_periods = 1), got {k}")
    n = int(problem.system.n_states)
    arr = as_float_array("x0", x0).reshape(-1)
    if arr.size == n:
        arr = np.append(arr, problem.period)
    return as_vector("x0", arr, n + 1)[None, :].copy()


@dataclass(frozen=True, eq=False)
class _CycleMap(MapResult):
    """The map of a cycle's shooting node, with the flow velocity at its end."""

    velocity: Any = None


def _cycle_shooting_system(problem: Autonomous, X: FloatArray
                           ) -> tuple[FloatArray, FloatArray, list[MapResult]]:
    """:func:`_shooting_system` of a cycle: one node ``(x0, T)``."""
    if X.shape[0] != 1:
        raise ModelError(f"n_periods: a cycle is shot from one node (n_periods = 1), got "
                         f"{X.shape[0]}")
    x, T = X[0, :-1], float(X[0, -1])
    if not T > 0.0:
        raise SolverError(f"period: the corrector drove the period to {T:.3g} <= 0")
    r, J, M, f, tr = _cycle_equations(problem.system, x, T, problem.normal, problem.offset,
                                      problem.method)
    sig = tuple((e.kind, int(e.index)) for e in tr.events)
    return r, J, [_CycleMap(np.append(tr.x[-1], T), M, tr, sig, np.inf, f)]


def _cycle_orbit(problem: Autonomous, X: FloatArray, maps: list[MapResult], iterations: int,
                 residual: float) -> Orbit:
    """:func:`make_orbit` of a cycle: the non-trivial multipliers only."""
    (m,) = maps
    velocity = m.velocity if isinstance(m, _CycleMap) else None
    mu, k = _trivial_index(m.jacobian, np.asarray(velocity, float))
    return Orbit(X.copy(), float(X[0, -1]), 1, m.jacobian, np.delete(mu, k), m.signature,
                 iterations=iterations, residual=residual, node_jacobians=(m.jacobian,))


@dataclass(frozen=True, eq=False)
class SectionReturn:
    """First return to a hyperplane ``normal·x = offset``: point, time and the Poincaré map's
    Jacobian ``(I - ẋ normalᵀ/(normal·ẋ)) ∂φ_τ/∂x0`` (the return time's dependence on ``x0``
    folded in, as in a saltation matrix with ``J = 0`` jump and zero field after).

    Parameters
    ----------
    x : ndarray
        The return point.
    time : float
        The return time.
    jacobian : ndarray
        The Poincaré map's Jacobian.
    """

    x: FloatArray
    time: float
    jacobian: FloatArray


def hyperplane_map(system: Any, x0: Any, *, normal: Any, offset: float, t_max: float,
                   method: Any = None, direction: int = 1,
                   samples: int = 2000, max_iter: int = 60) -> SectionReturn:
    """Poincaré map of an autonomous system on the hyperplane ``normal·x = offset``.

    The first crossing in ``direction`` (``+1``: ``normal·x`` increasing) after ``t = 0`` is
    bracketed on ``samples`` exact-flow samples of ``(0, t_max)`` and refined by secant steps
    on the flow from the bracket's start. Crossings within the first sample interval are not
    returns (the start lies on the section, or within rounding of a perturbation of it).

    Parameters
    ----------
    system
        An autonomous model.
    x0 : array_like
        The starting state.
    normal : array_like
        Normal of the hyperplane (nonzero).
    offset : float
        Its offset.
    t_max : float
        Longest time searched for a return.
    method : str or Integrator subclass, optional
        The integrator (default: the system's).
    direction : {1, -1}
        Crossing direction counted as a return.
    samples : int
        Samples of ``(0, t_max)`` that bracket the crossing.
    max_iter : int
        Secant steps at most refining the crossing time.

    Raises
    ------
    SolverError
        No crossing within ``t_max``.
    BudgetExceededError
        ``max_iter`` secant steps spent before the crossing time settled to rounding (the
        last estimate of the return time in ``err.partial``).
    """
    from ..simulate import simulate

    n = _n_states(system)
    x0 = as_vector("x0", x0, n)
    nv = _section_normal(normal, n)
    offset = as_finite_scalar("offset", offset)
    t_max = check_positive("t_max", t_max)
    samples = check_integer("samples", samples, minimum=1)
    max_iter = check_integer("max_iter", max_iter, minimum=1)
    if isinstance(direction, bool) or direction not in (1, -1):
        raise ModelError(f"direction: expected +1 or -1, got {direction!r}")
    grid = np.linspace(0.0, t_max, samples + 1)
    tr = simulate(system, x0, (0.0, t_max), method=method, t_eval=grid)
    X = at_times(tr, grid)
    g = direction * (X @ nv - offset)
    hits = np.flatnonzero((g[:-1] < 0) & (g[1:] >= 0))
    hits = hits[hits > 0]       # a start on (or a hair off) the section is not a return
    if not hits.size:
        raise SolverError(f"t_max: no crossing of the section within {t_max}; increase t_max")
    i = int(hits[0])
    ta, xa = grid[i], X[i]

    def gap(s: float) -> tuple[float, FloatArray]:
        if s == 0.0:
            return float(direction * (xa @ nv - offset)), xa
        y = simulate(system, xa, (0.0, s), method=method, t_eval=np.array([0.0, s])).x[-1]
        return float(direction * (y @ nv - offset)), y

    s0, s1 = 0.0, grid[i + 1] - ta
    g0, g1 = gap(s0)[0], gap(s1)[0]
    for _ in range(max_iter):
        s2 = s1 - g1 * (s1 - s0) / (g1 - g0) if g1 != g0 else 0.5 * (s0 + s1)
        g2 = gap(s2)[0]
        s0, g0, s1, g1 = s1, g1, s2, g2
        if abs(s1 - s0) <= 4 * np.finfo(float).eps * max(1.0, ta + s1):
            break
    else:
        raise BudgetExceededError(
            f"max_iter: the crossing time did not settle in {max_iter} secant steps (last "
            f"change {abs(s1 - s0):.3g} at t = {ta + s1:.12g}); raise max_iter, or check that "
            f"the flow crosses the section transversally there; the last estimate of the "
            f"return time is in err.partial", budget="max_iter", limit=max_iter,
            used=max_iter, partial=float(ta + s1))
    tau = ta + s1
    run = _transition_run(system, x0, tau, method, t_eval=_velocity_samples(tau))
    M = np.asarray(run.stats["state_transition"], float)
    f = _flow_velocity(system, run, tau, method)
    P = np.eye(n) - np.outer(f, nv) / float(nv @ f)
    return SectionReturn(np.asarray(run.x[-1], float), float(tau), P @ M)
