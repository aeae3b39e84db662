"""Sliding-mode control and Levant's differentiator, sampled, with explicit or implicit
discretization.

Three sampled blocks (the :class:`~nscontrol.systems.feedback.Controller` protocol, period
``h``, zero-order hold) on a :class:`~nscontrol.systems.sliding_mode.SlidingModePlant`
``x' = A x + B (u + d)``, ``s = c x``, with ``Φ = e^{Ah}``, ``Γ = ∫_0^h e^{Aτ} dτ B``:

* :class:`FirstOrderSMC` — ``u_k = u_eq,k + u_s,k`` with the discrete equivalent control
  ``u_eq,k = -(cΓ)^{-1} c (Φ - I) x_k`` (so ``s_{k+1} = s_k + cΓ u_s,k`` without disturbance)
  and the switching part, explicit ``u_s = -α sign(s_k)`` or implicit
  ``u_s ∈ -α Sign(s_{k+1})``, whose solution is the projection ``u_s = -proj_[-α,α](s_k/cΓ)``
  (Acary & Brogliato 2010);
* :class:`SuperTwistingController` — ``u = -k1 |s|^{1/2} sign(s) + ν``, ``ν' = -k2 sign(s)``;
  explicit: evaluated at ``s_k``; implicit: at the predicted ``s_{k+1}``, the root of the
  scalar inclusion ``s + cΓ k1 |s|^{1/2} sign(s) + cΓ h k2 Sign(s) ∋ c Φ x_k + cΓ ν_k``
  solved in closed form (a quadratic in ``|s|^{1/2}``; Brogliato, Polyakov & Efimov 2020);
* :class:`LevantDifferentiator` — the same two-term law driven by ``z0 - f``, explicit or
  implicit (the same scalar inclusion with ``h k1``, ``h² k2``).

``nscontrol.simulate(nscontrol.closed_loop(plant, controller), x0, t_span,
method="sampled_zoh")`` runs a block on a plant with exact zero-order-hold propagation of the
plant and of its disturbance generator, the block in its compiled form
(:meth:`FirstOrderSMC.compiled`, :meth:`SuperTwistingController.compiled`: the blocks'
Python methods call the same compiled functions); :func:`run_sampled` is that call. The gain
rule for a disturbance whose derivative is bounded by ``L`` is :func:`super_twisting_gains`.
The derivations are in ``docs/sliding_mode.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector, check_bool, check_positive
from ..errors import ModelError
from ..numerics.lti import discretize
from ..simulate.trajectory import Trajectory
from ..systems.feedback import CompiledBlock, Jump, Measurement, StaticLaw
from ..systems.sliding_mode import SlidingModePlant
from . import _sliding_mode_kernels as kern

__all__ = ["super_twisting_gains", "FirstOrderSMC", "SuperTwistingController",
           "LevantDifferentiator", "differentiate", "run_sampled"]

_DISCRETIZATIONS = ("implicit", "explicit")


def super_twisting_gains(L: float) -> tuple[float, float]:
    """Levant's gain rule ``k1 = 1.5 L^{1/2}``, ``k2 = 1.1 L`` for ``|d'| <= L``.

    With these gains the super-twisting loop ``s' = -k1 |s|^{1/2} sign(s) + ν + d(t)``,
    ``ν' = -k2 sign(s)`` reaches ``s = s' = 0`` in finite time for every disturbance with
    ``|d'| <= L`` (A. Levant, Int. J. Control 76(9/10), 2003: the parameters
    ``λ1 = 1.5``, ``λ0 = 1.1`` of the first-order differentiator, scaled by ``L``).

    Parameters
    ----------
    L : float
        Bound ``> 0`` on the derivative of the disturbance (on ``|f''|`` for the
        differentiator).

    Returns
    -------
    tuple of float
        ``(k1, k2)``.

    Examples
    --------
    >>> k1, k2 = super_twisting_gains(1.5)
    >>> round(k1, 6), round(k2, 6)
    (1.837117, 1.65)
    """
    L = check_positive("L", L)
    return 1.5 * float(np.sqrt(L)), 1.1 * L


def _check_discretization(value: Any) -> str:
    if value not in _DISCRETIZATIONS:
        raise ModelError(f"discretization: expected 'implicit' or 'explicit', got {value!r}")
    return str(value)


def _plant_model(plant: Any, h: float) -> tuple[FloatArray, FloatArray, float]:
    """``(c Φ, c (Φ - I), c Γ)`` of the plant's zero-order-hold model (no disturbance)."""
    if not isinstance(plant, SlidingModePlant):
        raise ModelError(f"plant: expected a SlidingModePlant, got {type(plant).__name__}")
    Phi, Gam = discretize(plant.A, plant.B, h)
    cPhi = plant.c @ Phi
    cG = float(plant.c @ Gam[:, 0])
    if cG == 0.0:
        raise ModelError(f"period: c Γ = 0 at h = {h:.3g}, so u does not reach the next "
                         f"sample of s; choose another sampling period")
    return cPhi, cPhi - plant.c, cG


