r"""Problems with known answers for :mod:`nscontrol.optimal`.

**A block pushed along a floor** (mass ``m``, Coulomb coefficient ``μ``, gravity ``g``), from
rest at ``0`` to rest at ``d``, by a horizontal force ``u``. While it slides forward the
floor pushes back with the constant force ``μ m g``, so ``m ẍ = u - μ m g``.

*Least effort in a fixed time* ``T`` (cost ``∫ u² dt``). Write ``u = μ m g + w``. The
velocity returns to zero, so ``∫ w dt = m (v(T) - v(0)) = 0`` and the cross term of
``∫ (μ m g + w)²`` vanishes: the cost is ``(μ m g)² T + ∫ w² dt``, and ``w = m ẍ`` is the
least-energy way of moving a free mass by ``d`` in ``T`` from rest to rest, the linear
acceleration ``ẍ = 6 d / T² (1 - 2 t / T)``. Hence, as long as the block keeps sliding
forward (``v > 0`` on ``(0, T)``: true for this profile),

    u*(t) = μ m g + 6 m d / T² (1 - 2 t / T),     J* = (μ m g)² T + 12 m² d² / T³.

On the Moreau–Jean grid (``N`` steps, ``h = T / N``, inputs held over each step) the same
argument holds step by step (the θ = ½ step is exact for a constant input while the block
slides): ``Σ w_k = 0`` and ``d = -(h² / m) Σ k w_k``, whose least ``h Σ w_k²`` is the affine
``w_k = 12 m d ((N - 1)/2 - k) / (h² N (N² - 1))``, so

    J*_h = (μ m g)² T + 12 m² d² / T³ · N² / (N² - 1),

a relative excess ``1 / (N² - 1) ≈ h² / T²`` over ``J*``: second order in ``h``. (The last
step ends at rest, where Coulomb's law leaves the friction anywhere in ``[-μ m g, μ m g]``;
the sliding value is the optimum's when ``u*(T) < 0``, i.e. ``6 d / T² > μ g``.)

*Least time* with ``|u| <= U`` (``U > μ m g``): bang-bang, full push then full brake. The
block accelerates at ``a₁ = (U - μ m g) / m`` and brakes at ``a₂ = (U + μ m g) / m``; with the
peak speed ``v̂`` reached at the switch, ``d = v̂² / (2 a₁) + v̂² / (2 a₂)``, so

    v̂ = sqrt(2 d a₁ a₂ / (a₁ + a₂)),     T* = v̂ (1/a₁ + 1/a₂) = sqrt(2 d (a₁ + a₂) / (a₁ a₂)).

On the grid (free step ``h``, ``N`` steps) the switch falls inside a step, whose held input is
the mean of the push and the brake: that step covers
``δx = (2U / m) h² τ (1 - τ) / 2 <= U h² / (4 m)`` less than the bang-bang, and each extra
metre costs ``dT*/dd = T* / (2 d) = 1 / v̂`` seconds, so
``T* <= T*_h <= T* + U h² / (4 m v̂)`` to first order in ``δx``.

**A drift that speeds up across a surface** (:class:`SpeedUp`): ``x' = u + a₁`` where
``x < 0`` and ``x' = u + a₂`` where ``x > 0`` (``0 < a₁ < a₂``), from ``x0 = -L < 0`` to
``x_T > 0`` in time ``T``, least effort ``∫ u² dt``. Between crossings the costate is
constant, so ``u`` is constant on each side: ``u₁ = L / s - a₁`` before the crossing at
``s``, ``u₂ = x_T / r - a₂`` after it (``r = T - s``), and the cost is the convex function

    J(s) = s (L / s - a₁)² + r (x_T / r - a₂)²,     J'(s) = a₁² - L² / s² - a₂² + x_T² / r²,

whose root is the optimal switching time: ``x_T² / r² - L² / s² = a₂² - a₁²`` (the
speed squared jumps by the fields' difference). With ``a₁ = 1``, ``a₂ = 3``, ``L = 1``,
``T = 1`` and ``x_T = √3``: ``s = 1/2``, ``u₁ = 1``, ``u₂ = 2√3 - 3``,
``J* = 1/2 + 2 (√3 - 3/2)²``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validation import check_positive
from ..errors import ModelError
from ..systems.lagrangian import LagrangianSystem
from .fesd import SwitchingProblem

__all__ = ["PushedBlock", "SpeedUp"]


@dataclass(frozen=True)
class PushedBlock:
    """A block on a floor with Coulomb friction, pushed horizontally (the module docstring).

    Parameters
    ----------
    mass : float
        ``m > 0``.
    mu : float
        Coulomb coefficient ``μ > 0``.
    distance : float
        Target ``d > 0``.
    g : float
        Gravity.
    """

    mass: float = 1.0
    mu: float = 0.5
    distance: float = 1.0
    g: float = 9.81

    def __post_init__(self) -> None:
        for name in ("mass", "mu", "distance", "g"):
            check_positive(name, getattr(self, name))

    @property
    def friction_force(self) -> float:
        """``μ m g``."""
        return self.mu * self.mass * self.g

    def system(self) -> LagrangianSystem:
        """The block as a 2-DOF Lagrangian system ``q = (x, y)``: gravity, the floor
        ``y >= 0`` with friction ``μ``, the force ``u`` along ``x``."""
        m = self.mass
        return LagrangianSystem(np.eye(2) * m, constant_force=[0.0, -m * self.g],
                                gap_matrix=[[0.0, 1.0]], gap_offset=[0.0],
                                friction=self.mu, tangent_matrix=[[1.0, 0.0]],
                                actuation=[[1.0], [0.0]], names=("x", "y"))

    @property
    def x0(self) -> np.ndarray:
        """At rest on the floor at the origin."""
        return np.zeros(4)

    @property
    def x_final(self) -> np.ndarray:
        """At rest on the floor at ``d``."""
        return np.array([self.distance, 0.0, 0.0, 0.0])

    def effort_input(self, t: np.ndarray, T: float) -> np.ndarray:
        """``u*(t)`` of the least-effort push in time ``T``."""
        t = np.asarray(t, float)
        return self.friction_force + 6.0 * self.mass * self.distance / T ** 2 * (1 - 2 * t / T)

    def effort_cost(self, T: float) -> float:
        """``J* = (μ m g)² T + 12 m² d² / T³``."""
        return self.friction_force ** 2 * T + 12.0 * (self.mass * self.distance) ** 2 / T ** 3

    def effort_cost_discrete(self, T: float, steps: int) -> float:
        """``J*_h``: the least effort with ``steps`` held inputs (the module docstring)."""
        N = steps
        return (self.friction_force ** 2 * T
                + 12.0 * (self.mass * self.distance) ** 2 / T ** 3 * N ** 2 / (N ** 2 - 1))

    def peak_speed(self, U: float) -> float:
        """``v̂`` of the least-time push with ``|u| <= U``."""
        a1, a2 = self._accelerations(U)
        return float(np.sqrt(2.0 * self.distance * a1 * a2 / (a1 + a2)))

    def minimum_time(self, U: float) -> float:
        """``T* = sqrt(2 d (a₁ + a₂) / (a₁ a₂))`` with ``|u| <= U``."""
        a1, a2 = self._accelerations(U)
        return float(np.sqrt(2.0 * self.distance * (a1 + a2) / (a1 * a2)))

    def switch_time(self, U: float) -> float:
        """When the least-time push turns into the brake, ``v̂ / a₁``."""
        return self.peak_speed(U) / self._accelerations(U)[0]

    def _accelerations(self, U: float) -> tuple[float, float]:
        U = check_positive("U", U)
        if U <= self.friction_force:
            raise ModelError(f"U: the bound {U} does not exceed the friction force "
                             f"{self.friction_force}; the block cannot move")
        return (U - self.friction_force) / self.mass, (U + self.friction_force) / self.mass


@dataclass(frozen=True)
class SpeedUp:
    """``x' = u + a₁`` for ``x < 0``, ``u + a₂`` for ``x > 0``, pushed from ``-L`` to
    ``x_T`` in time ``T`` at least effort (the module docstring); the defaults switch at
    ``T / 2`` exactly.

    Parameters
    ----------
    a1, a2 : float
        The drifts, ``0 < a1 < a2``.
    L : float
        Start at ``-L < 0``.
    x_T : float
        Target ``> 0``.
    T : float
        Horizon.
    """

    a1: float = 1.0
    a2: float = 3.0
    L: float = 1.0
    x_T: float = float(np.sqrt(3.0))
    T: float = 1.0

    def __post_init__(self) -> None:
        for name in ("a1", "a2", "L", "x_T", "T"):
            check_positive(name, getattr(self, name))
        if not self.a1 < self.a2:
            raise ModelError(f"a2: must exceed a1 = {self.a1}, got {self.a2}")

    def problem(self, elements: int, switch_detection: bool = True) -> SwitchingProblem:
        """The transcription with ``elements`` finite elements.

        Parameters
        ----------
        elements : int
            Number of finite elements.
        switch_detection : bool
            FESD, or a fixed grid.

        Returns
        -------
        SwitchingProblem
        """
        zero = np.zeros((1, 1))
        return SwitchingProblem(A=(zero, zero), b=([self.a1], [self.a2]), B=[[1.0]], c=[1.0],
                                d=0.0, x0=[-self.L], x_final=[self.x_T], T=self.T,
                                elements=elements, switch_detection=switch_detection)

    def switch_time(self) -> float:
        """The root of ``J'(s)`` in ``(0, T)`` (``J`` is convex: one root)."""
        from scipy.optimize import brentq

        def slope(s: float) -> float:
            r = self.T - s
            return self.a1 ** 2 - self.L ** 2 / s ** 2 - self.a2 ** 2 + self.x_T ** 2 / r ** 2

        eps = 1e-12 * self.T
        return float(brentq(slope, eps, self.T - eps, xtol=1e-15))

    def cost(self) -> float:
        """``J(s*)``."""
        s = self.switch_time()
        r = self.T - s
        return s * (self.L / s - self.a1) ** 2 + r * (self.x_T / r - self.a2) ** 2
