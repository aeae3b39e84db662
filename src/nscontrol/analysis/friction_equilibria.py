"""What friction compensation with a reduced-order observer predicts (chapter 7).

For the loop of :mod:`nscontrol.design.friction_compensation` (PD gains ``k_p, k_d``,
observer gain ``l``, inertia ``J``, plant friction ``F`` with static level ``T_s``, slope
constants ``sigma_tan >= sigma_sec``, compensation model ``f_hat``), in the coordinates
``x1 = theta - r``, ``x2 = omega_hat - r'``, ``e = omega - omega_hat``::

    x1' = x2 + e,   J x2' = -k_p x1 - k_d x2 + J l e,   J e' = -J l e + Delta,
    Delta in T_hat(omega_hat) - F(omega)

* **Exact compensation** (``T_hat = F``): ``J l > sigma_tan`` makes the set-point globally
  exponentially stable, with ``|e(t)| <= |e(0)| exp(-(l - sigma_tan/J) t)``
  (:func:`exact_compensation_condition`, :func:`observer_error_bound`).
* **Stuck equilibria** (``omega = 0``, ``x1 = c``): they exist iff
  ``g(|c|) = k_p |c| J l/(J l + k_d) + f_hat(k_p |c|/(J l + k_d)) <= T_s``, with the biased
  estimate ``omega_hat* = -k_p c/(J l + k_d)`` (:func:`stick_equilibria`,
  :func:`equilibrium_halfwidth` for the interval around the set-point under
  undercompensation). With exact compensation a stuck point off the set-point exists iff
  ``J l <= sigma_sec``: ``J l > sigma_sec`` is necessary, ``J l > sigma_tan`` sufficient.
* **Lur'e form** (:func:`closed_loop_lure_form`): ``F = F_m - sigma I`` puts the loop in the
  chapter-8 form, whose passivity LMI is feasible iff ``J l > sigma``
  (:func:`lure_form_certificate`).

These statements are our derivation (consistent with the published abstract: exact
compensation is globally exponentially stable under gain conditions, undercompensation gives
an equilibrium set, overcompensation limit cycles); the paper's own criterion could not be read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, check_positive
from ..errors import InfeasibleDesignError, ModelError

__all__ = ["ExactCompensationCondition", "exact_compensation_condition",
           "observer_error_bound", "stick_margin", "stick_equilibria",
           "equilibrium_halfwidth", "LureForm", "closed_loop_lure_form",
           "lure_form_certificate", "limit_cycle_summary"]


def _slopes(friction: Any) -> tuple[float, float, float]:
    """``(T_s, sigma_tan, sigma_sec)`` of a one-component friction law."""
    try:
        ts = float(np.asarray(friction.static).reshape(-1)[0])
        st = float(np.asarray(friction.sigma_tan).reshape(-1)[0])
        ss = float(np.asarray(friction.sigma_sec).reshape(-1)[0])
    except AttributeError:
        raise ModelError(f"friction: expected a Stribeck law, got {friction!r}") from None
    return ts, st, ss


@dataclass(frozen=True)
class ExactCompensationCondition:
    """Theorem A and its necessary counterpart for exact compensation.

    Attributes
    ----------
    J_l
        ``J l``.
    sigma_tan, sigma_sec
        The friction curve's slope constants.
    sufficient
        ``J l > sigma_tan``: the set-point is globally exponentially stable.
    necessary
        ``J l > sigma_sec``: otherwise a stuck equilibrium off the set-point exists.
    error_rate
        ``l - sigma_tan / J``: the proven decay rate of the estimation error.
    """

    J_l: float
    sigma_tan: float
    sigma_sec: float
    sufficient: bool
    necessary: bool
    error_rate: float


def exact_compensation_condition(J: float, l: float, friction: Any
                                 ) -> ExactCompensationCondition:
    """Check ``J l > sigma_tan`` (sufficient) and ``J l > sigma_sec`` (necessary).

    Parameters
    ----------
    J
        Inertia ``> 0``.
    l
        Observer gain ``> 0``.
    friction
        The plant's Stribeck law.

    Returns
    -------
    ExactCompensationCondition

    Examples
    --------
    >>> from nscontrol.laws import Stribeck
    >>> c = exact_compensation_condition(0.05, 150.0, Stribeck(0.4, 0.2, 0.05, 2.0, 0.02))
    >>> c.sufficient, c.necessary, round(c.error_rate, 2)
    (True, True, 81.78)
    """
    J, l = check_positive("J", J), check_positive("l", l)
    _, st, ss = _slopes(friction)
    return ExactCompensationCondition(J_l=J * l, sigma_tan=st, sigma_sec=ss,
                                      sufficient=J * l > st, necessary=J * l > ss,
                                      error_rate=l - st / J)


def observer_error_bound(t: ArrayLike, e0: float, J: float, l: float, friction: Any, *,
                         h: float = 0.0) -> FloatArray:
    """``|e0| exp(-(l - sigma_tan/J) t) + 4 h T_s / J`` (Theorem A plus the sampling slack).

    The slack covers the zero-order hold: each zero crossing of ``omega_hat`` switches the
    compensation one step late, a kick of about ``2 h T_s / J`` to ``e``.

    Parameters
    ----------
    t
        Times since the start.
    e0
        Initial estimation error ``omega(0) - omega_hat(0)``.
    J, l
        Inertia and observer gain (``J l > sigma_tan`` required).
    friction
        The plant's Stribeck law.
    h
        Control period (0: the continuous-time bound).

    Returns
    -------
    numpy.ndarray
    """
    cond = exact_compensation_condition(J, l, friction)
    if not cond.sufficient:
        raise ModelError(f"l: the error bound needs J l > sigma_tan, got J l = {cond.J_l:.6g} "
                         f"<= {cond.sigma_tan:.6g}; raise l above {cond.sigma_tan / J:.6g}")
    ts, _, _ = _slopes(friction)
    h = check_positive("h", h, allow_zero=True)
    return abs(e0) * np.exp(-cond.error_rate * np.asarray(t, float)) + 4.0 * h * ts / J


def _magnitude(law: Any, s: FloatArray) -> FloatArray:
    """``f_hat(s)`` (0 when there is no compensation)."""
    if law is None:
        return np.zeros_like(s)
    s = np.atleast_1d(np.asarray(s, float))
    if int(getattr(law, "dim", 0)) == 1:    # one component: the curve broadcasts over s
        return np.asarray(law.magnitude(s), float).reshape(s.shape)
    return np.asarray([float(law.magnitude(v)[0]) for v in s])


def stick_margin(c: ArrayLike, J: float, kp: float, kd: float, l: float, friction: Any,
                 compensation: Any) -> FloatArray:
    """``T_s - g(|c|)``: a stuck equilibrium at ``x1 = c`` exists iff it is ``>= 0``.

    Parameters
    ----------
    c
        Position errors (``c != 0``; at ``c -> 0+`` read ``f_hat(0+) = T_s_hat``).
    J, kp, kd, l
        Inertia, PD gains and observer gain.
    friction
        The plant's Stribeck law (its ``T_s``).
    compensation
        The compensation model (Stribeck) or ``None``.

    Returns
    -------
    numpy.ndarray
    """
    J, kp, kd, l = (check_positive(n, v) for n, v in (("J", J), ("kp", kp), ("kd", kd),
                                                       ("l", l)))
    ts, _, _ = _slopes(friction)
    a = np.abs(np.atleast_1d(np.asarray(c, float)))
    s = kp * a / (J * l + kd)
    g = kp * a * J * l / (J * l + kd) + _magnitude(compensation, s)
    return ts - g


def stick_equilibria(J: float, kp: float, kd: float, l: float, friction: Any,
                     compensation: Any, *, c_max: float | None = None,
                     n_grid: int = 4000) -> list[tuple[float, float]]:
    """The ranges of ``|c| > 0`` where a stuck equilibrium exists (Proposition B).

    Parameters
    ----------
    J, kp, kd, l, friction, compensation
        As in :func:`stick_margin`.
    c_max
        Largest ``|c|`` searched (default: ``2 T_s (J l + k_d)/(k_p J l)``, beyond which
        ``g > T_s`` always).
    n_grid
        Grid points before each boundary is refined by bisection to round-off.

    Returns
    -------
    list of (lo, hi)
        Ranges of ``|c|`` (symmetric: ``-c`` is stuck too); empty when only the set-point.

    Examples
    --------
    >>> from nscontrol.laws import Stribeck
    >>> F = Stribeck(0.4, 0.2, 0.05, 2.0, 0.02)
    >>> stick_equilibria(0.05, 2.0, 0.3, 150.0, F, F)
    []
    >>> len(stick_equilibria(0.05, 2.0, 0.3, 10.0, F, F))
    1
    """
    ts, _, _ = _slopes(friction)
    top = c_max if c_max is not None else 2.0 * ts * (J * l + kd) / (kp * J * l)
    grid = np.linspace(0.0, top, n_grid + 1)[1:]

    def margin(c: float) -> float:
        return float(stick_margin(c, J, kp, kd, l, friction, compensation)[0])

    ok = stick_margin(grid, J, kp, kd, l, friction, compensation) >= 0.0
    ranges = []
    i = 0
    while i < grid.size:
        if not ok[i]:
            i += 1
            continue
        j = i
        while j + 1 < grid.size and ok[j + 1]:
            j += 1
        lo = 0.0 if i == 0 else _boundary(margin, grid[i - 1], grid[i])
        hi = grid[j] if j + 1 == grid.size else _boundary(margin, grid[j + 1], grid[j])
        ranges.append((float(lo), float(hi)))
        i = j + 1
    return ranges


def _boundary(margin: Any, bad: float, good: float) -> float:
    """The point between ``bad`` (margin < 0) and ``good`` (>= 0) where it changes sign."""
    for _ in range(200):
        mid = 0.5 * (bad + good)
        if mid in (bad, good):
            break
        if margin(mid) >= 0.0:
            good = mid
        else:
            bad = mid
    return good


def equilibrium_halfwidth(J: float, kp: float, kd: float, l: float, friction: Any,
                          compensation: Any) -> float:
    """``c_max``: the stuck equilibria around the set-point fill ``|x1| <= c_max``.

    0 when no stuck point accumulates at the set-point (exact compensation with
    ``J l > sigma_sec``, overcompensation). Without compensation
    ``c_max = T_s (J l + k_d)/(k_p J l)``; for a small mismatch
    ``c_max ~ (T_s - T_s_hat)(J l + k_d)/(k_p J l)``.

    Parameters
    ----------
    J, kp, kd, l, friction, compensation
        As in :func:`stick_margin`.

    Returns
    -------
    float

    Examples
    --------
    >>> from nscontrol.laws import Stribeck
    >>> F = Stribeck(0.4, 0.2, 0.05, 2.0, 0.02)
    >>> round(equilibrium_halfwidth(0.05, 2.0, 0.3, 150.0, F, None), 6)   # 0.4 * 7.8 / 15
    0.208
    """
    for lo, hi in stick_equilibria(J, kp, kd, l, friction, compensation):
        if lo == 0.0:
            return hi
    return 0.0


@dataclass(frozen=True)
class LureForm:
    """The closed loop in the Lur'e form of chapter 8: ``X' = A X + G w``, ``z = H X = e``,
    ``w in -phi_t(z)`` with ``phi_t`` maximal monotone, ``X = (x1, x2, e)``.

    Attributes
    ----------
    A, G, H
        ``A = [[0, 1, 1], [-k_p/J, -k_d/J, l], [0, 0, -(l - sigma/J)]]``, ``G = [0, 0, 1/J]^T``,
        ``H = [0, 0, 1]``.
    sigma
        The slope moved into ``A``.
    """

    A: FloatArray
    G: FloatArray
    H: FloatArray
    sigma: float


def closed_loop_lure_form(J: float, kp: float, kd: float, l: float, sigma: float) -> LureForm:
    """The exact-compensation loop as a Lur'e system (module docstring).

    Parameters
    ----------
    J, kp, kd, l
        Inertia, PD gains, observer gain (all ``> 0``).
    sigma
        Slope ``>= sigma_tan`` of the loop transformation ``F = F_m - sigma I``.

    Returns
    -------
    LureForm
    """
    J, kp, kd, l = (check_positive(n, v) for n, v in (("J", J), ("kp", kp), ("kd", kd),
                                                       ("l", l)))
    sigma = check_positive("sigma", sigma, allow_zero=True)
    A = np.array([[0.0, 1.0, 1.0], [-kp / J, -kd / J, l], [0.0, 0.0, -(l - sigma / J)]])
    return LureForm(A=A, G=np.array([[0.0], [0.0], [1.0 / J]]),
                    H=np.array([[0.0, 0.0, 1.0]]), sigma=sigma)


def lure_form_certificate(form: LureForm) -> Any:
    """The chapter-8 passivity LMI ``P > 0``, ``A^T P + P A < 0``, ``P G = H^T`` on the loop.

    Solved by the chapter-8 observer LMI (:func:`nscontrol.design.lure_observer_lmi`, basic
    variant) with no output (``C = 0``, so no injection gain acts): feasible iff ``J l >
    sigma`` for ``k_p, k_d > 0``.

    Parameters
    ----------
    form
        From :func:`closed_loop_lure_form`.

    Returns
    -------
    LureObserverDesign or None
        The re-checked certificate (``P`` in ``.P``), or ``None`` when infeasible.
    """
    from ..design.lure_observer import lure_observer_lmi

    try:
        return lure_observer_lmi(form.A, form.G, form.H, np.zeros((1, 3)), variant="basic")
    except InfeasibleDesignError:
        return None


def limit_cycle_summary(t: ArrayLike, x1: ArrayLike, omega: ArrayLike, *,
                        window: float) -> dict[str, float]:
    """Amplitude, symmetry and period of an oscillation over the last ``window`` seconds.

    Parameters
    ----------
    t, x1, omega
        Times, position error and velocity.
    window
        Length of the final window.

    Returns
    -------
    dict
        ``amplitude`` (half the peak-to-peak of ``x1``), ``asymmetry``
        (``|max x1 + min x1| / (max x1 - min x1)``, 0 for a symmetric cycle), ``max_speed``
        and ``period`` (mean time between upward zero crossings of ``omega``; NaN if fewer
        than two).
    """
    t = np.asarray(t, float)
    x1, omega = np.asarray(x1, float), np.asarray(omega, float)
    m = t >= t[-1] - check_positive("window", window)
    hi, lo = float(x1[m].max()), float(x1[m].min())
    span = hi - lo
    up = np.flatnonzero((omega[m][:-1] <= 0.0) & (omega[m][1:] > 0.0))
    period = float(np.mean(np.diff(t[m][up]))) if up.size >= 2 else math.nan
    return {"amplitude": 0.5 * span,
            "asymmetry": abs(hi + lo) / span if span > 0.0 else 0.0,
            "max_speed": float(np.max(np.abs(omega[m]))), "period": period}
