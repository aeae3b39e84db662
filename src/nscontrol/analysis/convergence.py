"""Quadratic convergence of continuous piecewise-affine systems (chapter 11, §2.2–2.4).

A continuous PWA system ``x' = A_i x + b_i + D w`` is quadratically convergent **iff** its
linear parts share a quadratic Lyapunov function, ``A_iᵀP + PA_i < 0`` for a common ``P > 0``
(the offsets and the input play no role). This module decides that by an LMI with a margin,
re-checks the certificate in NumPy, cross-checks bimodal systems with two independent tests
(the ``A_1A_2`` eigenvalue test and the circle criterion), and turns a certificate into
steady-state bounds (input-to-state convergence gain, peak-to-peak and incremental-L2 bounds).

A discontinuous model is refused: the test is not valid when the vector field jumps.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_finite_scalar, as_matrix, as_square, check_bool, check_positive
from ..errors import (
    DimensionError,
    InaccurateCertificateWarning,
    InfeasibleDesignError,
    ModelError,
    SolverError,
)

if TYPE_CHECKING:   # imported where used at run time
    from ..systems.pwa import PiecewiseAffineSystem

__all__ = [
    "ConvergenceCertificate", "quadratic_convergence", "decay_rate",
    "BimodalTests", "bimodal_tests", "product_test", "circle_test", "circle_criterion_minimum",
    "most_negative_real_eigenvalue", "bisect_boundary",
    "SteadyStateBound", "isc_gain", "peak_to_peak_bound", "incremental_l2_bound", "equilibrium",
]

FloatArray = NDArray[np.float64]

#: A margin below this (in the normalised coordinates of the LMI) means "not certified".
MARGIN_TOL = 1e-7


@dataclass(frozen=True)
class ConvergenceCertificate:
    """Outcome of the quadratic convergence test.

    Attributes
    ----------
    convergent
        True when a common quadratic Lyapunov function was found and re-checked.
    P
        The certificate (original coordinates), ``None`` when not convergent.
    margin
        ``t*`` of ``max t s.t. I <= P̃ <= p_max I, Ã_iᵀP̃ + P̃Ã_i + 2σ̃P̃ <= -t I`` in the
        normalised coordinates; negative when no CQLF exists.
    decay
        The decay rate ``σ`` imposed in the LMI (1/time unit of the model).
    rate
        The largest ``σ`` the returned ``P`` certifies: ``A_iᵀP + PA_i + 2σP <= 0`` for all i
        (``nan`` when not convergent).
    epsilon
        ``ε = min_i λ_min(-(A_iᵀP + PA_i))`` (ε-form of the certificate; ``nan`` if none).
    kappa
        Condition number ``λ_max(P)/λ_min(P)`` (``nan`` if none).
    status
        The solver's status.
    reason
        Why the system is not certified (empty when it is).
    """

    convergent: bool
    P: FloatArray | None
    margin: float
    decay: float
    rate: float
    epsilon: float
    kappa: float
    status: str
    reason: str = ""

    def __bool__(self) -> bool:
        return self.convergent


def _mode_matrices(system: PiecewiseAffineSystem | Sequence[ArrayLike]
                   ) -> tuple[FloatArray, ...]:
    """The linear parts ``A_i`` of a PWA system (refusing a discontinuous one) or of a list."""
    if isinstance(system, Sequence):   # list or tuple of mode matrices
        As = tuple(as_square(f"As[{i}]", A) for i, A in enumerate(system))
    else:
        if not getattr(system, "continuous", True):
            raise ModelError(
                f"system: the quadratic convergence test (CQLF of the modes) holds only for "
                f"PWA systems with a continuous right-hand side; got a {type(system).__name__} "
                f"with continuous=False. The discontinuous case needs the structure and "
                f"passivity-like conditions of ch11 §2.7, not implemented")
        As = tuple(as_square(f"system.A[{i}]", A) for i, A in enumerate(system.A))
    if not As:
        raise DimensionError("As: expected at least one mode matrix, got none")
    n = As[0].shape[0]
    for i, A in enumerate(As):
        if A.shape != (n, n):
            raise DimensionError(f"As[{i}]: expected shape ({n}, {n}) like As[0], got {A.shape}")
    return As


def quadratic_convergence(system: PiecewiseAffineSystem | Sequence[ArrayLike], *,
                          decay: float = 0.0, p_max: float = 1e4,
                          normalise: bool = True) -> ConvergenceCertificate:
    """Decide quadratic convergence of a continuous PWA system by a common quadratic
    Lyapunov function.

    Parameters
    ----------
    system
        A continuous :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` (its ``A``
        matrices are used) or a sequence of square mode matrices ``A_i``.
    decay
        Decay rate ``σ >= 0`` to certify: ``A_iᵀP + PA_i + 2σP < 0``.
    p_max
        Bound on ``κ(P̃)`` in normalised coordinates (``I <= P̃ <= p_max I``).
    normalise
        Solve in balanced, time-normalised coordinates
        (:meth:`nscontrol.numerics.scaling.Scaling.balanced`).

    Returns
    -------
    ConvergenceCertificate
        ``convergent`` with ``P`` re-checked in NumPy, or the reason it is not.

    Raises
    ------
    ModelError
        ``system`` is declared discontinuous (``continuous=False``).
    DimensionError
        Mode matrices of inconsistent shapes.
    SolverError
        Neither Clarabel nor SCS returned an optimal solution.

    Notes
    -----
    Theorem (ch11 §2.2, Pavlov et al. 2007): a PWA system with a *continuous* right-hand side
    is quadratically convergent iff (CQLF) holds. Hypotheses: continuity (checked by the model
    at construction and refused here when ``continuous`` is False); regions convex (by
    construction of the model). Strictness is handled by maximising the margin ``t``; the
    system is certified when ``t* > 1e-7`` and the returned ``P`` passes the NumPy re-check
    :func:`~nscontrol.numerics.lmi.recheck_lyapunov` (``P > 0``, ``max eig(A_iᵀP + PA_i +
    2σP) <= 1e-8‖P‖``).

    References
    ----------
    D5.3 chapter 11 (Pavlov, van de Wouw, Nijmeijer); A. Pavlov, A. Pogromsky, N. van de Wouw,
    H. Nijmeijer, "On convergence properties of piecewise affine systems", Int. J. Control
    80(8), 2007.

    Examples
    --------
    Example A (``k = 1``, ``k_s = 5``) is quadratically convergent iff ``c > √6 - 1``:

    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> quadratic_convergence(one_sided_oscillator(0.1)).convergent
    False
    >>> cert = quadratic_convergence(one_sided_oscillator(3.0))
    >>> cert.convergent, bool(cert.margin > 1e-7 and cert.rate > 0)
    (True, True)
    """
    As = _mode_matrices(system)
    decay = check_positive("decay", decay, allow_zero=True)
    n = As[0].shape[0]
    from ..numerics.lmi import LYAPUNOV_RECHECK_RTOL, recheck_lyapunov
    from ..numerics.scaling import Scaling

    sc = Scaling.balanced(As) if check_bool("normalise", normalise) else Scaling.identity(n)
    try:
        P_s, margin, status = _max_margin_cqlf([sc.matrix(A) for A in As], decay / sc.omega,
                                               p_max)
    except InfeasibleDesignError as err:  # solver failure or a certificate failing re-check
        return ConvergenceCertificate(False, None, np.nan, decay, np.nan, np.nan, np.nan,
                                      str(err.status), f"undecided: {err}")
    P = sc.quadratic_back(P_s)
    P = 0.5 * (P + P.T)
    if margin <= MARGIN_TOL:
        return ConvergenceCertificate(False, None, margin, decay, np.nan, np.nan, np.nan, status,
                                      f"no common quadratic Lyapunov function: best margin "
                                      f"{margin:.3g} <= {MARGIN_TOL:g}")
    if not recheck_lyapunov(As, P, decay).holds(LYAPUNOV_RECHECK_RTOL):
        return ConvergenceCertificate(False, None, margin, decay, np.nan, np.nan, np.nan, status,
                                      "the solver's certificate failed the NumPy re-check "
                                      "(numerically undecided; rescale the model)")
    eps = min(float(-np.linalg.eigvalsh(A.T @ P + P @ A)[-1]) for A in As)
    lam = np.linalg.eigvalsh(P)
    return ConvergenceCertificate(True, P, margin, decay, decay_rate(As, P), eps,
                                  float(lam[-1] / lam[0]), status)


def _max_margin_cqlf(As: Sequence[FloatArray], decay: float,
                     p_max: float) -> tuple[FloatArray, float, str]:
    """``max t`` s.t. ``I <= P <= p_max I``, ``A_iᵀP + PA_i + 2σP <= -tI``, ``t <= 1``."""
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    n = As[0].shape[0]
    prob = LMIProblem("common quadratic Lyapunov function (ch11 CQLF)")
    P = prob.symmetric("P", n)
    t = prob.variable("t")
    prob.positive("P >= I", P, margin=1.0)
    prob.positive("P <= p_max I", p_max * np.eye(n) - P)
    prob.positive("t <= 1", cp.reshape(1 - t, (1, 1), order="F"))
    for i, A in enumerate(As):
        prob.negative(f"mode {i}", A.T @ P + P @ A + 2 * decay * P, margin=t)
    res = prob.solve(maximize=t)
    return res["P"], float(res["t"]), res.status


def _lyap(A: Any, P: FloatArray, decay: float) -> FloatArray:
    A = np.asarray(A, dtype=float)
    M = A.T @ P + P @ A + 2.0 * decay * P
    return 0.5 * (M + M.T)


def decay_rate(As: Sequence[ArrayLike], P: ArrayLike) -> float:
    """The largest ``σ`` with ``A_iᵀP + PA_i + 2σP <= 0`` for all i (exact, by generalised
    eigenvalues); negative when ``P`` is not a Lyapunov matrix of every mode.

    Parameters
    ----------
    As : sequence of (n, n) array_like
        The modes ``A_i``.
    P : (n, n) array_like
        A symmetric positive definite matrix.
    """
    from scipy.linalg import eigh

    Pa = np.asarray(P, float)
    Ps = 0.5 * (Pa + Pa.T)
    return min(float(eigh(-_lyap(A, Ps, 0.0), Ps, eigvals_only=True)[0]) / 2.0 for A in As)


# -- bimodal cross-checks (§2.4) --------------------------------------------------------------

@dataclass(frozen=True)
class BimodalTests:
    """The three equivalent tests of ch11 §2.4 on a bimodal system ``A_2 = A_1 - k g cᵀ``.

    Attributes
    ----------
    cqlf, product, circle
        Verdict of each test (True: quadratically convergent).
    hurwitz
        Both modes Hurwitz (a hypothesis of the equivalence; when False all verdicts are False).
    cqlf_margin
        LMI margin of :func:`quadratic_convergence`.
    min_negative_real_eig
        The most negative real eigenvalue of ``A_1A_2`` (``nan`` when it has none).
    circle_min
        ``min_ω 1 + k Re G(iω)`` with ``G(s) = cᵀ(sI - A_1)⁻¹g``.
    """

    cqlf: bool
    product: bool
    circle: bool
    hurwitz: bool
    cqlf_margin: float
    min_negative_real_eig: float
    circle_min: float

    @property
    def agree(self) -> bool:
        """True when the three verdicts coincide."""
        return self.cqlf == self.product == self.circle


def bimodal_tests(A1: ArrayLike, A2: ArrayLike) -> BimodalTests:
    """Run the CQLF LMI, the ``A_1A_2`` eigenvalue test and the circle criterion.

    Parameters
    ----------
    A1, A2
        The two mode matrices; their difference must have rank one (continuous bimodal PWA).

    Raises
    ------
    ModelError
        ``A1 - A2`` does not have rank one.

    Notes
    -----
    For Hurwitz ``A_1``, ``A_2`` with ``A_1 - A_2 = k g cᵀ`` (k > 0) the three conditions are
    equivalent (Shorten & Narendra 2003; Shorten, Mason, O'Cairbre, Curran 2004): a CQLF
    exists; ``A_1A_2`` has no real negative eigenvalue; ``1 + k Re G(iω) > 0`` for all
    ``ω ∈ R ∪ {∞}``. Disagreement signals a numerical problem, never a theorem.

    References
    ----------
    D5.3 chapter 11; R. Shorten, K. S. Narendra, "On common quadratic
    Lyapunov functions for pairs of stable LTI systems whose system matrices are in companion
    form", IEEE TAC 48(4), 2003; R. Shorten, O. Mason, F. O'Cairbre, P. Curran, "A unifying
    framework for the SISO circle criterion and other quadratic stability criteria", IJC
    77(1), 2004.

    Examples
    --------
    Example A below and above the damping threshold ``c* = √6 - 1``:

    >>> import numpy as np
    >>> def modes(c):
    ...     return np.array([[0, 1], [-6, -c]]), np.array([[0, 1], [-1, -c]])
    >>> low, high = bimodal_tests(*modes(0.1)), bimodal_tests(*modes(2.0))
    >>> (low.cqlf, low.product, low.circle), (high.cqlf, high.product, high.circle)
    ((False, False, False), (True, True, True))
    """
    A1, A2 = _pair(A1, A2)
    hurwitz = _both_hurwitz(A1, A2)
    cert = quadratic_convergence([A1, A2])
    worst = most_negative_real_eigenvalue(A1 @ A2)
    circle_min = circle_criterion_minimum(A1, A2)
    return BimodalTests(cqlf=cert.convergent, product=bool(hurwitz and np.isnan(worst)),
                        circle=bool(hurwitz and circle_min > 0), hurwitz=hurwitz,
                        cqlf_margin=cert.margin, min_negative_real_eig=worst,
                        circle_min=circle_min)


def _pair(A1: Any, A2: Any) -> tuple[FloatArray, FloatArray]:
    A1 = as_square("A1", A1)
    return A1, as_square("A2", A2, A1.shape[0])


def _both_hurwitz(A1: FloatArray, A2: FloatArray) -> bool:
    return all(float(np.max(np.linalg.eigvals(A).real)) < 0 for A in (A1, A2))


def most_negative_real_eigenvalue(M: ArrayLike) -> float:
    """The most negative real eigenvalue of ``M`` (``nan`` when it has none); an eigenvalue
    counts as real when ``|Im λ| <= 1e-9|λ|``.

    Parameters
    ----------
    M : (n, n) array_like
        The matrix.
    """
    lam = np.linalg.eigvals(np.asarray(M, float))
    real_neg = lam[(np.abs(lam.imag) <= 1e-9 * np.abs(lam)) & (lam.real < 0)].real
    return float(real_neg.min()) if real_neg.size else float("nan")


def product_test(A1: ArrayLike, A2: ArrayLike) -> bool:
    """Bimodal test 2 of §2.4: both modes Hurwitz and ``A_1A_2`` without a real negative
    eigenvalue (⇔ a CQLF exists, for a rank-one difference).

    Parameters
    ----------
    A1, A2 : (n, n) array_like
        The two modes, with a rank-one difference ``A_1 - A_2 = k g cᵀ``.
    """
    A1, A2 = _pair(A1, A2)
    _rank_one(A1 - A2)
    return bool(_both_hurwitz(A1, A2) and np.isnan(most_negative_real_eigenvalue(A1 @ A2)))


def circle_test(A1: ArrayLike, A2: ArrayLike) -> bool:
    """Bimodal test 3 of §2.4: both modes Hurwitz and ``1 + k Re G(iω) > 0`` for all ω.

    Parameters
    ----------
    A1, A2 : (n, n) array_like
        The two modes, with a rank-one difference ``A_1 - A_2 = k g cᵀ``.
    """
    A1, A2 = _pair(A1, A2)
    return bool(_both_hurwitz(A1, A2) and circle_criterion_minimum(A1, A2) > 0)


def circle_criterion_minimum(A1: ArrayLike, A2: ArrayLike) -> float:
    """``min_ω 1 + k Re G(iω)``, ``G(s) = cᵀ(sI - A_1)⁻¹g``, for ``A_1 - A_2 = k g cᵀ``.

    Parameters
    ----------
    A1, A2 : (n, n) array_like
        The two modes, with a rank-one difference ``A_1 - A_2 = k g cᵀ``.
    """
    A1, A2 = _pair(A1, A2)
    g, c, k = _rank_one(A1 - A2)
    return _circle_minimum(A1, g, c, k)


def _rank_one(Delta: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """``Delta = k g cᵀ`` with unit vectors g, c and k > 0."""
    U, s, Vt = np.linalg.svd(Delta)
    if s[0] == 0.0 or (s.size > 1 and s[1] > 1e-9 * s[0]):
        raise ModelError(f"A1 - A2: expected a rank-one difference (continuous bimodal system "
                         f"across one facet), got singular values {np.round(s, 12)}")
    return U[:, 0], Vt[0], float(s[0])


def _circle_minimum(A: FloatArray, g: FloatArray, c: FloatArray, k: float) -> float:
    """``min_ω 1 + k Re cᵀ(iωI - A)⁻¹g``: log grid around the modes, then Brent refinement."""
    from scipy.optimize import minimize_scalar

    n = A.shape[0]
    lam, V = np.linalg.eig(A)
    if np.linalg.cond(V) < 1e8:  # residues: G(iω) = Σ r_j / (iω - λ_j), vectorised over ω
        r = (c @ V) * np.linalg.solve(V, g)

        def phi(w: Any) -> Any:
            return 1.0 + k * np.real(np.sum(r / (1j * np.asarray(w, float)[..., None] - lam),
                                            axis=-1))
    else:  # defective A: solve per frequency
        def phi(w: Any) -> Any:
            return np.vectorize(lambda v: 1.0 + k * float(np.real(
                c @ np.linalg.solve(1j * v * np.eye(n) - A, g))))(w)

    mags = np.abs(np.linalg.eigvals(A))
    lo, hi = max(mags.min(), 1e-12) * 1e-3, max(mags.max(), 1e-12) * 1e3
    grid = np.concatenate([[0.0], np.geomspace(lo, hi, 4000)])
    vals = phi(grid)
    i = int(np.argmin(vals))
    best = float(vals[i])
    if 0 < i < grid.size - 1:
        res = minimize_scalar(lambda w: float(phi(w)), bounds=(grid[i - 1], grid[i + 1]),
                              method="bounded",
                              options={"xatol": 1e-12 * grid[i + 1]})
        best = min(best, float(res.fun))
    return min(best, 1.0)  # ω = ∞ gives exactly 1 (strictly proper G)


def bisect_boundary(is_convergent: Callable[[float], bool], lo: float, hi: float, *,
                    rtol: float = 1e-8) -> float:
    """Boundary ``p*`` of a monotone test on ``[lo, hi]`` by bisection.

    ``is_convergent(lo)`` and ``is_convergent(hi)`` must differ; the returned ``p*`` is where
    the verdict changes, to ``rtol`` relative.

    Parameters
    ----------
    is_convergent : callable ``p -> bool``
        The test, monotone in ``p``.
    lo, hi : float
        The bracket; the verdicts at its ends must differ.
    rtol : float
        Relative width of the final bracket.

    Raises
    ------
    ModelError
        Both ends give the same verdict (no boundary bracketed).
    """
    lo, hi = as_finite_scalar("lo", lo), as_finite_scalar("hi", hi)
    rtol = check_positive("rtol", rtol)
    f_lo, f_hi = bool(is_convergent(lo)), bool(is_convergent(hi))
    if f_lo == f_hi:
        raise ModelError(f"lo, hi: expected a bracket where the verdict changes, got "
                         f"{f_lo} at {lo} and at {hi}")
    while hi - lo > rtol * max(abs(lo), abs(hi)):
        mid = 0.5 * (lo + hi)
        if bool(is_convergent(mid)) == f_lo:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# -- steady-state bounds (§2.2–2.3) -----------------------------------------------------------

@dataclass(frozen=True)
class SteadyStateBound:
    """A steady-state bound and the LMI solution proving it.

    Attributes
    ----------
    bound
        The gain: ``sup|z̄_{w1} - z̄_{w2}| <= bound·‖w1 - w2‖_∞`` (peak-to-peak) or
        ``RMS(z̄_{w1} - z̄_{w2}) <= bound·RMS(w1 - w2)`` (incremental L2).
    P
        The matrix of the dissipation inequality.
    alpha
        The ``α`` of the invariant-ellipsoid bound (``nan`` for the L2 bound).
    status
        Solver status.
    """

    bound: float
    P: FloatArray
    alpha: float
    status: str


def isc_gain(P: ArrayLike, D: ArrayLike, epsilon: float) -> float:
    """Input-to-state convergence gain ``γ_ISC = 2|PD|·√κ(P)/ε`` (ch11 §2.2).

    With ``A_iᵀP + PA_i <= -εI``: ``limsup|x1 - x2| <= γ_ISC·sup|w1 - w2|``; for the steady
    state, ``sup_t|x̄_w(t) - x*| <= γ_ISC·sup_t|w(t) - w0|``.

    Parameters
    ----------
    P
        The certificate (symmetric positive definite).
    D
        Input matrix of ``w`` (common to all modes).
    epsilon
        ``ε > 0`` of the ε-form certificate (``ε = 2σλ_min(P)`` from a decay-form one).

    Raises
    ------
    ModelError
        Non-positive ``epsilon``.
    DimensionError
        ``P`` not square or ``D`` of the wrong height.

    Notes
    -----
    Hypotheses (not checked here — pass a certificate that holds them): the system is a
    *continuous* PWA system with the input entering through the same ``D`` in every mode,
    and ``A_iᵀP + PA_i <= -εI`` for every mode. Then, by the segment lemma of §2.2,
    ``d/dt ΔᵀPΔ <= -ε|Δ|² + 2|PD||Δ||w1 - w2|``, whence the gain; it is conservative (Example
    A closed loop: ``γ_ISC = 12.9`` against an actual ``sup|x̄| = 0.57``).

    References
    ----------
    D5.3 chapter 11; A. Pavlov, N. van de Wouw, H. Nijmeijer, *Uniform
    Output Regulation of Nonlinear Systems: A Convergent Dynamics Approach*, Birkhäuser 2006
    (input-to-state convergence).
    """
    P = as_square("P", P)
    D = as_matrix("D", np.reshape(D, (P.shape[0], -1)) if np.ndim(D) == 1 else D, P.shape[0])
    epsilon = check_positive("epsilon", epsilon)
    lam = np.linalg.eigvalsh(0.5 * (P + P.T))
    return 2.0 * float(np.linalg.norm(P @ D, 2)) * float(np.sqrt(lam[-1] / lam[0])) / epsilon


def _io_matrices(As: Sequence[ArrayLike], D: Any, Cz: Any) -> tuple[list[FloatArray], FloatArray,
                                                             FloatArray]:
    As_ = list(_mode_matrices(list(As)))
    n = As_[0].shape[0]
    D = as_matrix("D", np.reshape(D, (n, -1)) if np.ndim(D) == 1 else D, n)
    Cz = as_matrix("Cz", np.reshape(Cz, (-1, n)) if np.ndim(Cz) == 1 else Cz, cols=n)
    return As_, D, Cz


def peak_to_peak_bound(As: Sequence[ArrayLike], D: ArrayLike, Cz: ArrayLike, *,
                       alphas: Any = None, refine: bool = True) -> SteadyStateBound:
    """Invariant-ellipsoid peak-to-peak bound on incremental steady-state outputs (§2.3).

    For each ``α`` minimise ``μ`` s.t. ``P >= C_zᵀC_z`` and
    ``[[A_iᵀP + PA_i + αP, PD], [DᵀP, -μI]] <= 0``; the bound is ``min_α √(μ/α)``.

    Parameters
    ----------
    As
        Mode matrices of the (closed-loop) continuous PWA system.
    D, Cz
        Input and performance-output matrices.
    alphas
        Grid of ``α`` (default, as in ch11 §2.3: 40 log-spaced points in ``[0.01, 5]`` in
        units where the slowest pole is 1, i.e. ``[0.01, 5]·ρ_slow`` with
        ``ρ_slow = min_i min_j |λ_j(A_i)|``; infeasible ``α`` are skipped).
    refine
        Polish the best ``α`` of the grid by a bounded scalar search between its neighbours
        (about 12 more LMIs): any ``α`` gives a valid bound, so this only tightens it.

    Returns
    -------
    SteadyStateBound
        The smallest bound found and its ``α``.

    Raises
    ------
    SolverError
        No ``α`` of the grid gave a feasible problem.

    Notes
    -----
    Hypotheses: the same for every ``α``: a common ``P`` for all modes of a *continuous* PWA
    system (the segment lemma of ch11 §2.2 makes the dissipation inequality hold along the
    difference of two solutions), so ``(x1 - x2)ᵀP(x1 - x2) <= μ/α·‖w1 - w2‖²_∞`` is
    invariant and ``|z1 - z2|² <= (x1 - x2)ᵀP(x1 - x2)``. The optimal ``α`` is below twice the
    decay rate of the modes, i.e. of the order of the slowest pole — hence the grid's unit.
    On Example A's closed loop (σ = 0.3): 1.1286 on the grid, 1.1253 refined (a 400-point
    grid gives 1.1253).

    References
    ----------
    D5.3 chapter 11; S. Boyd, L. El Ghaoui, E. Feron, V. Balakrishnan,
    *Linear Matrix Inequalities in System and Control Theory*, SIAM 1994, §6.1.3.

    Examples
    --------
    One mode: the bound lies above the peak of ``|G(iω)|`` (0.638 here); a three-point
    grid, refined, finds the same optimum as the default one:

    >>> import numpy as np
    >>> A = np.array([[0.0, 1.0], [-4.0, -0.8]])
    >>> b = peak_to_peak_bound([A], [0.0, 1.0], [1.0, 0.0], alphas=[0.1, 0.3, 0.9])
    >>> round(b.bound, 3), round(b.alpha, 2)
    (0.897, 0.4)
    """
    As_, D, Cz = _io_matrices(As, D, Cz)
    refine = check_bool("refine", refine)
    if alphas is None:
        rho = min(float(np.min(np.abs(np.linalg.eigvals(A)))) for A in As_)
        if rho == 0.0:
            raise SolverError("peak_to_peak_bound: a mode has an eigenvalue at 0, so no "
                              "invariant ellipsoid exists (not quadratically convergent)",
                              status="infeasible")
        alphas = np.geomspace(0.01, 5.0, 40) * rho
    grid = np.sort(np.asarray(alphas, float))
    if grid.ndim != 1 or grid.size == 0 or np.any(grid <= 0) or not np.all(np.isfinite(grid)):
        raise ModelError(f"alphas: expected positive finite values, got {alphas!r}")
    values = np.full(grid.size, np.inf)
    best: SteadyStateBound | None = None

    def evaluate(a: float) -> float:
        nonlocal best
        try:
            res = _peak_lmi(As_, D, Cz, float(a))
        except InfeasibleDesignError:
            return np.inf  # this alpha is too large for an invariant ellipsoid
        value = float(np.sqrt(max(float(res["mu"]), 0.0) / a))
        if best is None or value < best.bound:
            best = SteadyStateBound(value, res["P"], float(a), res.status)
        return value

    for k, a in enumerate(grid):
        values[k] = evaluate(a)
    if best is None:
        raise SolverError("peak_to_peak_bound: no alpha of the grid gave a feasible LMI; the "
                          "system may not be quadratically convergent", status="infeasible")
    i = int(np.argmin(values))
    if refine and grid.size > 1:
        from scipy.optimize import minimize_scalar

        lo, hi = np.log(grid[max(i - 1, 0)]), np.log(grid[min(i + 1, grid.size - 1)])
        minimize_scalar(lambda s: evaluate(float(np.exp(s))), bounds=(lo, hi),
                        method="bounded", options={"xatol": 1e-3, "maxiter": 12})
    return best


#: Margin of the bound LMIs (data are O(1)): keeps the optimum off the re-check's edge.
_BOUND_MARGIN = 1e-8


def _peak_lmi(As: Sequence[FloatArray], D: FloatArray, Cz: FloatArray, alpha: float) -> Any:
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    n, m = D.shape
    prob = LMIProblem(f"peak-to-peak bound (alpha={alpha:.3g})")
    P = prob.symmetric("P", n)
    mu = prob.variable("mu")
    prob.positive("P >= Cz'Cz", P - Cz.T @ Cz, margin=_BOUND_MARGIN)
    for i, A in enumerate(As):
        prob.negative(f"mode {i}", cp.bmat([[A.T @ P + P @ A + alpha * P, P @ D],
                                            [D.T @ P, -mu * np.eye(m)]]), margin=_BOUND_MARGIN)
    with _quiet():
        return prob.solve(minimize=mu)


@contextmanager
def _quiet() -> Iterator[None]:
    """Silence thin-margin warnings of bound LMIs (their margin only guards the re-check)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", InaccurateCertificateWarning)
        yield


def incremental_l2_bound(As: Sequence[ArrayLike], D: ArrayLike, Cz: ArrayLike) -> SteadyStateBound:
    """Incremental L2 (RMS) gain bound of a continuous PWA system (§2.3).

    Minimise ``γ²`` s.t. ``P > 0`` and ``[[A_iᵀP + PA_i + C_zᵀC_z, PD], [DᵀP, -γ²I]] <= 0``.
    For T-periodic inputs ``RMS(z̄_{w1} - z̄_{w2}) <= γ·RMS(w1 - w2)``; one mode: the H∞ norm.

    Parameters
    ----------
    As : sequence of (n, n) array_like
        The modes ``A_i`` of the continuous PWA system.
    D : (n, q) array_like
        Input matrix of the input ``w`` (common to all modes).
    Cz : (r, n) array_like
        Performance output ``z = C_z x`` (common to all modes).

    Raises
    ------
    SolverError
        The LMI is infeasible (no common storage function) or the solver failed.

    Notes
    -----
    Hypotheses: a *continuous* PWA system (the segment lemma of ch11 §2.2 turns the per-mode
    LMIs into a dissipation inequality for the difference of two solutions driven by
    ``w1``, ``w2``), with ``D`` and ``C_z`` common to all modes. Integrating
    ``d/dt ΔᵀPΔ <= γ²|w1 - w2|² - |z1 - z2|²`` over one period of a periodic steady state
    (``V`` is periodic) gives the RMS bound at every frequency — an upper bound for the RMS
    version of the generalized Bode plot.

    References
    ----------
    D5.3 chapter 11; S. Boyd et al., *Linear Matrix Inequalities in System
    and Control Theory*, SIAM 1994, §6.3.2 (bounded-real lemma).

    Examples
    --------
    One mode: the H∞ norm of ``1/(s² + 0.8s + 4)``, 0.6379:

    >>> import numpy as np
    >>> A = np.array([[0.0, 1.0], [-4.0, -0.8]])
    >>> round(incremental_l2_bound([A], [0.0, 1.0], [1.0, 0.0]).bound, 4)
    0.6379
    """
    import cvxpy as cp

    from ..numerics.lmi import LMIProblem

    As_, D, Cz = _io_matrices(As, D, Cz)
    n, m = D.shape
    prob = LMIProblem("incremental L2 bound")
    P = prob.symmetric("P", n)
    g2 = prob.variable("gamma2")
    prob.positive("P > 0", P, margin=_BOUND_MARGIN)
    for i, A in enumerate(As_):
        prob.negative(f"mode {i}", cp.bmat([[A.T @ P + P @ A + Cz.T @ Cz, P @ D],
                                            [D.T @ P, -g2 * np.eye(m)]]), margin=_BOUND_MARGIN)
    try:
        with _quiet():
            res = prob.solve(minimize=g2)
    except InfeasibleDesignError as err:
        raise SolverError(f"incremental_l2_bound: {err}; the system may not be quadratically "
                          f"convergent", status=err.status) from err
    return SteadyStateBound(float(np.sqrt(res["gamma2"])), res["P"], np.nan, res.status)


def equilibrium(system: PiecewiseAffineSystem, w0: ArrayLike) -> FloatArray:
    """The equilibrium of a continuous PWA system for a constant input ``w0`` (ch11 §2.2).

    For each region solve ``A_i x = -b_i - E w0`` and keep the solution if it lies in the
    region (relative tolerance 1e-9); exactly one distinct point must survive (it may be found
    in two regions when it lies on a facet).

    Parameters
    ----------
    system : PiecewiseAffineSystem
        A continuous PWA model.
    w0 : array_like
        The constant input (length of the input matrix's columns).

    Raises
    ------
    ModelError
        None or several distinct equilibria (the system is then not convergent), or a
        discontinuous model.
    DimensionError
        ``w0`` does not match the input matrix.

    Notes
    -----
    Property used (ch11 P2): a convergent system with a constant input has a unique, globally
    attracting equilibrium. Hypotheses: continuous PWA model (refused otherwise), modes with
    nonsingular ``A_i`` (a singular mode is skipped), and convergence — certified separately
    by :func:`quadratic_convergence`; without it zero or several equilibria may survive,
    which is reported rather than resolved.

    References
    ----------
    D5.3 chapter 11; A. Pavlov, A. Pogromsky, N. van de Wouw,
    H. Nijmeijer, "On convergence properties of piecewise affine systems", Int. J. Control
    80(8), 2007.

    Examples
    --------
    Example A with ``w0 = -1``: the spring is engaged, ``6q = -1``:

    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> equilibrium(one_sided_oscillator(2.0), [-1.0]).round(6)
    array([-0.166667,  0.      ])
    """
    _mode_matrices(system)
    n = system.n_states
    forcing = np.zeros(n)
    if system.E is not None:
        w0 = np.atleast_1d(np.asarray(w0, float))
        if w0.shape != (system.E.shape[1],):
            raise DimensionError(f"w0: expected {system.E.shape[1]} entries, got {w0.shape}")
        forcing = system.E @ w0
    found: list[FloatArray] = []
    for i, (A, b) in enumerate(zip(system.A, system.b, strict=True)):
        try:
            x = np.linalg.solve(A, -b - forcing)
        except np.linalg.LinAlgError:
            continue
        if system.contains(i, x) and not any(np.allclose(x, y, rtol=1e-9, atol=1e-12)
                                             for y in found):
            found.append(np.asarray(x, dtype=float))
    if len(found) != 1:
        raise ModelError(f"system: expected exactly one equilibrium for w0={w0!r}, found "
                         f"{len(found)}; the system is not convergent (check "
                         f"quadratic_convergence first)")
    return found[0]
