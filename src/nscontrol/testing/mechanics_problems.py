"""Mechanical problems with known answers, for the conformance tests of the integrators.

* :class:`BouncingBall` — impact times in closed form and the accumulation (Zeno) time;
* :class:`RestingStack` — a stack of masses at rest: Moreau–Jean impulses ``(N - k) m g h``;
* :class:`NewtonsCradle` — beads apart on a line, a striker: velocity passed bead to bead at
  known times, momentum and energy conserved;
* :func:`impact_oscillator` — a damped, harmonically forced mass hitting a wall;
* :class:`ImpactingPendulum` — a forced pendulum hitting a wall (nonlinear between impacts):
  the determinant of the monodromy of a one-impact orbit in closed form.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._validation import FloatArray, check_bool, check_positive
from ..systems.lagrangian import LagrangianSystem

__all__ = ["BouncingBall", "RestingStack", "NewtonsCradle", "impact_oscillator",
           "ImpactingPendulum"]


@dataclass(frozen=True)
class BouncingBall:
    """A ball dropped from ``height`` at rest, ground ``q >= 0``, restitution ``e``.

    Free flights are parabolas: the first impact is at ``t_0 = sqrt(2 q0 / g)`` with speed
    ``v_0 = g t_0``; the k-th rebound lasts ``2 e^k v_0 / g``, so
    ``t_k = t_0 + (2 v_0 / g) e (1 - e^k) / (1 - e)`` and the impacts accumulate at
    ``t_∞ = t_0 + (2 v_0 / g) e / (1 - e)`` (8.578949 s for ``e = 0.9, q0 = 1, g = 9.81``),
    after which the ball rests on the ground.

    Parameters
    ----------
    restitution, height, g, mass : float
        Coefficient ``e``, drop height ``q0``, gravity and mass.

    Examples
    --------
    >>> ball = BouncingBall()
    >>> round(ball.accumulation_time, 6)
    8.578949
    >>> bool(np.allclose(ball.impact_times(2), [0.451524, 1.264267], atol=1e-6))
    True
    """

    restitution: float = 0.9
    height: float = 1.0
    g: float = 9.81
    mass: float = 1.0

    def system(self) -> LagrangianSystem:
        """The ball as a :class:`~nscontrol.systems.LagrangianSystem`."""
        return LagrangianSystem.bouncing_ball(self.restitution, self.g, self.mass)

    @property
    def x0(self) -> FloatArray:
        """Initial state ``(height, 0)``."""
        return np.array([check_positive("height", self.height), 0.0])

    def impact_times(self, count: int) -> FloatArray:
        """The first ``count`` impact times."""
        e, g = self.restitution, self.g
        t0 = np.sqrt(2.0 * self.height / g)
        k = np.arange(count)
        return t0 + 2.0 * t0 * np.sum(np.power.outer(e, np.arange(1, count + 1)) *
                                      (np.arange(1, count + 1)[None, :] <= k[:, None]),
                                      axis=1)

    @property
    def accumulation_time(self) -> float:
        """``t_∞``, where the impacts accumulate (``inf`` for ``e = 1``)."""
        e = self.restitution
        t0 = np.sqrt(2.0 * self.height / self.g)
        return float(t0 + 2.0 * t0 * e / (1.0 - e)) if e < 1.0 else np.inf

    def impact_velocity(self, k: int) -> float:
        """Speed just before the k-th impact (k = 0 first)."""
        return float(np.sqrt(2.0 * self.g * self.height) * self.restitution**k)


@dataclass(frozen=True)
class RestingStack:
    """``n`` masses stacked on the ground at rest (all gaps zero), ``e = 0``.

    With Moreau–Jean at step ``h`` every contact stays active and the impulse of contact
    ``k`` (under mass ``k``, counting from the ground) is the weight it carries over one step:
    ``P_k = (n - k) m g h``.

    Parameters
    ----------
    n : int
        Number of masses.
    mass, g : float
        Mass of each body and gravity.

    Examples
    --------
    >>> RestingStack(3).impulses(1e-3)
    array([0.02943, 0.01962, 0.00981])
    """

    n: int
    mass: float = 1.0
    g: float = 9.81

    def system(self) -> LagrangianSystem:
        """The stack as a :class:`~nscontrol.systems.LagrangianSystem` (sparse gaps)."""
        return LagrangianSystem.stack(self.n, mass=self.mass, g=self.g)

    @property
    def x0(self) -> FloatArray:
        """At rest on the ground: all positions and velocities zero."""
        return np.zeros(2 * self.n)

    def impulses(self, h: float) -> FloatArray:
        """Moreau–Jean impulses of a step ``h``: ``(n - k) m g h`` for contact ``k``."""
        return np.asarray((self.n - np.arange(self.n)) * self.mass * self.g * h, dtype=float)


@dataclass(frozen=True)
class NewtonsCradle:
    """``n`` equal beads ``spacing`` apart on a line; bead 0 strikes with ``velocity``, ``e = 1``.

    Each collision passes the whole velocity on (equal masses, elastic): contact ``j``
    (between beads ``j`` and ``j + 1``) closes at ``t_j = (j + 1) spacing / velocity``; at the
    end only the last bead moves, with ``velocity``. Momentum ``m v`` and kinetic energy
    ``m v² / 2`` are conserved at every impact.

    Parameters
    ----------
    n : int
        Number of beads.
    spacing, velocity, mass : float
        Initial distance of neighbours, striker speed, bead mass.

    Examples
    --------
    >>> NewtonsCradle(4).impact_times()
    array([0.01, 0.02, 0.03])
    """

    n: int
    spacing: float = 0.01
    velocity: float = 1.0
    mass: float = 1.0

    def system(self) -> LagrangianSystem:
        """The beads as a :class:`~nscontrol.systems.LagrangianSystem` (``e = 1``)."""
        return LagrangianSystem.newtons_cradle(self.n, mass=self.mass, restitution=1.0)

    @property
    def x0(self) -> FloatArray:
        """Beads ``spacing`` apart, bead 0 moving at ``velocity``."""
        v = np.zeros(self.n)
        v[0] = self.velocity
        return np.concatenate([self.spacing * np.arange(self.n), v])

    def impact_times(self) -> FloatArray:
        """Closing times of the ``n - 1`` contacts, in order."""
        return np.asarray(self.spacing * np.arange(1, self.n) / self.velocity, dtype=float)

    @property
    def final_time(self) -> float:
        """Time of the last collision."""
        return float(self.spacing * (self.n - 1) / self.velocity)


def impact_oscillator(*, mass: float = 1.0, stiffness: float = 1.0, damping: float = 0.1,
                      wall: float = 0.5, restitution: float = 0.8) -> LagrangianSystem:
    """A mass on a spring (and damper) hitting a wall at ``q = wall``: gap ``wall - q >= 0``.

    Drive it with ``u=Exosystem.sinusoid(F, omega)`` (the input acts on the mass).

    Parameters
    ----------
    mass, stiffness, damping : float
        ``m q'' + c q' + k q = u`` between impacts.
    wall : float
        Position of the wall.
    restitution : float
        Newton coefficient at the wall.

    Returns
    -------
    LagrangianSystem

    Examples
    --------
    >>> impact_oscillator(wall=0.3).gaps(np.array([0.1]))
    array([0.2])
    """
    return LagrangianSystem(np.array([[mass]]), stiffness=[[stiffness]], damping=[[damping]],
                            gap_matrix=[[-1.0]], gap_offset=[wall], restitution=restitution,
                            actuation=[[1.0]], names=("mass",))


@dataclass(frozen=True)
class ImpactingPendulum:
    """A damped pendulum forced at its pivot, hitting a wall at ``θ = wall``::

        θ'' + c θ' + sin θ = a cos(ωt)     while θ < wall   (gap wall - θ >= 0),
        θ'(t+) = -e θ'(t-)                 when θ = wall.

    Nonlinear between impacts, so ``event_driven`` integrates it with DOP853 (and, with
    ``sensitivity=True``, its variational equation).

    Known answer: over one period of an orbit with ``k`` impacts the monodromy has
    determinant ``e^{2k} e^{-cT}``, whatever ``a``: the flow's is ``exp(∫ tr ∂f/∂x) =
    e^{-cT}`` (Liouville; ``tr ∂f/∂x = -c``), and each impact's saltation matrix
    ``[[-e, 0], [(a+ + e a-)/v-, -e]]`` (one degree of freedom: the jump ``v -> -e v`` and
    the event-time correction only fill the lower-left entry) has determinant ``e²``.
    For the defaults a stable period-1 one-impact orbit passes near :attr:`x_guess` (from a
    long run: 150 periods at ``rtol = 1e-8``).

    Parameters
    ----------
    damping, forcing, omega : float
        ``c``, ``a`` and ``ω``.
    wall : float
        The wall's angle ``θ_w``.
    restitution : float
        ``e`` in ``[0, 1]``.
    force_jacobian : bool
        Give the force's analytic Jacobian (else the integrator differentiates the field).
    callable_mass : bool
        Give the (unit) mass as a callable ``q -> M(q)``, the path of configuration-dependent
        inertia.

    Examples
    --------
    >>> p = ImpactingPendulum()
    >>> round(p.monodromy_determinant(), 12)    # 0.8² e^{-0.2·2π/1.2}
    0.224588676594
    """

    damping: float = 0.2
    forcing: float = 0.5
    omega: float = 1.2
    wall: float = 0.4
    restitution: float = 0.8
    force_jacobian: bool = True
    callable_mass: bool = False

    #: A state at ``t = 0`` near the stable period-1 orbit of the default parameters.
    x_guess = (0.11440167, 0.93442945)

    @property
    def period(self) -> float:
        """``T = 2π/ω``."""
        return 2.0 * np.pi / check_positive("omega", self.omega)

    def with_(self, **changes: Any) -> ImpactingPendulum:
        """A copy with some parameters changed."""
        return replace(self, **changes)

    def system(self) -> LagrangianSystem:
        """The pendulum as a :class:`~nscontrol.systems.LagrangianSystem` (force callable)."""
        a, w = float(self.forcing), float(self.omega)

        def force(t: float, q: FloatArray, v: FloatArray) -> FloatArray:
            return np.array([-np.sin(q[0]) + a * np.cos(w * t)])

        def jacobian(t: float, q: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
            return np.array([[-np.cos(q[0])]]), np.zeros((1, 1))

        mass: Any = (lambda q: np.ones((1, 1))) if check_bool("callable_mass", self.callable_mass) \
            else np.ones((1, 1))
        return LagrangianSystem(mass, damping=[[self.damping]], force=force,
                                force_jacobian=(jacobian if check_bool("force_jacobian",
                                                                       self.force_jacobian)
                                                else None),
                                gap_matrix=[[-1.0]], gap_offset=[self.wall],
                                restitution=self.restitution, names=("theta",))

    def forced(self, **options: Any) -> Any:
        """The pendulum and its period as a :class:`~nscontrol.analysis.orbits.Forced`
        (``event_driven``; ``options`` such as ``rtol`` go to every run)."""
        from ..analysis.orbits import Forced

        return Forced(self.system(), None, self.period, method="event_driven",
                      options=tuple(sorted(options.items())))

    def monodromy_determinant(self, n_impacts: int = 1) -> float:
        """``e^{2k} e^{-cT}``: the monodromy's determinant of an orbit of one period ``T``
        with ``k`` impacts."""
        return float(self.restitution ** (2 * n_impacts) * np.exp(-self.damping * self.period))
