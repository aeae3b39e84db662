"""LMI design of convergent closed loops for continuous PWA systems (chapter 11, §2.5).

* :func:`design_state_feedback` — linear state feedback ``u = Kx`` with a decay rate and a
  gain bound (SF-σ);
* :func:`design_state_feedback_l2` — linear state feedback minimising the L2 gain ``γ`` from
  the disturbance to ``z = (C_z x, ρu)``, a control penalty ``ρ > 0`` setting the trade-off
  between attenuation and effort (SF-L2);
* :func:`design_pwa_state_feedback` — continuity-preserving PWA feedback
  ``u = Kx + ν·min(cᵀx - d, 0)`` for bimodal systems (§2.5 b), and
  :func:`tune_pwa_state_feedback` choosing ``ν`` by a one-dimensional search;
* :func:`design_observer` — piecewise-linear observer with the mode chosen by the estimate
  (OBS-σ), gain-bounded; :func:`output_feedback_loop` — plant + observer + feedback.

Every design is solved in scaled coordinates (:class:`~nscontrol.numerics.scaling.Scaling`),
mapped back, and its certificate re-checked in NumPy in the original coordinates
(:func:`~nscontrol.numerics.lmi.recheck_lyapunov`) before it is returned; an
infeasible problem raises :class:`~nscontrol.errors.InfeasibleDesignError` carrying the
solver's status.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_matrix, as_real_scalar, check_positive
from ..errors import DimensionError, InaccurateCertificateWarning, InfeasibleDesignError, ModelError
from ..numerics.scaling import Scaling
from ..numerics.statespace import is_state_space, state_space_matrices

if TYPE_CHECKING:   # imported where used at run time
    from ..systems.feedback import PiecewiseStateFeedback
    from ..systems.pwa import PiecewiseAffineSystem


__all__ = [
    "ConvergentStateFeedback", "PWAStateFeedback", "ConvergentObserver",
    "EstimateFeedback", "design_state_feedback", "design_state_feedback_l2",
    "design_pwa_state_feedback",
    "tune_pwa_state_feedback", "design_observer", "output_feedback_loop",
]

FloatArray = NDArray[np.float64]

#: Strictness margin imposed on the LMIs in scaled coordinates (``<= -δI`` instead of ``< 0``).
LMI_MARGIN = 1e-6


# -- certificate re-check ---------------------------------------------------------------------

def _recheck(As: Sequence[FloatArray], P: FloatArray, decay: float, *, who: str,
             status: str) -> None:
    """Raise InfeasibleDesignError unless P > 0 and the decay LMI holds (to 1e-8·‖P‖)."""
    from ..numerics.lmi import LYAPUNOV_RECHECK_RTOL, recheck_lyapunov

    check = recheck_lyapunov(As, P, decay)
    if not check.holds(LYAPUNOV_RECHECK_RTOL):
        raise InfeasibleDesignError(
            f"{who}: the solver returned {status!r} but its certificate fails the NumPy "
            f"re-check (min eig P = {check.P_min_eig:.3g}, max eig(AᵢᵀP + PAᵢ + 2σP)/‖P‖ = "
            f"{check.residual:.3g} > {LYAPUNOV_RECHECK_RTOL:g}); rescale the model "
            f"(scale=Scaling.mechanical(...) or 'auto') or lower sigma",
            status="certificate_check_failed")


def _resolve_scaling(scale: Scaling | str | None, As: Sequence[FloatArray],
                     B: FloatArray | None, C: FloatArray | None = None) -> Scaling:
    n = As[0].shape[0]
    if scale is None:
        return Scaling.identity(n)
    if isinstance(scale, str):
        if scale != "auto":
            raise ModelError(f"scale: expected None, 'auto' or a Scaling, got {scale!r}")
        return Scaling.auto(As, B, C)
    if not isinstance(scale, Scaling):
        raise ModelError(f"scale: expected None, 'auto' or a Scaling, got {type(scale).__name__}")
    if scale.S.shape != (n, n):
        raise DimensionError(f"scale.S: expected shape ({n}, {n}), got {scale.S.shape}")
    return scale


# -- results ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class ConvergentStateFeedback:
    """A linear state feedback ``u = Kx`` making the closed loop quadratically convergent.

    Attributes
    ----------
    K
        Gain, shape ``(p, n)`` (original units).
    B
        The control input matrix it was designed for, shape ``(n, p)``.
    P
        Certificate: ``(A_i + BK)ᵀP + P(A_i + BK) + 2σP <= 0`` for every mode, ``P > 0``
        (re-checked in NumPy).
    sigma
        Certified decay rate (1/time unit of the model).
    gain_bound
        ``√κ``: ``‖K̃‖ <= √κ`` in the scaled coordinates of :attr:`scaling`.
    scaling
        The coordinates the LMI was solved in.
    status
        The solver's status.
    gamma
        :func:`design_state_feedback_l2` only: the certified L2 gain from the disturbance
        ``w`` to ``z = (C_z x, ρu)``, in units of ``[z]/[w]`` (NaN for the other designs).
    rho
        :func:`design_state_feedback_l2` only: the control penalty, in ``[z]/[u]`` (NaN
        otherwise).
    """

    K: FloatArray
    B: FloatArray
    P: FloatArray
    sigma: float
    gain_bound: float
    scaling: Scaling
    status: str
    gamma: float = float("nan")
    rho: float = float("nan")

    def gains(self, n_regions: int) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
        """Per-region ``(K_i, k_i)`` (the same linear law in every region)."""
        p = self.K.shape[0]
        return (self.K,) * n_regions, (np.zeros(p),) * n_regions

    def control(self, x: ArrayLike) -> FloatArray:
        """``u = Kx`` (time-major ``x`` of shape ``(k, n)`` gives ``u`` of shape ``(k, p)``);
        pass it as ``control=`` to the frequency-response helpers to get the effort."""
        return np.asarray(x, float) @ self.K.T

    def closed_loop(self, system: PiecewiseAffineSystem) -> PiecewiseAffineSystem:
        """The closed loop ``x' = (A_i + BK)x + b_i + Eu(t)`` as a PWA system."""
        return _with_feedback(system, self.B, *self.gains(len(system.A)))

    def controller(self, n_regions: int) -> PiecewiseStateFeedback:
        """This law as a block for :func:`nscontrol.closed_loop` (``input_matrix=self.B``)."""
        from ..systems.feedback import PiecewiseStateFeedback

        return PiecewiseStateFeedback(*self.gains(n_regions))


