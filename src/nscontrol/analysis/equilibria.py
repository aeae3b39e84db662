"""Pseudo-arclength continuation of equilibria in one parameter, with bifurcation detection.

:func:`continue_equilibrium` follows the zeros of ``F(x, p)`` for a user factory
``p -> system``; the unknown is ``y = (x, p)`` and the branch is the solution curve of
``F(y) = 0``. Predictor, corrector, tangent and location are the engine shared with the
continuation of periodic orbits (:mod:`~nscontrol.analysis._arclength`).

What the factory may return
---------------------------
* a :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` with no input or a constant one:
  ``F = A_r x + b_r + E u`` on region ``r``. The branch is followed on one region's affine
  field at a time (``F_x = A_r``, exact); when its equilibrium reaches a facet of the region
  the **boundary equilibrium** is located and, for a continuous field, the continuation
  goes on in the region across the facet (the point solves both regions' equations there);
* a :class:`~nscontrol.systems.NonlinearSystem` (autonomous: its field at ``t = 0``, its
  ``jacobian`` or central differences) or a plain callable ``x -> ẋ`` (central differences).

Test functions (on the eigenvalues ``λ`` of ``F_x``)
----------------------------------------------------
* fold: ``det F_x = ∏ λ_i`` (real);
* Hopf: the bialternate product ``∏_{i<j} (λ_i + λ_j)`` (real), which vanishes when a pair
  ``±iω`` crosses the imaginary axis; a sign change from a real pair ``±κ`` (a neutral
  saddle) is discarded;
* boundary equilibrium (PWA): the smallest normalised slack ``(h_k - H_k x)/|H_k|`` of the
  current region, positive inside. Past the facet the region's equilibrium is *virtual*;
  the slack is smooth (affine when the parameter enters affinely) across it, so its zero is
  located like any other.

At a boundary equilibrium of a continuous PWA field, ``det A_r`` and ``det A_s`` of the two
regions having the same sign means **persistence** (the branch crosses the facet and ``p``
keeps its direction), opposite signs a **non-smooth fold** (two equilibria, one per region,
meet at the facet and vanish; the branch turns back in ``p``). The continuation orients the
new tangent into the new region, so it follows either.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import FloatArray, as_vector
from ..errors import BudgetExceededError, ModelError, SolverError
from ..numerics.differences import central_difference_jacobian
from ..systems.nonlinear import NonlinearSystem
from ._arclength import (
    CORRECTOR_MAX_ITER,
    LOCATE_MAX_ITER,
    ArclengthProblem,
    FactoryMemo,
    Point,
    check_options,
    locate,
    parameter_derivative,
    unit_tangent,
)
from .continuation import Branch, SpecialPoint

__all__ = ["EquilibriumPoint", "continue_equilibrium"]



@dataclass(frozen=True, eq=False)
class _SmoothField:
    """A smooth autonomous field at one parameter value: ``value(x)`` and ``derivative(x)``
    (a :class:`~nscontrol.systems.NonlinearSystem` at ``t = 0``, or a plain callable with
    central differences from :mod:`nscontrol.numerics.differences`)."""

    value: Callable[[FloatArray], FloatArray]
    derivative: Callable[[FloatArray], FloatArray]

    @classmethod
    def of(cls, obj: Any) -> _SmoothField:
        if isinstance(obj, NonlinearSystem):
            return cls(lambda x: obj.rhs(0.0, x), lambda x: obj.jac(0.0, x))

        def value(x: FloatArray) -> FloatArray:
            return np.atleast_1d(np.asarray(obj(x), float))

        return cls(value, lambda x: central_difference_jacobian(value, x))


@dataclass(frozen=True, eq=False)
class EquilibriumPoint:
    """One equilibrium on a branch.

    Attributes
    ----------
    x
        The state.
    p
        The parameter.
    eigenvalues
        Of ``F_x``, by decreasing real part.
    region
        The PWA region whose field it solves (``-1`` for a smooth field).
    iterations, residual
        Corrector iterations and final ``max|F|``.
    """

    x: FloatArray
    p: float
    eigenvalues: np.ndarray
    region: int = -1
    iterations: int = 0
    residual: float = 0.0

    @property
    def stable(self) -> bool:
        """All eigenvalues in the open left half-plane."""
        return bool(np.all(self.eigenvalues.real < 0.0))


def _is_pwa(system: Any) -> bool:
    from ..systems.pwa import PiecewiseAffineSystem

    return isinstance(system, PiecewiseAffineSystem)


def _constant_input(system: Any) -> FloatArray | None:
    """``E u`` of a PWA system whose input is absent or constant (``ModelError`` otherwise:
    a time-varying input has no equilibrium)."""
    u = system.u
    if u is None or system.E is None:
        return None
    if callable(u) or hasattr(u, "u") or hasattr(u, "S"):
        raise ModelError("factory: the PWA system has a time-varying input; equilibria need "
                         "no input or a constant one (u=array)")
    return system.E @ np.atleast_1d(system.input_at(0.0))


def _as_field(obj: Any) -> Any:
    if _is_pwa(obj):
        return obj
    if isinstance(obj, NonlinearSystem) or callable(obj):
        return _SmoothField.of(obj)
    raise ModelError(f"factory: expected a PiecewiseAffineSystem, a NonlinearSystem or a callable "
                     f"x -> dx/dt, got {type(obj).__name__}")


def _slack(system: Any, region: int, x: FloatArray) -> float:
    """Smallest normalised slack ``(h_k - H_k x)/|H_k|`` of ``region``: positive inside."""
    H, h = system.regions[region]
    return float(np.min((h - H @ x) / np.linalg.norm(H, axis=1)))


def _sorted_eig(J: FloatArray) -> np.ndarray:
    lam = np.linalg.eigvals(J)
    return lam[np.argsort(-lam.real, kind="stable")]


@dataclass
class _EquilibriumProblem(ArclengthProblem):
    """``F(x, p) = 0`` on one region's affine field (PWA) or a smooth field."""

    factory: Callable[[float], Any]
    n: int
    tol: float
    region: int = -1
    iterations: int = 0

    def __post_init__(self) -> None:
        self.system: FactoryMemo = FactoryMemo(self.factory, lambda obj, p: _as_field(obj))

    def value(self, x: FloatArray, p: float) -> FloatArray:
        s = self.system(p)
        if isinstance(s, _SmoothField):
            return s.value(x)
        f = s.A[self.region] @ x + s.b[self.region]
        eu = _constant_input(s)
        return f if eu is None else f + eu

    def jacobian_x(self, x: FloatArray, p: float) -> FloatArray:
        s = self.system(p)
        return s.derivative(x) if isinstance(s, _SmoothField) else np.array(s.A[self.region])

    def residual(self, y: FloatArray, G_p: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``F``, ``[F_x, F_p]`` (``F_p`` by central differences, step
        ``ε^{1/3}·max(1, |p|)``; exact up to rounding when ``p`` enters affinely) and
        ``F_x``. ``G_p`` is not reused: it costs two field evaluations."""
        x, p = y[:-1], float(y[-1])
        F_p = parameter_derivative(lambda q: self.value(x, q), p)
        Jx = self.jacobian_x(x, p)
        return self.value(x, p), np.column_stack([Jx, F_p]), Jx

    def solution(self, y: FloatArray, aux: Any, iterations: int,
                 residual: float) -> EquilibriumPoint:
        return EquilibriumPoint(y[:-1].copy(), float(y[-1]), _sorted_eig(aux), self.region,
                                iterations, residual)

    def tests(self, eq: EquilibriumPoint) -> dict[str, float]:
        lam = eq.eigenvalues
        pairs = [lam[i] + lam[j] for i in range(len(lam)) for j in range(i + 1, len(lam))]
        s = self.system(eq.p)
        return {"fold": float(np.prod(lam).real),
                "hopf": float(np.prod(pairs).real) if pairs else 1.0,
                "boundary_equilibrium": (_slack(s, self.region, eq.x)
                                         if not isinstance(s, _SmoothField) else 1.0)}

    def point(self, y_pred: FloatArray, t: FloatArray) -> Point:
        y, eq = self.correct(y_pred, t)
        return Point(y, eq, self.tests(eq))


def _genuine_hopf(eq: EquilibriumPoint, tol: float) -> bool:
    """A complex pair on the imaginary axis (not a neutral saddle ``±κ``)."""
    lam = eq.eigenvalues
    scale = max(1.0, float(np.max(np.abs(lam))))
    return bool(np.any((np.abs(lam.imag) > tol * scale) & (np.abs(lam.real) <= tol * scale)))


def _start(prob: _EquilibriumProblem, p0: float, x0: FloatArray) -> None:
    """PWA: pick the region of the admissible equilibrium nearest ``x0`` (each region's
    affine equilibrium solved exactly); smooth fields need nothing."""
    s = prob.system(p0)
    if isinstance(s, _SmoothField):
        return
    best, where = np.inf, -1
    for r in range(s.n_regions):
        prob.region = r
        try:
            xr = np.linalg.solve(s.A[r], -prob.value(np.zeros(prob.n), p0))
        except np.linalg.LinAlgError:
            continue
        if s.contains(r, xr) and np.linalg.norm(xr - x0) < best:
            best, where = float(np.linalg.norm(xr - x0)), r
    if where < 0:
        raise SolverError(f"x0: no region of the PWA system at p = {p0:g} has an admissible "
                          f"equilibrium (a singular A_r has none isolated)")
    prob.region = where


def _region_across(system: Any, region: int, x: FloatArray, d: FloatArray) -> int:
    """The region entered from the facet point ``x`` moving along ``d`` or ``-d`` (the
    continuation may turn back in ``p``: a non-smooth fold); ``-1`` when none."""
    step = 1e-7 * max(1.0, float(np.linalg.norm(x)))
    for sign in (1.0, -1.0):
        probe = x + sign * step * d / max(float(np.linalg.norm(d)), 1e-300)
        for r in range(system.n_regions):
            if r != region and system.contains(r, probe, tol=0.0):
                return r
    return -1


def _into_region(system: Any, region: int, x: FloatArray, t: FloatArray) -> FloatArray:
    """Orient the tangent so that its state part enters ``region`` (the slack of the facet
    rows active at ``x`` grows)."""
    H, h = system.regions[region]
    slack = (h - H @ x) / np.linalg.norm(H, axis=1)
    active = np.argsort(slack)[:1]
    rate = -(H[active] @ t[:-1])
    return t if float(np.min(rate)) >= 0.0 else -t


def continue_equilibrium(factory: Callable[[float], Any], p0: float, x0: Any, *,
                         p_range: tuple[float, float], step: float = 0.01,
                         step_min: float = 1e-8, step_max: float = 0.1, max_steps: int = 500,
                         direction: int = 1, tol: float = 1e-12, locate_tol: float = 1e-12,
                         detect: tuple[str, ...] = ("fold", "hopf", "boundary_equilibrium"),
                         stop_at: tuple[str, ...] = (), parameter_name: str = "p",
                         state_names: tuple[str, ...] = (),
                         corrector_max_iter: int = CORRECTOR_MAX_ITER,
                         locate_max_iter: int = LOCATE_MAX_ITER) -> Branch:
    """Continue the equilibrium near ``x0`` at ``p0`` in the parameter ``p``.

    Parameters
    ----------
    factory
        ``p -> system``: a :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` (no input
        or a constant one), a :class:`~nscontrol.systems.NonlinearSystem` or a callable ``x -> ẋ``.
    p0, x0
        Start: parameter and a guess of the equilibrium.
    p_range
        Stop when ``p`` leaves ``[lo, hi]``.
    step, step_min, step_max
        Initial, smallest and largest arclength steps.
    max_steps
        Largest number of continuation steps.
    direction
        ``+1``: start towards increasing ``p``; ``-1``: decreasing.
    tol
        Corrector tolerance on ``max|F|`` (relative to ``max(1, |x|)``).
    locate_tol
        Relative width (in ``(x, p)``) of the bracket at which a bifurcation counts as
        located; at a fold ``p`` is then known to ``O(locate_tol²)``.
    detect
        Test functions watched: ``"fold"``, ``"hopf"``, ``"boundary_equilibrium"``.
    stop_at
        Kinds after whose location the continuation stops.
    parameter_name, state_names
        Labels kept in the :class:`~nscontrol.analysis.continuation.Branch`.
    corrector_max_iter
        Newton iterations per correction (spent at the start: :class:`BudgetExceededError`;
        on the way the step is halved down to ``step_min``).
    locate_max_iter
        Corrected trial points per location of a bifurcation (spent:
        :class:`BudgetExceededError` with the branch so far in ``err.partial``).

    Returns
    -------
    Branch
        ``solution="equilibrium"``: ``x0`` the states, ``multipliers`` (also
        ``eigenvalues``) the Jacobian's eigenvalues, ``n_impacts`` the PWA region (``-1``
        for a smooth field), ``period`` NaN.

    Raises
    ------
    ModelError
        Bad options (``p0`` outside ``p_range``, ``step_min > step_max``, an unknown name in
        ``detect`` or ``stop_at``...), a factory returning something else, or a PWA system
        with a time-varying input.
    BudgetExceededError
        ``corrector_max_iter`` spent on the starting equilibrium, or ``locate_max_iter``
        spent locating a bifurcation.
    SolverError
        The starting equilibrium cannot be found.

    Examples
    --------
    The fold of ``ẋ = p - x²`` at ``p = 0``, followed from ``x = 1``:

    >>> b = continue_equilibrium(lambda p: (lambda x: p - x**2), 1.0, [1.0],
    ...                          p_range=(-1.0, 2.0), direction=-1, step=0.1, max_steps=60)
    >>> (fold,) = b.special("fold")
    >>> bool(abs(fold.parameter) < 1e-12), bool(b.stable[0]), bool(b.stable[-1])
    (True, True, False)
    """
    kinds = ("fold", "hopf", "boundary_equilibrium")
    opts = check_options(factory, p0, p_range, step=step, step_min=step_min,
                         step_max=step_max, max_steps=max_steps, direction=direction, tol=tol,
                         locate_tol=locate_tol, corrector_max_iter=corrector_max_iter,
                         locate_max_iter=locate_max_iter, detect=detect, stop_at=stop_at,
                         kinds=kinds, stop_kinds=kinds)
    lo, hi, p0, direction = opts.lo, opts.hi, opts.p0, opts.direction
    detect, max_steps, step_min, step_max = opts.detect, opts.max_steps, opts.step_min, \
        opts.step_max
    first = _as_field(factory(float(p0)))
    n = first.n_states if _is_pwa(first) else first.value(np.atleast_1d(
        np.asarray(x0, float))).shape[0]
    x0v = as_vector("x0", x0, n)
    prob = _EquilibriumProblem(factory, n, opts.tol)
    prob.max_iter = opts.corrector_max_iter
    _start(prob, float(p0), x0v)
    t0 = np.zeros(n + 1)
    t0[-1] = float(direction)
    start = prob.point(np.append(x0v, float(p0)), t0)   # the row (0..0, 1) pins p
    t = prob.tangent(start.y, t0)
    pts: list[Point] = [start]
    special: list[SpecialPoint] = []
    last = start            # the point stepped from (after a facet: re-evaluated across it)
    h, n_steps, reason = opts.step, 0, ""
    names = tuple(state_names) or tuple(getattr(first, "state_names", ()) or ())
    while not reason:
        if n_steps >= max_steps:
            reason = (f"max_steps ({max_steps}) reached at p = {last.y[-1]:.9g}; raise "
                      f"max_steps to go on")
            break
        try:
            new = prob.point(last.y + h * t, t)
        except SolverError as exc:
            h /= 2
            if h < step_min:
                reason = (f"step_min: the corrector failed at p ≈ {last.y[-1]:.9g} with "
                          f"every step down to {2 * h:.3g} < 2·step_min = "
                          f"{2 * step_min:.3g}: {exc}")
            continue
        n_steps += 1
        crossed = False
        try:
            located = _located(prob, last, new, t, h, detect, opts.locate_tol,
                               opts.locate_max_iter)
        except BudgetExceededError as exc:      # keep what was computed
            so_far = _branch(pts, special, f"{exc.budget} spent: {exc}", n_steps,
                             prob.iterations, parameter_name, names)
            raise BudgetExceededError(
                f"{exc}; the branch computed so far ({len(so_far)} points) is in "
                f"err.partial", budget=exc.budget, limit=exc.limit, used=exc.used,
                partial=so_far) from exc
        for kind, sp in located:
            pts.append(sp)
            special.append(_special(kind, sp, len(pts) - 1))
            if kind in stop_at:
                reason = f"{kind} at p = {sp.y[-1]:.12g}"
                break
            if kind == "boundary_equilibrium":
                reason, t = _cross_facet(prob, sp, t)
                # the same point in the new region's field: its tests are those it starts from
                last, crossed = prob.point(sp.y, t), True
                break
        if reason or crossed:
            continue            # past a facet the new point was virtual: step again
        pts.append(new)
        last = new
        p_new = float(new.y[-1])
        if not lo <= p_new <= hi:
            reason = f"left p_range [{lo:g}, {hi:g}] at p = {p_new:.9g}"
            break
        t = prob.tangent(new.y, t)
        if new.sol.iterations <= 3:
            h = min(1.5 * h, step_max)
    return _branch(pts, special, reason, n_steps, prob.iterations, parameter_name, names)


def _test_value(kind: str) -> Callable[[Point], float]:
    def value(pt: Point) -> float:
        return pt.tests[kind]

    return value


def _located(prob: _EquilibriumProblem, a: Point, b: Point, t: FloatArray, h: float,
             detect: tuple[str, ...], rtol: float, max_iter: int) -> list[tuple[str, Point]]:
    """The zeros of the test functions that changed sign between ``a`` and ``b``, in branch
    order; nothing past a boundary equilibrium (the branch continues in another region)."""
    found = []
    for kind in detect:
        if a.tests[kind] * b.tests[kind] >= 0.0:
            continue
        sp = locate(prob.point, a, t, h, _test_value(kind), rtol, whole_state=True,
                    max_iter=max_iter)
        if sp is None:
            continue
        if kind == "hopf" and not _genuine_hopf(sp.sol, 1e-6):
            continue
        found.append((float(t @ (sp.y - a.y)), kind, sp))
    found.sort(key=lambda item: item[0])
    out = []
    for _, kind, sp in found:
        out.append((kind, sp))
        if kind == "boundary_equilibrium":
            break
    return out


def _cross_facet(prob: _EquilibriumProblem, sp: Point, t: FloatArray
                 ) -> tuple[str, FloatArray]:
    """Switch the problem to the region across the facet at the boundary equilibrium ``sp``
    and return ``("", new tangent)``, or a stop reason."""
    x, p = sp.y[:-1], float(sp.y[-1])
    s = prob.system(p)
    if not s.continuous:
        return (f"boundary equilibrium at p = {p:.12g}: the field is discontinuous there "
                f"(the branch ends; pseudo-equilibria on the facet are not continued)", t)
    r_new = _region_across(s, prob.region, x, t[:-1])
    if r_new < 0:
        return f"boundary equilibrium at p = {p:.12g}: no region across the facet", t
    prob.region = r_new
    _, J, _ = prob.residual(sp.y)
    try:
        t_new = unit_tangent(J, t)
    except np.linalg.LinAlgError:
        return f"boundary equilibrium at p = {p:.12g}: singular A in region {r_new}", t
    return "", _into_region(s, r_new, x, t_new)


def _special(kind: str, pt: Point, index: int) -> SpecialPoint:
    eq = pt.sol
    return SpecialPoint(kind, eq.p, index, eq.x[None, :].copy(), eq.eigenvalues.copy(),
                        float(pt.tests.get("_width", 0.0)))


def _branch(pts: list[Point], special: list[SpecialPoint], reason: str, n_steps: int,
            iterations: int, name: str, state_names: tuple[str, ...]) -> Branch:
    eqs = [pt.sol for pt in pts]
    return Branch(name, np.array([e.p for e in eqs]), np.array([e.x[None, :] for e in eqs]),
                  np.full(len(eqs), np.nan), np.array([e.eigenvalues for e in eqs]),
                  np.array([e.stable for e in eqs]), np.array([e.region for e in eqs]),
                  tuple(special), reason, n_steps, iterations, state_names, "equilibrium")