_EMPTY = np.zeros(0)


def _vec(a: Any) -> FloatArray:
    """A measurement's field as the compiled forms take it (empty for ``None``)."""
    return _EMPTY if a is None else np.ascontiguousarray(a, dtype=np.float64).reshape(-1)


class _CompiledLaw:
    """A block whose law is its compiled form: ``output``/``update`` call the compiled
    functions (one source for the Python path and the compiled loops)."""

    _form: CompiledBlock

    def compiled(self) -> CompiledBlock:
        """The compiled form (:class:`~nscontrol.systems.feedback.CompiledBlock`) that the
        integrators' compiled loops call, and that :meth:`output` and :meth:`update` call."""
        return self._form

    def _call(self, fn: Any, t: float, xc: Any, m: Measurement) -> FloatArray:
        return np.asarray(fn(float(t), _vec(xc), _vec(m.y), _vec(m.x), _vec(m.xhat),
                             _vec(m.lam), self._form.params))

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The block's output ``[u_k]`` at the sampling instant ``t``.

        Parameters
        ----------
        t : float
            Sampling instant.
        xc : ndarray
            The internal state.
        m : Measurement
            Reads the plant state ``m.x``.
        """
        return self._call(self._form.output, t, xc, m)

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The internal state at the next sample.

        Parameters
        ----------
        t : float
            Sampling instant.
        xc : ndarray
            The internal state.
        m : Measurement
            Reads the plant state ``m.x``.
        """
        return self._call(self._form.update, t, xc, m)

    def reset(self, t: float, xc: FloatArray, jump: Jump) -> FloatArray:
        """The internal state is unchanged by a plant jump.

        Parameters
        ----------
        t : float
            Time of the jump.
        xc : ndarray
            The internal state.
        jump : Jump
            Unused.
        """
        return xc


