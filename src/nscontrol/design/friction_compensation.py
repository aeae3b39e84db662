"""Friction compensation of a one-link robot with a reduced-order velocity observer (ch. 7).

The plant (:class:`~nscontrol.systems.one_link.OneLinkRobot`) measures its angle only. A
digital controller (zero-order hold, period ``T``) applies::

    u_pd = J r'' - k_p (theta - r) - k_d (omega_hat - r')         (PD + feedforward)
    u    = u_pd + T_hat(omega_hat)                                  (friction compensation)

with ``T_hat`` a friction model of the plant's form whose force levels (``T_s, T_c, b``) are
the plant's times the compensation factor ``kappa`` (``kappa = 1`` exact, ``< 1`` under-,
``> 1`` over-compensation; scaling all levels is our choice of parameterisation). The
velocity estimate comes from the reduced-order linear observer of the *compensated* model
``J theta'' = u_pd``::

    xi' = -l xi - l^2 theta + u_pd / J,    omega_hat = xi + l theta

discretised by backward Euler at every controller tick with the new angle sample:
``xi_{k+1} = (xi_k + T(-l^2 theta_{k+1} + u_pd,k / J)) / (1 + T l)``. The observer is driven
by ``u_pd``, not ``u``: the compensation cancels from the estimation error, which is then
forced by the friction mismatch only (driving it by ``u`` would leave the full friction
torque in the error, which would never converge).

The controller outputs one number, so ``T_hat`` at ``omega_hat = 0`` is a chosen value
(``value_at_zero``, default 0). This is harmless with the observer: ``omega_hat`` does not
depend on the compensation and crosses zero transversally.

Both blocks are :class:`~nscontrol.systems.feedback.Controller` /
:class:`~nscontrol.systems.feedback.Observer` objects closed around the plant by
:func:`nscontrol.closed_loop` and run by implicit Euler (:func:`simulate_friction_loop`).

The reconstruction (observer structure, parameterisation of ``kappa``, gain-design rule of
:func:`one_link_gains`) is ours: the original paper's equations and numbers could not be read.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .._validation import FloatArray, check_bool, check_positive, named_record
from ..errors import ModelError, NscontrolWarning
from ..systems.feedback import StaticLaw
from . import _friction_compensation_kernels as _k

__all__ = ["SetPoint", "Sinusoid", "PDLaw", "compensation_model", "FrictionCompensatingPD",
           "ReducedOrderVelocityObserver", "OneLinkGains", "one_link_gains",
           "FrictionLoopRun", "friction_loop", "simulate_friction_loop"]


# -- references --------------------------------------------------------------------------
@dataclass(frozen=True)
class SetPoint:
    """A constant reference ``r(t) = value`` (``r' = r'' = 0``).

    Attributes
    ----------
    value
        The set-point [rad].
    """

    value: float = 0.0

    def __call__(self, t: float) -> tuple[float, float, float]:
        return float(self.value), 0.0, 0.0


@dataclass(frozen=True)
class Sinusoid:
    """``r(t) = amplitude sin(frequency t)`` with its two derivatives.

    Attributes
    ----------
    amplitude
        Amplitude [rad].
    frequency
        Angular frequency [rad/s].
    """

    amplitude: float = 1.0
    frequency: float = 1.0

    def __call__(self, t: float) -> tuple[float, float, float]:
        return _k.sinusoid(float(t), float(self.amplitude), float(self.frequency))


# -- the PD part and the compensation ------------------------------------------------------
@dataclass(frozen=True)
class PDLaw:
    """``u_pd = J r'' - k_p (theta - r) - k_d (omega_hat - r')`` (feedforward optional).

    Parameters
    ----------
    kp, kd
        Gains ``> 0``.
    J
        Inertia used by the feedforward and the observer.
    reference
        ``t -> (r, r', r'')`` (:class:`SetPoint`, :class:`Sinusoid` or any callable).
    feedforward
        Include ``J r''``.
    """

    kp: float
    kd: float
    J: float
    reference: Any = field(default_factory=SetPoint)
    feedforward: bool = True
    _record: Any = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("kp", "kd", "J"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        object.__setattr__(self, "feedforward", check_bool("feedforward", self.feedforward))
        if not callable(self.reference):
            raise ModelError(f"reference: expected a callable t -> (r, r', r''), got "
                             f"{type(self.reference).__name__}")
        object.__setattr__(self, "_record", _parameters(self))

    def reference_at(self, t: float) -> tuple[float, float, float]:
        """``(r, r', r'')`` at ``t`` from the reference callable."""
        r, dr, ddr = self.reference(t)
        return float(r), float(dr), float(ddr)

    def torque(self, t: float, theta: float, omega_hat: float) -> float:
        """``u_pd`` at ``t`` for the angle ``theta`` and velocity estimate ``omega_hat``."""
        return _k.pd_torque(*self.reference_at(t), float(theta), float(omega_hat),
                            self._record)

    def compiled_parameters(self) -> dict[str, float] | None:
        """The law's fields of the compiled blocks' parameter records (``kind, a, w`` of the
        reference, ``kp, kd, J, feedforward``), or ``None`` when the reference is not a
        :class:`SetPoint` or :class:`Sinusoid` (an arbitrary callable has no compiled
        form)."""
        return self.fields() if type(self.reference) in (SetPoint, Sinusoid) else None

    def fields(self) -> dict[str, float]:
        """The law's fields of the blocks' parameter record (``PARAMETERS`` of the kernels
        module); an arbitrary reference (no compiled form) gets ``kind = a = w = 0``, unused:
        the Python methods pass its values."""
        ref = self.reference
        kind, a, w = 0.0, 0.0, 0.0
        if type(ref) is SetPoint:
            a = float(ref.value)
        elif type(ref) is Sinusoid:
            kind, a, w = 1.0, float(ref.amplitude), float(ref.frequency)
        return {"kind": kind, "a": a, "w": w, "kp": self.kp, "kd": self.kd, "J": self.J,
                "feedforward": 1.0 if self.feedforward else 0.0}


def _parameters(pd: PDLaw, **fields: float) -> FloatArray:
    """The blocks' parameter record (``PARAMETERS``, flat ``float64`` view): the PD law's
    fields, then ``fields``; the fields a block does not read stay 0."""
    values = dict.fromkeys(_k.PARAMETERS.names or (), 0.0) | pd.fields() | fields
    return named_record(_k.PARAMETERS, **values).view(np.float64)


def compensation_model(friction: Any, kappa: float) -> Any:
    """The plant's friction law with its force levels ``T_s, T_c, b`` scaled by ``kappa``.

    Parameters
    ----------
    friction
        A one-component :class:`~nscontrol.laws.Stribeck` law.
    kappa
        Compensation factor ``>= 0`` (1: exact; our parameterisation of under/over).

    Returns
    -------
    Stribeck or None
        ``None`` for ``kappa = 0`` (no compensation).

    Raises
    ------
    ModelError
        ``kappa < 0`` or not finite, or ``friction`` is not a Stribeck law.
    """
    from ..laws.friction import Stribeck

    kappa = check_positive("kappa", kappa, allow_zero=True)
    if not isinstance(friction, Stribeck):
        raise ModelError(f"friction: expected a Stribeck law to scale, got {friction!r}")
    if kappa == 0.0:
        return None
    return Stribeck(kappa * friction.static, kappa * friction.coulomb,
                    friction.stribeck_velocity, friction.delta, kappa * friction.viscous)


def _curve(law: Any) -> tuple[float, float, float, float, float]:
    """``(T_s, T_c, omega_s, delta, b)`` of a one-component Stribeck law."""
    from ..laws.friction import Stribeck

    if not isinstance(law, Stribeck) or law.dim != 1:
        raise ModelError(f"compensation: expected a one-component Stribeck law, got {law!r}")
    return (float(law.static[0]), float(law.coulomb[0]), float(law.stribeck_velocity[0]),
            float(law.delta[0]), float(law.viscous[0]))


@dataclass(frozen=True, eq=False)
class FrictionCompensatingPD(StaticLaw):
    """The digital controller ``u = u_pd + T_hat(omega_hat)`` (a ``Controller``).

    Reads ``omega_hat`` from the observer's estimate; without an observer in the loop it
    reads the *measured* velocity (then, with ``value_at_zero = 0``, static friction is never
    compensated at rest).

    Parameters
    ----------
    pd
        The PD (+ feedforward) part.
    compensation
        The friction model ``T_hat`` (a Stribeck law, e.g. :func:`compensation_model`) or
        ``None`` for no compensation.
    period
        Control period ``T > 0`` (zero-order hold).
    value_at_zero
        ``T_hat(0)`` (default 0).
    smooth_eps
        Optional smoothing ``sat(v / eps) f_hat(|v|)`` of the sign (off by default; it
        re-creates a small stuck region of width about ``eps (J l + k_d) / k_p``).
    """

    pd: PDLaw
    compensation: Any
    period: float
    value_at_zero: float = 0.0
    smooth_eps: float | None = None
    n_states: int = field(default=0, init=False)
    n_outputs: int = field(default=1, init=False)
    _record: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "period", check_positive("period", self.period))
        if self.smooth_eps is not None:
            object.__setattr__(self, "smooth_eps", check_positive("smooth_eps",
                                                                  self.smooth_eps))
        curve = (0.0,) * 5 if self.compensation is None else _curve(self.compensation)
        eps = self.smooth_eps
        rec = _parameters(
            self.pd, has_compensation=0.0 if self.compensation is None else 1.0,
            **dict(zip(("T_s", "T_c", "omega_s", "delta", "b"), curve, strict=True)),
            value_at_zero=float(self.value_at_zero), has_eps=0.0 if eps is None else 1.0,
            eps=0.0 if eps is None else float(eps))
        object.__setattr__(self, "_record", rec)

    def friction_estimate(self, omega_hat: float) -> float:
        """``T_hat(omega_hat)``: ``sign(v) f_hat(|v|)``, ``value_at_zero`` at 0."""
        return _k.friction_estimate(float(omega_hat), self._record)

    def compiled(self) -> Any:
        """The compiled form (a :class:`~nscontrol.systems.feedback.CompiledBlock`), or
        ``None`` when the reference has none (see :meth:`PDLaw.compiled_parameters`)."""
        from ..systems._feedback_kernels import static_update
        from ..systems.feedback import CompiledBlock

        if self.pd.compiled_parameters() is None:
            return None
        return CompiledBlock(_k.controller_output, static_update, self._record)

    def velocity(self, m: Any) -> float:
        """The velocity the controller uses: the estimate, else the measured one."""
        return float(m.xhat[0]) if m.xhat is not None else float(m.x[1])

    def output(self, t: float, xc: FloatArray, m: Any) -> FloatArray:
        """``[u]`` at the tick ``t``."""
        return np.array([_k.control(*self.pd.reference_at(t), float(m.y[0]), self.velocity(m),
                                    self._record)])


@dataclass(frozen=True, eq=False)
class ReducedOrderVelocityObserver:
    """The reduced-order linear velocity observer, backward Euler at each tick (an
    ``Observer``).

    Its state carried into tick ``k`` is ``(xi_{k-1}, u_pd,k-1, omega_hat_{k-1})``: the
    update to ``xi_k`` needs the new angle sample ``theta_k`` and the previous tick's
    ``u_pd`` (recomputed from the same :class:`PDLaw` as the controller's). Its recorded
    estimate (``E`` picks ``omega_hat``) is thus the one that acted over each step.

    Parameters
    ----------
    l
        Observer gain ``l > 0`` [1/s] (the estimate's error decays like ``exp(-l t)`` on the
        compensated model; ``l <= 0`` is unstable and refused).
    pd
        The controller's PD law (the observer is driven by ``u_pd``).
    period
        Sampling period ``T`` (the controller's).
    x0
        Initial internal state (use :meth:`starting_at`).
    """

    l: float
    pd: PDLaw
    period: float
    x0: FloatArray | None = None
    n_states: int = field(default=3, init=False)
    n_outputs: int = field(default=1, init=False)
    E: FloatArray = field(default_factory=lambda: np.array([[0.0, 0.0, 1.0]]), init=False)
    _record: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        try:
            l_val = check_positive("l", self.l)
        except ModelError:
            raise ModelError(f"l: the observer gain must be > 0 (its error dynamics "
                             f"e' = -l e is unstable for l <= 0), got l = {self.l!r}") from None
        object.__setattr__(self, "l", l_val)
        object.__setattr__(self, "period", check_positive("period", self.period))
        object.__setattr__(self, "_record", _parameters(self.pd, T=self.period, l=self.l))

    @property
    def estimates(self) -> FloatArray:
        """``S = [0, 1]``: the observer estimates the velocity of ``(theta, omega)``."""
        return np.array([[0.0, 1.0]])

    def starting_at(self, theta0: float, omega_hat0: float) -> ReducedOrderVelocityObserver:
        """The same observer whose estimate at the first tick is ``omega_hat0``."""
        T, l = self.period, self.l
        xi0 = omega_hat0 - l * theta0
        # the state before tick 0 that the first update maps to xi0 (with u_pd = 0)
        xi_prev = xi0 * (1.0 + T * l) + T * l * l * theta0
        return replace(self, x0=np.array([xi_prev, 0.0, float(omega_hat0)]))

    def estimate(self, xo: FloatArray, theta: float) -> float:
        """``omega_hat`` at a tick with angle sample ``theta`` and carried state ``xo``."""
        return _k.observer_estimate(float(xo[0]), float(xo[1]), float(theta),
                                    self._record)

    def estimates_at(self, xo: FloatArray, theta: FloatArray) -> FloatArray:
        """:meth:`estimate` for many ticks at once (rows of ``xo``, entries of ``theta``),
        by the same compiled function.

        Parameters
        ----------
        xo : ndarray, shape (k, 3)
            Carried states.
        theta : ndarray, shape (k,)
            Angle samples.
        """
        xo = np.ascontiguousarray(xo, dtype=float).reshape(-1, 3)
        theta = np.ascontiguousarray(theta, dtype=float).reshape(-1)
        return _k.observer_estimates(xo, theta, self._record)

    def output(self, t: float, xo: FloatArray, m: Any) -> FloatArray:
        """``[omega_hat]`` at the tick ``t``."""
        return np.array([self.estimate(xo, float(m.y[0]))])

    def update(self, t: float, xo: FloatArray, m: Any) -> FloatArray:
        """The state carried into the next tick."""
        return np.array(_k.observer_step(*self.pd.reference_at(t), float(xo[0]), float(xo[1]),
                                         float(m.y[0]), self._record))

    def reset(self, t: float, xo: FloatArray, jump: Any) -> FloatArray:
        """The plant does not jump."""
        return xo

    def compiled(self) -> Any:
        """The compiled form (a :class:`~nscontrol.systems.feedback.CompiledBlock`), or
        ``None`` when the PD law's reference has none."""
        from ..systems.feedback import CompiledBlock

        if self.pd.compiled_parameters() is None:
            return None
        return CompiledBlock(_k.observer_output, _k.observer_update, self._record)


# -- gain design -------------------------------------------------------------------------
@dataclass(frozen=True)
class OneLinkGains:
    """Gains from :func:`one_link_gains`.

    Attributes
    ----------
    kp, kd, l
        PD gains and observer gain.
    l_sufficient
        ``sigma_tan / J``: ``l`` above it proves global exponential stability under exact
        compensation.
    l_necessary
        ``sigma_sec / J``: at or below it a stuck equilibrium off the set-point exists.
    warnings
        The design warnings raised (also issued as ``NscontrolWarning``).
    """

    kp: float
    kd: float
    l: float
    l_sufficient: float
    l_necessary: float
    warnings: tuple[str, ...] = ()


def one_link_gains(J: float, friction: Any, omega_n: float, zeta: float, *,
                   margin: float = 2.0, control_period: float | None = None,
                   encoder_step: float | None = None) -> OneLinkGains:
    """PD and observer gains for a frictionless target ``(omega_n, zeta)`` (our rule).

    ``k_p = J omega_n^2``, ``k_d = 2 zeta omega_n J``, ``l = max(margin sigma_tan / J,
    5 omega_n)``.

    Parameters
    ----------
    J
        Inertia ``> 0``.
    friction
        The plant's Stribeck law.
    omega_n, zeta
        Natural frequency ``> 0`` and damping ``> 0`` of the frictionless loop.
    margin
        Factor ``>= 1`` over the sufficient observer gain.
    control_period
        If given, warn when ``l T > 0.2`` (the sampled observer lags).
    encoder_step
        If given, warn when ``l q > 0.1 omega_s`` (encoder noise flips the compensation).

    Returns
    -------
    OneLinkGains

    Examples
    --------
    >>> from nscontrol.laws import Stribeck
    >>> g = one_link_gains(0.05, Stribeck(0.4, 0.2, 0.05, 2.0, 0.02), 2 * 10 ** 0.5, 0.5)
    >>> round(g.kp, 6), round(g.l_sufficient, 2), round(g.l, 2)
    (2.0, 68.22, 136.44)
    """
    J = check_positive("J", J)
    omega_n, zeta = check_positive("omega_n", omega_n), check_positive("zeta", zeta)
    margin = check_positive("margin", margin)
    if margin < 1.0:
        raise ModelError(f"margin: expected >= 1 (the observer must beat sigma_tan / J), got "
                         f"{margin}")
    ts, tc, ws, dl, b = _curve(friction)
    l_suf = float(friction.sigma_tan[0]) / J
    l_nec = float(friction.sigma_sec[0]) / J
    l_gain = max(margin * l_suf, 5.0 * omega_n)
    notes = []
    if control_period is not None and l_gain * check_positive("control_period",
                                                              control_period) > 0.2:
        notes.append(f"l * control_period = {l_gain * control_period:.3g} > 0.2: the sampled "
                     f"observer lags; shorten the period")
    if encoder_step is not None and l_gain * check_positive("encoder_step",
                                                            encoder_step) > 0.1 * ws:
        notes.append(f"l * encoder_step = {l_gain * encoder_step:.3g} > 0.1 omega_s = "
                     f"{0.1 * ws:.3g}: estimate noise flips the compensation at rest")
    for note in notes:
        warnings.warn(f"one_link_gains: {note}", NscontrolWarning, stacklevel=2)
    return OneLinkGains(kp=J * omega_n ** 2, kd=2.0 * zeta * omega_n * J, l=l_gain,
                        l_sufficient=l_suf, l_necessary=l_nec, warnings=tuple(notes))


# -- running the loop ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class FrictionLoopRun:
    """A closed-loop run at the controller ticks.

    Attributes
    ----------
    t, theta, omega
        Tick times and the plant's angle and velocity there.
    omega_hat
        The velocity estimate computed at each tick (the measured velocity without observer).
    u
        Torque applied from each tick to the next.
    friction
        Friction torque ``T_f`` over the step ending at each tick (``F(omega)``).
    reference
        ``r(t)`` at the ticks.
    trajectory
        The underlying :class:`~nscontrol.simulate.trajectory.Trajectory`.
    """

    t: FloatArray
    theta: FloatArray
    omega: FloatArray
    omega_hat: FloatArray
    u: FloatArray
    friction: FloatArray
    reference: FloatArray
    trajectory: Any

    @property
    def error(self) -> FloatArray:
        """Tracking error ``theta - r``."""
        return self.theta - self.reference

    @property
    def estimation_error(self) -> FloatArray:
        """``e = omega - omega_hat``."""
        return self.omega - self.omega_hat

    def window(self, start: float) -> np.ndarray:
        """Boolean mask of the ticks with ``t >= start``."""
        return self.t >= start - 1e-9 * max(1.0, abs(start))

    @classmethod
    def from_trajectory(cls, traj: Any, robot: Any, pd: PDLaw, observer: Any,
                        omega_hat0: float) -> FrictionLoopRun:
        """The tick-wise view of a run of :func:`friction_loop` (``simulate`` by implicit
        Euler with the control period as step).

        Parameters
        ----------
        traj
            The :class:`~nscontrol.simulate.trajectory.Trajectory`.
        robot
            The :class:`~nscontrol.systems.one_link.OneLinkRobot`.
        pd
            The controller's PD law (its reference).
        observer
            The loop's :class:`ReducedOrderVelocityObserver`, or ``None``.
        omega_hat0
            The estimate at the first tick.
        """
        t, x = traj.t, traj.x
        friction = robot.friction_torque(x[:, 1], traj.signal("w")[:, 0])
        if observer is None:
            omega_hat = x[:, 1].copy()
        else:   # the estimate of each tick from its carried state and angle sample
            omega_hat = observer.estimates_at(traj.signal("xo"), x[:, 0])
            omega_hat[0] = omega_hat0
        u = traj.signal("u")[:, 0]
        u = np.concatenate([u[1:], u[-1:]])   # the signal shows what acted over the step before
        if pd.compiled_parameters() is not None:    # the compiled blocks' reference
            ref = _k.references(np.ascontiguousarray(t), pd._record)
        else:
            ref = np.array([pd.reference_at(tk)[0] for tk in t])
        return cls(t=t, theta=x[:, 0].copy(), omega=x[:, 1].copy(), omega_hat=omega_hat, u=u,
                   friction=friction, reference=ref, trajectory=traj)


def friction_loop(robot: Any, pd: PDLaw, *, l: float | None, kappa: float, h: float,
                  theta0: float = 0.0, omega_hat0: float = 0.0, value_at_zero: float = 0.0,
                  smooth_eps: float | None = None, compiled: bool = True) -> Any:
    """The digital friction-compensating loop as a closed loop for :func:`nscontrol.simulate`.

    The plant is ``robot.lure_system()``; the controller a :class:`FrictionCompensatingPD`
    with the compensation ``compensation_model(robot.friction, kappa)`` and period ``h``; the
    observer (if ``l`` is given) a :class:`ReducedOrderVelocityObserver` whose estimate at the
    first tick is ``omega_hat0``. Run it with
    ``nscontrol.simulate(loop, [theta0, omega0], (0, T), method="implicit_euler", h=h)``.

    Parameters
    ----------
    robot
        The :class:`~nscontrol.systems.one_link.OneLinkRobot`.
    pd
        The PD (+ feedforward) law and its reference.
    l
        Observer gain, or ``None`` to feed back the measured velocity (no observer).
    kappa
        Compensation factor ``>= 0`` (0: none, 1: exact).
    h
        Control period (and the plant step to run it with); ``h sigma_tan < J`` is required.
    theta0, omega_hat0
        Initial angle (the observer's start) and velocity estimate.
    value_at_zero, smooth_eps
        Passed to :class:`FrictionCompensatingPD`.
    compiled
        Run the blocks' compiled forms when they have one (default; ``False``: their Python
        methods, the same functions called one tick at a time). The run's
        ``stats["controller"]`` says which ran.

    Returns
    -------
    ClosedLoop

    Raises
    ------
    ModelError
        ``h sigma_tan >= J`` (with the bound), ``kappa < 0``, ``l <= 0``.
    """
    from ..systems.closed_loop import closed_loop

    h = robot.check_step(h)
    comp = compensation_model(robot.friction, kappa)
    ctrl = FrictionCompensatingPD(pd, comp, h, value_at_zero=value_at_zero,
                                  smooth_eps=smooth_eps)
    obs = None
    if l is not None:
        obs = ReducedOrderVelocityObserver(l, pd, h).starting_at(theta0, omega_hat0)
    return closed_loop(robot.lure_system(), ctrl, obs, compiled=compiled)


def simulate_friction_loop(robot: Any, pd: PDLaw, *, l: float | None, kappa: float,
                           h: float, T: float, theta0: float = 0.0, omega0: float = 0.0,
                           omega_hat0: float = 0.0, value_at_zero: float = 0.0,
                           smooth_eps: float | None = None,
                           compiled: bool = True) -> FrictionLoopRun:
    """Run the digital friction-compensating loop (control period ``h``) by implicit Euler.

    A convenience over ``nscontrol.simulate(friction_loop(...), [theta0, omega0], (0, T),
    method="implicit_euler", h=h)``: it builds the loop (:func:`friction_loop`) and reads the
    trajectory tick by tick (:meth:`FrictionLoopRun.from_trajectory`: the estimate each tick
    computed, the torque that acted after it, the friction torque and the reference).

    Parameters
    ----------
    robot
        The :class:`~nscontrol.systems.one_link.OneLinkRobot`.
    pd
        The PD (+ feedforward) law and its reference.
    l
        Observer gain, or ``None`` to feed back the measured velocity (no observer).
    kappa
        Compensation factor ``>= 0`` (0: none, 1: exact).
    h
        Plant step and control period; ``h sigma_tan < J`` is required.
    T
        Final time.
    theta0, omega0, omega_hat0
        Initial angle, velocity and velocity estimate.
    value_at_zero, smooth_eps
        Passed to :class:`FrictionCompensatingPD`.
    compiled
        Run the blocks' compiled forms in implicit Euler's compiled loop (default; the
        same numbers as their Python methods, ``False``).

    Returns
    -------
    FrictionLoopRun

    Raises
    ------
    ModelError
        ``h sigma_tan >= J`` (with the bound), ``kappa < 0``, ``l <= 0``.
    """
    from ..simulate import simulate

    loop = friction_loop(robot, pd, l=l, kappa=kappa, h=h, theta0=theta0,
                         omega_hat0=omega_hat0, value_at_zero=value_at_zero,
                         smooth_eps=smooth_eps, compiled=compiled)
    traj = simulate(loop, [theta0, omega0], (0.0, check_positive("T", T)),
                    method="implicit_euler", h=h, progress=False)
    return FrictionLoopRun.from_trajectory(traj, robot, loop.controller.pd, loop.observer,
                                           omega_hat0)