@dataclass(frozen=True)
class PWAStateFeedback:
    """Continuity-preserving bimodal PWA feedback ``u = Kx + ν·min(cᵀx - d, 0)``.

    With the model's bimodal convention (region 0: ``cᵀx <= d``, region 1: ``cᵀx >= d``) the
    per-region law ``u = K_i x + k_i`` is ``K_0 = K + νcᵀ``, ``k_0 = -νd`` and ``K_1 = K``,
    ``k_1 = 0``: ``K_0 - K_1 = νcᵀ``, ``k_0 - k_1 = -νd``, so ``u`` is continuous across the
    facet.

    Attributes
    ----------
    K, k
        Per-region gains and offsets (region order of the model).
    B
        Control input matrix.
    nu
        Slope ``ν`` of the one-sided term (one entry per input).
    c, d
        The facet ``cᵀx = d``.
    P, sigma, gain_bound, scaling, status
        As in :class:`ConvergentStateFeedback` (common ``P`` for both closed-loop modes).
    """

    K: tuple[FloatArray, FloatArray]
    k: tuple[FloatArray, FloatArray]
    B: FloatArray
    nu: FloatArray
    c: FloatArray
    d: float
    P: FloatArray
    sigma: float
    gain_bound: float
    scaling: Scaling
    status: str

    def gains(self, n_regions: int = 2) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
        """Per-region ``(K_i, k_i)``."""
        return self.K, self.k

    @property
    def region_gains(self) -> tuple[float, float]:
        """``‖K̃_i‖`` per region in the scaled coordinates (``K̃_i = K_i S⁻¹/f``), the figure
        :func:`tune_pwa_state_feedback` minimises the largest of."""
        Sinv = np.linalg.inv(self.scaling.S)
        return tuple(float(np.linalg.norm(K @ Sinv, 2)) / self.scaling.input_unit
                     for K in self.K)  # type: ignore[return-value]  # bimodal: 2 gains

    def control(self, x: ArrayLike) -> FloatArray:
        """``u = K_1x + ν·min(cᵀx - d, 0)`` (time-major ``x`` gives time-major ``u``)."""
        x = np.asarray(x, float)
        s = np.minimum(x @ self.c - self.d, 0.0)
        return x @ self.K[1].T + np.multiply.outer(s, self.nu)

    def closed_loop(self, system: PiecewiseAffineSystem) -> PiecewiseAffineSystem:
        """The closed loop ``x' = (A_i + BK_i)x + b_i + Bk_i + Eu(t)`` as a PWA system."""
        return _with_feedback(system, self.B, self.K, self.k)

    def controller(self, n_regions: int = 2) -> PiecewiseStateFeedback:
        """This law as a block for :func:`nscontrol.closed_loop` (``input_matrix=self.B``)."""
        from ..systems.feedback import PiecewiseStateFeedback

        return PiecewiseStateFeedback(self.K, self.k)


@dataclass(frozen=True)
class ConvergentObserver:
    """A piecewise-linear observer ``x̂' = A_{j(x̂)}x̂ + b_{j(x̂)} + Bv + Eu + L(y - Cx̂)``.

    Attributes
    ----------
    L
        Output injection gain, shape ``(n, q)``.
    C
        The measured output matrix it was designed for.
    P
        Certificate: ``(A_i - LC)ᵀP + P(A_i - LC) + 2σP <= 0`` for every mode, so
        ``|e(t)| <= √κ(P) e^{-σt}|e(0)|`` whatever the plant does.
    sigma
        Certified decay rate of the error.
    gain_bound
        ``√κ_o``: ``‖L̃‖ <= √κ_o`` in scaled coordinates.
    kappa
        Condition number of ``P`` (the overshoot factor is ``√kappa``).
    scaling, status
        As in :class:`ConvergentStateFeedback`.
    """

    L: FloatArray
    C: FloatArray
    P: FloatArray
    sigma: float
    gain_bound: float
    kappa: float
    scaling: Scaling
    status: str

    def error_bound(self, t: ArrayLike, e0_norm: float) -> FloatArray:
        """``√κ(P) e^{-σt}|e(0)|``."""
        return np.sqrt(self.kappa) * np.exp(-self.sigma * np.asarray(t, float)) * e0_norm


@dataclass(frozen=True)
class EstimateFeedback:
    """The control of an observer-based loop, ``u = K_{j(x̂)}x̂ + k_{j(x̂)}``, read from the
    state ``(x, x̂)`` of :func:`output_feedback_loop` (a picklable callable: pass it as
    ``control=`` to the frequency-response helpers to get the effort).

    Attributes
    ----------
    feedback
        The state feedback applied to the estimate.
    n_plant
        ``n``: the estimate is ``x[:, n:]``.
    """

    feedback: Any
    n_plant: int

    def __call__(self, x: Any) -> FloatArray:
        return self.feedback.control(np.asarray(x, float)[..., self.n_plant:])


# -- closed loops ----------------------------------------------------------------------------

def _with_feedback(system: PiecewiseAffineSystem, B: FloatArray, Ks: Sequence[FloatArray],
                   ks: Sequence[FloatArray]) -> PiecewiseAffineSystem:
    from ..simulate.lowering import stacked_model
    from ..systems.closed_loop import closed_loop
    from ..systems.feedback import PiecewiseStateFeedback

    return stacked_model(closed_loop(system, PiecewiseStateFeedback(Ks, ks),
                                     input_matrix=B))


