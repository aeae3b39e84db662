"""The one pseudo-arclength engine: corrector, tangent and location of a test function's zero.

A continuation problem is a map ``G: R^{m+1} -> R^m`` of ``y = (unknowns, p)`` whose zero set
is the branch. :class:`ArclengthProblem` owns what every problem shares — Newton on
``G(y) = 0, t·(y - y_pred) = 0`` (the pseudo-arclength condition), the unit tangent
``[G_y; t_prevᵀ] t = [0; 1]`` and the iteration count — and a subclass says only how ``G``,
its Jacobian and the solution record are computed. :func:`locate` finds the zero of a test
function along the arclength, each trial point corrected onto the branch.

Periodic orbits (:mod:`~nscontrol.analysis.continuation`) and equilibria
(:mod:`~nscontrol.analysis.equilibria`) are the two clients.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_interval,
    check_integer,
    check_names,
    check_positive,
)
from ..errors import BudgetExceededError, InadmissibleStateError, ModelError, SolverError

#: Default budgets of a continuation: Newton iterations per correction, corrected trial
#: points per location of a test function's zero.
CORRECTOR_MAX_ITER = 8
LOCATE_MAX_ITER = 100


@dataclass(frozen=True)
class Options:
    """The checked options of a continuation (:func:`check_options`)."""

    p0: float
    lo: float
    hi: float
    step: float
    step_min: float
    step_max: float
    max_steps: int
    direction: int
    tol: float
    locate_tol: float
    corrector_max_iter: int
    locate_max_iter: int
    detect: tuple[str, ...]
    stop_at: tuple[str, ...]


def check_options(factory: Any, p0: Any, p_range: Any, *, step: Any, step_min: Any,
                  step_max: Any, max_steps: Any, direction: Any, tol: Any, locate_tol: Any,
                  corrector_max_iter: Any, locate_max_iter: Any, detect: Any, stop_at: Any,
                  kinds: tuple[str, ...], stop_kinds: tuple[str, ...]) -> Options:
    """Every option of a continuation checked before anything is computed (one place for
    orbits and equilibria): ``p_range`` an increasing pair holding ``p0``, steps positive
    with ``step_min <= step_max``, budgets whole numbers, ``detect`` among ``kinds`` and
    ``stop_at`` among ``stop_kinds`` (a misspelt name would silently watch nothing)."""
    if not callable(factory):
        raise ModelError(f"factory: expected a callable p -> problem, got "
                         f"{type(factory).__name__}")
    p = as_finite_scalar("p0", p0)
    lo, hi = as_interval("p_range", p_range)
    if not lo <= p <= hi:
        raise ModelError(f"p0: expected a value in p_range [{lo:g}, {hi:g}], got {p:g}; start "
                         f"inside the range or widen it")
    h, h_min, h_max = (check_positive(name, v) for name, v in
                       (("step", step), ("step_min", step_min), ("step_max", step_max)))
    if h_min > h_max:
        raise ModelError(f"step_min: expected step_min <= step_max, got step_min = {h_min:g} > "
                         f"step_max = {h_max:g}")
    if isinstance(direction, bool) or direction not in (1, -1):
        raise ModelError(f"direction: expected +1 or -1, got {direction!r}")
    return Options(p, lo, hi, h, h_min, h_max, check_integer("max_steps", max_steps, minimum=0),
                   int(direction), check_positive("tol", tol),
                   check_positive("locate_tol", locate_tol),
                   check_integer("corrector_max_iter", corrector_max_iter, minimum=1),
                   check_integer("locate_max_iter", locate_max_iter, minimum=1),
                   check_names("detect", detect, kinds), check_names("stop_at", stop_at,
                                                                     stop_kinds))


def parameter_derivative(G: Callable[[float], FloatArray], p: float) -> FloatArray:
    """``∂G/∂p`` by a central difference with step ``ε^{1/3}·max(1, |p|)`` (truncation
    ``O(δ²)`` against rounding ``O(ε/δ)``; exact up to rounding when ``p`` enters affinely)."""
    dp = float(np.finfo(float).eps) ** (1 / 3) * max(1.0, abs(p))
    return (G(p + dp) - G(p - dp)) / (2 * dp)


class FactoryMemo:
    """``factory(p)`` remembered for the last few parameter values: the corrector and the
    central difference in ``p`` ask for the same few ``p`` again and again, and a factory may
    build matrices or exponentials. ``convert`` checks or adapts what the factory returns."""

    def __init__(self, factory: Callable[[float], Any],
                 convert: Callable[[Any, float], Any], size: int = 16) -> None:
        self.factory, self.convert, self.size = factory, convert, size
        self._memo: dict[float, Any] = {}

    def __call__(self, p: float) -> Any:
        hit = self._memo.get(p)
        if hit is None:
            if len(self._memo) > self.size:
                self._memo.clear()
            hit = self._memo[p] = self.convert(self.factory(p), p)
        return hit


@dataclass
class Point:
    """A corrected branch point: ``y``, the problem's solution record and its test values."""

    y: FloatArray
    sol: Any
    tests: dict[str, float]


