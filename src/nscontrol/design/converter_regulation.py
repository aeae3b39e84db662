"""Zero-average-dynamics (ZAD) regulation of a buck converter with centred PWM, and its
perturbation analysis in the sampling period ``T``.

At each sampling instant ``t_k = kT`` the controller reads ``x_k`` and chooses the on-time
``d_k`` of a centred pulse so that the error surface ``s(x) = x1 - x_ref + k_s x2`` has a zero
average over the period:

* **PL-ZAD** approximates ``s(t)`` on each piece by the line of slope ``ṡ`` taken at ``x_k``
  for the mode in force: ``d_k = (2 s(x_k) + T ṡ_off(x_k)) / (ṡ_off(x_k) - ṡ_on(x_k))``, affine
  in ``x_k``;
* **exact ZAD** solves ``∫ s dt = 0`` along the exact solution (a scalar root in ``d_k``).

``d_k`` is saturated to ``[0, T]``. The closed loop is the stroboscopic map
``P: x_k -> x_{k+1}`` (:class:`ZADLoopMap`), exact and in closed form, with the Jacobian
``DP = E(T) + (∂P/∂d) ∇dᵀ`` (compiled kernels). The 1T-periodic orbit loses stability through
a flip (``1 + tr J + det J = 0``); expanding ``J`` in ``T`` gives the boundary
``k_s,c = 1/δ + D(2 - D) T/(4δ²) + O(T²)`` (:func:`zad_flip_boundary`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_real_scalar,
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import InaccurateCertificateWarning, InfeasibleDesignError, ModelError, SolverError
from ..systems.buck import BuckConverter
from . import _zad_kernels as K

__all__ = ["ZADController", "ZADLoopMap", "ZADOrbit", "ZADRun", "ZADDesign",
           "zad_flip_coefficients", "zad_flip_boundary", "zad_multipliers_series",
           "leading_duty", "critical_ks", "design_zad"]

Variant = Literal["pl", "exact"]


def leading_duty(system: BuckConverter, x_ref: float) -> float:
    """The leading-order duty ratio ``D0 = (x_ref - u_off)/(u_on - u_off)``.

    Parameters
    ----------
    system : BuckConverter
        The model (its switch levels).
    x_ref : float
        Normalised reference ``V_ref/E``.

    Returns
    -------
    float
        ``D0``; the target is reachable without saturation only for ``0 < D0 < 1``.
    """
    return (float(x_ref) - system.u_off) / (system.u_on - system.u_off)


@dataclass(frozen=True)
class ZADController:
    """A ZAD duty law with centred PWM, built on a model of the converter.

    Parameters
    ----------
    model : BuckConverter
        The converter model the controller uses (its ``δ`` may differ from the plant's).
    ks : float
        Slope ``k_s > 0`` of the error surface ``s = x1 - x_ref + k_s x2``.
    T : float
        Normalised sampling (and PWM) period.
    x_ref : float
        Normalised reference.
    variant : {"pl", "exact"}
        PL-ZAD (closed form) or exact ZAD (root of ``∫ s dt = 0``).
    x_ref_offset : float
        Added to ``x_ref`` inside the surface (offset pre-compensation; 0 by default).

    Raises
    ------
    ModelError
        A non-positive ``ks`` or ``T``, a non-finite reference, an unknown variant or a
        model that is not a :class:`BuckConverter`.

    Examples
    --------
    >>> ctrl = ZADController(BuckConverter.normalized(0.35), ks=5.0, T=0.18, x_ref=0.8)
    >>> round(ctrl.duty([0.8, 0.0]) / ctrl.T, 4)   # at the reference: D = (0.8 + 1)/2
    0.9
    """

    model: BuckConverter
    ks: float
    T: float
    x_ref: float
    variant: Variant = "pl"
    x_ref_offset: float = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.model, BuckConverter):
            raise ModelError(f"model: expected a BuckConverter, got {type(self.model).__name__}")
        object.__setattr__(self, "ks", check_positive("ks", self.ks))
        object.__setattr__(self, "T", check_positive("T", self.T))
        for name in ("x_ref", "x_ref_offset"):
            v = as_real_scalar(name, getattr(self, name))
            if not math.isfinite(v):
                raise ModelError(f"{name}: expected a finite number, got {v!r}")
            object.__setattr__(self, name, v)
        if self.variant not in ("pl", "exact"):
            raise ModelError(f"variant: expected 'pl' or 'exact', got {self.variant!r}")

    def params(self, plant: BuckConverter | None = None) -> FloatArray:
        """The kernels' parameter array for this controller on ``plant`` (default: its model).

        Parameters
        ----------
        plant : BuckConverter, optional
            The converter actually controlled; its switch levels must be the model's.

        Returns
        -------
        ndarray, shape (8,)
        """
        plant = self.model if plant is None else plant
        if plant.u_levels != self.model.u_levels:
            raise ModelError(f"plant: its u_levels {plant.u_levels} differ from the model's "
                             f"{self.model.u_levels}; the switch levels are known exactly")
        p = np.empty(K.N_PARAMS)
        p[K.P_DELTA], p[K.P_DELTA_MODEL] = plant.delta, self.model.delta
        p[K.P_U_OFF], p[K.P_U_ON] = plant.u_off, plant.u_on
        p[K.P_T], p[K.P_KS] = self.T, self.ks
        p[K.P_XREF] = self.x_ref + self.x_ref_offset
        p[K.P_VARIANT] = 0.0 if self.variant == "pl" else 1.0
        return p

    def duty(self, x: ArrayLike) -> float:
        """The saturated on-time ``d_k ∈ [0, T]`` for the sampled state ``x``.

        Parameters
        ----------
        x : (2,) array_like
            Sampled state.

        Returns
        -------
        float
        """
        x = as_vector("x", x, 2)
        return float(K.duty_and_gradient(self.params(), x[0], x[1])[0])

    def __call__(self, t_k: float, x_k: FloatArray) -> float:
        """``duty(x_k)``: the duty law of a :class:`~nscontrol.systems.PWMController`.

        Parameters
        ----------
        t_k : float
            Sampling instant (unused: the law is time-invariant).
        x_k : (2,) ndarray
            Sampled state.
        """
        return self.duty(x_k)

    def loop(self, plant: BuckConverter | None = None) -> ZADLoopMap:
        """The closed loop's stroboscopic map on ``plant`` (default: the model).

        Parameters
        ----------
        plant : BuckConverter, optional
            The converter controlled.

        Returns
        -------
        ZADLoopMap
        """
        return ZADLoopMap(self.model if plant is None else plant, self)

    def switched(self, plant: BuckConverter | None = None) -> Any:
        """The closed loop as a :class:`~nscontrol.systems.SwitchedAffineSystem` (the
        generic route of ``simulate(method="switching")``).

        Parameters
        ----------
        plant : BuckConverter, optional
            The converter controlled (default: the model).

        Returns
        -------
        SwitchedAffineSystem
        """
        return (self.model if plant is None else plant).switched(self.T, self)


@dataclass(frozen=True)
class ZADRun:
    """Per-period record of an iteration of the map.

    Attributes
    ----------
    states
        ``(n, 2)`` sampled states ``x_k``.
    duties
        ``(n,)`` on-times ``d_k``.
    mean_x1
        ``(n,)`` mean of ``x1`` over each period.
    last
        The state after the last period.
    period
        ``T``.
    """

    states: FloatArray
    duties: FloatArray
    mean_x1: FloatArray
    last: FloatArray
    period: float

    @property
    def saturated(self) -> np.ndarray:
        """Periods whose duty is ``0`` or ``T`` (no switching)."""
        return (self.duties <= 0.0) | (self.duties >= self.period)


@dataclass(frozen=True)
class ZADOrbit:
    """A ``period``-periodic orbit of the stroboscopic map (fixed point of ``P^period``).

    Attributes
    ----------
    states
        ``(period, 2)`` the sampled states along the orbit.
    duties
        ``(period,)`` its on-times.
    multipliers
        Eigenvalues of the monodromy ``DP^period`` (Floquet multipliers).
    monodromy
        ``DP^period`` at the orbit.
    iterations
        Newton iterations used.
    mean_x1
        Mean of ``x1`` over the orbit.
    """

    states: FloatArray
    duties: FloatArray
    multipliers: np.ndarray
    monodromy: FloatArray
    iterations: int
    mean_x1: float

    @property
    def flip_function(self) -> float:
        """``1 + tr M + det M``: positive while no multiplier has crossed ``-1``."""
        M = self.monodromy
        return float(1.0 + np.trace(M) + np.linalg.det(M))

    @property
    def stable(self) -> bool:
        """Every multiplier strictly inside the unit circle."""
        return bool(np.all(np.abs(self.multipliers) < 1.0))


@dataclass(frozen=True)
class ZADLoopMap:
    """The exact stroboscopic map ``x_k -> x_{k+1}`` of a ZAD loop and its Jacobian.

    Parameters
    ----------
    plant : BuckConverter
        The converter.
    controller : ZADController
        The duty law.

    Examples
    --------
    >>> buck = BuckConverter.normalized(0.35)
    >>> P = ZADController(buck, ks=5.0, T=0.18, x_ref=0.8).loop()
    >>> orbit = P.fixed_point()
    >>> np.round(orbit.multipliers.real, 3).tolist()
    [0.965, -0.981]
    """

    plant: BuckConverter
    controller: ZADController
    p: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.plant, BuckConverter):
            raise ModelError(f"plant: expected a BuckConverter, got {type(self.plant).__name__}")
        object.__setattr__(self, "p", self.controller.params(self.plant))

    @property
    def n_states(self) -> int:
        """Two."""
        return 2

    @property
    def period(self) -> float:
        """The sampling period ``T``."""
        return self.controller.T

    @property
    def state_names(self) -> tuple[str, str]:
        """The plant's state names."""
        return self.plant.state_names

    def __call__(self, x: ArrayLike) -> FloatArray:
        """``P(x)``.

        Parameters
        ----------
        x : (2,) array_like
            Sampled state.
        """
        x = as_vector("x", x, 2)
        y0, y1, _ = K.step(self.p, x[0], x[1])
        return np.array([y0, y1])

    def jacobian(self, x: ArrayLike) -> FloatArray:
        """``DP(x)`` in closed form (``E(T)`` in a saturated period).

        Parameters
        ----------
        x : (2,) array_like
            Sampled state.
        """
        x = as_vector("x", x, 2)
        return np.asarray(K.jacobian(self.p, x[0], x[1]))

    def duties(self, states: ArrayLike) -> FloatArray:
        """The saturated duty of each sampled state.

        Parameters
        ----------
        states : (n, 2) array_like
            Sampled states, one per row.
        """
        X = np.ascontiguousarray(np.atleast_2d(np.asarray(states, float)))
        return np.asarray(K.duties(self.p, X))

    def run(self, x0: ArrayLike, n_record: int, *, n_transient: int = 0) -> ZADRun:
        """Iterate the map: ``n_transient`` periods discarded, ``n_record`` recorded.

        Parameters
        ----------
        x0 : (2,) array_like
            Initial sampled state.
        n_record : int
            Periods recorded (at least 1).
        n_transient : int
            Periods discarded first.

        Returns
        -------
        ZADRun
        """
        x = as_vector("x0", x0, 2)
        nr = check_integer("n_record", n_record, minimum=1)
        nt = check_integer("n_transient", n_transient, minimum=0)
        X, D, M, last = K.iterate(self.p, x[0], x[1], nt, nr)
        return ZADRun(X, D, M, last, self.period)

    def stroboscopic_samples(self, x: FloatArray, n_transient: int, n_sample: int
                             ) -> tuple[FloatArray, FloatArray]:
        """``(samples, last)`` for :func:`~nscontrol.analysis.bifurcation_diagram`.

        Parameters
        ----------
        x : (2,) ndarray
            Start.
        n_transient, n_sample : int
            Periods discarded, then recorded.
        """
        X, _, _, last = K.iterate(self.p, float(x[0]), float(x[1]), int(n_transient),
                                  int(n_sample))
        return X, last

    def initial_state(self) -> FloatArray:
        """A cold start ``1e-6`` off the 1T orbit (along ``x1``), or ``(x_ref, 0)`` when no
        orbit is found."""
        try:
            return self.fixed_point().states[0] + np.array([1e-6, 0.0])
        except SolverError:
            return np.array([self.controller.x_ref, 0.0])

    def fixed_point(self, x0: ArrayLike | None = None, *, period: int = 1,
                    tol: float = 1e-13, max_iter: int = 50) -> ZADOrbit:
        """The ``period``-periodic orbit by Newton on ``P^period(x) - x``.

        Parameters
        ----------
        x0 : (2,) array_like, optional
            Start (default ``(x_ref, 0)``).
        period : int
            Number of map periods of the orbit.
        tol : float
            Newton step tolerance, relative to ``1 + |x|``; Newton also stops when the
            residual ``P^period(x) - x`` is at its rounding floor (near a flip, where
            ``DP^period - I`` is nearly singular, rounding alone moves the steps by more).
        max_iter : int
            Newton iterations allowed.

        Returns
        -------
        ZADOrbit

        Raises
        ------
        SolverError
            Newton did not converge (the message gives the last state).
        """
        x = (np.array([self.controller.x_ref, 0.0]) if x0 is None else as_vector("x0", x0, 2))
        k = check_integer("period", period, minimum=1)
        xs, iterations, ok = K.fixed_point(self.p, x[0], x[1], k, float(tol),
                                           check_integer("max_iter", max_iter, minimum=1))
        if not ok:
            raise SolverError(f"fixed_point: Newton on P^{k}(x) - x did not converge in "
                              f"{iterations} iterations (last x = {np.round(xs, 8).tolist()}); "
                              "start closer to the orbit or raise max_iter", status="newton")
        rec = self.run(xs, k)
        M = np.eye(2)
        for s in rec.states:
            M = self.jacobian(s) @ M
        return ZADOrbit(rec.states, rec.duties, np.linalg.eigvals(M), M, int(iterations),
                        float(np.mean(rec.mean_x1)))


def zad_flip_coefficients(delta: float, ks: float, D: float) -> tuple[float, float, float]:
    """Coefficients of ``1 + tr J + det J = c1 T + c2 T² + c3 T³ + O(T⁴)`` for PL-ZAD.

    Parameters
    ----------
    delta : float
        Plant damping ``δ``.
    ks : float
        Surface slope.
    D : float
        Duty ratio of the 1T orbit (held fixed in the expansion).

    Returns
    -------
    (c1, c2, c3) : tuple of float
        ``c1 = 2(δ - 1/k_s)``; ``c2``, ``c3`` from the Taylor expansion of the closed-form
        Jacobian (their check: ``tests/design/test_converter_regulation.py``).
    """
    d, k = float(delta), float(ks)
    alpha, beta = _c2_parts(d, D)
    c3_p, c3_q = _c3_parts(d, D)
    return 2.0 * (d - 1.0 / k), -(k * alpha + beta) / (2.0 * k), c3_p + c3_q / k


def _c2_parts(d: float, D: float) -> tuple[float, float]:
    """``c2 = -(k_s α + β)/(2 k_s)``."""
    alpha = D * D * d * d - D * D - 2 * D * d * d + 2 * D + 2 * d * d
    beta = -D * D * d + 2 * D * d - 2 * d
    return alpha, beta


def _c3_parts(d: float, D: float) -> tuple[float, float]:
    """``c3 = P + Q/k_s``."""
    P = (D * D * d**3 / 2 - 3 * D * D * d / 4 - D * d**3 + 3 * D * d / 2 + d**3 / 2 - d / 2)
    Q = (-D * D * d * d / 2 + D * D / 4 + D * d * d - D / 2 - d * d / 2 + 0.5)
    return P, Q


def zad_flip_boundary(delta: float, D: float, T: float,
                      order: Literal[0, 1, "poly3"] = 1) -> float:
    """The predicted ``k_s`` at which the 1T orbit of PL-ZAD flips (loses stability).

    Parameters
    ----------
    delta : float
        Plant damping ``δ > 0``.
    D : float
        Duty ratio (``D0`` at leading order).
    T : float
        Normalised sampling period.
    order : {0, 1, "poly3"}
        ``0``: ``1/δ``; ``1``: ``1/δ + D(2 - D) T/(4δ²)``; ``"poly3"``: the root in ``k_s`` of
        ``1 + tr J + det J`` truncated after ``T³`` (linear in ``k_s`` once multiplied by it).

    Returns
    -------
    float

    Examples
    --------
    >>> [round(zad_flip_boundary(0.35, 0.9, 0.18, order), 4) for order in (0, 1, "poly3")]
    [2.8571, 3.2208, 3.253]
    """
    d = check_positive("delta", delta)
    T = check_positive("T", T)
    if order == 0:
        return 1.0 / d
    if order == 1:
        return 1.0 / d + D * (2.0 - D) * T / (4.0 * d * d)
    if order == "poly3":
        alpha, beta = _c2_parts(d, D)
        P, Q = _c3_parts(d, D)
        return (2.0 + T * beta / 2.0 - T * T * Q) / (2.0 * d - T * alpha / 2.0 + T * T * P)
    raise ModelError(f"order: expected 0, 1 or 'poly3', got {order!r}")


def zad_multipliers_series(delta: float, ks: float, D: float, T: float,
                           order: int = 1) -> tuple[float, float]:
    """First-order series of the two Floquet multipliers of the 1T orbit.

    Parameters
    ----------
    delta : float
        Plant damping.
    ks : float
        Surface slope.
    D : float
        Duty ratio (unused at first order; kept for higher orders).
    T : float
        Sampling period.
    order : int
        Only 1 is provided.

    Returns
    -------
    (lambda_slow, lambda_fast) : tuple of float
        ``1 - T/k_s`` (sliding on ``s = 0``) and ``-1 + T(δ - 1/k_s)`` (the ``s``-dynamics).
    """
    if order != 1:
        raise ModelError(f"order: only the first-order series is provided, got {order!r}")
    return 1.0 - T / ks, -1.0 + T * (delta - 1.0 / ks)


def critical_ks(system: BuckConverter, *, T: float, x_ref: float, variant: Variant = "pl",
                plant: BuckConverter | None = None, bracket: tuple[float, float] | None = None,
                tol: float = 1e-10) -> float:
    """The ``k_s`` where the 1T orbit flips, by bisection on ``1 + tr J + det J``.

    Parameters
    ----------
    system : BuckConverter
        The controller's model.
    T : float
        Sampling period.
    x_ref : float
        Reference.
    variant : {"pl", "exact"}
        ZAD variant.
    plant : BuckConverter, optional
        The converter controlled (default: the model).
    bracket : (float, float), optional
        ``k_s`` interval with a sign change (default: around the first-order prediction).
    tol : float
        Width of the final interval.

    Returns
    -------
    float

    Raises
    ------
    SolverError
        No sign change in the bracket.
    """
    def flip(ks: float) -> float:
        loop = ZADController(system, ks, T, x_ref, variant).loop(plant)
        return loop.fixed_point().flip_function

    if bracket is None:
        guess = zad_flip_boundary((plant or system).delta, leading_duty(system, x_ref), T, 1)
        bracket = (0.7 * guess, 1.5 * guess)
    lo, hi = bracket
    f_lo, f_hi = flip(lo), flip(hi)
    if f_lo * f_hi > 0.0:
        raise SolverError(f"bracket: 1 + tr J + det J has the same sign at k_s = {lo:.6g} "
                          f"({f_lo:.3g}) and {hi:.6g} ({f_hi:.3g}); give a bracket around the "
                          "flip", status="bracket")
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        f_mid = flip(mid)
        if (f_mid > 0.0) == (f_hi > 0.0):
            hi, f_hi = mid, f_mid
        else:
            lo, f_lo = mid, f_mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class ZADDesign:
    """A ZAD design and its re-checked certificate.

    Attributes
    ----------
    controller
        The duty law with the chosen ``k_s``.
    orbit
        The 1T orbit of the closed loop (multipliers from the closed-form Jacobian).
    ks_critical
        The flip boundary found on the exact map.
    ks_predicted
        The first-order prediction ``1/δ + D0(2 - D0)T/(4δ²)``.
    margin
        ``k_s = (1 + margin) k_s,c``.
    mean_error
        ``mean(x1) - x_ref`` on the orbit.
    recheck_multipliers
        The multipliers recomputed from central differences of the map.
    recheck_error
        Their largest distance to ``orbit.multipliers``.
    min_current
        Smallest normalised inductor current ``x2 + δ x1`` sampled along the orbit
        (continuous conduction needs it positive when ``u_off = 0``).
    status
        ``"certified"`` or the reason the re-check was thin.
    """

    controller: ZADController
    orbit: ZADOrbit
    ks_critical: float
    ks_predicted: float
    margin: float
    mean_error: float
    recheck_multipliers: np.ndarray
    recheck_error: float
    min_current: float
    status: str

    @property
    def stability_margin(self) -> float:
        """``1 + λ_fast``: the distance of the negative multiplier from ``-1``."""
        return float(1.0 + np.min(self.orbit.multipliers.real))


#: Multipliers of the central-difference Jacobian (step ``h ~ 1e-6``, error
#: ``h² |P'''| + u/h ≈ 1e-10``) agree with the closed form to far better than this; a larger
#: gap means the certificate and the map disagree.
RECHECK_TOL = 1e-6


def design_zad(system: BuckConverter, *, T: float, x_ref: float, margin: float = 0.2,
               variant: Variant = "pl", compensate_offset: bool = False,
               duty_margin: float = 0.01) -> ZADDesign:
    """Choose ``k_s`` above the flip boundary with a margin and certify the 1T orbit.

    Parameters
    ----------
    system : BuckConverter
        The converter model.
    T : float
        Normalised sampling period.
    x_ref : float
        Normalised reference (``u_off < x_ref < u_on``).
    margin : float
        ``k_s = (1 + margin) k_s,c`` (``>= 0``).
    variant : {"pl", "exact"}
        ZAD variant.
    compensate_offset : bool
        Shift the surface's reference by the measured mean error (one Newton step), which
        removes PL-ZAD's ``O(T²)`` offset.
    duty_margin : float
        ``D0`` must lie in ``[duty_margin, 1 - duty_margin]`` (so ``0 <= duty_margin <=
        0.5``).

    Returns
    -------
    ZADDesign

    Raises
    ------
    InfeasibleDesignError
        The reference needs a duty outside ``(0, 1)`` (``x_ref >= u_on`` or ``<= u_off``),
        or the designed orbit is not stable.
    ModelError
        ``system`` not a :class:`BuckConverter`; ``duty_margin`` outside ``[0, 0.5]``; a
        non-numeric or non-finite number, a non-bool ``compensate_offset``.

    Examples
    --------
    >>> des = design_zad(BuckConverter.normalized(0.35), T=0.18, x_ref=0.8)
    >>> des.status, round(des.controller.ks / des.ks_critical, 6)
    ('certified', 1.2)
    """
    check_type("system", system, BuckConverter,
               hint="build it with BuckConverter(...) or BuckConverter.normalized(...)")
    T = check_positive("T", T)
    x_ref = as_finite_scalar("x_ref", x_ref)
    margin = check_positive("margin", margin, allow_zero=True)
    compensate_offset = check_bool("compensate_offset", compensate_offset)
    duty_margin = check_in_interval(
        "duty_margin", duty_margin, 0.0, 0.5,
        hint="D0 must lie in [duty_margin, 1 - duty_margin], which is empty above 0.5")
    D0 = leading_duty(system, x_ref)
    if not duty_margin <= D0 <= 1.0 - duty_margin:
        raise InfeasibleDesignError(
            f"x_ref: {x_ref} needs the duty ratio D0 = {D0:.4g}, outside [{duty_margin}, "
            f"{1 - duty_margin}]: the reference is not reachable between u_off = "
            f"{system.u_off} and u_on = {system.u_on} without saturation; lower x_ref below "
            "u_on (or raise the source voltage)", status="unreachable_reference")
    ks_c = critical_ks(system, T=T, x_ref=x_ref, variant=variant)
    ctrl = ZADController(system, (1.0 + margin) * ks_c, T, x_ref, variant)
    orbit = ctrl.loop().fixed_point()
    if compensate_offset:
        ctrl = ZADController(system, ctrl.ks, T, x_ref, variant,
                             x_ref_offset=x_ref - orbit.mean_x1)
        orbit = ctrl.loop().fixed_point(orbit.states[0])
    if not orbit.stable:
        raise InfeasibleDesignError(
            f"margin: the 1T orbit at k_s = {ctrl.ks:.6g} has multipliers "
            f"{np.round(orbit.multipliers, 6).tolist()}; raise margin", status="unstable")
    return _certify(system, ctrl, orbit, ks_c, D0, margin)


def _certify(system: BuckConverter, ctrl: ZADController, orbit: ZADOrbit, ks_c: float,
             D0: float, margin: float) -> ZADDesign:
    """Re-check the multipliers with a central-difference Jacobian and sample the current."""
    from ..numerics.differences import central_difference_jacobian

    loop = ctrl.loop()
    x_star = orbit.states[0]
    J_fd = central_difference_jacobian(loop, x_star)
    lam_fd = np.linalg.eigvals(J_fd)
    err = float(np.max(np.abs(np.sort_complex(lam_fd) - np.sort_complex(orbit.multipliers))))
    status = "certified"
    if err > RECHECK_TOL or not np.all(np.abs(lam_fd) < 1.0):
        status = f"recheck_thin: multipliers differ by {err:.3g}"
        warnings.warn(f"design_zad: the re-checked multipliers {np.round(lam_fd, 8).tolist()} "
                      f"differ from the closed form by {err:.3g}", InaccurateCertificateWarning,
                      stacklevel=3)
    i_min = _min_current(system, x_star, float(orbit.duties[0]), ctrl.T)
    if system.u_off == 0.0 and i_min <= 0.0:   # a diode blocks: the model assumes i > 0
        status = f"discontinuous_conduction: min current {i_min:.3g}"
        warnings.warn(f"design_zad: the inductor current reaches {i_min:.3g} <= 0 on the "
                      "orbit: the converter leaves continuous conduction and the model does "
                      "not hold; raise the load current or lower the period",
                      InaccurateCertificateWarning, stacklevel=3)
    return ZADDesign(ctrl, orbit, ks_c, zad_flip_boundary(system.delta, D0, ctrl.T, 1),
                     margin, orbit.mean_x1 - ctrl.x_ref, lam_fd, err, i_min, status)


def _min_current(system: BuckConverter, x: FloatArray, d: float, T: float,
                 n: int = 64) -> float:
    """``min (x2 + δ x1)`` over ``n`` samples of each piece of one period."""
    lows = []
    for u, tau in ((system.u_on, d / 2), (system.u_off, T - d), (system.u_on, d / 2)):
        for t in np.linspace(0.0, tau, n):
            y = K.piece(system.delta, u, x[0], x[1], t)
            lows.append(y[1] + system.delta * y[0])
        x = np.array(K.piece(system.delta, u, x[0], x[1], tau))
    return float(min(lows))