def output_feedback_loop(system: PiecewiseAffineSystem, observer: ConvergentObserver,
                         feedback: ConvergentStateFeedback | PWAStateFeedback | None = None
                         ) -> Any:
    """Plant + observer + feedback ``u = K_{j(x̂)}x̂ + k_{j(x̂)}`` as one PWA system in
    ``(x, x̂)`` (2n states, regions = products of plant and observer regions).

    In region ``(i, j)`` (plant in ``i``, estimate in ``j``)::

        x'  = A_i x + b_i + BK_j x̂ + Bk_j + E u(t)
        x̂' = A_j x̂ + b_j + BK_j x̂ + Bk_j + E u(t) + LC(x - x̂)

    With ``feedback=None`` the plant runs open loop (observer only). The output ``C`` of the
    result is ``[I, 0]`` (plant state) — use ``x[:, n:]`` for the estimate.

    Parameters
    ----------
    system : PiecewiseAffineSystem
        The continuous plant.
    observer : ConvergentObserver
        From :func:`design_observer`.
    feedback : ConvergentStateFeedback or PWAStateFeedback, optional
        From :func:`design_state_feedback` or :func:`design_pwa_state_feedback` (default: open
        loop).

    Notes
    -----
    Separation (ch11 §2.5 d): the error decays by the observer certificate whatever the
    plant does, and the plant is input-to-state convergent under the feedback, so the loop is
    convergent and its steady state has ``x̂ = x = x̄^{SF}``. Hypotheses: the plant is a
    continuous PWA model (checked by the designs), the feedback and the observer were designed
    for it (independently), and the observer knows ``u(t)``. A CQLF of the 2n-dimensional
    loop need not exist; test it by simulation and Floquet multipliers. The loop's control
    signal is :class:`EstimateFeedback` ``(feedback, n)``.

    References
    ----------
    D5.3 chapter 11 §2.5(d); A. Pavlov, N. van de Wouw, H. Nijmeijer, "Convergent systems:
    analysis and synthesis", LNCIS 322, Springer 2005 (output-feedback design for
    input-to-state convergence).

    Examples
    --------
    The steady state of the observer-based loop is the state-feedback one, with ``e = 0``:

    >>> import numpy as np
    >>> from nscontrol.analysis.periodic import periodic_steady_state
    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> from nscontrol.numerics.lti import Exosystem
    >>> plant = one_sided_oscillator(0.1)
    >>> sf = design_state_feedback(plant, sigma=0.3)
    >>> loop = output_feedback_loop(plant, design_observer(plant, sigma=1.0), sf)
    >>> loop.n_states, loop.n_regions
    (4, 4)
    >>> w = Exosystem.sinusoid(1.0, 2.9)
    >>> x0 = periodic_steady_state(loop, 2 * np.pi / 2.9, u=w).x0
    >>> ref = periodic_steady_state(sf.closed_loop(plant), 2 * np.pi / 2.9, u=w).x0
    >>> bool(np.allclose(x0[:2], ref, atol=1e-9) and np.allclose(x0[2:], x0[:2], atol=1e-9))
    True
    """
    from ..simulate.lowering import stacked_model
    from ..systems.closed_loop import closed_loop
    from ..systems.feedback import PiecewiseObserver, PiecewiseStateFeedback

    controller = None
    if feedback is not None:
        controller = PiecewiseStateFeedback(*feedback.gains(len(system.A)), on="estimate")
    return stacked_model(closed_loop(system, controller,
                                     PiecewiseObserver(observer.L, observer.C),
                                     input_matrix=None if feedback is None else feedback.B))


# -- designs ---------------------------------------------------------------------------------

def _scalar_block(kappa: Any, k: int) -> Any:
    """``κ·I_k`` as a CVXPY block (a 1×1 reshape when ``k = 1``)."""
    import cvxpy as cp

    return cp.reshape(kappa, (1, 1), order="F") if k == 1 else kappa * np.eye(k)


def _linear_plant(system: Any) -> Any:
    """A python-control ``StateSpace`` as a one-mode model (its ``A``; ``B``, ``C`` serve
    as ``E``, ``C``); any other model unchanged."""
    if not is_state_space(system):
        return system
    A, B, C, _ = state_space_matrices(system, "system")
    return SimpleNamespace(A=(A,), E=B if B.size else None, C=C if C.size else None,
                           n_states=A.shape[0], continuous=True)


def _modes(system: Any) -> tuple[FloatArray, ...]:
    if not getattr(system, "continuous", True):
        raise ModelError(f"system: the convergent-PWA designs need a continuous right-hand "
                         f"side (ch11 §2.2); got a {type(system).__name__} with "
                         f"continuous=False")
    return tuple(np.asarray(A, float) for A in system.A)


def _input_matrix(system: Any, B: Any) -> FloatArray:
    return _matrix_or_E(system, B, "B", "the control input matrix B (n, p)")


def _matrix_or_E(system: Any, M: Any, name: str, what: str) -> FloatArray:
    """``M`` checked as an ``(n, ·)`` matrix (a length-``n`` vector is one column), or the
    model's input matrix ``E`` when ``M`` is ``None``."""
    n = system.n_states
    if M is None:
        M = getattr(system, "E", None)
        if M is None:
            raise ModelError(f"{name}: the model has no input matrix E; pass {what}")
        return np.asarray(M, float)
    M = np.asarray(M, float)
    return as_matrix(name, M.reshape(n, -1) if M.ndim == 1 and M.size == n else M, rows=n)


def design_state_feedback(system: PiecewiseAffineSystem, *, sigma: float,
                          B: ArrayLike | None = None,
                          scale: Scaling | str | None = None) -> ConvergentStateFeedback:
    """Linear state feedback ``u = Kx`` with decay rate ``σ`` and minimal gain bound (SF-σ).

    Solves, in the coordinates of ``scale``,
    ``min κ`` s.t. ``Q >= I``, ``[[κI, Y], [Yᵀ, Q]] >= 0``,
    ``Ã_iQ + QÃ_iᵀ + B̃Y + YᵀB̃ᵀ + 2σ̃Q <= -δI`` (all modes), then ``K̃ = YQ⁻¹``.

    Parameters
    ----------
    system
        Continuous :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem`, or a linear plant
        as a python-control ``StateSpace`` (one mode; its ``B`` is the default ``B``).
    sigma
        Decay rate to certify (> 0, 1/time unit of the model).
    B
        Control input matrix ``(n, p)``; default: the model's input matrix ``E`` (actuator
        where the disturbance acts).
    scale
        :class:`Scaling`, ``"auto"`` (balanced states, time scale ``max‖Ã_i‖``, ``‖B̃‖ = 1``:
        for badly scaled models such as the beam) or ``None`` (no scaling, the default: the
        gain bound that is minimised is then in the model's own units).

    Returns
    -------
    ConvergentStateFeedback
        With ``‖K̃‖ <= gain_bound`` and the certificate re-checked.

    Raises
    ------
    InfeasibleDesignError
        No such ``K`` (``status`` holds the solver's diagnosis) or the certificate failed its
        re-check.
    ModelError
        A model declared discontinuous.

    Notes
    -----
    Hypotheses: continuous right-hand side (checked: ``continuous=False`` is refused); a
    linear feedback keeps the closed loop continuous, so the CQLF theorem of ch11 §2.2 applies
    to ``A_i + BK``; the closed loop is exponentially and input-to-state convergent with rate
    ``σ``. ``Q >= I`` gives ``‖K̃‖ <= √κ``.

    References
    ----------
    D5.3 chapter 11 §2.5(a); A. Pavlov, N. van de Wouw, H. Nijmeijer, "Convergent systems:
    analysis and synthesis", LNCIS 322, Springer 2005.

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.systems.pwa import PiecewiseAffineSystem
    >>> plant = PiecewiseAffineSystem.bimodal([[0, 1], [-6, -0.1]], [[0, 1], [-1, -0.1]],
    ...                                       [1, 0], E=[[0], [1]])
    >>> sf = design_state_feedback(plant, sigma=0.3)
    >>> np.round(sf.K, 2), round(sf.gain_bound, 2)
    (array([[-1.48, -1.74]]), 3.9)
    """
    system = _linear_plant(system)
    As = _modes(system)
    return _state_feedback(As, _input_matrix(system, B), check_positive("sigma", sigma), scale)