class ArclengthProblem:
    """``G(y) = 0`` with the shared corrector and tangent.

    Subclasses implement :meth:`residual` (``G``, ``[G_x, G_p]`` and whatever the solution
    record needs), :meth:`solution` (the record of a converged point) and :meth:`scale` (the
    size the tolerance is relative to). ``tol`` is the corrector tolerance on ``max|G|``.
    """

    tol: float
    iterations: int
    #: Newton iterations per correction (the ``corrector_max_iter`` option).
    max_iter: int = CORRECTOR_MAX_ITER

    def residual(self, y: FloatArray, G_p: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray, Any]:
        """``G(y)``, ``[G_x, G_p]`` (``G_p`` reused when given) and auxiliary data."""
        raise NotImplementedError

    def solution(self, y: FloatArray, aux: Any, iterations: int, residual: float) -> Any:
        """The solution record of a converged ``y``."""
        raise NotImplementedError

    def scale(self, y: FloatArray) -> float:
        """``max(1, max|x|)``: the corrector tolerance is relative to it."""
        return max(1.0, float(np.max(np.abs(y[:-1])))) if y.size > 1 else 1.0

    def correct(self, y_pred: FloatArray, t: FloatArray, max_iter: int | None = None,
                G_p: FloatArray | None = None, *, start: bool = False) -> tuple[FloatArray, Any]:
        """Newton on ``G = 0``, ``t·(y - y_pred) = 0`` from ``y_pred``; ``SolverError`` when it
        fails, :class:`BudgetExceededError` (``budget="corrector_max_iter"``, the last
        iterate in ``partial``) when ``max_iter`` (default :attr:`max_iter`) iterations did
        not converge. ``G_p`` is evaluated once per correction (a chord in the ``p`` column only:
        it is the costly column for shooting problems and changes little over a step); a
        given ``G_p`` is used instead (with ``t = (0, ..., 0, 1)``, ``p`` is pinned and the
        column does not matter: pass zeros).

        An iterate the model refuses (:class:`InadmissibleStateError`: a predicted node that
        penetrates a contact) is a failed correction, a ``SolverError`` naming the iterate,
        so that the step is halved; only with ``start`` (``y_pred`` is the user's start) is
        the refusal of iterate 0 passed on as it is."""
        max_iter = self.max_iter if max_iter is None else max_iter
        y = y_pred.copy()
        res = np.inf
        for it in range(max_iter + 1):
            try:
                R, J, aux = self.residual(y, G_p)
            except InadmissibleStateError as exc:
                if start and it == 0:
                    raise
                cause = str(exc).removeprefix("x0: ")
                raise SolverError(f"the corrector's iterate {it} at p = {y[-1]:.9g} left the "
                                  f"admissible set: {cause}") from exc
            G_p = J[:, -1]
            res = float(np.max(np.abs(R))) if R.size else 0.0
            if res <= self.tol * self.scale(y):
                return y, self.solution(y, aux, it, res)
            if it == max_iter:
                break
            A = np.vstack([J, t])
            b = -np.concatenate([R, [t @ (y - y_pred)]])
            try:
                y = y + np.linalg.solve(A, b)
            except np.linalg.LinAlgError as exc:
                raise SolverError(f"singular extended Jacobian at p = {y[-1]:.9g}") from exc
            self.iterations += 1
        raise BudgetExceededError(
            f"corrector_max_iter: the corrector did not converge in {max_iter} iterations at "
            f"p = {y[-1]:.9g} (residual {res:.3g} > tol = {self.tol:g}); raise "
            f"corrector_max_iter, or start closer to the branch", budget="corrector_max_iter",
            limit=max_iter, used=max_iter, partial=y.copy())

    def tangent(self, y: FloatArray, t_prev: FloatArray) -> FloatArray:
        """Unit tangent at ``y`` oriented like ``t_prev`` (``t_prev·t = 1 > 0`` before
        normalisation, so a fold is passed without turning back), from a fresh Jacobian
        (the correction's chord in ``p`` is not accurate enough for a tangent near a
        grazing, where ``∂G/∂p`` varies fast)."""
        _, J, _ = self.residual(y)
        return unit_tangent(J, t_prev)


def unit_tangent(J: FloatArray, t_prev: FloatArray) -> FloatArray:
    """Solve ``[J; t_prevᵀ] t = [0; 1]`` and normalise.

    Parameters
    ----------
    J : (m, m+1) ndarray
        ``[G_x, G_p]`` at the point.
    t_prev : (m+1,) ndarray
        The previous tangent (orientation).
    """
    A = np.vstack([J, t_prev])
    b = np.zeros(A.shape[0])
    b[-1] = 1.0
    t = np.linalg.solve(A, b)
    return t / np.linalg.norm(t)


