"""Tracking control of complementarity Lagrangian systems: the switching Slotine–Li controller.

Task coordinates ``q = (q1, q2)``, ``q1 >= 0`` the constraint (normal coordinate first). Each
cycle ``k`` of the task is free motion, a transition phase containing the impacts, and
constrained motion on ``q1 = 0``; the controller switches between

* ``U_nc = M q̈_r + C q̇_r + g - γ1 s`` (free motion; also during the approach, with the
  *virtual* reference ``q*_d`` that dives below the constraint by a depth ``d_k``);
* ``U_t = M q̈_r + C q̇_r + g - γ1 s̄`` after the first impact, ``q_d = (0, q*_2d)`` frozen and
  ``s̄`` built on ``q*_d = (-d_k, q*_2d)``: Slotine–Li toward the surface plus the constant
  pressing force ``γ1 γ2 d_k`` along the inward normal;
* ``U_c = U_nc - Dᵀλ_d + K_f Dᵀ(λ̂ - λ_d)`` on the constraint, with a desired contact force
  ``λ_d`` that ramps to zero at the planned take-off ``t_d``,

with ``q̃ = q - q_d``, ``s = q̃' + γ2 q̃``, ``q̇_r = q̇_d - γ2 q̃`` and the Lyapunov function
``V = ½ sᵀ M(q) s + γ1 γ2 q̃ᵀ q̃``. The controller is a :class:`~nscontrol.systems.Controller`
(continuous-time, no vector state: its phase logic is Python state) that reads the
Moreau–Jean contact estimate ``λ̂`` (the last step's impulse over ``h``) to detect the first
impact and the persistent contact. It logs, at every step start, the quantities the analysis
of :mod:`nscontrol.analysis.tracking_cycles` needs (``V``, ``V1``, phase, cycle, references).

The framework (phases, laws, virtual trajectory, Lyapunov function) is Bourgeot & Brogliato's
(2005); the depth clip, the contact-force ramp and the quintic lift-off are our choices where
the published descriptions leave the design open (see ``docs/ch03.md``).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Protocol

import numpy as np

from .._validation import (
    FloatArray,
    as_finite_scalar,
    check_in_interval,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import DimensionError, ModelError
from ..systems.feedback import StaticLaw

__all__ = ["PBCGains", "TransitionDesign", "ContactPhaseDesign", "CyclicTask",
           "CircleTask", "HalfSineTask", "TaskSpaceModel", "SwitchingTrackingController",
           "slotine_li_force", "lyapunov_decay_rate", "virtual_dive", "liftoff_blend"]


class Phase(IntEnum):
    """Phase of motion of a cycle (logged as its integer value)."""

    FREE = 0
    APPROACH = 1
    IMPACTS = 2
    CONSTRAINED = 3


@dataclass(frozen=True)
class PBCGains:
    """Gains of the passivity-based controller.

    Attributes
    ----------
    gamma1
        Velocity-error gain ``γ1 > 0``.
    gamma2
        Position-error gain ``γ2 > 0`` (in ``s = q̃' + γ2 q̃``).
    Kf
        Contact-force feedback gain ``K_f >= 0`` (``< 1`` keeps the one-step-delayed force
        loop ``λ_{k+1} = c - K_f λ_k`` stable).
    """

    gamma1: float = 8.0
    gamma2: float = 7.0
    Kf: float = 0.5

    def __post_init__(self) -> None:
        check_positive("gamma1", self.gamma1)
        check_positive("gamma2", self.gamma2)
        check_positive("Kf", self.Kf, allow_zero=True)


@dataclass(frozen=True)
class TransitionDesign:
    """The virtual trajectory of the transition phase.

    Attributes
    ----------
    delta
        Duration of the time warp that brings the nominal path to rest (s).
    Delta
        Duration of the cubic dive from rest to ``-d_k`` (s).
    depth_law
        ``"sqrt"``: ``d_k = α √V1(τ0)``; ``"linear"``: ``d_k = φ V1(τ0)``.
    alpha, phi
        Coefficients of the two depth laws.
    depth_min, depth_max
        Clip of ``d_k`` (m): ``depth_min > 0`` keeps the pressing force from vanishing with
        the tracking error (otherwise the approach stalls), ``depth_max`` bounds the impact
        when the tracking error is large. ``depth_min = 0`` and ``depth_max = inf`` remove it.
    n_consecutive_contact
        Steps with a positive impulse that declare persistent contact (start of the
        constrained phase).
    """

    delta: float = 0.4
    Delta: float = 1.0
    depth_law: str = "sqrt"
    alpha: float = 100.0
    phi: float = 1e5
    depth_min: float = 0.005
    depth_max: float = 0.05
    n_consecutive_contact: int = 5

    def __post_init__(self) -> None:
        check_positive("delta", self.delta)
        check_positive("Delta", self.Delta)
        if self.depth_law not in ("sqrt", "linear"):
            raise ModelError(f"depth_law: expected 'sqrt' or 'linear', got {self.depth_law!r}")
        check_positive("depth_min", self.depth_min, allow_zero=True)
        if not self.depth_max >= self.depth_min:
            raise ModelError(f"depth_max: expected >= depth_min = {self.depth_min}, got "
                             f"{self.depth_max}")

    def depth(self, v1: float) -> float:
        """``d_k`` from the kinetic part ``V1`` of the Lyapunov function at ``τ0``.

        Parameters
        ----------
        v1 : float
            ``V1(τ0ᵏ) = ½ sᵀ M s``.
        """
        raw = self.alpha * math.sqrt(max(v1, 0.0)) if self.depth_law == "sqrt" \
            else self.phi * max(v1, 0.0)
        return float(min(max(raw, self.depth_min), self.depth_max))


@dataclass(frozen=True)
class ContactPhaseDesign:
    """Desired contact force and take-off.

    Attributes
    ----------
    lam_rate
        ``c_λ``: ``λ_d(t) = c_λ (t_d - t)`` (N/s), zero at the planned take-off.
    lam_sat
        Saturation of the measured ``λ̂`` (N): the impulsive part of the last impacts must
        not be fed back as a force.
    liftoff_time
        ``T_l``: the normal reference leaves the surface as ``σ((t - t_d)/T_l) q1d(t)``,
        ``σ = 10θ³ - 15θ⁴ + 6θ⁵`` (zero position, velocity, acceleration at take-off).
    """

    lam_rate: float = 1.5
    lam_sat: float = 20.0
    liftoff_time: float = 0.5

    def __post_init__(self) -> None:
        check_positive("lam_rate", self.lam_rate)
        check_positive("lam_sat", self.lam_sat)
        check_positive("liftoff_time", self.liftoff_time)


class CyclicTask(Protocol):
    """A nominal task with a cycle structure (free, contact, free ...)."""

    period: float

    def nominal(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q_d, q̇_d, q̈_d)`` of the nominal task at ``t`` (new arrays: the controller
        modifies them in place)."""
        ...

    def tau0(self, k: int) -> float:
        """Start of the transition design of cycle ``k``."""
        ...

    def t_detach(self, k: int) -> float:
        """Planned take-off of cycle ``k``."""
        ...


@dataclass(frozen=True)
class CircleTask:
    """The two-link task: a circle cut by the ground, ``q = (y, x)``.

    ``x_d = xc + r cos(2πt/P)``, ``y_d = r sin(2πt/P)`` on the upper half; on the lower half
    the end effector slides on ``y = 0`` back to ``x = xc + r`` (reached at the period's end).

    Attributes
    ----------
    centre
        ``(x, y)`` of the circle's centre (``y`` must be 0: the ground cuts it in half).
    radius, period
        Radius (m) and period ``P`` (s).
    y_threshold
        ``τ0ᵏ`` is where ``y_d`` falls to this height on the descending branch.
    """

    centre: float = 0.65
    radius: float = 0.1
    period: float = 10.0
    y_threshold: float = 0.01

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", as_finite_scalar("centre", self.centre))
        object.__setattr__(self, "radius", check_positive(
            "radius", self.radius, hint="the circle's radius in metres"))
        object.__setattr__(self, "period", check_positive(
            "period", self.period, hint="the time of one turn in seconds"))
        object.__setattr__(self, "y_threshold", check_in_interval(
            "y_threshold", self.y_threshold, 0.0, self.radius,
            hint="τ0 is where the descending y_d falls to this height, between the ground "
                 "and the top of the circle"))

    def nominal(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q_d, q̇_d, q̈_d)``; on the lower half the circle's own (below-ground) path.

        Parameters
        ----------
        t : float
            Time.
        """
        w = 2 * math.pi / self.period
        c, s = math.cos(w * t), math.sin(w * t)
        r = self.radius
        return (np.array([r * s, self.centre + r * c]), np.array([r * w * c, -r * w * s]),
                np.array([-r * w * w * s, -r * w * w * c]))

    def tau0(self, k: int) -> float:
        """``kP + P/2 - P asin(y_thr/r)/(2π)``.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        P = self.period
        return k * P + P / 2 - P * math.asin(self.y_threshold / self.radius) / (2 * math.pi)

    def t_detach(self, k: int) -> float:
        """``(k + 1) P``: the end of the sliding segment.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        return (k + 1) * self.period


@dataclass(frozen=True)
class HalfSineTask:
    """The one-degree-of-freedom task: ``q_d = A sin(ωt)`` on the positive half-wave, contact
    on the negative one.

    Attributes
    ----------
    amplitude, omega
        ``A`` (m) and ``ω`` (rad/s).
    threshold
        ``τ0ᵏ`` is where ``q_d`` falls to this height on the descending branch.
    """

    amplitude: float = 0.1
    omega: float = 2 * math.pi / 8
    threshold: float = 0.01

    def __post_init__(self) -> None:
        object.__setattr__(self, "amplitude", check_positive(
            "amplitude", self.amplitude, hint="the half-wave's height in metres"))
        object.__setattr__(self, "omega", check_positive(
            "omega", self.omega, hint="the task's angular frequency in rad/s"))
        object.__setattr__(self, "threshold", check_in_interval(
            "threshold", self.threshold, 0.0, self.amplitude,
            hint="τ0 is where the descending q_d falls to this height, between the ground "
                 "and the amplitude"))

    @property
    def period(self) -> float:
        """``2π/ω``."""
        return 2 * math.pi / self.omega

    def nominal(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q_d, q̇_d, q̈_d)`` of the full sine (the controller clips the contact half).

        Parameters
        ----------
        t : float
            Time.
        """
        A, w = self.amplitude, self.omega
        return (np.array([A * math.sin(w * t)]), np.array([A * w * math.cos(w * t)]),
                np.array([-A * w * w * math.sin(w * t)]))

    def tau0(self, k: int) -> float:
        """Where ``A sin(ωt) = threshold`` descending in cycle ``k``.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        return k * self.period + (math.pi - math.asin(self.threshold / self.amplitude)) \
            / self.omega

    def t_detach(self, k: int) -> float:
        """``(k + 1) 2π/ω``.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        return (k + 1) * self.period


class TaskSpaceModel(Protocol):
    """What the controller needs of the plant model (``TwoLinkArm``, ``OneDofMass``)."""

    n_dof: int

    def task_state(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
        """Task coordinates and velocities."""
        ...

    def task_dynamics(self, theta: FloatArray, dtheta: FloatArray
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``(M_q, C_q, g_q, J)``."""
        ...

    def task_model(self, theta: FloatArray, dtheta: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                              FloatArray]:
        """``(q, q', M_q, C_q, g_q, J)`` in one evaluation."""
        ...


def slotine_li_force(Mq: FloatArray, Cq: FloatArray, gq: FloatArray, q: FloatArray,
                     dq: FloatArray, qd: FloatArray, dqd: FloatArray, ddqd: FloatArray,
                     gains: PBCGains, q_star: FloatArray | None = None) -> FloatArray:
    """``M q̈_r + C q̇_r + g - γ1 s̄``, the Slotine–Li law in task coordinates.

    ``s̄ = s`` unless ``q_star`` is given: then ``s̄ = q̇ + γ2 (q - q_star)`` (the reference
    velocity is ``q̇_d`` in both; after the first impact ``q̇_d = 0``).

    Parameters
    ----------
    Mq, Cq, gq : ndarray
        Task-space inertia, Coriolis matrix, gravity.
    q, dq : ndarray
        Task coordinates and velocities.
    qd, dqd, ddqd : ndarray
        Reference and its derivatives.
    gains : PBCGains
        ``γ1, γ2``.
    q_star : ndarray, optional
        Virtual reference of ``s̄``.
    """
    g2 = gains.gamma2
    dqr = dqd - g2 * (q - qd)
    ddqr = ddqd - g2 * (dq - dqd)
    s_bar = dq - dqr if q_star is None else dq - dqd + g2 * (q - q_star)
    return Mq @ ddqr + Cq @ dqr + gq - gains.gamma1 * s_bar


def lyapunov_decay_rate(gains: PBCGains, lambda_max: float) -> float:
    """``γ = γ1 γ2 / (γ2 λ_max + γ1)``: ``V' <= -γ V`` in the smooth phases.

    From ``V' = -γ1 |q̃'|² - γ1 γ2² |q̃|²`` and ``V <= λ_max |q̃' + γ2 q̃|² / 2 + γ1 γ2 |q̃|²``.

    Parameters
    ----------
    gains : PBCGains
        ``γ1, γ2``.
    lambda_max : float
        Largest eigenvalue of ``M(q)`` over the workspace.

    Examples
    --------
    >>> round(lyapunov_decay_rate(PBCGains(8.0, 7.0), 1.0), 6)
    3.733333
    """
    check_positive("lambda_max", lambda_max)
    return gains.gamma1 * gains.gamma2 / (gains.gamma2 * lambda_max + gains.gamma1)


def virtual_dive(t: float, tau0: float, q10: float, depth: float, delta: float,
                 Delta: float) -> tuple[float, float, float] | None:
    """Normal component of the cubic dive ``q1*(θ) = a0 + a2θ² + a3θ³`` from ``q10`` at rest
    (``t = τ0 + δ``) to ``-depth`` at rest (``t = τ0 + δ + Δ``), clamped afterwards.

    Returns ``None`` before ``τ0 + δ`` (the warp phase).

    Parameters
    ----------
    t, tau0 : float
        Time and start of the transition.
    q10 : float
        Nominal normal coordinate at ``τ0``.
    depth : float
        ``d_k``.
    delta, Delta : float
        Warp and dive durations.

    Examples
    --------
    >>> virtual_dive(0.5, 0.0, 0.01, 0.005, 0.5, 1.0)[0]
    0.01
    >>> virtual_dive(3.0, 0.0, 0.01, 0.005, 0.5, 1.0)
    (-0.005, 0.0, 0.0)
    """
    if t < tau0 + delta:
        return None
    th = min((t - tau0 - delta) / Delta, 1.0)
    a = q10 + depth
    if th >= 1.0:
        return -depth, 0.0, 0.0
    return (q10 - 3 * a * th * th + 2 * a * th ** 3, (-6 * a * th + 6 * a * th * th) / Delta,
            (-6 * a + 12 * a * th) / Delta ** 2)


def liftoff_blend(theta: float) -> tuple[float, float, float]:
    """``σ(θ) = 10θ³ - 15θ⁴ + 6θ⁵`` and its first two derivatives (``θ`` clipped to [0, 1]).

    Parameters
    ----------
    theta : float
        Normalised time since take-off.

    Examples
    --------
    >>> liftoff_blend(0.0), liftoff_blend(1.0)
    ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0))
    """
    if theta >= 1.0:
        return 1.0, 0.0, 0.0
    th = max(theta, 0.0)
    return (10 * th ** 3 - 15 * th ** 4 + 6 * th ** 5, 30 * th ** 2 - 60 * th ** 3 + 30 * th ** 4,
            60 * th - 180 * th ** 2 + 120 * th ** 3)


def _hermite(t: float, t0: float, t1: float, p0: float, v0: float, p1: float, v1: float
             ) -> tuple[float, float, float]:
    """Cubic Hermite from ``(p0, v0)`` at ``t0`` to ``(p1, v1)`` at ``t1`` (clamped)."""
    T = t1 - t0
    if T <= 0.0 or t >= t1:
        return p1, v1, 0.0
    s = max((t - t0) / T, 0.0)
    h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, \
        s**3 - s**2
    d00, d10, d01, d11 = 6 * s**2 - 6 * s, 3 * s**2 - 4 * s + 1, -6 * s**2 + 6 * s, 3 * s**2 - 2 * s
    e00, e10, e01, e11 = 12 * s - 6, 6 * s - 4, -12 * s + 6, 6 * s - 2
    pos = h00 * p0 + h10 * T * v0 + h01 * p1 + h11 * T * v1
    vel = (d00 * p0 + d10 * T * v0 + d01 * p1 + d11 * T * v1) / T
    acc = (e00 * p0 + e10 * T * v0 + e01 * p1 + e11 * T * v1) / T**2
    return pos, vel, acc


@dataclass
class _Cycle:
    """What the controller fixes and detects in one cycle (read by the analysis)."""

    index: int
    tau0: float = math.nan
    V_tau0: float = math.nan
    V1_tau0: float = math.nan
    depth: float = math.nan
    q10: float = math.nan
    q2_star: FloatArray = field(default_factory=lambda: np.zeros(0))
    t_first_impact: float = math.nan
    t_constrained: float = math.nan
    t_detach: float = math.nan
    t_star: float = math.nan
    u_star: float = math.nan


def _check_model_and_task(model: Any, task: Any) -> None:
    """A task-space model and a cyclic task of the same dimension, the task in the arm's
    reach: refused here rather than by an ``AttributeError`` or a run that cannot track."""
    from ..systems.two_link import TwoLinkArm

    for name, kind, obj, needs, example in (
            ("model", "TaskSpaceModel", model,
             ("n_dof", "task_state", "task_dynamics", "task_model"),
             "TwoLinkArm() or OneDofMass() of nscontrol.systems.two_link"),
            ("task", "CyclicTask", task, ("nominal", "tau0", "t_detach"),
             "CircleTask() or HalfSineTask()")):
        missing = [a for a in needs if not hasattr(obj, a)]
        if missing:
            raise ModelError(f"{name}: expected a {kind} (with {', '.join(needs)}), got a "
                             f"{type(obj).__name__} without {', '.join(missing)}; pass e.g. "
                             f"{example}")
    n = check_integer("model.n_dof", model.n_dof, minimum=1)
    q_d = np.atleast_1d(task.nominal(0.0)[0])
    if q_d.shape != (n,):
        raise DimensionError(f"task: its nominal q_d has {q_d.size} coordinate(s), the model "
                             f"{n}; a CircleTask goes with a TwoLinkArm, a HalfSineTask with "
                             f"a OneDofMass")
    if isinstance(model, TwoLinkArm) and isinstance(task, CircleTask):
        l1, l2 = model.params.l1, model.params.l2
        near, far = abs(task.centre) - task.radius, abs(task.centre) + task.radius
        if near < abs(l1 - l2) or far > l1 + l2:   # the circle's distances from the base
            raise ModelError(f"task: the circle of centre x = {task.centre:g} m and radius "
                             f"{task.radius:g} m spans distances [{near:.6g}, {far:.6g}] m "
                             f"from the arm's base, outside its reach [{abs(l1 - l2):.6g}, "
                             f"{l1 + l2:.6g}] m; move the centre or shrink the radius")


class SwitchingTrackingController(StaticLaw):
    """The switching passivity-based tracking controller (module docstring) as a
    continuous-time :class:`~nscontrol.systems.Controller` for :func:`nscontrol.closed_loop`.

    Parameters
    ----------
    model : TaskSpaceModel
        Task map and dynamics of the plant (``TwoLinkArm``, ``OneDofMass``).
    task : CyclicTask
        Nominal task (``CircleTask``, ``HalfSineTask``).
    gains : PBCGains
        ``γ1, γ2, K_f``.
    transition : TransitionDesign
        Virtual trajectory (ignored by the ``"impact-triggered"`` switching).
    contact : ContactPhaseDesign
        Desired contact force, saturation of ``λ̂``, lift-off.
    model_scale : float
        The controller's ``M, C, g`` are the model's times this factor (1: exact model).
    switching : {"designed", "impact-triggered"}
        ``"designed"``: transition at ``τ0ᵏ`` with the virtual dive, constrained phase after
        ``n_consecutive_contact`` contact steps, take-off at ``t_dᵏ`` with a ramp of ``λ_d``.
        ``"impact-triggered"`` (the 2007 Siconos logic): transition at the first contact
        impulse with ``q2 < trigger_q2``, ``d = √(γ2 V/γ1)``, constrained once gap and normal
        velocity are below ``1e-4``, ``λ_d = 0.5 (q2_end - q2)``, take-off when
        ``λ̂ < 1e-4`` or at the end of the nominal sliding segment (the period's end).
    trigger_q2 : float
        Tangential position below which the impact-triggered transition starts.
    q2_end : float
        End of the sliding segment (impact-triggered ``λ_d``).
    force_feedback_scale : float
        Multiplies ``K_f (λ̂ - λ_d)`` (1: the law as stated). The 2007 Siconos code fed back
        the impulse ``P = h λ̂`` instead of the force: ``h`` reproduces that scaling, which
        keeps its ``K_f = 3`` from destabilising the one-step-delayed force loop.
    detection_delay : int
        Steps by which the phase logic sees the contact impulse late (0: the last step's, as
        designed). Only the detection of the first impact and of persistent contact is
        delayed; the force feedback ``λ̂`` is not. The recorded ``t_first_impact`` is the true
        step of the impulse; the phase switch happens ``detection_delay`` steps later.
    position_noise : float
        Standard deviation (rad) of white Gaussian noise added to the measured joint angles
        at every step (0: exact measurement). The log and the ``V(τ0ᵏ)`` of each cycle are
        those of the true state (what the analysis judges); the control law and the depth
        ``d_k`` use the measured one.
    noise_seed : int
        Seed of the noise generators, reset by :meth:`reset_run`: a run is reproducible.
    force_scale, force_bias, force_noise : float
        Model of the contact-force sensor the force loop reads: ``λ̂ = a P/h + b + n``,
        ``a = force_scale``, ``b = force_bias`` (N), ``n`` white Gaussian of standard
        deviation ``force_noise`` (N), then saturated at ``lam_sat``. Defaults (1, 0, 0): the
        exact impulse over ``h``, as designed. The detection of impacts and persistent
        contact reads the true impulse (a separate contact switch), so these act on the
        force feedback ``K_f (λ̂ - λ_d)`` only.

    Examples
    --------
    >>> from nscontrol.systems.two_link import OneDofMass
    >>> ctrl = SwitchingTrackingController(OneDofMass(), HalfSineTask(), PBCGains(5.0, 5.0))
    >>> ctrl.period, ctrl.n_outputs, ctrl.compiled() is not None
    (None, 1, True)
    """

    def __init__(self, model: Any, task: Any, gains: PBCGains = PBCGains(),
                 transition: TransitionDesign = TransitionDesign(),
                 contact: ContactPhaseDesign = ContactPhaseDesign(), model_scale: float = 1.0,
                 switching: str = "designed", trigger_q2: float = 0.65,
                 q2_end: float = 0.75, force_feedback_scale: float = 1.0,
                 detection_delay: int = 0, position_noise: float = 0.0,
                 noise_seed: int = 0, force_scale: float = 1.0, force_bias: float = 0.0,
                 force_noise: float = 0.0) -> None:
        if switching not in ("designed", "impact-triggered"):
            raise ModelError(f"switching: expected 'designed' or 'impact-triggered', got "
                             f"{switching!r}")
        _check_model_and_task(model, task)
        check_type("gains", gains, PBCGains)
        check_type("transition", transition, TransitionDesign)
        check_type("contact", contact, ContactPhaseDesign)
        self.model, self.task, self.gains = model, task, gains
        self.transition, self.contact = transition, contact
        self.model_scale = check_positive("model_scale", model_scale)
        self.switching, self.trigger_q2, self.q2_end = switching, trigger_q2, q2_end
        self.force_feedback_scale = check_positive("force_feedback_scale",
                                                   force_feedback_scale, allow_zero=True)
        self.detection_delay = check_integer("detection_delay", detection_delay, minimum=0)
        self.position_noise = check_positive("position_noise", position_noise,
                                             allow_zero=True)
        self.noise_seed = check_integer("noise_seed", noise_seed, minimum=0)
        self.force_scale = check_positive("force_scale", force_scale, allow_zero=True)
        if not math.isfinite(force_bias):
            raise ModelError(f"force_bias: expected a finite force (N), got {force_bias}")
        self.force_bias = float(force_bias)
        self.force_noise = check_positive("force_noise", force_noise, allow_zero=True)
        self.n = int(model.n_dof)
        self.reset_run()

    # -- Controller protocol (update and reset from StaticLaw: the phase logic is Python
    # state of the object, not a vector state; impacts are detected from λ̂) --------------
    period = None

    @property
    def n_outputs(self) -> int:
        """One torque per joint."""
        return self.n

    @property
    def n_states(self) -> int:  # type: ignore[override]  # StaticLaw's is a constant 0
        """Length of the block state: the compiled form's phase logic when it has one
        (:meth:`compiled`; the Python methods carry it unchanged), else 0."""
        from ._complementarity_tracking_kernels import state_size

        return state_size(self.detection_delay) if self._compilable() else 0

    @property
    def x0(self) -> FloatArray:
        """The block state before a run (see :attr:`n_states`)."""
        from ._complementarity_tracking_kernels import initial_state

        return initial_state(self.detection_delay) if self._compilable() else np.zeros(0)

    def _compilable(self) -> bool:
        """The compiled form covers the designed switching with exact measurements on the
        chapter's two plants and tasks; noise and a force-sensor model stay in Python."""
        from ..systems.two_link import OneDofMass, TwoLinkArm

        return (self.switching == "designed" and self.position_noise == 0.0
                and self.force_scale == 1.0 and self.force_bias == 0.0
                and self.force_noise == 0.0 and type(self.model) in (TwoLinkArm, OneDofMass)
                and type(self.task) in (CircleTask, HalfSineTask)
                and (self.n == 2) == isinstance(self.model, TwoLinkArm)
                and (self.n == 2) == isinstance(self.task, CircleTask))

    def compiled(self) -> Any:
        """The compiled form (a :class:`~nscontrol.systems.feedback.CompiledBlock`) for
        the integrators' compiled loops, or ``None`` when a setting has none (the
        ``"impact-triggered"`` switching, position noise, a force-sensor model, another
        plant or task): the loop then runs the Python methods.

        The compiled form keeps the phase logic in the block state (layout in
        ``nscontrol.design._complementarity_tracking_kernels``), which the loop logs at
        every step start; this object's own log (:meth:`signals`) stays empty on that path.
        """
        if not self._compilable():
            return None
        from ..systems.feedback import CompiledBlock
        from . import _complementarity_tracking_kernels as kern

        return CompiledBlock(kern.tracking_output, kern.tracking_update, self._kernel_params())

    def _kernel_params(self) -> FloatArray:
        """The parameter array of the compiled form (``P_*`` layout of the kernels)."""
        from ..systems.two_link import OneDofMass
        from . import _complementarity_tracking_kernels as kern

        p = np.zeros(kern.N_PARAMS)
        p[kern.P_N] = self.n
        task = self.task
        if isinstance(task, CircleTask):
            p[kern.P_TASK] = kern.TASK_CIRCLE
            p[kern.P_TASK0:kern.P_TASK0 + 4] = (task.centre, task.radius, task.period,
                                                task.y_threshold)
        else:
            p[kern.P_TASK] = kern.TASK_HALF_SINE
            p[kern.P_TASK0:kern.P_TASK0 + 4] = (task.amplitude, task.omega, task.threshold,
                                                task.period)
        if isinstance(self.model, OneDofMass):
            p[kern.P_MODEL] = kern.MODEL_ONE_DOF
            p[kern.P_MODEL0:kern.P_MODEL0 + 2] = (self.model.m, self.model.g)
        else:
            pr = self.model.params
            p[kern.P_MODEL] = kern.MODEL_TWO_LINK
            p[kern.P_MODEL0:kern.P_MODEL0 + 7] = (pr.l1, pr.l2, pr.m1, pr.m2, pr.I1, pr.I2,
                                                  pr.g)
        g, tr, c = self.gains, self.transition, self.contact
        p[kern.P_G1], p[kern.P_G2], p[kern.P_KF] = g.gamma1, g.gamma2, g.Kf
        p[kern.P_DELTA:kern.P_NCONS + 1] = (tr.delta, tr.Delta,
                                             0.0 if tr.depth_law == "sqrt" else 1.0,
                                             tr.alpha, tr.phi, tr.depth_min, tr.depth_max,
                                             tr.n_consecutive_contact)
        p[kern.P_LRATE], p[kern.P_LSAT], p[kern.P_TLIFT] = (c.lam_rate, c.lam_sat,
                                                            c.liftoff_time)
        p[kern.P_SCALE], p[kern.P_FFS] = self.model_scale, self.force_feedback_scale
        p[kern.P_DELAY] = self.detection_delay
        return p

    def output(self, t: float, xc: FloatArray, m: Any) -> FloatArray:
        """Joint torques ``U = Jᵀ τ`` at a step start (also advances the phase logic).

        Parameters
        ----------
        t : float
            Time.
        xc : ndarray
            Empty internal state.
        m : Measurement
            Plant state ``x = [θ; θ']`` and contact estimate ``λ̂``.
        """
        lam = 0.0 if m.lam is None or np.size(m.lam) == 0 else float(np.asarray(m.lam)[0])
        return self.step(t, np.asarray(m.x, float), lam)

    def __call__(self, t: float, q: FloatArray, v: FloatArray, *,
                 lam_hat: FloatArray) -> FloatArray:
        """The same law as a Moreau–Jean ``controller=`` callable (no closed-loop block
        machinery: the integrator runs it inside its step loop).

        Parameters
        ----------
        t : float
            Time (a step start).
        q, v : ndarray
            Joint angles and velocities.
        lam_hat : ndarray
            Last step's impulses over ``h``.
        """
        lam = float(lam_hat[0]) if np.size(lam_hat) else 0.0
        return self.step(t, np.concatenate([q, v]), lam)

    # -- run state ----------------------------------------------------------------------
    def reset_run(self) -> None:
        """Forget the phase logic and the log (before a new simulation)."""
        self.phase = Phase.FREE
        self.cycle = 0
        self.contact_steps = 0
        self.liftoff_at = -math.inf
        self.cycles: list[_Cycle] = [_Cycle(0)]
        self._log: list[tuple] = []
        self._loaded: dict[str, FloatArray] | None = None     # a compiled run's (load_run)
        self._t_prev = -math.inf
        # (step start, impulse over h) of the last detection_delay + 1 steps: the phase
        # logic reads the oldest one
        self._seen: deque[tuple[float, float]] = deque(maxlen=self.detection_delay + 1)
        self._rng = np.random.default_rng(self.noise_seed)
        # the force sensor's own stream: adding force noise leaves the position noise alone
        self._force_rng = np.random.default_rng((self.noise_seed, 1))

    @property
    def current(self) -> _Cycle:
        return self.cycles[-1]

    def step(self, t: float, x: FloatArray, lam_raw: float) -> FloatArray:
        """Advance the phase logic with the contact seen over the last step, then return the
        joint torques for the next one.

        Parameters
        ----------
        t : float
            Time (a step start).
        x : ndarray
            ``[θ; θ']``.
        lam_raw : float
            Last step's impulse over ``h`` (unsaturated).
        """
        n = self.n
        x_true = x
        if self.position_noise > 0.0:   # no draw at σ = 0: the noiseless run is unchanged
            x = x.copy()
            x[:n] += self._rng.normal(0.0, self.position_noise, n)
        q, dq, Mq, Cq, gq, J = self.model.task_model(x[:n], x[n:])
        cycle, phase = self.cycle, self.phase
        self._advance(t, q, dq, Mq, self._detected(lam_raw))
        qd, dqd, ddqd, q_star, lam_d = self._reference(t, q)
        sc = self.model_scale
        tau = slotine_li_force(sc * Mq, sc * Cq, sc * gq, q, dq, qd, dqd, ddqd, self.gains,
                               q_star)
        lam_hat = min(self._force_reading(lam_raw), self.contact.lam_sat)
        if self.phase == Phase.CONSTRAINED:
            tau[0] += -lam_d + self.force_feedback_scale * self.gains.Kf * (lam_hat - lam_d)
        if x is not x_true:             # log and judge the true state, not the measured one
            q, dq = self.model.task_state(x_true[:n], x_true[n:])
            Mq = self.model.task_dynamics(x_true[:n], x_true[n:])[0]
        V, V1 = self._lyapunov(Mq, q, dq, qd, dqd)
        if x is not x_true and (cycle, phase) == (self.cycle, Phase.FREE) \
                and self.phase == Phase.APPROACH:
            self.current.V_tau0, self.current.V1_tau0 = V, V1
        self._log.append((t, int(self.phase), self.cycle, V, V1, lam_d, lam_hat,
                          self.current.depth, *q.tolist(), *dq.tolist(), *qd.tolist()))
        self._t_prev = t
        return J.T @ tau

    def _force_reading(self, lam_raw: float) -> float:
        """What the force sensor reports for the true impulse over ``h`` (``force_scale``,
        ``force_bias``, ``force_noise``); the exact value, untouched, by default."""
        lam = lam_raw
        if self.force_scale != 1.0 or self.force_bias != 0.0:
            lam = self.force_scale * lam + self.force_bias
        if self.force_noise > 0.0:      # no draw at σ = 0: the exact-sensor run is unchanged
            lam += float(self._force_rng.normal(0.0, self.force_noise))
        return lam

    def _lyapunov(self, Mq: FloatArray, q: FloatArray, dq: FloatArray, qd: FloatArray,
                  dqd: FloatArray) -> tuple[float, float]:
        g1, g2 = self.gains.gamma1, self.gains.gamma2
        e = q - qd
        s = dq - dqd + g2 * e
        V1 = 0.5 * float(s @ Mq @ s)
        return V1 + g1 * g2 * float(e @ e), V1

    def lyapunov(self, t: float, x: FloatArray) -> tuple[float, float]:
        """``(V, V1)`` at ``(t, x)`` with the current phase's reference (no phase change).

        Parameters
        ----------
        t : float
            Time.
        x : ndarray
            ``[θ; θ']``.
        """
        n = self.n
        q, dq = self.model.task_state(x[:n], x[n:])
        Mq = self.model.task_dynamics(x[:n], x[n:])[0]
        qd, dqd, _, _, _ = self._reference(t, q)
        return self._lyapunov(Mq, q, dq, qd, dqd)

    # -- phase logic --------------------------------------------------------------------
    def _detected(self, lam_raw: float) -> float:
        """The impulse over ``h`` the phase logic sees: the one ``detection_delay`` steps
        old (0 before that many steps have been taken); ``self._t_seen`` is its step start."""
        self._seen.append((self._t_prev, lam_raw))
        if len(self._seen) < (self._seen.maxlen or 1):
            self._t_seen = -math.inf
            return 0.0
        self._t_seen, lam = self._seen[0]
        return lam

    def _advance(self, t: float, q: FloatArray, dq: FloatArray, Mq: FloatArray,
                 lam_raw: float) -> None:
        if self.switching == "designed":
            self._advance_designed(t, q, dq, Mq, lam_raw)
        else:
            self._advance_triggered(t, q, dq, Mq, lam_raw)

    def _advance_designed(self, t: float, q: FloatArray, dq: FloatArray, Mq: FloatArray,
                          lam_raw: float) -> None:
        cyc, tr = self.current, self.transition
        if self.phase == Phase.FREE and t >= self.task.tau0(self.cycle) - 1e-12:
            qd, dqd, _, _, _ = self._reference(t, q)
            V, V1 = self._lyapunov(Mq, q, dq, qd, dqd)
            q_nom = self.task.nominal(t)[0]
            cyc.tau0, cyc.V_tau0, cyc.V1_tau0 = t, V, V1
            cyc.depth = tr.depth(V1)
            cyc.q10, cyc.q2_star = float(q_nom[0]), q_nom[1:].copy()
            cyc.t_detach = self.task.t_detach(self.cycle)
            cyc.t_star, cyc.u_star = self._dive_crossing(cyc)
            self.phase = Phase.APPROACH
        elif self.phase == Phase.APPROACH and lam_raw > 0.0:
            cyc.t_first_impact = self._t_seen
            self.phase, self.contact_steps = Phase.IMPACTS, 1
        elif self.phase == Phase.IMPACTS:
            self.contact_steps = self.contact_steps + 1 if lam_raw > 0.0 else 0
            if self.contact_steps >= tr.n_consecutive_contact:
                cyc.t_constrained = t
                self.phase = Phase.CONSTRAINED
        if self.phase in (Phase.IMPACTS, Phase.CONSTRAINED) and t >= cyc.t_detach - 1e-12:
            self._take_off(t)

    def _advance_triggered(self, t: float, q: FloatArray, dq: FloatArray, Mq: FloatArray,
                           lam_raw: float) -> None:
        cyc = self.current
        if self.phase == Phase.FREE and lam_raw > 0.0 and q[1] < self.trigger_q2:
            qd, dqd, _, _, _ = self._reference(t, q)
            V, V1 = self._lyapunov(Mq, q, dq, qd, dqd)
            cyc.tau0 = cyc.t_first_impact = self._t_seen
            cyc.V_tau0, cyc.V1_tau0 = V, V1
            cyc.depth = math.sqrt(self.gains.gamma2 * V / self.gains.gamma1)
            cyc.q10, cyc.q2_star = 0.0, q[1:].copy()
            # the nominal sliding segment of this period ends at the period's end
            cyc.t_detach = self.task.t_detach(int(t // self.task.period))
            self.phase = Phase.IMPACTS
        elif self.phase == Phase.IMPACTS and q[0] <= 1e-4 and abs(dq[0]) <= 1e-4:
            cyc.t_constrained = t
            self.phase, self.contact_steps = Phase.CONSTRAINED, 0
        elif self.phase == Phase.CONSTRAINED:
            # take-off once the contact force, after it has built up, falls below 1e-4 N
            # (a gap of up to 1e-4 m is accepted as contact: no force may follow at once)
            if lam_raw >= 1e-4:
                self.contact_steps += 1
            elif self.contact_steps > 0:
                self._take_off(t)
                return
            if t >= cyc.t_detach - 1e-12:   # the nominal path leaves the ground
                self._take_off(t)

    def _take_off(self, t: float) -> None:
        self.current.t_detach = t
        self.liftoff_at = t
        self.phase = Phase.FREE
        self.cycle += 1
        self.cycles.append(_Cycle(self.cycle))

    def _dive_crossing(self, cyc: _Cycle) -> tuple[float, float]:
        """``t*`` where the dive crosses ``q1 = 0`` and its speed there (bisection on the
        monotone cubic)."""
        tr = self.transition
        lo, hi = cyc.tau0 + tr.delta, cyc.tau0 + tr.delta + tr.Delta
        if cyc.q10 <= 0.0:
            return lo, 0.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            val = virtual_dive(mid, cyc.tau0, cyc.q10, cyc.depth, tr.delta, tr.Delta)
            if val is not None and val[0] > 0.0:
                lo = mid
            else:
                hi = mid
        dive = virtual_dive(hi, cyc.tau0, cyc.q10, cyc.depth, tr.delta, tr.Delta)
        return hi, float(dive[1]) if dive is not None else 0.0

    # -- references ---------------------------------------------------------------------
    def _reference(self, t: float, q: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray | None, float]:
        """``(q_d, q̇_d, q̈_d, q*_d or None, λ_d)`` of the current phase."""
        cyc, n = self.current, self.n
        if self.phase == Phase.FREE:
            qd, dqd, ddqd = self.task.nominal(t)     # fresh arrays: modified in place below
            if self.switching == "designed":
                a, b, c = liftoff_blend((t - self.liftoff_at) / self.contact.liftoff_time)
                if a < 1.0:   # y = σ y_nom: leaves the surface with zero velocity
                    T = self.contact.liftoff_time
                    qd[0], dqd[0], ddqd[0] = (a * qd[0], b / T * qd[0] + a * dqd[0],
                                              c / T**2 * qd[0] + 2 * b / T * dqd[0]
                                              + a * ddqd[0])
            return qd, dqd, ddqd, None, 0.0
        if self.phase == Phase.APPROACH:
            return (*self._virtual(t, cyc), None, 0.0)
        if self.phase == Phase.IMPACTS:
            qd = np.concatenate([[0.0], cyc.q2_star])
            q_star = np.concatenate([[-cyc.depth], cyc.q2_star])
            return qd, np.zeros(n), np.zeros(n), q_star, 0.0
        # constrained
        if self.switching == "designed":
            qd, dqd, ddqd = np.zeros(n), np.zeros(n), np.zeros(n)
            for i in range(1, n):
                p1, v1 = self.task.nominal(cyc.t_detach)[0][i], \
                    self.task.nominal(cyc.t_detach)[1][i]
                qd[i], dqd[i], ddqd[i] = _hermite(t, cyc.t_constrained, cyc.t_detach,
                                                  float(cyc.q2_star[i - 1]), 0.0, p1, v1)
            lam_d = self.contact.lam_rate * max(cyc.t_detach - t, 0.0)
            return qd, dqd, ddqd, None, lam_d
        qd, dqd, ddqd = (a.copy() for a in self.task.nominal(t))
        qd[0] = dqd[0] = ddqd[0] = 0.0
        lam_d = 0.5 * max(self.q2_end - float(q[1]), 0.0) if n > 1 else 0.0
        return qd, dqd, ddqd, None, lam_d

    def _virtual(self, t: float, cyc: _Cycle) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``q*_d``: the nominal path time-warped to rest, then the cubic dive."""
        tr, n = self.transition, self.n
        dive = virtual_dive(t, cyc.tau0, cyc.q10, cyc.depth, tr.delta, tr.Delta)
        if dive is not None:
            qd = np.concatenate([[dive[0]], cyc.q2_star])
            dqd, ddqd = np.zeros(n), np.zeros(n)
            dqd[0], ddqd[0] = dive[1], dive[2]
            return qd, dqd, ddqd
        s, d = t - cyc.tau0, tr.delta
        psi = cyc.tau0 + (s - d) ** 2 * s / d**2
        dpsi = (s - d) * (3 * s - d) / d**2
        ddpsi = (6 * s - 4 * d) / d**2
        p, v, a = self.task.nominal(psi)
        return p, v * dpsi, a * dpsi**2 + v * ddpsi

    # -- log ----------------------------------------------------------------------------
    def signals(self, traj: Any = None) -> dict[str, FloatArray]:
        """The per-step log as arrays (one row per step start).

        Keys: ``t``, ``phase``, ``cycle``, ``V``, ``V1``, ``lam_d``, ``lam_hat``, ``depth``,
        ``q_task``, ``dq_task``, ``qd``.

        Parameters
        ----------
        traj : Trajectory, optional
            A closed-loop run on the compiled path (its ``"xc"`` signal holds the compiled
            form's block state): the log is read back from it, with the same rows as the
            Python path's. Without it, the Python path's own log.
        """
        n = self.n
        if traj is not None and self.n_states and "xc" in traj.signals:
            return self._signals_from_block_state(traj)
        if self._loaded is not None:
            return self._loaded
        if not self._log:
            return {}
        a = np.array(self._log, dtype=float)
        return {"t": a[:, 0], "phase": a[:, 1], "cycle": a[:, 2], "V": a[:, 3],
                "V1": a[:, 4], "lam_d": a[:, 5], "lam_hat": a[:, 6], "depth": a[:, 7],
                "q_task": a[:, 8:8 + n], "dq_task": a[:, 8 + n:8 + 2 * n],
                "qd": a[:, 8 + 2 * n:8 + 3 * n]}

    def _signals_from_block_state(self, traj: Any) -> dict[str, FloatArray]:
        """:meth:`signals` of a compiled run: the block state logged at every step start
        (sample ``k + 1`` shows the row of step start ``k``)."""
        from . import _complementarity_tracking_kernels as kern

        n = self.n
        xc = np.asarray(traj.signals["xc"])
        if xc.ndim != 2 or xc.shape[1] != self.n_states or xc.shape[0] != traj.t.size:
            raise ModelError(f"traj: expected the 'xc' signal of this controller's compiled "
                             f"form at every step ({traj.t.size} x {self.n_states}), got "
                             f"shape {xc.shape}; record every step")
        rows = xc[1:]
        x = np.ascontiguousarray(np.asarray(traj.x, float)[:-1, :2 * n])
        task = kern.task_rows(x, self._kernel_params())
        phase = rows[:, kern.X_PHASE]
        # the Python log shows a cycle's depth as NaN until it is fixed (free motion)
        depth = np.where(phase == kern.FREE, np.nan, rows[:, kern.X_DEPTH])
        return {"t": rows[:, kern.X_TPREV].copy(), "phase": phase.copy(),
                "cycle": rows[:, kern.X_CYCLE].copy(), "V": rows[:, kern.X_V].copy(),
                "V1": rows[:, kern.X_V1].copy(), "lam_d": rows[:, kern.X_LAM_D].copy(),
                "lam_hat": rows[:, kern.X_LAM_HAT].copy(), "depth": depth,
                "q_task": task[:, :n], "dq_task": task[:, n:],
                "qd": rows[:, kern.X_QD:kern.X_QD + n].copy()}

    def cycles_of(self, traj: Any) -> list[_Cycle]:
        """The per-cycle record (what ``self.cycles`` holds after a Python run) read back
        from a closed-loop run on the compiled path.

        Parameters
        ----------
        traj : Trajectory
            The run (its ``"xc"`` signal, recorded at every step).
        """
        from . import _complementarity_tracking_kernels as kern

        self._signals_from_block_state(traj)          # validates the signal's shape
        rows = np.asarray(traj.signals["xc"])[1:]
        cyc = rows[:, kern.X_CYCLE]
        out: list[_Cycle] = []
        for c in range(int(cyc.max()) + 1 if cyc.size else 1):
            lo, hi = int(np.searchsorted(cyc, c, "left")), int(np.searchsorted(cyc, c, "right"))
            out.append(self._cycle_of_rows(c, rows, lo, hi))
        return out

    def _cycle_of_rows(self, c: int, rows: FloatArray, lo: int, hi: int) -> _Cycle:
        """Cycle ``c`` from its rows ``lo:hi`` (phases only move forward in a cycle, and a
        take-off leaves from the impacts or constrained phase: the last row holds every
        field fixed so far; the next cycle's first row, the take-off)."""
        from . import _complementarity_tracking_kernels as kern

        cycle = _Cycle(c)
        if hi <= lo:
            return cycle
        last = rows[hi - 1]
        phase = last[kern.X_PHASE]
        if phase >= kern.APPROACH:
            cycle.tau0, cycle.V_tau0, cycle.V1_tau0 = (float(last[kern.X_TAU0]),
                                                       float(last[kern.X_V_TAU0]),
                                                       float(last[kern.X_V1_TAU0]))
            cycle.depth, cycle.q10 = float(last[kern.X_DEPTH]), float(last[kern.X_Q10])
            cycle.q2_star = np.array([last[kern.X_Q2STAR]])[:self.n - 1]
            cycle.t_detach = float(last[kern.X_T_DETACH])
            cycle.t_star, cycle.u_star = float(last[kern.X_T_STAR]), float(last[kern.X_U_STAR])
        if phase >= kern.IMPACTS:
            cycle.t_first_impact = float(last[kern.X_T_IMPACT])
        if phase >= kern.CONSTRAINED:
            cycle.t_constrained = float(last[kern.X_T_CONSTRAINED])
        if hi < rows.shape[0]:                   # taken off: the next cycle's first row
            cycle.t_detach = float(rows[hi, kern.X_LIFTOFF])
        if cycle.t_first_impact == kern.NEVER:
            cycle.t_first_impact = -math.inf
        return cycle

    def load_run(self, traj: Any) -> None:
        """Make this object's run state that of a closed-loop run on the compiled path, as
        if the run had called the Python methods: :meth:`signals` (without argument) gives
        its log, ``cycles`` its per-cycle record, and the phase, cycle and take-off time
        are those after its last step start (what :meth:`lyapunov` reads).

        Parameters
        ----------
        traj : Trajectory
            The run (its ``"xc"`` signal, recorded at every step).
        """
        from . import _complementarity_tracking_kernels as kern

        signals = self._signals_from_block_state(traj)
        self.reset_run()
        self.cycles = self.cycles_of(traj)
        self._loaded = signals
        if signals["t"].size:
            last = np.asarray(traj.signals["xc"])[-1]
            self.phase, self.cycle = Phase(int(last[kern.X_PHASE])), int(last[kern.X_CYCLE])
            self.contact_steps = int(last[kern.X_CONTACT])
            lift = float(last[kern.X_LIFTOFF])
            self.liftoff_at = -math.inf if lift == kern.NEVER else lift
            self._t_prev = float(last[kern.X_TPREV])