def _state_feedback(As: Sequence[FloatArray], B: FloatArray, sigma: float,
                    scale: Scaling | str | None) -> ConvergentStateFeedback:
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    sc = _resolve_scaling(scale, As, B)
    n, p = B.shape
    Sinv = np.linalg.inv(sc.S)
    At = [sc.S @ A @ Sinv / sc.omega for A in As]
    Bt = sc.S @ B * (sc.input_unit / sc.omega)
    s_t = sigma / sc.omega
    prob = LMIProblem("convergent state feedback (ch11 SF-sigma)")
    Q = prob.symmetric("Q", n)
    Y = prob.variable("Y", (p, n))
    kappa = prob.variable("kappa")
    prob.positive("Q >= I", Q, margin=1.0)
    prob.positive("gain bound [[kI, Y], [Y', Q]] >= 0",
                  cp.bmat([[_scalar_block(kappa, p), Y], [Y.T, Q]]), margin=LMI_MARGIN)
    for i, A in enumerate(At):
        prob.negative(f"decay, mode {i}", A @ Q + Q @ A.T + Bt @ Y + Y.T @ Bt.T + 2 * s_t * Q,
                      margin=LMI_MARGIN)
    try:
        res = prob.solve(minimize=kappa)
    except InfeasibleDesignError as err:
        raise InfeasibleDesignError(
            f"design_state_feedback: no linear K certifies decay rate sigma={sigma:g} for all "
            f"{len(As)} modes ({err}); lower sigma or add actuators", status=err.status) from err
    status = res.status
    Q, Y, kappa = res["Q"], res["Y"], float(res["kappa"])
    K = sc.input_unit * (Y @ np.linalg.inv(Q)) @ sc.S
    P = sc.S.T @ np.linalg.inv(Q) @ sc.S
    P = 0.5 * (P + P.T)
    _recheck([A + B @ K for A in As], P, sigma, who="design_state_feedback", status=status)
    return ConvergentStateFeedback(K, B, P, sigma, float(np.sqrt(kappa)), sc, status)



