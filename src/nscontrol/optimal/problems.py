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

**A car whose engine weakens above a speed** (:class:`SimpleCar`, the problem of nosnoc's
``simple_car_algebraic`` example): ``q' = v``, ``v' = k(v) u`` with ``k = k₁`` below the
speed ``v_s`` and ``k₂`` above it, from rest at ``0`` to rest at ``d`` in time ``T``, least
``∫ u² dt`` with ``|u| <= U`` (not binding at the optimum), ``d / T > v_s`` (it must exceed
``v_s``). Between crossings the costates obey ``p_q' = 0``, ``p_v' = -p_q`` and
``u = -k p_v / 2``, so ``u`` is affine in time with the slope ``k p_q / 2``: the slopes of
the two modes are in the ratio ``k₁ : k₂``. At a crossing of ``v = v_s`` (transversal,
``v' = k u ≠ 0``) the Hamiltonian ``min_u H = p_q v - u²`` is continuous and so is ``p_q``
(the surface does not depend on ``q``): ``|u|`` is continuous. The problem is mapped onto
itself by ``t → T - t``, ``q → d - q``, ``u → -u``, so the optimum crosses up at ``τ`` and
down at ``T - τ`` with ``u(T/2) = 0``. With ``m = T / 2`` and ``r = k₁ / k₂``,
``u = c (m - t)`` on ``[τ, m]`` and ``u = c (m - τ) + r c (τ - t)`` on ``[0, τ]``;
``v(τ) = v_s`` and ``q(m) = d / 2`` give

    c = v_s / (k₁ ((m - τ) τ + r τ² / 2)),
    k₁ c ((m - τ) τ² / 2 + r τ³ / 3) + v_s (m - τ) + k₂ c (m - τ)³ / 3 = d / 2,

one equation in ``τ`` whose left side falls from ``+∞`` at ``τ → 0`` to
``2 v_s m / 3 < d / 2`` at ``τ = m``: its root in ``(0, m)`` is the switching time. The cost is
``J* = 2 ((u₀³ - u_τ³) / (3 r c) + c² (m - τ)³ / 3)`` (``u₀ = u(0)``, ``u_τ = u(τ)``).
nosnoc's numbers ``k₁ = 5``, ``k₂ = 3``, ``v_s = 15``, ``d = 500``, ``T = 30``, ``U = 1``:
``τ = 4.4511``, ``u(0) = 0.849``, ``J* = 5.8838``.

On the FESD grid (implicit Euler, one input per control stage) the same structure holds
exactly away from the crossings: the discrete costate of ``v`` changes by ``h_k p_q`` over
element ``k`` and ``u_s`` is ``k`` times the mean costate over stage ``s``, so on stages of
equal elements wholly in one mode the input steps by ``k p_q (T / N) / 2`` from stage to
stage. Implicit Euler is exact on ``v`` (constant acceleration per element) and errs on
``q`` by ``h_k Δv_k / 2`` per element.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import check_positive
from ..errors import ModelError
from ..systems.lagrangian import LagrangianSystem
from .fesd import SwitchingProblem
from .stewart import FesdProblem, StewartSystem

__all__ = ["PushedBlock", "SpeedUp", "SimpleCar"]


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


@dataclass(frozen=True)
class SimpleCar:
    """``q' = v``, ``v' = k₁ u`` below the speed ``v_s`` and ``k₂ u`` above it, from rest to
    rest at ``d`` in time ``T`` at least effort (the module docstring); the defaults are
    nosnoc's ``simple_car_algebraic`` example.

    Parameters
    ----------
    k1, k2 : float
        The input gains below and above ``v_s`` (``> 0``).
    v_switch : float
        ``v_s > 0``.
    distance : float
        ``d``, with ``d / T > v_s``.
    T : float
        Horizon.
    u_max : float
        ``U``: ``|u| <= U``.

    Raises
    ------
    ModelError
        ``d / T <= v_s`` (the car need not pass ``v_s``: no switch).
    """

    k1: float = 5.0
    k2: float = 3.0
    v_switch: float = 15.0
    distance: float = 500.0
    T: float = 30.0
    u_max: float = 1.0

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "v_switch", "distance", "T", "u_max"):
            check_positive(name, getattr(self, name))
        if not self.distance / self.T > self.v_switch:
            raise ModelError(f"distance: the mean speed d / T = {self.distance / self.T:g} "
                             f"must exceed v_switch = {self.v_switch:g} (else no switch); "
                             "raise distance or shorten T")

    def system(self) -> StewartSystem:
        """The car in Stewart's form: field 1 (``k₁``) where ``c = v - v_s < 0``."""
        def field(k: float) -> Callable[[Any, Any], list[Any]]:
            return lambda x, u: [x[1], k * u[0]]

        return StewartSystem([field(self.k1), field(self.k2)], lambda x: x[1] - self.v_switch,
                             signs=[[-1.0], [1.0]])

    def problem(self, stages: int = 30, elements: int = 2, equilibration: float = 1.0,
                equilibration_form: str = "delta", start: str = "consistent") -> FesdProblem:
        """The FESD transcription (nosnoc's grid by default: 30 stages of 2 elements, each
        element within ``(0, 2) h̄``, nosnoc's default step equilibration).

        Parameters
        ----------
        stages, elements : int
            Control stages and finite elements per stage.
        equilibration : float
            Step equilibration weight.
        equilibration_form : {"mean", "delta"}
            Its form.
        start : {"consistent", "centred"}
            The algebraic variables' start (:class:`FesdProblem`).

        Returns
        -------
        FesdProblem
        """
        return FesdProblem(self.system(), [0.0, 0.0], self.T, stages, elements=elements,
                           inputs=1, stage_cost=lambda x, u: u[0] ** 2,
                           x_final=[self.distance, 0.0], u_min=-self.u_max, u_max=self.u_max,
                           element_bounds=(0.0, 2.0), equilibration=equilibration,
                           equilibration_form=equilibration_form, start=start)

    def _slope(self, tau: float) -> float:
        """``c`` of the module docstring for the crossing at ``tau``."""
        m, r = 0.5 * self.T, self.k1 / self.k2
        return self.v_switch / (self.k1 * ((m - tau) * tau + r * tau ** 2 / 2))

    def switch_times(self) -> tuple[float, float]:
        """``(τ, T - τ)``: the crossings of ``v_s`` up and down.

        Raises
        ------
        ModelError
            The optimum's input reaches ``u_max`` (the closed form assumes it does not).
        """
        from scipy.optimize import brentq

        m, r, vs = 0.5 * self.T, self.k1 / self.k2, self.v_switch

        def excess(tau: float) -> float:
            c = self._slope(tau)
            return (self.k1 * c * ((m - tau) * tau ** 2 / 2 + r * tau ** 3 / 3)
                    + vs * (m - tau) + self.k2 * c * (m - tau) ** 3 / 3 - self.distance / 2)

        tau = float(brentq(excess, 1e-9 * m, m, xtol=1e-14))
        if self.input(0.0, tau) >= self.u_max:
            raise ModelError(f"u_max: the least-effort input starts at "
                             f"{self.input(0.0, tau):g} >= u_max = {self.u_max:g}; the "
                             "closed form needs the bound inactive (raise u_max or T)")
        return tau, self.T - tau

    def input(self, t: Any, tau: float | None = None) -> Any:
        """``u*(t)`` (odd about ``T / 2``)."""
        tau = self.switch_times()[0] if tau is None else tau
        m, c = 0.5 * self.T, self._slope(tau)
        t = np.asarray(t, float)
        s = np.minimum(t, self.T - t)   # the time to the nearer end
        up = np.where(s < tau, c * (m - tau) + self.k1 / self.k2 * c * (tau - s), c * (m - s))
        return np.where(t <= m, up, -up)

    def cost(self) -> float:
        """``J*``."""
        tau, _ = self.switch_times()
        m, c, r = 0.5 * self.T, self._slope(tau), self.k1 / self.k2
        u0, ut = float(self.input(0.0, tau)), c * (m - tau)
        return 2.0 * ((u0 ** 3 - ut ** 3) / (3 * r * c) + c ** 2 * (m - tau) ** 3 / 3)
