"""Friction laws: Coulomb (a relay of height mu N) and set-valued Stribeck (non-monotone)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray
from ..errors import ModelError
from ._roots import solve_increasing
from .base import LoopTransformation, SetValuedLaw, broadcast_parameter, check_dim
from .relay import Relay

__all__ = ["Coulomb", "Stribeck", "AsymmetricStribeck"]


@dataclass(frozen=True, eq=False, init=False, repr=False)
class Coulomb(Relay):
    """Coulomb friction with a given normal force: ``phi(v) = mu N Sign(v)``.

    A :class:`Relay` of bound ``c = mu * normal_force``; with ``w in -phi(v)`` the friction force
    opposes the sliding velocity ``v`` and lies in ``[-mu N, mu N]`` when sticking.

    Parameters
    ----------
    mu
        Friction coefficients ``>= 0`` (scalar or per contact).
    normal_force
        Normal forces ``N >= 0`` (scalar or per contact).
    dim
        Number of contacts when both are scalars (default 1).
    """

    bound: Any = field(init=False, default=None)     # derived: mu * normal_force
    # Set by the own __init__ below; init fields (dataclasses.replace varies them) whose
    # None defaults only satisfy the field order after Relay's defaulted fields.
    mu: FloatArray = field(default=None)  # type: ignore[arg-type]
    normal_force: FloatArray = field(default=None)  # type: ignore[arg-type]

    def __init__(self, mu: Any, normal_force: Any = 1.0, dim: int | None = None) -> None:
        if dim is not None:
            dim = check_dim(dim)
        else:
            sizes = {np.size(mu), np.size(normal_force)} - {1}
            dim = sizes.pop() if len(sizes) == 1 else (1 if not sizes else None)
            if dim is None:
                raise ModelError(f"mu, normal_force: lengths disagree ({np.size(mu)} vs "
                                 f"{np.size(normal_force)})")
        mu_v = broadcast_parameter("mu", mu, dim)
        n_v = broadcast_parameter("normal_force", normal_force, dim)
        if np.any(~np.isfinite(mu_v)) or np.any(mu_v < 0.0):
            raise ModelError(f"mu: expected finite friction coefficients >= 0, got {mu_v}")
        if np.any(~np.isfinite(n_v)) or np.any(n_v < 0.0):
            raise ModelError(f"normal_force: expected finite normal forces >= 0 (compressive), "
                             f"got {n_v}; a pulling contact has separated and carries no friction")
        object.__setattr__(self, "mu", mu_v)
        object.__setattr__(self, "normal_force", n_v)
        super().__init__(bound=mu_v * n_v)

    def __repr__(self) -> str:
        return f"Coulomb(mu={self.mu.tolist()}, normal_force={self.normal_force.tolist()})"


def _tangent_shape_constant(delta: float) -> float:
    """``sup_x delta x^(delta-1) exp(-x^delta)``: the steepest descent of ``exp(-x^delta)``."""
    if delta < 1.0:
        return np.inf
    if delta == 1.0:
        return 1.0
    k = (delta - 1.0) / delta                      # maximiser satisfies x^delta = k
    return float(delta * k ** k * np.exp(-k))


@functools.lru_cache(maxsize=64)
def _secant_shape_constant(delta: float) -> float:
    """``sup_x (1 - exp(-x^delta)) / x``: the steepest secant from the static level."""
    if delta < 1.0:
        return np.inf
    if delta == 1.0:
        return 1.0                                  # supremum at x -> 0+

    def ratio(x: float) -> float:
        return float(-np.expm1(-x ** delta) / x)

    # coarse log grid, then golden-section refinement around the best node (unimodal there)
    grid = np.logspace(-6, 3, 400)
    i = int(np.argmax([ratio(x) for x in grid]))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    invphi = (np.sqrt(5.0) - 1.0) / 2.0
    while b - a > 1e-13 * b:
        c, d = b - invphi * (b - a), a + invphi * (b - a)
        if ratio(c) >= ratio(d):
            b = d
        else:
            a = c
    return max(ratio(0.5 * (a + b)), ratio(grid[i]))


@dataclass(frozen=True, eq=False)
class Stribeck(SetValuedLaw):
    """Set-valued Stribeck friction ``phi(v) = Sign(v) f(|v|)`` (not monotone in general).

    ``f(s) = T_c + (T_s - T_c) exp(-(s / omega_s)^delta) + b s`` for ``s >= 0``, and
    ``phi(0) = [-T_s, T_s]`` (the static-friction interval). Componentwise for vectors.

    Parameters
    ----------
    static
        Static level ``T_s >= coulomb``.
    coulomb
        Coulomb (sliding) level ``T_c >= 0``.
    stribeck_velocity
        ``omega_s > 0``.
    delta
        Shape exponent ``> 0`` (2 usual); ``delta < 1`` has an unbounded negative slope at 0+.
    viscous
        Viscous coefficient ``b >= 0``.
    dim
        Number of components when all parameters are scalars.

    Attributes
    ----------
    sigma_tan
        Tangent slope bound ``max(0, sup_s -f'(s))`` per component: ``phi + sigma I`` is
        maximal monotone exactly when ``sigma >= sigma_tan``.
    sigma_sec
        Secant slope bound ``max(0, sup_s (T_s - f(s)) / s)`` (``<= sigma_tan``).
    monotone
        ``True`` only when ``sigma_tan == 0`` everywhere (e.g. ``T_s = T_c``).

    Notes
    -----
    Resolvent: ``z = 0`` when ``|x| <= gamma T_s``, otherwise ``z = sign(x) s`` with
    ``s + gamma f(s) = |x|``, ``0 < s < |x|``; the left side increases strictly (unique root,
    safeguarded Newton) when ``gamma sigma_tan < 1``, which is required (ch07 §3.1: ``h sigma_tan
    < J``). Use :meth:`loop_transformation` for methods needing monotonicity (ch08 §2.6).
    ``graph_residual`` is exact on the vertical segment and the vertical distance on the
    curved branches. No complementarity form.

    Examples
    --------
    >>> law = Stribeck(static=0.3, coulomb=0.1, stribeck_velocity=1.0, delta=2.0, viscous=0.01)
    >>> law.monotone, round(float(law.sigma_tan[0]), 6)
    (False, 0.161553)
    >>> lt = law.loop_transformation()
    >>> lt.monotone_part.monotone
    True
    """

    static: Any
    coulomb: Any
    stribeck_velocity: Any
    delta: Any = 2.0
    viscous: Any = 0.0
    dim: int = field(default=None)  # type: ignore[assignment]  # None: set in __post_init__
    # slope constants, derived in __post_init__
    sigma_tan: FloatArray = field(init=False, repr=False)
    sigma_sec: FloatArray = field(init=False, repr=False)
    componentwise = True

    def __post_init__(self) -> None:
        names = ("static", "coulomb", "stribeck_velocity", "delta", "viscous")
        dim = None if self.dim is None else check_dim(self.dim)
        if dim is None:
            sizes = {int(np.size(getattr(self, n))) for n in names} - {1}
            if len(sizes) > 1:
                raise ModelError(f"Stribeck parameters: lengths disagree ({sorted(sizes)})")
            dim = sizes.pop() if sizes else 1
        vals = {n: broadcast_parameter(n, getattr(self, n), dim) for n in names}
        for n, v in vals.items():
            if np.any(~np.isfinite(v)):
                raise ModelError(f"{n}: expected finite values, got {v}")
        ts, tc, ws, dl, b = (vals[n] for n in names)
        if np.any(tc < 0.0):
            raise ModelError(f"coulomb: expected Coulomb levels T_c >= 0, got {tc}")
        if np.any(ts < tc):
            raise ModelError(f"static: expected static levels T_s >= coulomb T_c, got T_s = {ts},"
                             f" T_c = {tc}")
        if np.any(ws <= 0.0) or np.any(dl <= 0.0):
            raise ModelError(f"stribeck_velocity, delta: expected positive values, got "
                             f"omega_s = {ws}, delta = {dl}")
        if np.any(b < 0.0):
            raise ModelError(f"viscous: expected b >= 0, got {b}")
        for n, v in vals.items():
            object.__setattr__(self, n, v)
        object.__setattr__(self, "dim", dim)
        drop = (ts - tc) / ws
        kt = np.array([_tangent_shape_constant(d) for d in dl])
        ks = np.array([_secant_shape_constant(float(d)) for d in dl])
        with np.errstate(invalid="ignore"):
            raw_tan = np.where(drop > 0.0, drop * kt, 0.0) - b
            raw_sec = np.where(drop > 0.0, drop * ks, 0.0) - b
        # a slope cancelled by a loop transformation leaves rounding noise: treat it as zero
        noise = 1e-12 * (np.where(drop > 0.0, drop * np.minimum(kt, 1e300), 0.0) + b)
        object.__setattr__(self, "sigma_tan", np.where(raw_tan > noise, raw_tan, 0.0))
        object.__setattr__(self, "sigma_sec", np.where(raw_sec > noise, raw_sec, 0.0))
        object.__setattr__(self, "monotone", bool(np.all(self.sigma_tan == 0.0)))

    # -- the curve ------------------------------------------------------------------------
    def magnitude(self, s: Any) -> FloatArray:
        """``f(s)`` for speeds ``s >= 0`` (vector of length ``dim``)."""
        s = np.abs(np.asarray(s, dtype=np.float64))
        return (self.coulomb + (self.static - self.coulomb)
                * np.exp(-(s / self.stribeck_velocity) ** self.delta) + self.viscous * s)

    def _magnitude_slope(self, s: FloatArray) -> FloatArray:
        x = s / self.stribeck_velocity
        with np.errstate(divide="ignore", invalid="ignore"):
            shape = self.delta * x ** (self.delta - 1.0) * np.exp(-x ** self.delta)
        return self.viscous - (self.static - self.coulomb) / self.stribeck_velocity * shape

    def loop_transformation(self, sigma: ArrayLike | None = None) -> LoopTransformation:
        """``phi = phi_m - diag(sigma) I`` with the monotone ``phi_m = phi + sigma I`` (ch08 §2.6).

        Parameters
        ----------
        sigma
            Slopes ``>= sigma_tan`` (default ``sigma_tan``, the smallest that works).

        Returns
        -------
        LoopTransformation
            ``monotone_part`` is a :class:`Stribeck` with viscous term ``b + sigma``.
        """
        sig = self.sigma_tan.copy() if sigma is None else broadcast_parameter("sigma", sigma,
                                                                              self.dim)
        if np.any(~np.isfinite(sig)):
            raise ModelError(f"sigma: no finite loop transformation exists (sigma_tan = "
                             f"{self.sigma_tan}; delta < 1 has an unbounded negative slope)")
        if np.any(sig < self.sigma_tan * (1.0 - 1e-12)):
            raise ModelError(f"sigma: expected sigma >= sigma_tan = {self.sigma_tan} so that "
                             f"phi + sigma I is monotone, got {sig}")
        return LoopTransformation(monotone_part=self._shifted(sig), slope=sig)

    def _shifted(self, sigma: FloatArray) -> Stribeck:
        """``phi + diag(sigma) I``: the same law with viscous term ``b + sigma``."""
        return Stribeck(self.static, self.coulomb, self.stribeck_velocity, self.delta,
                        self.viscous + sigma)

    # -- SetValuedLaw hooks ---------------------------------------------------------------
    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        if np.any(gamma * self.sigma_tan >= 1.0):
            raise ModelError(f"gamma: the Stribeck resolvent is unique only for gamma * "
                             f"sigma_tan < 1, got gamma * sigma_tan = {gamma * self.sigma_tan}; "
                             "reduce the step or use the loop transformation")
        a = np.abs(x)
        slip = a > gamma * self.static
        s = solve_increasing(lambda s: s + gamma * self.magnitude(s) - a,
                             lambda s: 1.0 + gamma * self._magnitude_slope(s),
                             np.zeros(self.dim), np.where(slip, a, 0.0))
        return np.where(slip, np.sign(x) * s, 0.0)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        to_segment = np.hypot(z, np.maximum(np.abs(v) - self.static, 0.0))
        branch = np.sign(z) * self.magnitude(z)
        to_branch = np.where(z != 0.0, np.abs(v - branch), np.inf)
        return float(np.linalg.norm(np.minimum(to_segment, to_branch)))

    def _select(self, z: FloatArray) -> FloatArray:
        return np.where(z != 0.0, np.sign(z) * self.magnitude(z), 0.0)

    def __repr__(self) -> str:
        return (f"Stribeck(static={self.static.tolist()}, coulomb={self.coulomb.tolist()}, "
                f"stribeck_velocity={self.stribeck_velocity.tolist()}, "
                f"delta={self.delta.tolist()}, viscous={self.viscous.tolist()})")


@dataclass(frozen=True, eq=False)
class AsymmetricStribeck(SetValuedLaw):
    """Stribeck friction with its own curve on each side (ch07 §1.1, asymmetric variant).

    ``phi(v) = f_plus(v)`` for ``v > 0``, ``-f_minus(-v)`` for ``v < 0`` and
    ``phi(0) = [-T_s_minus, T_s_plus]``, with ``f_plus``, ``f_minus`` the magnitudes of two
    symmetric :class:`Stribeck` laws. Slope constants are the worse of the two sides.

    Parameters
    ----------
    plus, minus
        :class:`Stribeck` laws of the same ``dim`` giving the positive and negative branches.
    """

    plus: Stribeck
    minus: Stribeck
    sigma_tan: FloatArray = field(init=False, repr=False)
    sigma_sec: FloatArray = field(init=False, repr=False)
    componentwise = True

    def __post_init__(self) -> None:
        if not (isinstance(self.plus, Stribeck) and isinstance(self.minus, Stribeck)):
            raise ModelError(f"plus, minus: expected two Stribeck laws, got "
                             f"{type(self.plus).__name__} and {type(self.minus).__name__}")
        if self.plus.dim != self.minus.dim:
            raise ModelError(f"plus, minus: dimensions disagree ({self.plus.dim} vs "
                             f"{self.minus.dim})")
        object.__setattr__(self, "dim", self.plus.dim)
        object.__setattr__(self, "sigma_tan", np.maximum(self.plus.sigma_tan,
                                                         self.minus.sigma_tan))
        object.__setattr__(self, "sigma_sec", np.maximum(self.plus.sigma_sec,
                                                         self.minus.sigma_sec))
        object.__setattr__(self, "monotone", self.plus.monotone and self.minus.monotone)

    def loop_transformation(self, sigma: ArrayLike | None = None) -> LoopTransformation:
        """Both sides shifted by the same slope ``sigma >= sigma_tan`` (``sigma I`` is odd)."""
        sig = self.sigma_tan.copy() if sigma is None else broadcast_parameter("sigma", sigma,
                                                                              self.dim)
        plus = self.plus.loop_transformation(sig).monotone_part
        minus = self.minus.loop_transformation(sig).monotone_part
        # Stribeck.loop_transformation's monotone part is a Stribeck (checked, not assumed)
        if not (isinstance(plus, Stribeck) and isinstance(minus, Stribeck)):
            raise ModelError("plus, minus: their loop transformations are not Stribeck laws")
        return LoopTransformation(monotone_part=AsymmetricStribeck(plus, minus), slope=sig)

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        z_plus = self.plus._resolvent(np.maximum(x, 0.0), gamma)
        z_minus = self.minus._resolvent(np.minimum(x, 0.0), gamma)
        return np.where(x > 0.0, z_plus, z_minus)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        below = np.maximum(-self.minus.static - v, 0.0)
        above = np.maximum(v - self.plus.static, 0.0)
        to_segment = np.hypot(z, below + above)
        branch = np.where(z > 0.0, self.plus.magnitude(z), -self.minus.magnitude(z))
        to_branch = np.where(z != 0.0, np.abs(v - branch), np.inf)
        return float(np.linalg.norm(np.minimum(to_segment, to_branch)))

    def _select(self, z: FloatArray) -> FloatArray:
        return np.where(z > 0.0, self.plus.magnitude(z),
                        np.where(z < 0.0, -self.minus.magnitude(z), 0.0))

    def __repr__(self) -> str:
        return f"AsymmetricStribeck(plus={self.plus!r}, minus={self.minus!r})"