def design_state_feedback_l2(system: PiecewiseAffineSystem, *, rho: float,
                             Cz: ArrayLike | None = None, D: ArrayLike | None = None,
                             B: ArrayLike | None = None, sigma: float = 0.0,
                             slack: float = 0.1, scale: Scaling | str | None = None
                             ) -> ConvergentStateFeedback:
    """Linear state feedback ``u = Kx`` with a certified L2 gain ``γ`` from the disturbance
    ``w`` to ``z = (C_z x, ρu)``, within ``1 + slack`` of the least one, for every mode
    (SF-L2), with decay rate ``σ``.

    With ``Q = P⁻¹`` and ``Y = KQ``, first solves (in the coordinates of ``scale``)
    ``min γ²`` s.t. ``Q > 0`` and, for every mode ``i``::

        [[A_iQ + QA_iᵀ + BY + YᵀBᵀ + 2σQ,  D,     QC_zᵀ,  ρYᵀ],
         [Dᵀ,                             −γ²I,  0,      0  ],
         [C_zQ,                           0,     −I,     0  ],
         [ρY,                             0,     0,      −I ]]  <=  −δI,

    giving ``γ_inf`` (when the solver cannot finish it, because the infimum lies where ``Q``
    turns singular, by bisection on the feasibility of the problem with ``γ`` fixed, to
    ``1e-3`` on ``γ²``); then, with ``γ = (1 + slack)·γ_inf`` fixed, the most interior
    certificate (``max t`` s.t. ``Q >= tI``), and ``K = YQ⁻¹``. By the Schur complement
    the LMI is ``V' + |C_z x|² + ρ²|u|² − γ²|w|² <= −2σV`` for ``V = xᵀPx`` along every
    mode.

    Parameters
    ----------
    system
        Continuous :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem`, or a linear plant
        as a python-control ``StateSpace`` (one mode).
    rho
        Penalty on the control effort (finite, ``> 0``), in units of ``[z]/[u]`` (e.g. m/N:
        ``ρ|u|`` is compared with the displacement ``|C_z x|``).
    Cz
        Performance output ``(k, n)`` (default: the model's ``C``).
    D
        Disturbance input matrix ``(n, m)`` (default: the model's input matrix ``E``).
    B
        Control input matrix ``(n, p)`` (default: the model's ``E``: actuator where the
        disturbance acts).
    sigma
        Decay rate to certify as well (``>= 0``, 1/time unit of the model; ``0``: the
        strictness margin only).
    slack
        Relative slack on ``γ`` (``>= 0``) bought for a finite, well-conditioned gain:
        ``γ = (1 + slack)·γ_inf``; ``0`` asks for the infimum itself, which may have no
        certificate at all (see Notes).
    scale
        As in :func:`design_state_feedback`. The LMIs are solved for ``x̃ = Sx``,
        ``τ = ωt``, ``u = fũ`` and ``w = fw̃`` (the disturbance in the input unit, as a
        force beside a force), with ``z`` in units of ``ρf`` (so the penalty block is the
        identity and ``γ̃ = γ/ρ``; the scale's output unit is not used). The results are
        mapped back to the model's units: ``γ`` in ``[z]/[w]``, ``ρ`` as given in
        ``[z]/[u]``, ``K = fK̃S``, ``P = ((ρf)²/ω) SᵀQ̃⁻¹S`` (the storage function).

    Returns
    -------
    ConvergentStateFeedback
        With :attr:`~ConvergentStateFeedback.gamma` (the certified ``γ``) and
        :attr:`~ConvergentStateFeedback.rho` set, :attr:`~ConvergentStateFeedback.gain_bound`
        the attained ``‖K̃‖`` (scaled), and both the decay and the dissipation inequalities
        re-checked in NumPy.

    Raises
    ------
    ModelError
        ``rho <= 0`` or not finite, ``sigma < 0``, ``slack < 0``, or a model declared
        discontinuous.
    DimensionError
        ``Cz``, ``D`` or ``B`` of the wrong shape.
    InfeasibleDesignError
        No gain certifies ``σ`` (the solver's status), or a certificate fails its re-check.

    Notes
    -----
    Why ``ρ > 0``: with the actuator where the disturbance acts (``B = D``, the beam) and
    ``ρ = 0`` the infimum of ``γ`` is ``0``: ``u = Kx`` cancels ``w`` better and better as
    ``‖K‖ → ∞``. With ``ρ > 0`` the effort enters ``z``, and ``γ >= ρ·‖K(iω − A_cl)⁻¹D‖``.
    The infimum is still not attained: as the gain grows ``u → −w``, a *finite* effort, so
    ``γ_inf = ρ`` (measured on the chapter-6 beam: ``γ_inf/ρ = 1`` to 1e-4 for ρ from 1e-8
    to 1e-4 m/N) and the minimiser of the first LMI has a gain set by the solver's
    tolerance. Hence the second step, the standard sub-optimal design: the slack on ``γ``
    buys a finite gain, and ``ρ`` then trades attenuation against gain.

    Hypotheses and what is guaranteed: a continuous PWA model (checked). The field of the
    closed loop is continuous, so on a segment between two states it is a convex combination
    of the modes (ch11 §2.2) and the LMI of every mode gives, for the difference ``Δx`` of
    two solutions driven by ``w`` and ``w + Δw``, ``∫|Δz|² <= γ²∫|Δw|² + V(Δx(0))``: an
    incremental L2 gain ``γ``; for a piecewise *linear* model (``b_i = 0``, the origin the
    response to ``w = 0``) this is the L2 gain of ``w ↦ z`` itself. On a ``T``-periodic
    steady state ``V`` returns to its value, so
    ``mean|C_z x|² + ρ² mean|u|² <= γ² mean|w|²`` over a period; in particular
    ``RMS(u) <= (γ/ρ)·RMS(w)``. With ``σ > 0`` the loop is also exponentially convergent
    with rate ``σ``; with ``σ = 0`` only through the margin ``δ``.

    References
    ----------
    S. Boyd, L. El Ghaoui, E. Feron, V. Balakrishnan, *Linear Matrix Inequalities in System
    and Control Theory*, SIAM 1994, §7.5 (state feedback for the L2 gain); A. Pavlov,
    N. van de Wouw, H. Nijmeijer, "Convergent systems: analysis and synthesis", LNCIS 322,
    Springer 2005; D5.3 chapters 6 and 11.

    Examples
    --------
    The one-sided oscillator with ``u`` where ``w`` acts: a larger penalty gives a smaller
    gain and a larger ``γ``:

    >>> import numpy as np
    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> plant = one_sided_oscillator(0.1)
    >>> lo, hi = (design_state_feedback_l2(plant, rho=r, Cz=[[1.0, 0.0]]) for r in (0.1, 1.0))
    >>> bool(np.linalg.norm(lo.K) > np.linalg.norm(hi.K) and lo.gamma < hi.gamma)
    True
    """
    system = _linear_plant(system)
    As = _modes(system)
    n = As[0].shape[0]
    rho = _penalty(rho)
    sigma = check_positive("sigma", sigma, allow_zero=True)
    Bm = _input_matrix(system, B)
    Dm = _disturbance_matrix(system, D)
    Czm = _performance_output(system, Cz, n)
    slack = check_positive("slack", slack, allow_zero=True)
    return _l2_state_feedback(As, Bm, Dm, Czm, rho, sigma, slack, scale)


def _penalty(rho: Any) -> float:
    r = as_real_scalar("rho", rho)
    if not np.isfinite(r) or r <= 0.0:
        raise ModelError(f"rho: expected a finite control penalty > 0, got {rho!r}; without "
                         f"it the effort is free and, with the actuator where the "
                         f"disturbance acts (B = D), the attenuation has no optimum: the "
                         f"gain goes to infinity")
    return r


def _disturbance_matrix(system: Any, D: Any) -> FloatArray:
    return _matrix_or_E(system, D, "D", "the disturbance input matrix D (n, m)")


def _performance_output(system: Any, Cz: Any, n: int) -> FloatArray:
    if Cz is None:
        Cz = getattr(system, "C", None)
        if Cz is None:
            raise ModelError("Cz: the model has no output matrix C; pass the performance "
                             "output Cz (k, n)")
    Cz = np.asarray(Cz, float)
    return as_matrix("Cz", Cz.reshape(1, n) if Cz.ndim == 1 and Cz.size == n else Cz, cols=n)


def _l2_state_feedback(As: Sequence[FloatArray], B: FloatArray, D: FloatArray, Cz: FloatArray,
                       rho: float, sigma: float, slack: float, scale: Scaling | str | None
                       ) -> ConvergentStateFeedback:
    sc = _resolve_scaling(scale, As, B)
    # z in units of g = ρf: the penalty ρ̃ = ρf/g is 1 and γ̃ = γ/ρ, O(1) when the effort
    # dominates (with the model's output unit the beam's LMIs failed in Clarabel from ρf = 7.6)
    f, w = sc.input_unit, sc.omega
    g = rho * f
    Sinv = np.linalg.inv(sc.S)
    data = ([sc.S @ A @ Sinv / w for A in As], sc.S @ B * (f / w), sc.S @ D * (f / w),
            Cz @ Sinv / g, 1.0, sigma / w)
    try:
        res = _solve_l2(*data, gamma2=(1.0 + slack)**2 * _least_gamma2(data))
    except InfeasibleDesignError as err:
        raise InfeasibleDesignError(
            f"design_state_feedback_l2: no linear K certifies decay rate sigma={sigma:g} with "
            f"a finite L2 gain for all {len(As)} modes ({err}); lower sigma, raise slack or "
            f"add actuators", status=err.status) from err
    Qv = res["Q"]
    Kt = res["Y"] @ np.linalg.inv(Qv)
    K = f * Kt @ sc.S
    P = (g**2 / w) * sc.S.T @ np.linalg.inv(Qv) @ sc.S
    P = 0.5 * (P + P.T)
    gamma = float(np.sqrt(max(float(res["gamma2"]), 0.0))) * g / f
    closed = [A + B @ K for A in As]
    _recheck(closed, P, sigma, who="design_state_feedback_l2", status=res.status)
    _recheck_dissipation(closed, P, D, Cz, rho * K, gamma, sigma, sc, g, status=res.status)
    return ConvergentStateFeedback(K, B, P, sigma, float(np.linalg.norm(Kt, 2)), sc,
                                   res.status, gamma=gamma, rho=rho)