def locate(correct: Callable[[FloatArray, FloatArray], Point], a: Point, t: FloatArray,
           h: float, value: Callable[[Point], float], rtol: float,
           s_first: float | None = None, closest: bool = True,
           whole_state: bool = False, max_iter: int = LOCATE_MAX_ITER) -> Point | None:
    """Zero of ``value`` along the arclength from ``a`` (``s`` in ``(0, 2h)``).

    Secant steps while no sign change is bracketed, Illinois regula falsi once one is: an end
    of the bracket kept twice in a row has its value halved. The far end always; the near
    end (on ``a``'s side) only for a smooth test function (``closest``: plain regula falsi
    on a convex one would keep it for good, and the bracket would never narrow), not for a
    grazing, whose one-sided approach from the impacting side is what converges. A trial
    whose corrector fails (past a grazing the map is not smooth) counts as beyond the zero;
    from then on the near end is not halved either (the failures may lie on either side of
    the zero). Stops when the bracket is ``rtol`` (relative) wide: in the parameter, or with
    ``whole_state`` in ``|y|`` — at a fold the parameter is stationary along the branch, so a
    narrow parameter bracket says nothing about the state.

    Parameters
    ----------
    correct
        ``(y_pred, t) -> Point``: the corrector.
    a
        The last branch point before the sign change.
    t
        The tangent at ``a``.
    h
        The step that produced the sign change.
    value
        The test function of a corrected point.
    rtol
        Relative width of the parameter bracket at which the zero counts as located.
    s_first
        First trial arclength (default ``h``).
    closest
        Return whichever bracket end has the smaller ``|value|`` (``False``: always the end
        on ``a``'s side, as for a grazing, whose far side belongs to another map).
    whole_state
        Measure the bracket in ``y = (state, p)`` instead of ``p`` alone.
    max_iter
        Corrected trial points at most (the ``locate_max_iter`` option).

    Returns
    -------
    Point or None
        ``None`` when no bracket can be formed (the sign change was not confirmed by a
        corrected point).

    Raises
    ------
    BudgetExceededError
        ``max_iter`` trials spent before the bracket was ``rtol`` wide
        (``budget="locate_max_iter"``; the best end of the bracket in ``partial``).
    """
    f_a = value(a)
    good = [(0.0, f_a, a)]                        # (s, f, point), same sign as at a
    other: tuple[float, float, Point] | None = None
    w_good = w_other = 1.0                        # Illinois weights of the bracket's ends
    last = 0                                      # side of the last trial: +1 a's, -1 other
    failed = False                                # a trial's corrector failed
    s_bad = 2.0 * h                               # smallest s known to fail or overshoot
    s = h if s_first is None else float(s_first)
    width = np.inf

    def dist(u: Point, v: Point) -> float:
        return float(np.max(np.abs(u.y - v.y)) if whole_state else abs(u.y[-1] - v.y[-1]))

    def size(u: Point) -> float:
        return max(1.0, float(np.max(np.abs(u.y)) if whole_state else abs(u.y[-1])))

    for _ in range(max_iter):
        s = min(max(s, 0.0), s_bad)
        pt: Point | None
        try:
            pt = correct(a.y + s * t, t)
            f = value(pt)
        except SolverError:
            pt, f = None, np.nan
        if pt is None:
            s_bad, failed = s, True
            s = 0.5 * (good[-1][0] + s)
        elif f == 0.0:
            good.append((s, f, pt))
            width = 0.0
        elif f * f_a > 0:
            width = dist(pt, other[2] if other is not None else good[-1][2])
            good.append((s, f, pt))
            w_good = 1.0
            if other is not None and last == 1:
                w_other /= 2   # Illinois: the end kept twice in a row counts half
            last = 1
        else:
            width = dist(pt, good[-1][2])
            other = (s, f, pt)
            w_other = 1.0
            if last == -1 and closest and not failed:
                w_good /= 2
            last = -1
            s_bad = s
        if width <= rtol * size(good[-1][2]):
            break
        if pt is None:
            continue
        if other is None and len(good) < 2:
            return None
        s0, f0 = good[-1][0], w_good * good[-1][1]
        s1, f1 = ((other[0], w_other * other[1]) if other is not None
                  else (good[-2][0], good[-2][1]))
        s_next = s1 - f1 * (s1 - s0) / (f1 - f0) if f1 != f0 else 0.5 * (s0 + s1)
        if other is not None and not min(s0, s1) < s_next < max(s0, s1):
            s_next = 0.5 * (s0 + s1)
        s = s_next if s_next < s_bad else 0.5 * (good[-1][0] + s_bad)
    else:
        raise BudgetExceededError(
            f"locate_max_iter: the zero was not located in {max_iter} corrected trial points "
            f"(bracket {width:.3g} wide in {'(x, p)' if whole_state else 'p'} at p = "
            f"{good[-1][2].y[-1]:.12g}, against locate_tol = {rtol:g} relative); raise "
            f"locate_max_iter or locate_tol", budget="locate_max_iter", limit=max_iter,
            used=max_iter, partial=good[-1][2])
    best = good[-1][2]
    if closest and other is not None and abs(other[1]) < abs(good[-1][1]):
        best = other[2]
    best.tests["_width"] = float(width)
    return best
