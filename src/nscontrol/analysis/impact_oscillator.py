"""The harmonically forced impact oscillator: closed-form period-1 orbits, multipliers, grazing.

Model
-----
A mass ``m`` on a spring ``k`` and a damper ``c``, driven by ``F cos(ωt)``, with a rigid stop
at ``q = d`` (gap ``d - q >= 0``) and Newton restitution ``r``::

    m q'' + c q' + k q = F cos(ωt)      while q < d,
    q'(t+) = -r q'(t-)                  when q = d, q'(t-) > 0.

Non-impacting steady state and grazing
--------------------------------------
Away from the stop the steady state is ``q_p(t) = A cos(ωt - φ)`` with
``A = F / |k - mω² + icω|``, ``φ = arg(k - mω² + icω)``. It touches the stop (grazes) when
``A = d``: for ``d > 0`` the **grazing forcing** is exactly

    F_g = d · sqrt((k - mω²)² + (cω)²).

Period-1 one-impact orbit (Shaw & Holmes 1983, derived here)
------------------------------------------------------------
Write ``q = q_p + e``: the deviation ``e = (e_q, e_v)`` obeys the homogeneous flow
``e' = H e``, ``H = [[0, 1], [-k/m, -c/m]]``, ``Φ(t) = e^{Ht}``. Let the impact happen at
``t0`` with speed ``v > 0`` and let ``θ = ωt0 - φ``, ``P = d - A cos θ`` (gap of ``q_p`` at
the impact), ``Q = q_p'(t0) = -Aω sin θ``. Just after the impact ``e(t0+) = (P, -rv - Q)``;
one period later the orbit must be back just before the impact, ``e(t0-) = (P, v - Q)``
(``q_p`` is ``T``-periodic, ``T = 2π/ω``)::

    (P, v - Q) = Φ(T) (P, -rv - Q).

With ``Φ(T) = [[φ11, φ12], [φ21, φ22]]`` the second row gives the impact speed

    v = (φ21 P + (1 - φ22) Q) / (1 + r φ22)

and, substituted in the first, ``α P + β Q = 0`` with ``α = (1 - φ11)(1 + rφ22) + rφ12φ21``,
``β = (1 + r)φ12``, i.e. ``A (α cos θ + βω sin θ) = α d``, or

    A R cos(θ - ψ) = α d,   R = sqrt(α² + β²ω²),  ψ = atan2(βω, α).

Two phases ``θ± = ψ ± arccos(αd/(AR))`` exist when ``|αd| <= AR`` (they merge at a fold);
an orbit is physical when ``v > 0`` and ``q < d`` between impacts (checked on the exact flow).

Multipliers
-----------
The impact map ``(q, v) -> (q, -rv)`` on the guard ``h(x) = q - d = 0`` has the saltation
matrix ``S = R + (f+ - R f-) ∇hᵀ / (∇hᵀ f-)`` with ``R = diag(1, -r)``,
``f± = (v±, a±)``, ``a± = (F cos ωt0 - c v± - k d)/m``, ``v- = v``, ``v+ = -rv``. Since
``a+ + r a- = (1 + r)(F cos ωt0 - k d)/m``,

    S = [[-r, 0], [(1 + r)(F cos ωt0 - k d)/(m v), -r]],

and the monodromy over one period, from just before an impact to just before the next, is
``M = Φ(T) S``, whose
eigenvalues are the Floquet multipliers: ``det M = r² e^{-cT/m}`` and
``μ = tr M/2 ± sqrt(tr² M/4 - det M)``. The orbit flips where ``1 + tr M + det M = 0`` and
folds where ``1 - tr M + det M = 0``; as ``v → 0`` (grazing) ``S21 → ∞`` and one multiplier
leaves the unit circle, the square-root singularity of grazing.

References
----------
S. W. Shaw, P. J. Holmes, "A periodically forced piecewise linear oscillator", J. Sound Vib.
90 (1983); A. B. Nordmark, "Non-periodic motion caused by grazing incidence in an impact
oscillator", J. Sound Vib. 145 (1991).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize

from .._validation import FloatArray, check_bool, check_in_interval, check_positive
from ..errors import ModelError

__all__ = ["ImpactOscillator", "OneImpactOrbit", "OscillatorFamily"]


@dataclass(frozen=True)
class OneImpactOrbit:
    """A period-1 orbit with one impact per period, in closed form.

    Attributes
    ----------
    impact_time
        ``t0`` in ``[0, T)``: the impact instant.
    impact_velocity
        ``v`` just before the impact (``> 0`` for a physical orbit).
    monodromy
        ``Φ(T) S``, from just before the impact to just before the next (2×2).
    multipliers
        Its eigenvalues, by decreasing modulus.
    admissible
        ``v > 0`` and the orbit stays left of the stop between impacts.
    x0
        The state ``(q, v)`` at ``t = 0`` (the stroboscopic section).
    """

    impact_time: float
    impact_velocity: float
    monodromy: FloatArray
    multipliers: np.ndarray
    admissible: bool
    x0: FloatArray

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle."""
        return bool(np.all(np.abs(self.multipliers) < 1.0))