#: Relative width of the bracket on ``γ²`` when the infimum is found by bisection.
_L2_BISECTION_RTOL = 1e-3


def _least_gamma2(data: tuple[Any, ...]) -> float:
    """``γ̃²_inf`` of the scaled (SF-L2) problem: ``min γ²`` directly; when the solver cannot
    finish it (the infimum sits where ``Q`` turns singular, e.g. ``B = D``), the upper end of
    a geometric bisection on the feasibility of the problem with ``γ²`` fixed, to
    :data:`_L2_BISECTION_RTOL`."""
    # only γ² is used from these solves (the certificate returned is the interior one at
    # (1 + slack)²γ²): their thin margins near the boundary are expected, not reported
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InaccurateCertificateWarning)
            return float(_solve_l2(*data, gamma2=None)["gamma2"])
    except InfeasibleDesignError as err:
        if err.status == "infeasible":      # a decision, not a failure to finish
            raise

    def feasible(g2: float) -> bool:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InaccurateCertificateWarning)
            try:
                _solve_l2(*data, gamma2=g2)
            except InfeasibleDesignError:
                return False
        return True

    lo, hi = 0.0, 1.0
    for _ in range(40):                      # bracket: hi feasible, lo not (or 0)
        if feasible(hi):
            break
        lo, hi = hi, 4.0 * hi
    else:
        raise InfeasibleDesignError("no gamma up to 4^40 (scaled) is certified",
                                    status="infeasible")
    if lo == 0.0:
        lo = hi / 4.0
        while lo > 1e-12 * hi and feasible(lo):
            hi, lo = lo, lo / 4.0
    while hi > (1.0 + _L2_BISECTION_RTOL) * lo:
        mid = float(np.sqrt(lo * hi))
        lo, hi = (lo, mid) if feasible(mid) else (mid, hi)
    return hi


def _solve_l2(At: Sequence[FloatArray], Bt: FloatArray, Dt: FloatArray, Ct: FloatArray,
              rho_t: float, s_t: float, *, gamma2: float | None) -> Any:
    """The scaled (SF-L2) LMIs: ``min γ²`` (``gamma2=None``), or, with ``γ²`` fixed, the
    most interior ``Q`` (``max t`` s.t. ``Q >= tI``): a result holding ``Q``, ``Y`` and
    ``gamma2``."""
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    n, p = Bt.shape
    m, k = Dt.shape[1], Ct.shape[0]
    prob = LMIProblem("L2 state feedback with a control penalty (SF-L2)")
    Q = prob.symmetric("Q", n)
    Y = prob.variable("Y", (p, n))
    g2: Any = prob.variable("gamma2") if gamma2 is None else gamma2
    t = None
    prob.positive("Q > 0", Q, margin=LMI_MARGIN)
    if gamma2 is not None:     # t >= δ by the line above: a certificate, never an indefinite Q
        t = prob.variable("t")
        prob.positive("Q >= tI", Q, margin=t)
    for i, A in enumerate(At):
        prob.negative(f"dissipation, mode {i}", cp.bmat([
            [A @ Q + Q @ A.T + Bt @ Y + Y.T @ Bt.T + 2 * s_t * Q, Dt, Q @ Ct.T, rho_t * Y.T],
            [Dt.T, -(_scalar_block(g2, m) if gamma2 is None else g2 * np.eye(m)),
             np.zeros((m, k)), np.zeros((m, p))],
            [Ct @ Q, np.zeros((k, m)), -np.eye(k), np.zeros((k, p))],
            [rho_t * Y, np.zeros((p, m)), np.zeros((p, k)), -np.eye(p)]]), margin=LMI_MARGIN)
    if gamma2 is None:
        return prob.solve(minimize=g2)
    res = prob.solve(maximize=t)
    return replace(res, values={**res.values, "gamma2": np.asarray(gamma2)})


def _recheck_dissipation(closed: Sequence[FloatArray], P: FloatArray, D: FloatArray,
                         Cz: FloatArray, rhoK: FloatArray, gamma: float, sigma: float,
                         sc: Scaling, g: float, *, status: str) -> None:
    """Raise InfeasibleDesignError unless ``[[A_clᵀP + PA_cl + 2σP + C_zᵀC_z + ρ²KᵀK, PD],
    [DᵀP, −γ²I]] <= 0`` for every closed-loop mode, to ``1e-8`` of the matrix's norm after
    the congruence ``diag(S⁻¹, fI)/g`` that makes it ``ω`` times the scaled, O(1) one
    (``g = ρf``, the unit of ``z`` in the LMI)."""
    from ..numerics.lmi import LYAPUNOV_RECHECK_RTOL

    m = D.shape[1]
    T = np.zeros((P.shape[0] + m,) * 2)
    T[:P.shape[0], :P.shape[0]] = np.linalg.inv(sc.S)
    T[P.shape[0]:, P.shape[0]:] = sc.input_unit * np.eye(m)
    T /= g
    worst = -np.inf
    for A in closed:
        M = np.block([[A.T @ P + P @ A + 2 * sigma * P + Cz.T @ Cz + rhoK.T @ rhoK, P @ D],
                      [D.T @ P, -gamma**2 * np.eye(m)]])
        Mt = T.T @ (0.5 * (M + M.T)) @ T
        worst = max(worst, float(np.linalg.eigvalsh(Mt)[-1] / np.linalg.norm(Mt, 2)))
    if worst > LYAPUNOV_RECHECK_RTOL:
        raise InfeasibleDesignError(
            f"design_state_feedback_l2: the solver returned {status!r} but the dissipation "
            f"inequality fails the NumPy re-check (largest eigenvalue {worst:.3g} of its "
            f"matrix, relative, > {LYAPUNOV_RECHECK_RTOL:g}); rescale the model "
            f"(scale=Scaling.mechanical(...) or 'auto')", status="certificate_check_failed")

