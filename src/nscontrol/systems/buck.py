"""The DC-DC buck converter in normalised form: a switched affine system with two modes.

``L di/dt = E u - v``, ``C dv/dt = i - v/R`` with the switch ``u ∈ {u_off, u_on}``. With the
time ``τ = t/√(LC)``, ``x1 = v/E`` and ``x2 = dx1/dτ`` (the normalised derivative of the
output voltage) it reads

    x' = A x + B u,   A = [[0, 1], [-1, -δ]],   B = [0, 1]ᵀ,   δ = (1/R)√(L/C).

Constant ``u = ū`` has the equilibrium ``(ū, 0)``. A sampled pulse-width modulated switch
turns it into a :class:`~nscontrol.systems.switched.SwitchedAffineSystem`
(:meth:`BuckConverter.switched`), the generic route of ``simulate(method="switching")``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_real_scalar, as_vector, check_positive
from ..errors import ModelError
from .switched import PWMController, SwitchedAffineSystem

__all__ = ["BuckConverter"]


@dataclass(frozen=True)
class BuckConverter:
    """A buck converter in normalised coordinates (ideal switch, continuous conduction).

    Parameters
    ----------
    delta : float
        Damping ``δ = (1/R)√(L/C) > 0``.
    u_levels : (float, float)
        ``(u_off, u_on)`` with ``u_off < u_on``: ``(0, 1)`` for the DC-DC buck, ``(-1, 1)``
        for the bipolar (full-bridge) switch.
    time_scale : float
        ``√(LC)`` in seconds (1 for a model given in normalised form).
    voltage_scale : float
        The source voltage ``E`` in volts (1 in normalised form).

    Raises
    ------
    ModelError
        ``delta`` not finite and positive, ``u_levels`` not two finite increasing numbers,
        or a non-positive scale.

    Examples
    --------
    >>> buck = BuckConverter.from_physical(R=20.0, L=2e-3, C=40e-6, E=40.0)
    >>> round(buck.delta, 4), round(buck.time_scale * 1e3, 4)
    (0.3536, 0.2828)
    >>> buck.propagate(1.0, [0.0, 0.0], 0.0).tolist()
    [0.0, 0.0]
    """

    delta: float
    u_levels: tuple[float, float] = (-1.0, 1.0)
    time_scale: float = 1.0
    voltage_scale: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "delta", check_positive("delta", self.delta))
        try:
            u_off, u_on = self.u_levels
        except (TypeError, ValueError):
            raise ModelError(f"u_levels: expected a pair (u_off, u_on), got "
                             f"{self.u_levels!r}") from None
        u_off = as_real_scalar("u_levels[0]", u_off)
        u_on = as_real_scalar("u_levels[1]", u_on)
        if not (math.isfinite(u_off) and math.isfinite(u_on) and u_off < u_on):
            raise ModelError(f"u_levels: expected finite u_off < u_on, got ({u_off}, {u_on}); "
                             "give the switch levels in increasing order")
        object.__setattr__(self, "u_levels", (u_off, u_on))
        for name in ("time_scale", "voltage_scale"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))

    @classmethod
    def normalized(cls, delta: float, u_levels: tuple[float, float] = (-1.0, 1.0)
                   ) -> BuckConverter:
        """The model given directly in normalised form.

        Parameters
        ----------
        delta : float
            Damping ``δ > 0``.
        u_levels : (float, float)
            ``(u_off, u_on)``.

        Returns
        -------
        BuckConverter
        """
        return cls(delta, u_levels)

    @classmethod
    def from_physical(cls, R: float, L: float, C: float, E: float, *,
                      u_levels: tuple[float, float] = (0.0, 1.0)) -> BuckConverter:
        """The normalised model of a converter given in SI units.

        Parameters
        ----------
        R, L, C : float
            Load [Ω], inductance [H], capacitance [F] (all positive).
        E : float
            Source voltage [V] (positive).
        u_levels : (float, float)
            ``(u_off, u_on)``; ``(0, 1)`` for the DC-DC buck.

        Returns
        -------
        BuckConverter
            ``δ = (1/R)√(L/C)``, ``time_scale = √(LC)``, ``voltage_scale = E``.

        Raises
        ------
        ModelError
            A non-positive or non-finite component value (named).
        """
        R, L, C, E = (check_positive(n, v) for n, v in (("R", R), ("L", L), ("C", C),
                                                         ("E", E)))
        return cls(math.sqrt(L / C) / R, u_levels, math.sqrt(L * C), E)

    @property
    def n_states(self) -> int:
        """Two: ``x1 = v/E`` and ``x2 = dx1/dτ``."""
        return 2

    @property
    def state_names(self) -> tuple[str, str]:
        """``("x1", "x2")``."""
        return ("x1", "x2")

    @property
    def u_off(self) -> float:
        """The switch level of the off mode."""
        return self.u_levels[0]

    @property
    def u_on(self) -> float:
        """The switch level of the on mode."""
        return self.u_levels[1]

    @property
    def A(self) -> FloatArray:
        """``[[0, 1], [-1, -δ]]``."""
        return np.array([[0.0, 1.0], [-1.0, -self.delta]])

    @property
    def B(self) -> FloatArray:
        """``[0, 1]``."""
        return np.array([0.0, 1.0])

    def normalized_period(self, switching_frequency: float) -> float:
        """The normalised sampling period ``T = 1/(f_s √(LC))``.

        Parameters
        ----------
        switching_frequency : float
            ``f_s`` in Hz (positive).

        Returns
        -------
        float
        """
        return 1.0 / (check_positive("switching_frequency", switching_frequency)
                      * self.time_scale)

    def field(self, u: float, x: ArrayLike) -> FloatArray:
        """The vector field ``A x + B u``.

        Parameters
        ----------
        u : float
            Switch level.
        x : (2,) array_like
            State.

        Returns
        -------
        ndarray, shape (2,)
        """
        return self.A @ as_vector("x", x, 2) + self.B * float(u)

    def propagate(self, u: float, x: ArrayLike, t: float) -> FloatArray:
        """The exact state after ``t`` with the switch held at ``u``.

        Parameters
        ----------
        u : float
            Switch level.
        x : (2,) array_like
            State at time 0.
        t : float
            Duration (normalised time, ``t >= 0``).

        Returns
        -------
        ndarray, shape (2,)
            ``(u, 0) + e^{At}(x - (u, 0))``.
        """
        from scipy.linalg import expm

        eq = np.array([float(u), 0.0])
        return eq + expm(self.A * float(t)) @ (as_vector("x", x, 2) - eq)

    def switched(self, period: float, duty: Callable[[float, FloatArray], float], *,
                 pattern: Literal["centered", "leading", "trailing"] = "centered"
                 ) -> SwitchedAffineSystem:
        """The converter driven by a sampled pulse-width modulator, as a switched system.

        Parameters
        ----------
        period : float
            Normalised sampling period ``T``.
        duty : callable ``duty(t_k, x_k) -> float``
            The on-time of the period starting at ``t_k`` (clipped to ``[0, T]``).
        pattern : {"centered", "leading", "trailing"}
            Position of the on-time in the period (``centered``: ``d/2``, off, ``d/2``).

        Returns
        -------
        SwitchedAffineSystem
            Mode 0 is off, mode 1 on; ``simulate(..., method="switching")`` integrates it
            exactly piece by piece.
        """
        modes = ((self.A, self.B * self.u_off), (self.A, self.B * self.u_on))
        return SwitchedAffineSystem(modes, PWMController(period, duty, on_mode=1, off_mode=0,
                                                         pattern=pattern),
                                    state_names=self.state_names)