@dataclass(frozen=True)
class ImpactOscillator:
    """``m q'' + c q' + k q = F cos(ωt)``, stop at ``q = d``, restitution ``r``.

    Parameters
    ----------
    mass, damping, stiffness : float
        ``m > 0``, ``c >= 0``, ``k > 0``.
    forcing, omega : float
        Amplitude ``F >= 0`` and frequency ``ω > 0`` of the drive.
    stop : float
        Position ``d`` of the stop.
    restitution : float
        ``r`` in ``(0, 1]``.

    Examples
    --------
    >>> osc = ImpactOscillator(forcing=0.5, omega=1.5, stop=0.2)
    >>> round(osc.grazing_forcing(), 12)   # d·|k - mω² + icω|
    0.25179356624
    """

    mass: float = 1.0
    damping: float = 0.1
    stiffness: float = 1.0
    forcing: float = 1.0
    omega: float = 2.0
    stop: float = 0.5
    restitution: float = 0.8

    def __post_init__(self) -> None:
        check_positive("mass", self.mass)
        check_positive("damping", self.damping, allow_zero=True)
        check_positive("stiffness", self.stiffness)
        check_positive("forcing", self.forcing, allow_zero=True)
        check_positive("omega", self.omega)
        if check_in_interval("restitution", self.restitution, 0.0, 1.0) == 0.0:
            raise ModelError("restitution: expected r in (0, 1], got 0 (a plastic stop has "
                             "sticking phases, which the one-impact closed form excludes)")
        if not math.isfinite(self.stop):
            raise ModelError(f"stop: expected a finite position, got {self.stop!r}")

    # -- the model --------------------------------------------------------------------------
    @property
    def period(self) -> float:
        """``T = 2π/ω``."""
        return 2.0 * math.pi / self.omega

    def with_(self, **changes: Any) -> ImpactOscillator:
        """A copy with some parameters changed (``osc.with_(forcing=2.0)``)."""
        return replace(self, **changes)

    def system(self, *, drive_as_force: bool = False) -> Any:
        """The model as a :class:`~nscontrol.systems.lagrangian.LagrangianSystem`.

        With ``drive_as_force`` the drive ``F cos(ωt)`` is part of the model as a force
        callable (then no input is passed): the same motion, but nonlinear to the integrator,
        which takes DOP853 (and for orbits its variational equation) instead of exponentials.
        """
        from ..systems.lagrangian import LagrangianSystem

        drive = _Drive(self.forcing, self.omega) \
            if check_bool("drive_as_force", drive_as_force) else None
        return LagrangianSystem(np.array([[self.mass]]), stiffness=np.array([[self.stiffness]]),
                                damping=np.array([[self.damping]]),
                                gap_matrix=np.array([[-1.0]]), gap_offset=np.array([self.stop]),
                                restitution=self.restitution, actuation=np.array([[1.0]]),
                                names=("mass",), force=drive,
                                force_jacobian=None if drive is None else _Drive.jacobian)

    def input(self) -> Any:
        """The drive ``F cos(ωt)`` as an :class:`~nscontrol.numerics.lti.Exosystem`."""
        from ..numerics.lti import Exosystem

        return Exosystem.sinusoid(self.forcing, self.omega, phase=math.pi / 2)

    def forced(self, *, drive_as_force: bool = False, **options: Any) -> Any:
        """The model, its drive and period as a :class:`~nscontrol.analysis.orbits.Forced`
        (``drive_as_force``: see :meth:`system`; ``options`` such as ``rtol`` go to every
        run)."""
        from .orbits import Forced

        return Forced(self.system(drive_as_force=drive_as_force),
                      None if drive_as_force else self.input(), self.period,
                      method="event_driven", options=tuple(sorted(options.items())))

    # -- closed forms -----------------------------------------------------------------------
    def _response(self) -> complex:
        return complex(self.stiffness - self.mass * self.omega ** 2, self.damping * self.omega)

    def amplitude(self) -> float:
        """Amplitude ``A`` of the non-impacting steady state."""
        return self.forcing / abs(self._response())

    def phase_lag(self) -> float:
        """``φ`` in ``q_p = A cos(ωt - φ)``."""
        return math.atan2(self.damping * self.omega, self.stiffness - self.mass * self.omega ** 2)

    def grazing_forcing(self) -> float:
        """``F_g = d·|k - mω² + icω|``: the forcing at which the non-impacting steady state
        just touches the stop (requires ``d > 0``)."""
        if self.stop <= 0:
            raise ModelError(f"stop: grazing of the non-impacting orbit needs d > 0, got "
                             f"{self.stop}")
        return self.stop * abs(self._response())

    def non_impacting_state(self, t: float = 0.0) -> FloatArray:
        """``(q_p(t), q_p'(t))`` of the non-impacting steady state."""
        A, phi = self.amplitude(), self.phase_lag()
        th = self.omega * t - phi
        return np.array([A * math.cos(th), -A * self.omega * math.sin(th)])

    def homogeneous_flow(self, t: float) -> FloatArray:
        """``Φ(t) = e^{Ht}`` of the unforced oscillator."""
        H = np.array([[0.0, 1.0], [-self.stiffness / self.mass, -self.damping / self.mass]])
        return scipy.linalg.expm(H * t)

    def one_impact_orbits(self) -> list[OneImpactOrbit]:
        """Both closed-form period-1 one-impact orbits (empty past their fold), the
        admissible ones first; see the module docstring for the derivation."""
        T, d, r, A = self.period, self.stop, self.restitution, self.amplitude()
        Phi = self.homogeneous_flow(T)
        (p11, p12), (p21, p22) = Phi
        alpha = (1 - p11) * (1 + r * p22) + r * p12 * p21
        beta = (1 + r) * p12
        R = math.hypot(alpha, beta * self.omega)
        if A == 0.0 or abs(alpha * d) > A * R:
            return []
        psi = math.atan2(beta * self.omega, alpha)
        acos = math.acos(alpha * d / (A * R))
        orbits = [self._orbit_at(psi + s * acos, Phi) for s in (1.0, -1.0)]
        return sorted(orbits, key=lambda o: not o.admissible)

    def _orbit_at(self, theta: float, Phi: FloatArray) -> OneImpactOrbit:
        m, k, F, w = self.mass, self.stiffness, self.forcing, self.omega
        d, r, A, T = self.stop, self.restitution, self.amplitude(), self.period
        P, Q = d - A * math.cos(theta), -A * w * math.sin(theta)
        v = (Phi[1, 0] * P + (1 - Phi[1, 1]) * Q) / (1 + r * Phi[1, 1])
        t0 = ((theta + self.phase_lag()) / w) % T
        if v != 0.0:
            S = np.array([[-r, 0.0], [(1 + r) * (F * math.cos(w * t0) - k * d) / (m * v), -r]])
            M = Phi @ S
            mu = np.linalg.eigvals(M)
            mu = mu[np.argsort(-np.abs(mu))]
        else:   # exactly grazing: the saltation matrix is unbounded
            M, mu = np.full((2, 2), np.nan), np.full(2, np.nan + 0j)
        e_post = np.array([P, -r * v - Q])
        x0 = self.non_impacting_state(0.0) + self.homogeneous_flow(T - t0) @ e_post
        ok = v > 0 and self._stays_left(t0, e_post)
        return OneImpactOrbit(t0, float(v), M, mu, bool(ok), x0)

    def _stays_left(self, t0: float, e_post: FloatArray, n: int = 512) -> bool:
        """``q < d`` strictly inside ``(t0, t0 + T)``: sampled exact flow, the samples'
        maximum refined by a parabola (it only has to separate ``q < d`` from a crossing)."""
        T = self.period
        s = np.linspace(0.0, T, n + 1)[1:-1]
        H = np.array([[0.0, 1.0], [-self.stiffness / self.mass, -self.damping / self.mass]])
        lam, V = np.linalg.eig(H)
        coef = np.linalg.solve(V, e_post.astype(complex))
        e_q = np.real((V[0] * coef) @ np.exp(np.outer(lam, s)))
        A, phi = self.amplitude(), self.phase_lag()
        q = A * np.cos(self.omega * (t0 + s) - phi) + e_q
        return bool(np.max(q) < self.stop)

    def admissible_orbit(self) -> OneImpactOrbit:
        """The admissible one-impact orbit; ``ModelError`` when there is none."""
        orbits = [o for o in self.one_impact_orbits() if o.admissible]
        if not orbits:
            raise ModelError(f"forcing: no admissible period-1 one-impact orbit at F = "
                             f"{self.forcing}, ω = {self.omega}; check the stop and the "
                             f"forcing (grazing at F = {self.stop * abs(self._response()):.6g})")
        return orbits[0]

    def flip_forcing(self, bracket: tuple[float, float]) -> float:
        """The forcing at which a multiplier of the admissible one-impact orbit is ``-1``
        (``1 + tr M + det M = 0``), by Brent's method on the closed form inside
        ``bracket`` (which must hold one sign change)."""
        def g(F: float) -> float:
            M = self.with_(forcing=F).admissible_orbit().monodromy
            return 1.0 + float(np.trace(M)) + float(np.linalg.det(M))

        return float(scipy.optimize.brentq(g, *bracket, xtol=1e-15, rtol=4 * np.finfo(float).eps))