def design_pwa_state_feedback(system: PiecewiseAffineSystem, *, nu: ArrayLike, sigma: float,
                              B: ArrayLike | None = None,
                              scale: Scaling | str | None = None) -> PWAStateFeedback:
    """Continuity-preserving bimodal PWA feedback ``u = Kx + ν·min(cᵀx - d, 0)`` (§2.5 b).

    The continuity constraint ``K_0 - K_1 = νcᵀ`` makes the joint problem bilinear in
    ``(ν, Q)``; for a *given* ``ν`` the one-sided term is absorbed into the plant
    (``A_0 ← A_0 + νBcᵀ``, ``b_0 ← b_0 - νBd``) and (SF-σ) is solved for the common ``K``.
    Scan or bisect ``ν`` outside to trade gain bound against nonlinearity.

    Parameters
    ----------
    system
        Continuous *bimodal* model built by
        :meth:`~nscontrol.systems.pwa.PiecewiseAffineSystem.bimodal` (region 0: ``cᵀx <= d``).
    nu
        Slope of the one-sided term, one entry per input.
    sigma
        Decay rate to certify.
    B, scale
        As in :func:`design_state_feedback`.

    Raises
    ------
    ModelError
        The model is not bimodal with a single facet.
    InfeasibleDesignError
        No common ``K`` for this ``ν``.

    Notes
    -----
    Hypotheses: continuous bimodal model (checked); the feedback is continuous by
    construction, so the closed loop is a continuous PWA system and the CQLF theorem applies;
    the common ``P`` is re-checked on both closed-loop modes. This extension is ours (not
    known to be in the chapter).

    References
    ----------
    D5.3 chapter 11.

    Examples
    --------
    Example A with ``ν = 2.5`` (ch11 check 15): the gain bound drops from 3.90 (ν = 0) to 2.29
    and the law is continuous across ``q = 0``:

    >>> import numpy as np
    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> pf = design_pwa_state_feedback(one_sided_oscillator(0.1), nu=2.5, sigma=0.3)
    >>> round(pf.gain_bound, 2), pf.K[0] - pf.K[1]
    (2.29, array([[2.5, 0. ]]))
    """
    As = _modes(system)
    B = _input_matrix(system, B)
    c, d = _bimodal_facet(system)
    nu = np.atleast_1d(np.asarray(nu, float))
    if nu.shape != (B.shape[1],):
        raise DimensionError(f"nu: expected {B.shape[1]} entries (one per input), got "
                             f"shape {nu.shape}")
    absorbed = (As[0] + B @ np.outer(nu, c), As[1])
    sf = _state_feedback(absorbed, B, check_positive("sigma", sigma), scale)
    K0 = sf.K + np.outer(nu, c)
    return PWAStateFeedback((K0, sf.K), (-nu * d, np.zeros(B.shape[1])), B, nu, c, d, sf.P,
                            sigma, sf.gain_bound, sf.scaling, sf.status)