class _SampledBlock:
    """The block interface of a sampled law with internal state whose one step gives both
    its output at ``t_k`` and its state at the next sample (:meth:`_advance`)."""

    def _advance(self, xc: FloatArray, m: Measurement) -> tuple[FloatArray, FloatArray]:
        raise NotImplementedError

    def output(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The block's output at the sampling instant ``t``.

        Parameters
        ----------
        t : float
            Sampling instant.
        xc : ndarray
            The internal state.
        m : Measurement
            The plant's measurement at ``t``.
        """
        return self._advance(xc, m)[0]

    def update(self, t: float, xc: FloatArray, m: Measurement) -> FloatArray:
        """The internal state at the next sample.

        Parameters
        ----------
        t : float
            Sampling instant.
        xc : ndarray
            The internal state.
        m : Measurement
            The plant's measurement at ``t``.
        """
        return self._advance(xc, m)[1]

    def reset(self, t: float, xc: FloatArray, jump: Any) -> FloatArray:
        """The internal state is unchanged by a plant jump.

        Parameters
        ----------
        t : float
            Time of the jump.
        xc : ndarray
            The internal state.
        jump : Jump
            Unused.
        """
        return xc


@dataclass(frozen=True, eq=False)
class FirstOrderSMC(_CompiledLaw, StaticLaw):
    """First-order sliding-mode control with the discrete equivalent control, sampled.

    Parameters
    ----------
    plant : SlidingModePlant
        The plant (its ``A``, ``B``, ``c``; the disturbance is unknown to the controller).
    alpha : float
        Switching gain ``> 0``; the surface is reached when ``alpha > sup |d|``.
    period : float
        Sampling period ``h > 0``.
    discretization : {"implicit", "explicit"}
        ``u_s ∈ -α Sign(s_{k+1})`` solved exactly, or ``u_s = -α sign(s_k)``.

    Notes
    -----
    Without disturbance the implicit loop reaches ``s = 0`` after
    ``ceil(|s_0| / (α |cΓ|))`` samples and keeps ``s_k = 0`` with ``u_k = u_eq,k`` (the
    projection is inactive) to roundoff; the explicit one switches every sample around the
    surface with ``|s_k| <= α |cΓ| = O(h)``.

    Examples
    --------
    >>> import nscontrol as nsc
    >>> p = SlidingModePlant.double_integrator()
    >>> ctrl = FirstOrderSMC(p, alpha=1.0, period=1e-3)
    >>> tr = nsc.simulate(nsc.closed_loop(p, ctrl), [1.0, 0.0], (0.0, 2.0),
    ...                   method="sampled_zoh")
    >>> bool(np.max(np.abs(tr.signal("s")[-500:])) < 1e-12)
    True
    """

    plant: SlidingModePlant
    alpha: float
    period: float
    discretization: str = "implicit"
    n_outputs: int = field(default=1, init=False)
    _model: tuple[FloatArray, FloatArray, float] = field(init=False, repr=False)
    _form: CompiledBlock = field(init=False, repr=False)

    def __post_init__(self) -> None:
        from ..systems._feedback_kernels import static_update

        object.__setattr__(self, "alpha", check_positive("alpha", self.alpha))
        object.__setattr__(self, "period", check_positive("period", self.period))
        object.__setattr__(self, "discretization", _check_discretization(self.discretization))
        model = _plant_model(self.plant, self.period)
        object.__setattr__(self, "_model", model)
        n = self.plant.n_states
        head = [float(n), float(self.discretization == "implicit"), self.alpha, model[2]]
        assert len(head) == kern.FO_ROWS
        object.__setattr__(self, "_form", CompiledBlock(
            kern.first_order_output, static_update,
            np.concatenate([head, self.plant.c, model[1]])))

    @property
    def cG(self) -> float:
        """``c Γ``: the gain of ``u_k`` in ``s_{k+1}``."""
        return self._model[2]

    def equivalent_control(self, x: ArrayLike) -> float:
        """``u_eq = -(cΓ)^{-1} c (Φ - I) x``: the input that keeps ``s_{k+1} = s_k``.

        Parameters
        ----------
        x : array_like
            Plant state.
        """
        return -float(self._model[1] @ np.asarray(x, dtype=float)) / self.cG


@dataclass(frozen=True, eq=False)
class SuperTwistingController(_CompiledLaw):
    """The super-twisting controller, sampled; internal state ``ν``.

    Parameters
    ----------
    plant : SlidingModePlant
        The plant (``c B > 0``); the implicit law predicts ``s_{k+1}`` with its ZOH model.
    k1, k2 : float
        Gains ``> 0`` (:func:`super_twisting_gains`).
    period : float
        Sampling period ``h > 0``.
    discretization : {"implicit", "explicit"}
        See the module's notes.
    nu0 : float
        Initial ``ν`` (default 0).
    estimate_disturbance : bool
        Implicit law only (default True): predict ``s_{k+1}`` with the one-step disturbance
        estimate ``d̂_k = d̂_{k-1} + (s_k - s̃_k) / cΓ`` (``s̃_k`` the law's own prediction of
        ``s_k``), i.e. ``p = c Φ x_k + cΓ (ν_k + d̂_k)``. It brings ``|s_k|`` from
        ``cΓ |d| = O(h)`` down to ``cΓ |d̄_k - d̄_{k-1}| = O(h²)`` (``d̄_k`` the mean
        disturbance over step ``k``); without disturbance ``d̂`` stays at rounding level.

    Notes
    -----
    Implicit: with ``p = c Φ x_k + cΓ ν_k`` the predicted sample solves
    ``s + cΓ k1 |s|^{1/2} sign(s) + cΓ h k2 Sign(s) ∋ p``: ``s = 0`` when
    ``|p| <= cΓ h k2``, else ``s = sign(p) r²`` with ``r² + cΓ k1 r = |p| - cΓ h k2``. Then
    ``σ = (p - s - cΓ k1 |s|^{1/2} sign(s)) / (cΓ h k2) ∈ Sign(s)``, ``ν_{k+1} = ν_k - h k2 σ``,
    ``u_k = -k1 |s|^{1/2} sign(s) + ν_{k+1}``. Without disturbance the plant's next sample
    is that ``s``, so ``s_k`` is zero from the first sample where ``|p| <= cΓ h k2``.

    Examples
    --------
    >>> import nscontrol as nsc
    >>> p = SlidingModePlant.double_integrator()
    >>> st = SuperTwistingController(p, *super_twisting_gains(1.5), period=1e-2)
    >>> tr = nsc.simulate(nsc.closed_loop(p, st), [0.5, 0.0], (0.0, 6.0),
    ...                   method="sampled_zoh")
    >>> bool(np.max(np.abs(tr.signal("s")[-100:])) < 1e-14)
    True
    """

    plant: SlidingModePlant
    k1: float
    k2: float
    period: float
    discretization: str = "implicit"
    nu0: float = 0.0
    estimate_disturbance: bool = True
    n_outputs: int = field(default=1, init=False)
    _model: tuple[FloatArray, FloatArray, float] = field(init=False, repr=False)
    _form: CompiledBlock = field(init=False, repr=False)

    @property
    def n_states(self) -> int:
        """``ν`` (explicit); ``ν``, the last prediction ``s̃``, ``d̂`` and a started flag
        (implicit)."""
        return 4 if self.discretization == "implicit" else 1

    @property
    def x0(self) -> FloatArray:
        """The internal state at the first sample (``ν = nu0``, what ``closed_loop`` starts
        the block from)."""
        return np.array([self.nu0, 0.0, 0.0, 0.0][:self.n_states])

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "period"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        object.__setattr__(self, "discretization", _check_discretization(self.discretization))
        object.__setattr__(self, "nu0", float(as_vector("nu0", [self.nu0], 1)[0]))
        object.__setattr__(self, "estimate_disturbance",
                           check_bool("estimate_disturbance", self.estimate_disturbance))
        model = _plant_model(self.plant, self.period)
        if model[2] <= 0.0:
            raise ModelError(f"plant: expected c Γ > 0 (u pushing s up; got {model[2]:.3g}); "
                             f"use -c as the sliding variable")
        object.__setattr__(self, "_model", model)
        head = [float(self.plant.n_states), float(self.discretization == "implicit"),
                float(self.estimate_disturbance), self.k1, self.k2, self.period, model[2]]
        assert len(head) == kern.ST_ROWS
        object.__setattr__(self, "_form", CompiledBlock(
            kern.super_twisting_output, kern.super_twisting_update,
            np.concatenate([head, self.plant.c, model[0]])))

    @property
    def cG(self) -> float:
        """``c Γ``: the gain of ``u_k`` in ``s_{k+1}``."""
        return self._model[2]


@dataclass(frozen=True, eq=False)
class LevantDifferentiator(_SampledBlock):
    """Levant's robust exact differentiator of the measured ``y = f(t)``, sampled.

    ``z0' = -k1 |z0 - f|^{1/2} sign(z0 - f) + z1``, ``z1' = -k2 sign(z0 - f)``; its output is
    ``(z0, z1) ≈ (f, f')``.

    Parameters
    ----------
    k1, k2 : float
        Gains ``> 0`` (:func:`super_twisting_gains` with ``L >= sup |f''|``).
    period : float
        Sampling period ``h > 0``.
    discretization : {"implicit", "explicit"}
        Implicit: the estimate at ``t_k`` solves the inclusion with ``f_k`` at the new sample
        (``e + h k1 |e|^{1/2} sign(e) + h² k2 Sign(e) ∋ z0 + h z1 - f_k``,
        ``z0 = f_k + e``); explicit: the forward Euler step with ``sign(z0_k - f_k)``.
    x0 : array_like
        Initial ``(z0, z1)`` (default zeros).

    Notes
    -----
    Noise-free, the sampled differentiator's errors after convergence are ``O(h²)`` on ``f``
    and ``O(h)`` on ``f'`` (Levant 2003); :func:`differentiate` runs it over samples.
    """

    k1: float
    k2: float
    period: float
    discretization: str = "implicit"
    x0: Any = (0.0, 0.0)
    n_states: int = field(default=2, init=False)
    n_outputs: int = field(default=2, init=False)

    def __post_init__(self) -> None:
        for name in ("k1", "k2", "period"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        object.__setattr__(self, "discretization", _check_discretization(self.discretization))
        object.__setattr__(self, "x0", as_vector("x0", self.x0, 2))

    def step(self, z: FloatArray, f: float) -> tuple[FloatArray, FloatArray]:
        """``(estimate at t_k, state for the next sample)`` from the state ``z`` and ``f_k``.

        Parameters
        ----------
        z : ndarray
            ``(z0, z1)``: the previous estimate (implicit) or the prediction for ``t_k``
            (explicit).
        f : float
            The sample ``f_k``.
        """
        h, k1, k2 = self.period, self.k1, self.k2
        if self.discretization == "implicit":
            p = z[0] + h * z[1] - f
            e = kern.st_resolvent(p, h * k1, h * h * k2)
            sigma = min(max((p - e - h * k1 * kern.psi(e)) / (h * h * k2), -1.0), 1.0)
            new = np.array([f + e, z[1] - h * k2 * sigma])
            return new, new
        e = z[0] - f
        sg = float(np.sign(e))
        nxt = np.array([z[0] + h * (-k1 * kern.psi(e) + z[1]), z[1] - h * k2 * sg])
        return np.asarray(z, dtype=float).copy(), nxt

    def _advance(self, xc: FloatArray, m: Measurement) -> tuple[FloatArray, FloatArray]:
        """``(estimate (f̂, f̂') at t_k, state at the next sample)`` from ``(z0, z1)`` and the
        measured ``m.y[0] = f_k``."""
        return self.step(xc, float(m.y[0]))


def differentiate(diff: LevantDifferentiator, samples: ArrayLike) -> FloatArray:
    """Run a sampled differentiator over ``f_k = samples[k]``; returns ``(k, 2)`` estimates.

    Parameters
    ----------
    diff : LevantDifferentiator
        The block (its period is the sample spacing).
    samples : array_like
        The samples ``f(t0 + k h)``.

    Examples
    --------
    >>> h = 1e-3
    >>> t = np.arange(0.0, 5.0, h)
    >>> est = differentiate(LevantDifferentiator(*super_twisting_gains(1.0), period=h),
    ...                     np.sin(t))
    >>> bool(np.max(np.abs(est[-1000:, 1] - np.cos(t[-1000:]))) < 1e-2)
    True
    """
    f = as_vector("samples", samples)
    z = diff.x0.copy()
    out = np.empty((f.shape[0], 2))
    for k, fk in enumerate(f.tolist()):
        out[k], z = diff.step(z, fk)
    return out


def run_sampled(plant: SlidingModePlant, controller: FirstOrderSMC | SuperTwistingController,
                x0: ArrayLike, t_span: tuple[float, float]) -> Trajectory:
    """The sampled loop of ``plant`` and ``controller``, propagated exactly between samples.

    The same as ``nscontrol.simulate(nscontrol.closed_loop(plant, controller), x0, t_span,
    method="sampled_zoh")``, which it calls (see :mod:`nscontrol.simulate.sampled_zoh`): the
    plant and its disturbance generator ``[x; w]`` form one linear system stepped by its
    exact zero-order-hold matrices over each sampling period (no integration error); the
    controller runs in its compiled form (the functions its ``output``/``update`` call).

    Parameters
    ----------
    plant : SlidingModePlant
        The plant, with its disturbance.
    controller : FirstOrderSMC or SuperTwistingController
        A sampled block (any sampled :class:`~nscontrol.systems.feedback.Controller` runs).
    x0 : array_like
        Plant initial state.
    t_span : (float, float)
        ``(t0, tf)``; the samples are ``t0 + k T`` up to the last one at or before ``tf``
        (``T`` the controller's period).

    Returns
    -------
    Trajectory
        The samples ``x_k``, with signals ``"s"`` (``s_k``), ``"u"`` (the input held over
        ``[t_k, t_{k+1})``) and ``"xc"`` (the controller's state at ``t_k``: super-twisting's
        ``ν_k`` is its first column).

    Raises
    ------
    ModelError
        A controller that is not a sampled block.
    DimensionError
        ``x0`` of the wrong length, or a span shorter than one period.
    """
    from ..simulate import simulate
    from ..simulate.closed_loop import closed_loop

    return simulate(closed_loop(plant, controller), x0, t_span, method="sampled_zoh")
