"""Smooth autonomous systems whose limit cycles are known: exactly, or as series in a small
parameter.

* :func:`polar_normal_form` — ``r' = r g(r)``, ``θ' = ω`` in Cartesian coordinates, ``g`` a
  polynomial: a cycle at every positive root ``r*`` of ``g``, of period ``2π/ω`` exactly and
  non-trivial multiplier ``exp(2π r* g'(r*)/ω)`` (the radial equation linearised at ``r*``,
  ``δr' = r* g'(r*) δr``, over one period; the angle does not depend on ``r``, so nothing
  else enters). ``g(r) = (1 - r)(2 - r)``: cycles ``r = 1`` (``exp(-2π/ω)``, stable) and
  ``r = 2`` (``exp(4π/ω)``, unstable).
* :func:`hopf_normal_form` — ``g(r) = μ - r²``: the cycle ``r = √μ`` with multiplier
  ``exp(-4πμ/ω)``, born at ``μ = 0``.
* :func:`van_der_pol` — ``x'' - ε(1 - x²)x' + x = 0`` and :func:`van_der_pol_series`, the
  Poincaré–Lindstedt series of its cycle (below).

Van der Pol's cycle for small ``ε``
-----------------------------------
With ``τ = Ωt``, ``Ω = 1 - ε²/16 + O(ε⁴)``, the cycle through its maximum at ``τ = 0`` is
``x = 2 cos τ + ε(3/4 sin τ - 1/4 sin 3τ) + ε²(-1/8 cos τ + 3/16 cos 3τ - 5/96 cos 5τ) + O(ε³)``.
Hence:

* period ``T = 2π(1 + ε²/16 - 5ε⁴/3072 + O(ε⁶))``;
* amplitude ``x_max = 2 + ε²/96 + O(ε⁴)`` (the ``ε⁴`` coefficient is ``-1033/552960``);
* multiplier: for a planar cycle the non-trivial multiplier is ``det M = exp(∮ div f dt)``
  (Liouville), ``div f = ε(1 - x²)``. Over one period ``∫(1 - x²) dτ = -2π - (π/8)ε² +
  O(ε⁴)`` (the ``ε`` term vanishes: ``∫ cos τ · x₁ dτ = 0``), so with ``dt = dτ/Ω``
  ``ln μ = -2πε - (π/4)ε³ + O(ε⁵)``. Averaging gives the leading term ``exp(-2πε)``; the
  relative error of that approximation is ``ε²/8 + O(ε⁴)``. ``ln μ`` is odd in ``ε`` (time
  reversal maps ``ε`` to ``-ε`` and the cycle to itself with the inverse multiplier), so
  the remainders skip a power.

References: A.H. Nayfeh, *Perturbation methods*, 1973, §3.1 (Lindstedt–Poincaré for Van der
Pol); C.M. Andersen and J.F. Geer, SIAM J. Appl. Math. 42 (1982) 678–693 (the period and
amplitude series to high order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_real_scalar, as_vector, check_positive
from ..errors import ModelError
from ..systems.nonlinear import NonlinearSystem

__all__ = ["KnownCycle", "polar_normal_form", "hopf_normal_form", "van_der_pol",
           "van_der_pol_series"]


@dataclass(frozen=True, eq=False)
class KnownCycle:
    """A limit cycle known in closed form.

    Attributes
    ----------
    x0
        The point of the cycle on the phase-condition hyperplane ``normal·x = offset``.
    period
        Its period.
    multiplier
        Its non-trivial Floquet multiplier (planar systems have one).
    normal, offset
        A hyperplane the cycle crosses transversally at ``x0``.
    """

    x0: FloatArray
    period: float
    multiplier: float
    normal: FloatArray
    offset: float = 0.0


class _Horner:
    """A polynomial of one real variable, coefficients lowest degree first."""

    def __init__(self, coefficients: list[float]) -> None:
        self.reversed = coefficients[::-1]

    def __call__(self, r: float) -> float:
        value = 0.0
        for c in self.reversed:
            value = value * r + c
        return value


class _PolarField:
    """``x' = g(r) x - ω y``, ``y' = g(r) y + ω x`` (``r' = r g(r)``, ``θ' = ω``) and its
    Jacobian; a module-level class, so the systems pickle."""

    def __init__(self, coefficients: FloatArray, omega: float) -> None:
        # Plain floats evaluated by Horner's rule, in numpy's polyval order: the same values
        # as np.polynomial.Polynomial at a fraction of its per-call cost (an integrator calls
        # the field hundreds of thousands of times in a sweep).
        c = [float(v) for v in coefficients]
        self.polynomial = np.polynomial.Polynomial(c)     # its roots: the cycles' radii
        self.g = _Horner(c)
        self.dg = _Horner([k * c[k] for k in range(1, len(c))] or [0.0])
        self.omega = omega

    def __call__(self, t: float, x: FloatArray) -> FloatArray:
        g = self.g(np.hypot(x[0], x[1]))
        return np.array([g * x[0] - self.omega * x[1], g * x[1] + self.omega * x[0]])

    def jacobian(self, t: float, x: FloatArray) -> FloatArray:
        r = float(np.hypot(x[0], x[1]))
        g = self.g(r)
        k = self.dg(r) / r if r > 0.0 else 0.0    # ∂g/∂x = g'(r) x/r
        return np.array([[g + k * x[0] ** 2, k * x[0] * x[1] - self.omega],
                         [k * x[0] * x[1] + self.omega, g + k * x[1] ** 2]])


def polar_normal_form(radial: ArrayLike = (2.0, -3.0, 1.0), omega: float = 4.0
                      ) -> tuple[NonlinearSystem, tuple[KnownCycle, ...]]:
    """``r' = r g(r)``, ``θ' = ω`` in Cartesian coordinates and its cycles.

    Parameters
    ----------
    radial : array_like
        Coefficients of the polynomial ``g``, lowest degree first (default
        ``2 - 3r + r² = (1 - r)(2 - r)``).
    omega : float
        Angular velocity ``ω > 0``.

    Returns
    -------
    system : NonlinearSystem
        States ``(x, y)``, with the exact Jacobian.
    cycles : tuple of KnownCycle
        One per simple positive root ``r*`` of ``g``, by increasing radius: ``x0 = (r*, 0)``
        on the section ``y = 0``, period ``2π/ω``, multiplier ``exp(2π r* g'(r*)/ω)``.

    Raises
    ------
    ModelError
        ``radial`` is not a real, finite coefficient vector.
    """
    coef = as_vector("radial", radial)
    w = check_positive("omega", omega)
    field = _PolarField(coef, w)
    system = NonlinearSystem(2, field, field.jacobian, state_names=("x", "y"))
    roots = np.asarray(field.polynomial.roots(), complex)
    real = roots.real[np.abs(roots.imag) <= 1e-12 * (1.0 + np.abs(roots))]
    radii = sorted(float(r) for r in real if r > 0.0 and field.dg(r) != 0.0)
    cycles = tuple(KnownCycle(np.array([r, 0.0]), 2 * np.pi / w,
                              float(np.exp(2 * np.pi * r * field.dg(r) / w)),
                              np.array([0.0, 1.0])) for r in radii)
    return system, cycles


def hopf_normal_form(mu: float, omega: float = 1.0
                     ) -> tuple[NonlinearSystem, KnownCycle]:
    """The Hopf normal form ``r' = r(μ - r²)``, ``θ' = ω`` and its cycle ``r = √μ``.

    Parameters
    ----------
    mu : float
        The bifurcation parameter (``> 0``: the cycle exists).
    omega : float
        Angular velocity.

    Returns
    -------
    system : NonlinearSystem
    cycle : KnownCycle
        ``x0 = (√μ, 0)``, period ``2π/ω``, multiplier ``exp(-4πμ/ω)``.

    Raises
    ------
    ModelError
        ``mu <= 0`` (no cycle).
    """
    m = as_real_scalar("mu", mu)
    if not m > 0.0:
        raise ModelError(f"mu: the cycle exists for mu > 0, got {m}")
    system, (cycle,) = polar_normal_form((m, 0.0, -1.0), omega)
    return system, cycle


class _VanDerPol:
    """``x' = v``, ``v' = -x + ε(1 - x²)v`` and its Jacobian (picklable)."""

    def __init__(self, eps: float) -> None:
        self.eps = eps

    def __call__(self, t: float, x: FloatArray) -> FloatArray:
        return np.array([x[1], -x[0] + self.eps * (1.0 - x[0] ** 2) * x[1]])

    def jacobian(self, t: float, x: FloatArray) -> FloatArray:
        e = self.eps
        return np.array([[0.0, 1.0], [-1.0 - 2.0 * e * x[0] * x[1], e * (1.0 - x[0] ** 2)]])


def van_der_pol(eps: float) -> NonlinearSystem:
    """Van der Pol's oscillator ``x'' - ε(1 - x²)x' + x = 0`` as ``(x, v)``.

    Parameters
    ----------
    eps : float
        ``ε > 0``.

    Returns
    -------
    NonlinearSystem
        With the exact Jacobian; its cycle crosses ``v = 0`` downwards at its maximum
        ``x_max`` (the section of :func:`van_der_pol_series`).
    """
    field = _VanDerPol(check_positive("eps", eps))
    return NonlinearSystem(2, field, field.jacobian, state_names=("x", "v"))


def van_der_pol_series(eps: float) -> dict[str, float]:
    """The Poincaré–Lindstedt series of Van der Pol's cycle (module docstring).

    Parameters
    ----------
    eps : float
        ``ε > 0`` (small).

    Returns
    -------
    dict
        ``period`` ``2π(1 + ε²/16 - 5ε⁴/3072)`` (remainder ``O(ε⁶)``), ``amplitude``
        ``2 + ε²/96`` (``O(ε⁴)``), ``log_multiplier`` ``-2πε - (π/4)ε³`` (``O(ε⁵)``) and
        ``averaging_multiplier`` ``exp(-2πε)``, the first-order (averaging) value.
    """
    e = check_positive("eps", eps)
    return {"period": 2 * np.pi * (1 + e ** 2 / 16 - 5 * e ** 4 / 3072),
            "amplitude": 2 + e ** 2 / 96,
            "log_multiplier": -2 * np.pi * e - np.pi / 4 * e ** 3,
            "averaging_multiplier": float(np.exp(-2 * np.pi * e))}