def tune_pwa_state_feedback(system: PiecewiseAffineSystem, *, sigma: float,
                            nu_bounds: tuple[float, float], n_grid: int = 11,
                            B: ArrayLike | None = None,
                            scale: Scaling | str | None = None) -> PWAStateFeedback:
    """Continuity-preserving PWA feedback with the slope ``ν`` chosen to minimise the largest
    per-region gain ``max(‖K̃_0‖, ‖K̃_1‖)`` (scaled units) over ``nu_bounds`` (single input).

    ``ν`` enters the (SF-σ) problem bilinearly, so it is searched outside the LMI: a grid of
    ``n_grid`` values (infeasible ones skipped), then a bounded Brent search between the best
    point's neighbours — about ``n_grid + 12`` LMI solves. The largest per-region gain, not
    :attr:`PWAStateFeedback.gain_bound`, is the objective: the gain bound only bounds the
    common ``K`` and decreases all the way to the ``ν`` that cancels the nonlinearity (Example
    A: ``ν = k_s = 5``, bound 0.58) while ``K_0 = K + νcᵀ`` grows with ``ν``.

    Parameters
    ----------
    system, sigma, B, scale
        As in :func:`design_pwa_state_feedback`.
    nu_bounds
        ``(lo, hi)``, the interval searched.
    n_grid
        Points of the initial grid (>= 3).

    Returns
    -------
    PWAStateFeedback
        The design at the best ``ν`` found (a local optimum of a one-dimensional search).

    Raises
    ------
    ModelError
        More than one input, or a bad interval/grid.
    InfeasibleDesignError
        No ``ν`` of the grid gives a feasible design.

    Notes
    -----
    Each candidate is a full :func:`design_pwa_state_feedback` (certificate re-checked), so
    the returned design carries the same guarantees; only the choice of ``ν`` is heuristic.

    References
    ----------
    D5.3 chapter 11 (the bilinearity and the outer search over ``ν``).

    Examples
    --------
    Example A, ``σ = 0.3``: the largest per-region gain drops from 2.29 (``ν = 0``, linear)
    to 1.71 at ``ν ≈ 1.9``, where ``‖K_0‖ = ‖K_1‖``:

    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> pf = tune_pwa_state_feedback(one_sided_oscillator(0.1), sigma=0.3, nu_bounds=(0, 5),
    ...                              n_grid=6)
    >>> round(float(pf.nu[0]), 1), round(max(pf.region_gains), 2)
    (1.9, 1.71)
    """
    from scipy.optimize import minimize_scalar

    B_ = _input_matrix(system, B)
    if B_.shape[1] != 1:
        raise ModelError(f"B: tune_pwa_state_feedback searches a scalar nu (one input); got "
                         f"{B_.shape[1]} inputs — call design_pwa_state_feedback per nu")
    lo, hi = (as_real_scalar(f"nu_bounds[{i}]", v) for i, v in enumerate(nu_bounds))
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi) or int(n_grid) < 3:
        raise ModelError(f"nu_bounds, n_grid: expected finite lo < hi and n_grid >= 3, got "
                         f"{nu_bounds!r}, {n_grid!r}")
    found: dict[float, PWAStateFeedback | None] = {}

    def design(nu: float) -> PWAStateFeedback | None:
        if nu not in found:
            try:
                found[nu] = design_pwa_state_feedback(system, nu=nu, sigma=sigma, B=B_,
                                                      scale=scale)
            except InfeasibleDesignError:
                found[nu] = None
        return found[nu]

    def cost(nu: float) -> float:
        pf = design(float(nu))
        return np.inf if pf is None else max(pf.region_gains)

    grid = np.linspace(lo, hi, int(n_grid))
    costs = np.array([cost(v) for v in grid])
    if not np.any(np.isfinite(costs)):
        raise InfeasibleDesignError(f"tune_pwa_state_feedback: no nu in [{lo:g}, {hi:g}] "
                                    f"({int(n_grid)} points) gives a feasible design for "
                                    f"sigma={sigma:g}", status="infeasible")
    i = int(np.argmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = minimize_scalar(cost, bounds=(a, b), method="bounded",
                          options={"xatol": 1e-3 * max(hi - lo, 1e-12), "maxiter": 12})
    best = float(res.x) if np.isfinite(res.fun) and res.fun < costs[i] else float(grid[i])
    out = design(best)
    assert out is not None
    return out


def _bimodal_facet(system: Any) -> tuple[FloatArray, float]:
    """``(c, d)`` of a bimodal model with region 0 ``cᵀx <= d`` and region 1 ``cᵀx >= d``."""
    regs = system.regions
    ok = len(regs) == 2 and all(np.shape(H)[0] == 1 for H, _ in regs)
    if ok:
        (H0, h0), (H1, h1) = regs
        ok = np.allclose(H0[0], -H1[0]) and np.isclose(h0[0], -h1[0])
    if not ok:
        raise ModelError("system: expected a bimodal model (two half-spaces cᵀx <= d and "
                         "cᵀx >= d, as built by PiecewiseAffineSystem.bimodal)")
    return np.asarray(regs[0][0][0], float), float(regs[0][1][0])


def design_observer(system: PiecewiseAffineSystem, *, sigma: float, C: ArrayLike | None = None,
                    scale: Scaling | str | None = None) -> ConvergentObserver:
    """Gain-bounded piecewise-linear observer with error decay rate ``σ`` (OBS-σ).

    Solves ``min κ_o`` s.t. ``P̃ >= I``, ``[[κ_o I, Zᵀ], [Z, P̃]] >= 0``,
    ``Ã_iᵀP̃ + P̃Ã_i - C̃ᵀZᵀ - ZC̃ + 2σ̃P̃ <= -δI`` (all modes), then ``L̃ = P̃⁻¹Z``.

    Parameters
    ----------
    system
        Continuous PWA model, or a linear plant as a python-control ``StateSpace`` (one
        mode; its ``C`` is the default ``C``).
    sigma
        Error decay rate to certify.
    C
        Measured output ``y = Cx`` (default: the model's ``C``).
    scale
        As in :func:`design_state_feedback` (``C̃ = CS⁻¹/g``, ``L = ωS⁻¹L̃/g``; ``"auto"``
        also normalises ``‖C̃‖ = 1``).

    Raises
    ------
    InfeasibleDesignError
        No such ``L``, or the certificate failed its re-check.

    Notes
    -----
    The observer chooses its mode by the *estimate*; by the segment lemma of ch11 §2.2
    (continuity) ``e' = (Σθ_i A_i - LC)e``, so the common ``P`` gives
    ``|e(t)| <= √κ(P) e^{-σt}|e(0)|`` whatever ``x``, ``u`` and ``w`` — the plant need not be
    convergent. Hypotheses: continuous model (checked), inputs known to the observer.
    Without the gain bound the solver places poles far too fast (seen: 2700× on the beam).

    References
    ----------
    D5.3 chapter 11 §2.5(c); A. Juloski, W.P.M.H. Heemels, S. Weiland, "Observer design for a
    class of piecewise linear systems", Int. J. Robust Nonlinear Control, 2007.

    Examples
    --------
    Example A (ch11 §4.1), ``y = q``, ``σ_o = 1``; the badly scaled beam needs ``"auto"``:

    >>> import numpy as np
    >>> from nscontrol.examples.ch11_convergent_pwa import beam_surrogate, one_sided_oscillator
    >>> obs = design_observer(one_sided_oscillator(0.1), sigma=1.0)
    >>> np.round(obs.L.ravel(), 2), round(obs.kappa, 2)
    (array([3.11, 3.4 ]), 9.73)
    >>> beam = design_observer(beam_surrogate(), sigma=0.3 * 2 * np.pi * 20, scale="auto")
    >>> beam.status
    'optimal'
    """
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    system = _linear_plant(system)
    As = _modes(system)
    n = As[0].shape[0]
    C = system.C if C is None else C
    if C is None:
        raise ModelError("C: the observer needs the measured output matrix; pass C or build "
                         "the model with C=...")
    C = as_matrix("C", np.reshape(C, (-1, n)) if np.ndim(C) == 1 else C, cols=n)
    sigma = check_positive("sigma", sigma)
    sc = _resolve_scaling(scale, As, None, C)
    q = C.shape[0]
    Sinv = np.linalg.inv(sc.S)
    At = [sc.S @ A @ Sinv / sc.omega for A in As]
    Ct = C @ Sinv / sc.output_unit
    s_t = sigma / sc.omega
    prob = LMIProblem("convergent PWA observer (ch11 OBS-sigma)")
    P = prob.symmetric("P", n)
    Z = prob.variable("Z", (n, q))
    kappa = prob.variable("kappa")
    prob.positive("P >= I", P, margin=1.0)
    prob.positive("gain bound [[kI, Z'], [Z, P]] >= 0",
                  cp.bmat([[_scalar_block(kappa, q), Z.T], [Z, P]]), margin=LMI_MARGIN)
    for i, A in enumerate(At):
        prob.negative(f"decay, mode {i}", A.T @ P + P @ A - Ct.T @ Z.T - Z @ Ct + 2 * s_t * P,
                      margin=LMI_MARGIN)
    try:
        res = prob.solve(minimize=kappa)
    except InfeasibleDesignError as err:
        raise InfeasibleDesignError(
            f"design_observer: no output injection L certifies error decay rate sigma="
            f"{sigma:g} for all {len(As)} modes ({err}); lower sigma or measure more outputs",
            status=err.status) from err
    status = res.status
    Pv = res["P"]
    L = (sc.omega / sc.output_unit) * Sinv @ np.linalg.solve(Pv, res["Z"])
    Po = sc.S.T @ Pv @ sc.S
    Po = 0.5 * (Po + Po.T)
    _recheck([A - L @ C for A in As], Po, sigma, who="design_observer", status=status)
    lam = np.linalg.eigvalsh(Po)
    return ConvergentObserver(L, C, Po, sigma, float(np.sqrt(res["kappa"])),
                              float(lam[-1] / lam[0]), sc, status)
