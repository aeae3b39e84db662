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
(continuous-time; its phase logic is its block state) that reads the Moreau–Jean contact
estimate ``λ̂`` (the last step's impulse over ``h``) to detect the first impact and the
persistent contact. It logs, at every step start, the quantities the analysis of
:mod:`nscontrol.analysis.tracking_cycles` needs (``V``, ``V1``, phase, cycle, references).

The law, the references and the phase logic are written once, as the compiled kernels of
``nscontrol.design._complementarity_tracking_kernels``: the compiled closed loop runs them as
a :class:`~nscontrol.systems.feedback.CompiledBlock`, the Python methods call them (adding
the measurement noise drawn from NumPy's generators), and the helpers below
(:func:`virtual_dive`, :func:`liftoff_blend`, :func:`slotine_li_force`, the tasks) wrap the
same kernels.

The framework (phases, laws, virtual trajectory, Lyapunov function) is Bourgeot & Brogliato's
(2005); the depth clip, the contact-force ramp and the quintic lift-off are our choices where
the published descriptions leave the design open (see ``docs/ch03.md``).
"""

from __future__ import annotations

import math
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
from . import _complementarity_tracking_kernels as kern

__all__ = ["PBCGains", "TransitionDesign", "ContactPhaseDesign", "CyclicTask",
           "CircleTask", "HalfSineTask", "TaskSpaceModel", "SwitchingTrackingController",
           "TrackingCycle", "slotine_li_force", "lyapunov_decay_rate", "virtual_dive",
           "liftoff_blend"]


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
        return float(kern.depth(float(v1), 0.0 if self.depth_law == "sqrt" else 1.0,
                                float(self.alpha), float(self.phi), float(self.depth_min),
                                float(self.depth_max)))


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
        qd, dqd, ddqd = np.empty(2), np.empty(2), np.empty(2)
        kern.circle_nominal(float(t), self.centre, self.radius, self.period, qd, dqd, ddqd)
        return qd, dqd, ddqd

    def tau0(self, k: int) -> float:
        """``kP + P/2 - P asin(y_thr/r)/(2π)``.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        return float(kern.circle_tau0(k, self.radius, self.period, self.y_threshold))

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
        qd, dqd, ddqd = np.empty(1), np.empty(1), np.empty(1)
        kern.half_sine_nominal(float(t), self.amplitude, self.omega, qd, dqd, ddqd)
        return qd, dqd, ddqd

    def tau0(self, k: int) -> float:
        """Where ``A sin(ωt) = threshold`` descending in cycle ``k``.

        Parameters
        ----------
        k : int
            Cycle index.
        """
        return float(kern.half_sine_tau0(k, self.amplitude, self.omega, self.threshold,
                                         self.period))

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
    args = [np.ascontiguousarray(a, dtype=float) for a in (Mq, Cq, gq, q, dq, qd, dqd, ddqd)]
    tau = np.empty(args[3].size)
    has_star = q_star is not None
    qs = np.ascontiguousarray(q_star if has_star else args[3], dtype=float)
    kern.slotine_li(*args, float(gains.gamma1), float(gains.gamma2), 1.0,  # type: ignore[call-arg]  # numba's stub
                    has_star, qs, tau)
    return tau


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
    q1, v1, a1 = kern.dive(float(t), float(tau0), float(q10), float(depth), float(delta),
                           float(Delta))
    return float(q1), float(v1), float(a1)


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
    a, b, c = kern.liftoff_blend(float(theta))
    return float(a), float(b), float(c)


@dataclass
class TrackingCycle:
    """What the controller fixed and detected in one cycle of the task (the analysis of
    :mod:`nscontrol.analysis.tracking_cycles` reads it). An instant or value the cycle has
    not reached yet is NaN.

    Attributes
    ----------
    index : int
        The cycle ``k`` (from 0).
    tau0 : float
        ``τ0ᵏ``: the start of the transition phase (s).
    V_tau0, V1_tau0 : float
        The Lyapunov function ``V`` and its kinetic part ``V1 = ½ sᵀ M s`` at ``τ0ᵏ``.
    depth : float
        ``d_k``: the depth of the virtual dive below the constraint (m).
    q10 : float
        The nominal normal coordinate at ``τ0ᵏ``, where the dive starts (m).
    q2_star : ndarray
        ``q*_2d``: the tangential coordinates frozen during the impacts (empty for the
        one-coordinate mass, and before ``τ0ᵏ``).
    t_first_impact : float
        The step start of the first contact impulse of the cycle (s).
    t_constrained : float
        The start of the constrained phase (s).
    t_detach : float
        The planned take-off ``t_dᵏ`` while the cycle runs; once the arm has taken off, the
        take-off's step start (s).
    t_star, u_star : float
        Where the designed dive crosses ``q1 = 0`` (s) and its speed there (m/s); NaN for
        the impact-triggered switching.
    """

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


#: The compiled blocks made so far, by their parameters' bytes (see ``compiled``).
_BLOCKS: dict[bytes, Any] = {}


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
    from ..systems.two_link import OneDofMass

    if type(model) not in (TwoLinkArm, OneDofMass) or type(task) not in (CircleTask,
                                                                          HalfSineTask):
        raise ModelError(f"model, task: the controller's kernels know the TwoLinkArm and "
                         f"OneDofMass models and the CircleTask and HalfSineTask tasks, got "
                         f"a {type(model).__name__} and a {type(task).__name__}; pass those "
                         f"of nscontrol.systems.two_link and this module")
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
        if switching == "impact-triggered" and self.n < 2:
            raise ModelError("switching: 'impact-triggered' reads the tangential coordinate "
                             "q2 (its trigger and force reference); the model has one "
                             "coordinate: use switching='designed' or a TwoLinkArm")
        self._params = self._kernel_params()
        self._block: Any = None
        self.reset_run()

    # -- Controller protocol (update and reset from StaticLaw: ``output`` advances the
    # phase logic in the block state itself, the derivative is zero) ----------------------
    period = None

    @property
    def n_outputs(self) -> int:
        """One torque per joint."""
        return self.n

    @property
    def n_states(self) -> int:  # type: ignore[override]  # StaticLaw's is a constant 0
        """Length of the block state: the phase logic's record and the detection ring
        (layout in ``nscontrol.design._complementarity_tracking_kernels``)."""
        return kern.state_size(self.detection_delay)

    @property
    def x0(self) -> FloatArray:
        """The block state before a run (see :attr:`n_states`)."""
        return kern.initial_state(self.detection_delay)

    def update(self, t: float, xc: FloatArray, m: Any) -> FloatArray:
        """A zero derivative: :meth:`output` has already moved the block state (in place,
        as the compiled form does), so that the loop's explicit Euler step keeps it.

        Parameters
        ----------
        t : float
            Time.
        xc : ndarray
            The block state.
        m : Measurement
            Unused.
        """
        return np.zeros(np.shape(xc)[0])

    def compiled_reason(self) -> str | None:
        """Why this setting has no compiled form (``None``: it has one)."""
        if self.position_noise > 0.0 or self.force_noise > 0.0:
            return ("position_noise / force_noise: the noise is drawn from NumPy's "
                    "generators, which the compiled loop does not run")
        return None

    def compiled(self) -> Any:
        """The compiled form (a :class:`~nscontrol.systems.feedback.CompiledBlock`) for
        the integrators' compiled loops, or ``None`` when the setting has none (position or
        force noise, see :meth:`compiled_reason`): the loop then runs the Python methods,
        which call the same kernels.

        The compiled form keeps the phase logic in the block state, which the loop logs at
        every step start (:meth:`signals` with the run, :meth:`load_run`).
        """
        if self.compiled_reason() is not None:
            return None
        if self._block is None:         # its checks cost a millisecond: kept per params
            from ..systems.feedback import CompiledBlock

            key = self._params.tobytes()
            block = _BLOCKS.pop(key, None)
            if block is None:
                block = CompiledBlock(kern.tracking_output, kern.tracking_update,
                                      self._params.copy())
                if len(_BLOCKS) >= 64:          # the least recently used goes
                    del _BLOCKS[next(iter(_BLOCKS))]
            _BLOCKS[key] = self._block = block
        return self._block

    def _kernel_params(self) -> FloatArray:
        """The parameters as the kernels' record ``PARAMS`` (flat, in its order)."""
        from ..systems.two_link import OneDofMass

        r: dict[str, float] = {"n": self.n}
        task, model = self.task, self.model
        if isinstance(task, CircleTask):
            r.update(task=kern.TASK_CIRCLE, centre=task.centre, radius=task.radius,
                     threshold=task.y_threshold)
        else:
            r.update(task=kern.TASK_HALF_SINE, amplitude=task.amplitude, omega=task.omega,
                     threshold=task.threshold)
        r["period"] = task.period
        if isinstance(model, OneDofMass):
            r.update(model=kern.MODEL_ONE_DOF, mass=model.m, gravity=model.g)
        else:
            r["model"] = kern.MODEL_TWO_LINK
            for name in ("l1", "l2", "m1", "m2", "I1", "I2", "g"):
                r[f"arm_{name}"] = getattr(model.params, name)
        r["switching"] = kern.DESIGNED if self.switching == "designed" \
            else kern.IMPACT_TRIGGERED
        g, tr, c = self.gains, self.transition, self.contact
        r.update(gamma1=g.gamma1, gamma2=g.gamma2, Kf=g.Kf, delta=tr.delta, Delta=tr.Delta,
                 alpha=tr.alpha, phi=tr.phi, depth_law=0.0 if tr.depth_law == "sqrt" else 1.0,
                 depth_min=tr.depth_min, depth_max=tr.depth_max,
                 n_consecutive_contact=tr.n_consecutive_contact, lam_rate=c.lam_rate,
                 lam_sat=c.lam_sat, liftoff_time=c.liftoff_time, model_scale=self.model_scale,
                 force_feedback_scale=self.force_feedback_scale, force_scale=self.force_scale,
                 force_bias=self.force_bias, detection_delay=self.detection_delay,
                 trigger_q2=self.trigger_q2, q2_end=self.q2_end)
        # the record by name (a field left out is 0), made in one go
        names = kern.PARAMS.names or ()
        assert set(r) <= set(names), sorted(set(r) - set(names))
        return np.array([tuple(r.get(name, 0.0) for name in names)],
                        dtype=kern.PARAMS).view(np.float64)

    def output(self, t: float, xc: FloatArray, m: Any) -> FloatArray:
        """Joint torques ``U = Jᵀ τ`` at a step start (also advances the phase logic, and
        leaves it in ``xc`` as the compiled form does).

        Parameters
        ----------
        t : float
            Time.
        xc : ndarray
            The block state (see :attr:`n_states`).
        m : Measurement
            Plant state ``x = [θ; θ']`` and contact estimate ``λ̂``.
        """
        lam = 0.0 if m.lam is None or np.size(m.lam) == 0 else float(np.asarray(m.lam)[0])
        own = isinstance(xc, np.ndarray) and xc.shape == self._xb.shape
        if own:               # the loop's block state is the phase logic's
            self._xb[:] = xc
        u = self.step(t, np.asarray(m.x, float), lam)
        if own and xc.flags.writeable:
            xc[:] = self._xb
        return u

    # -- run state ----------------------------------------------------------------------
    def reset_run(self) -> None:
        """Forget the phase logic and the log (before a new simulation)."""
        self._xb = kern.initial_state(self.detection_delay)
        # the log: the block state after each step start and the true plant state there
        self._rows: list[FloatArray] = []
        self._xs: list[FloatArray] = []
        self._loaded: tuple[FloatArray, FloatArray] | None = None   # load_run's
        self._cycles: tuple[int, list[TrackingCycle]] | None = None
        # the noise generators, made at the first draw (a generator costs about a millisecond)
        self._rng: np.random.Generator | None = None
        self._force_rng: np.random.Generator | None = None

    def _field(self, name: str) -> float:
        return float(self._xb[:kern.N_STATE].view(kern.STATE)[name][0])

    @property
    def phase(self) -> Phase:
        """The current phase."""
        return Phase(int(self._field("phase")))

    @property
    def cycle(self) -> int:
        """The current cycle's index."""
        return int(self._field("cycle"))

    @property
    def contact_steps(self) -> int:
        """Consecutive steps with contact counted by the phase logic."""
        return int(self._field("contact_steps"))

    @property
    def liftoff_at(self) -> float:
        """The last take-off (``-inf`` before the first)."""
        t = self._field("liftoff_at")
        return -math.inf if t == kern.NEVER else t

    @property
    def cycles(self) -> list[TrackingCycle]:
        """The per-cycle record of the run so far (one :class:`TrackingCycle` a cycle)."""
        rows, _ = self._run_rows()
        if self._cycles is None or self._cycles[0] != rows.shape[0]:
            self._cycles = (rows.shape[0], self._cycles_of_rows(rows))
        return self._cycles[1]

    @property
    def current(self) -> TrackingCycle:
        """The current cycle's record."""
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
        x_true = np.array(x, dtype=float)            # a copy: logged
        x_meas = x_true
        if self.position_noise > 0.0:   # no draw at σ = 0: the noiseless run is unchanged
            if self._rng is None:
                self._rng = np.random.default_rng(self.noise_seed)
            x_meas = x_true.copy()
            x_meas[:n] += self._rng.normal(0.0, self.position_noise, n)
        noise = 0.0
        if self.force_noise > 0.0:      # no draw at σ = 0: the exact-sensor run is unchanged
            if self._force_rng is None:
                # the sensor's own stream: adding force noise leaves the position noise alone
                self._force_rng = np.random.default_rng((self.noise_seed, 1))
            noise = float(self._force_rng.normal(0.0, self.force_noise))
        u = kern.control(float(t), self._xb, x_meas, x_true, x_meas is not x_true,
                         float(lam_raw), noise, self._params)
        self._rows.append(self._xb.copy())
        self._xs.append(x_true)
        return np.asarray(u)

    def lyapunov(self, t: float, x: FloatArray) -> tuple[float, float]:
        """``(V, V1)`` at ``(t, x)`` with the current phase's reference (no phase change).

        Parameters
        ----------
        t : float
            Time.
        x : ndarray
            ``[θ; θ']``.
        """
        x = np.ascontiguousarray(np.asarray(x, float)[:2 * self.n])
        V, V1 = kern.lyapunov_at(float(t), self._xb.copy(), x, self._params)
        return float(V), float(V1)

    def reference(self, t: float, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(q_d, q̇_d, q̈_d)`` of the current phase at ``(t, x)`` (no phase change).

        Parameters
        ----------
        t : float
            Time.
        x : ndarray
            ``[θ; θ']``.
        """
        x = np.ascontiguousarray(np.asarray(x, float)[:2 * self.n])
        return kern.reference_at(float(t), self._xb.copy(), x, self._params)

    # -- log ----------------------------------------------------------------------------
    def _run_rows(self) -> tuple[FloatArray, FloatArray]:
        """``(block states, true plant states)`` at every step start of the run."""
        if self._loaded is not None:
            return self._loaded
        if not self._rows:
            return np.zeros((0, self.n_states)), np.zeros((0, 2 * self.n))
        return np.array(self._rows), np.array(self._xs)

    def signals(self, traj: Any = None) -> dict[str, FloatArray]:
        """The per-step log as arrays (one row per step start).

        Keys: ``t``, ``phase``, ``cycle``, ``V``, ``V1``, ``lam_d``, ``lam_hat``, ``depth``,
        ``q_task``, ``dq_task``, ``qd``.

        Parameters
        ----------
        traj : Trajectory, optional
            A closed-loop run (its ``"xc"`` signal holds the block state): the log is read
            back from it. Without it, this object's own run (or the one :meth:`load_run`
            loaded).
        """
        if traj is not None and "xc" in traj.signals:
            return self._signals_of_rows(*self._rows_of(traj))
        rows, xs = self._run_rows()
        return self._signals_of_rows(rows, xs) if rows.shape[0] else {}

    def _rows_of(self, traj: Any) -> tuple[FloatArray, FloatArray]:
        """The block state after each step start and the plant state there, from a
        closed-loop run (sample ``k + 1`` shows the row of step start ``k``)."""
        xc = np.asarray(traj.signals["xc"])
        if xc.ndim != 2 or xc.shape[1] != self.n_states or xc.shape[0] != traj.t.size:
            raise ModelError(f"traj: expected the 'xc' signal of this controller's block "
                             f"state at every step ({traj.t.size} x {self.n_states}), got "
                             f"shape {xc.shape}; record every step")
        return xc[1:], np.ascontiguousarray(np.asarray(traj.x, float)[:-1, :2 * self.n])

    def _signals_of_rows(self, rows: FloatArray, xs: FloatArray) -> dict[str, FloatArray]:
        n = self.n
        st = np.ascontiguousarray(rows[:, :kern.N_STATE]).view(kern.STATE)[:, 0]
        task = kern.task_rows(np.ascontiguousarray(xs), self._params)
        phase = st["phase"].copy()
        # a cycle's depth is NaN until it is fixed (free motion)
        depth = np.where(phase == kern.FREE, np.nan, st["depth"])
        qd = np.stack([st["qd1"], st["qd2"]], axis=1)[:, :n].copy()
        return {"t": st["t_prev"].copy(), "phase": phase, "cycle": st["cycle"].copy(),
                "V": st["V"].copy(), "V1": st["V1"].copy(), "lam_d": st["lam_d"].copy(),
                "lam_hat": st["lam_hat"].copy(), "depth": depth,
                "q_task": task[:, :n], "dq_task": task[:, n:], "qd": qd}

    def cycles_of(self, traj: Any) -> list[TrackingCycle]:
        """The per-cycle record of a closed-loop run, read back from its block state.

        Parameters
        ----------
        traj : Trajectory
            The run (its ``"xc"`` signal, recorded at every step).
        """
        return self._cycles_of_rows(self._rows_of(traj)[0])

    def _cycles_of_rows(self, rows: FloatArray) -> list[TrackingCycle]:
        """Cycle ``c`` from its rows (phases only move forward in a cycle, and a take-off
        leaves from the impacts or constrained phase: the last row holds every field fixed
        so far; the next cycle's first row, the take-off)."""
        st = np.ascontiguousarray(rows[:, :kern.N_STATE]).view(kern.STATE)[:, 0]
        cyc = st["cycle"]
        out: list[TrackingCycle] = []
        for c in range(int(cyc.max()) + 1 if cyc.size else 1):
            lo, hi = int(np.searchsorted(cyc, c, "left")), int(np.searchsorted(cyc, c, "right"))
            cycle = TrackingCycle(c)
            out.append(cycle)
            if hi <= lo:
                continue
            last = st[hi - 1]
            for name in kern.CYCLE_FIELDS:
                value = float(last[name])
                if name != "q2_star":
                    setattr(cycle, name, math.nan if value == kern.NEVER else value)
            if last["tau0"] != kern.NEVER:
                cycle.q2_star = np.array([last["q2_star"]])[:self.n - 1]
            if hi < st.shape[0]:                   # taken off: the next cycle's first row
                cycle.t_detach = float(st[hi]["liftoff_at"])
        return out

    def load_run(self, traj: Any) -> None:
        """Make this object's run state that of a closed-loop run, as if the run had called
        its methods: :meth:`signals` (without argument) gives its log, ``cycles`` its
        per-cycle record, and the phase, cycle and take-off time are those after its last
        step start (what :meth:`lyapunov` reads).

        Parameters
        ----------
        traj : Trajectory
            The run (its ``"xc"`` signal, recorded at every step).
        """
        rows, xs = self._rows_of(traj)
        self.reset_run()
        self._loaded = (rows, xs)
        if rows.shape[0]:
            self._xb = np.array(rows[-1], dtype=float)
