"""Filippov systems and switched affine systems driven by a sampled (PWM) controller.

* :class:`FilippovSystem`: smooth fields on the sides of switching surfaces ``h_j(x) = 0``; on
  a surface the solution follows Filippov's convex combination (sliding when both sides push
  towards it).
* :class:`SwitchedAffineSystem` with a :class:`PWMController`: modes ``x' = A_σ x + b_σ``; at
  each sampling instant ``t_k = t0 + kT`` the controller reads ``x(t_k)`` and sets the duty
  time ``d_k ∈ [0, T]`` of the "on" mode (DC-DC converters).

Both are integrated by ``simulate(..., method="switching")``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from .._validation import FloatArray, as_matrix, as_square, as_vector, check_positive
from ..errors import DimensionError, ModelError

__all__ = ["FilippovSystem", "SwitchedAffineSystem", "PWMController"]


def _fd_gradient(h: Callable[[FloatArray], float], x: FloatArray) -> FloatArray:
    g = np.empty_like(x)
    for k in range(x.shape[0]):
        d = 1e-7 * (1.0 + abs(x[k]))
        e = np.zeros_like(x)
        e[k] = d
        g[k] = (h(x + e) - h(x - e)) / (2.0 * d)
    return g


@dataclass(frozen=True, eq=False)
class FilippovSystem:
    """Vector fields on the sides of switching surfaces, with Filippov's convention on them.

    Parameters
    ----------
    n_states : int
        State dimension.
    surfaces : sequence of callables ``h_j(x) -> float``
        The switching surfaces ``h_j(x) = 0``.
    field : callable ``field(t, x, signs) -> (n,) array``
        The smooth field used where ``sign(h_j(x)) = signs[j]`` (``signs`` a tuple of ±1); it
        must be defined (smoothly extended) up to and across the surfaces.
    gradients : sequence of callables ``∇h_j(x)``, optional
        Surface gradients (default: central finite differences).
    jacobian : callable ``jacobian(t, x, signs) -> (n, n)``, optional
        ``∂field/∂x`` for ``sensitivity=True`` (default: central finite differences).
    state_names : tuple of str

    Notes
    -----
    Mode numbers in event tables: ``Σ_j [signs_j > 0] 2^j``; sliding on surface ``j`` adds
    ``(j + 1) 2^J`` (``J`` surfaces). On surface ``j`` with ``σ± = ∇h_jᵀ F±``: crossing when
    ``σ⁻σ⁺ > 0``; attracting sliding when ``σ⁻ > 0 > σ⁺`` with the Filippov field
    ``F_s = (σ⁺F⁻ - σ⁻F⁺)/(σ⁺ - σ⁻)``, left when ``σ⁻`` or ``σ⁺`` reaches zero; repelling
    sliding (``σ⁻ < 0 < σ⁺``) has no unique forward solution and is refused.

    References
    ----------
    A.F. Filippov, *Differential equations with discontinuous righthand sides*, 1988;
    SICONOS D5.3 chapter 12 (switching control of limit cycles) for the conventions.
    """

    n_states: int
    surfaces: Sequence[Callable[[FloatArray], float]]
    field: Callable[[float, FloatArray, tuple[int, ...]], FloatArray]
    gradients: Sequence[Callable[[FloatArray], FloatArray]] | None = None
    jacobian: Callable[[float, FloatArray, tuple[int, ...]], FloatArray] | None = None
    state_names: tuple[str, ...] = ()

    default_method = "switching"

    def __post_init__(self) -> None:
        if isinstance(self.n_states, bool) or int(self.n_states) < 1:
            raise DimensionError(f"n_states: expected a positive integer, got "
                                 f"{self.n_states!r}")
        object.__setattr__(self, "n_states", int(self.n_states))
        if len(self.surfaces) == 0:
            raise ModelError("surfaces: expected at least one switching surface h_j(x)")
        if not all(callable(h) for h in self.surfaces) or not callable(self.field):
            raise ModelError("surfaces, field: expected callables h_j(x) and field(t, x, signs)")
        if self.gradients is not None and len(self.gradients) != len(self.surfaces):
            raise DimensionError(f"gradients: expected {len(self.surfaces)} gradients (one per "
                                 f"surface), got {len(self.gradients)}")
        probe = np.asarray(self.field(0.0, np.zeros(self.n_states),
                                      (1,) * len(self.surfaces)), float)
        if probe.shape != (self.n_states,):
            raise DimensionError(f"field: expected field(t, x, signs) of shape "
                                 f"({self.n_states},), got {probe.shape}")
        if self.state_names and len(self.state_names) != self.n_states:
            raise DimensionError(f"state_names: expected {self.n_states} names")

    @property
    def n_surfaces(self) -> int:
        return len(self.surfaces)

    def h(self, x: FloatArray) -> FloatArray:
        """All surface functions at ``x``."""
        return np.array([float(h(x)) for h in self.surfaces])

    def gradient(self, j: int, x: FloatArray) -> FloatArray:
        """``∇h_j(x)``."""
        if self.gradients is not None:
            return np.asarray(self.gradients[j](x), float)
        return _fd_gradient(self.surfaces[j], x)

    def jac(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        """``∂field/∂x`` (user-given or central differences)."""
        if self.jacobian is not None:
            return np.asarray(self.jacobian(t, x, signs), float)
        return _fd_jacobian(lambda xx: np.asarray(self.field(t, xx, signs), float), x)

    @classmethod
    def two_sided(cls, f_minus: Callable[[float, FloatArray], FloatArray],
                  f_plus: Callable[[float, FloatArray], FloatArray],
                  h: Callable[[FloatArray], float], n_states: int, *,
                  gradient: Callable[[FloatArray], FloatArray] | None = None,
                  state_names: tuple[str, ...] = ()) -> FilippovSystem:
        """One surface ``h(x) = 0``: ``f_minus(t, x)`` where ``h < 0``, ``f_plus`` where
        ``h > 0``."""
        return cls(n_states, (h,), lambda t, x, s: f_plus(t, x) if s[0] > 0 else f_minus(t, x),
                   gradients=None if gradient is None else (gradient,), state_names=state_names)

    @classmethod
    def from_pwa(cls, pwa: Any) -> FilippovSystem:
        """The Filippov form of a bimodal :class:`~.pwa.PiecewiseAffineSystem` (two regions
        split by one hyperplane), for discontinuous fields with sliding."""
        if pwa.n_regions != 2 or any(H.shape[0] != 1 for H, _ in pwa.regions):
            raise ModelError("pwa: from_pwa handles bimodal systems (two half-spaces); got "
                             f"{pwa.n_regions} regions")
        (H0, h0), _ = pwa.regions
        c, d = H0[0].copy(), float(h0[0])  # region 0: cᵀx <= d is the side h = cᵀx - d < 0

        def field(t: float, x: FloatArray, s: tuple[int, ...]) -> FloatArray:
            return pwa.field(1 if s[0] > 0 else 0, x, t)

        def jac(t: float, x: FloatArray, s: tuple[int, ...]) -> FloatArray:
            return pwa.A[1 if s[0] > 0 else 0]

        return cls(pwa.n_states, (lambda x: float(c @ x) - d,), field,
                   gradients=(lambda x: c,), jacobian=jac, state_names=pwa.state_names)


def _fd_jacobian(f: Callable[[FloatArray], FloatArray], x: FloatArray) -> FloatArray:
    n = x.shape[0]
    J = np.empty((n, n))
    for k in range(n):
        d = 1e-6 * (1.0 + abs(x[k]))
        e = np.zeros(n)
        e[k] = d
        J[:, k] = (f(x + e) - f(x - e)) / (2.0 * d)
    return J


@dataclass(frozen=True, eq=False)
class PWMController:
    """A sampled pulse-width modulator: duty time ``d_k = duty(t_k, x(t_k))`` clipped to
    ``[0, period]``.

    Parameters
    ----------
    period : float
        Sampling (and PWM) period ``T``.
    duty : callable ``duty(t_k, x_k) -> float``
        Time spent in ``on_mode`` during ``[t_k, t_k + T)``.
    on_mode, off_mode : int
        Mode indices of the switched system.
    pattern : {"centered", "leading", "trailing"}
        ``centered``: on for ``d/2``, off, on for the last ``d/2`` (ch10); ``leading``: on
        first; ``trailing``: on last.
    """

    period: float
    duty: Callable[[float, FloatArray], float]
    on_mode: int = 1
    off_mode: int = 0
    pattern: Literal["centered", "leading", "trailing"] = "centered"

    def __post_init__(self) -> None:
        object.__setattr__(self, "period", check_positive("period", self.period))
        if not callable(self.duty):
            raise ModelError("duty: expected a callable duty(t_k, x_k) -> float")
        if self.pattern not in ("centered", "leading", "trailing"):
            raise ModelError(f"pattern: expected 'centered', 'leading' or 'trailing', got "
                             f"{self.pattern!r}")

    def schedule(self, t_k: float, x_k: FloatArray) -> tuple[float, list[tuple[float, int]]]:
        """``(d_k, [(duration, mode), ...])`` for the period starting at ``t_k``."""
        T = self.period
        d = float(np.clip(float(self.duty(t_k, x_k)), 0.0, T))
        on, off = self.on_mode, self.off_mode
        if self.pattern == "centered":
            pieces = [(d / 2, on), (T - d, off), (d / 2, on)]
        elif self.pattern == "leading":
            pieces = [(d, on), (T - d, off)]
        else:
            pieces = [(T - d, off), (d, on)]
        return d, [(s, m) for s, m in pieces if s > 0.0]


@dataclass(frozen=True, eq=False)
class SwitchedAffineSystem:
    """Modes ``x' = A_σ x + b_σ`` selected by a controller.

    Parameters
    ----------
    modes : sequence of (A, b)
        One affine field per mode.
    controller : PWMController, optional
        Sampled controller setting the mode (``simulate(..., controller=...)`` is not needed
        when given here).
    C : (p, n) array_like, optional
        Output ``y = C x`` (recorded as a signal).
    state_names : tuple of str
    """

    modes: Sequence[tuple[Any, Any]]
    controller: PWMController | None = None
    C: Any = None
    state_names: tuple[str, ...] = ()

    default_method = "switching"

    def __post_init__(self) -> None:
        if len(self.modes) < 2:
            raise ModelError(f"modes: expected at least two modes (A, b), got "
                             f"{len(self.modes)}")
        mats = []
        n = None
        for i, mode in enumerate(self.modes):
            try:
                A, b = mode
            except (TypeError, ValueError):
                raise DimensionError(f"modes[{i}]: expected a pair (A, b)") from None
            A = as_square(f"modes[{i}].A", A, n)
            n = A.shape[0]
            mats.append((A, as_vector(f"modes[{i}].b", b, n)))
        object.__setattr__(self, "modes", tuple(mats))
        if self.controller is not None:
            if not isinstance(self.controller, PWMController):
                raise ModelError(f"controller: expected a PWMController, got "
                                 f"{type(self.controller).__name__}")
            for name in ("on_mode", "off_mode"):
                k = getattr(self.controller, name)
                if not 0 <= k < len(mats):
                    raise ModelError(f"controller.{name}: expected a mode index in "
                                     f"[0, {len(mats)}), got {k}")
        if self.C is not None:
            object.__setattr__(self, "C", as_matrix("C", self.C, cols=n))

    @property
    def n_states(self) -> int:
        return int(self.modes[0][0].shape[0])

    def field(self, mode: int, x: FloatArray) -> FloatArray:
        """The field of ``mode`` at ``x``."""
        A, b = self.modes[mode]
        return A @ np.asarray(x, float) + b

    def propagate(self, mode: int, x: Any, t: float) -> FloatArray:
        """Exact solution of mode ``mode`` after time ``t`` from ``x`` (augmented ``expm``)."""
        from scipy.linalg import expm

        A, b = self.modes[mode]
        n = A.shape[0]
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n] = A, b
        return (expm(M * t) @ np.r_[np.asarray(x, float), 1.0])[:n]