@dataclass(frozen=True)
class _Drive:
    """``(t, q, v) -> [F cos(ωt)]`` as a picklable force callable."""

    forcing: float
    omega: float

    def __call__(self, t: float, q: FloatArray, v: FloatArray) -> FloatArray:
        return np.array([self.forcing * math.cos(self.omega * t)])

    @staticmethod
    def jacobian(t: float, q: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The drive depends on time only."""
        return np.zeros((1, 1)), np.zeros((1, 1))


@dataclass(frozen=True)
class OscillatorFamily:
    """Picklable factory ``p -> Forced`` varying one parameter of an :class:`ImpactOscillator`
    (for :func:`~nscontrol.analysis.continuation.continue_orbit` and
    :func:`~nscontrol.analysis.bifurcation.bifurcation_diagram`).

    Parameters
    ----------
    base : ImpactOscillator
        The oscillator whose parameter varies.
    parameter : str
        The name of the varied field of :class:`ImpactOscillator`.

    Examples
    --------
    >>> fam = OscillatorFamily(ImpactOscillator(), "forcing")
    >>> fam(2.0).period == ImpactOscillator().period
    True
    """

    base: ImpactOscillator
    parameter: str = "forcing"

    def __post_init__(self) -> None:
        if self.parameter not in self.parameters():
            raise ModelError(f"parameter: expected one of {list(self.parameters())}, got "
                             f"{self.parameter!r}")

    @staticmethod
    def parameters() -> tuple[str, ...]:
        """The names a family can vary: the fields of :class:`ImpactOscillator`, sorted."""
        return tuple(sorted(ImpactOscillator.__dataclass_fields__))

    def oscillator(self, p: float) -> ImpactOscillator:
        """The oscillator at parameter value ``p``."""
        return self.base.with_(**{self.parameter: float(p)})

    def __call__(self, p: float) -> Any:
        return self.oscillator(p).forced()
