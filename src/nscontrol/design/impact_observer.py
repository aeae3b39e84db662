"""Observers for bodies that are unobservable without impacts (chapter 2).

Two bodies on a line interact only through impacts; only ``y = q_1`` (body a) is measured, so
body b is invisible between impacts. This module designs

* the asymptotic high-gain observer of equation (7) for the (n-1, 1) case: flow
  ``xh_a' = A_a xh_a + B_a u + G_eps (y - C_a xh_a)``, ``xh_b' = A_b xh_b`` and, at each impact
  of the plant, the jumps (7c)-(7g) with the restitution matrix of coefficient ``e``
  (Remark 1) -- :func:`design_impact_observer`, returning an :class:`ImpactObserverDesign`
  that builds the closed loop "plant + observer + exosystem" as one
  :class:`~nscontrol.systems.hybrid.LinearHybridSystem`;
* dead-beat observers built from the constructive proofs (**our choice**, the seed is
  truncated): :func:`deadbeat_n1` (finite-window reconstruction of body a, restarted at each
  impact, plus the impact formula for the free mass) and :func:`deadbeat_1n` (body b of n-1
  masses recovered by least squares from the data of its impacts).

Gain placement (**our choice**, :func:`place_scaled`). ``(C_a, A_a)`` is put in observer
canonical form ``P^{-1} A_a P = A_c`` (coefficients in the first column, ``C_a P = e_1^T``),
where the gain placing ``Lambda_eps = Lambda_1 / eps`` is read off the characteristic
polynomials, ``g_eps[k] = p_k / eps^k - a_k``. In the scaled coordinates
``xi = S_eps P^{-1} xh_a``, ``S_eps = diag(1, eps, ..., eps^{N-1})`` (the chapter's (9)), the
observer's flow matrix is ``companion(Lambda_1) / eps`` and its gain ``g = S_eps g_eps`` has
no ``eps^-N`` entries; the closed loop integrates the observer there (``realisation=
"scaled"``), so the stacked flow matrix stays of size ``O(1/eps)``.

This does *not* remove the sensitivity of high-gain placement: the error dynamics the closed
loop realises are ``T^{-1} A_a T - g (C_a T)`` with ``T = P S_eps^{-1}``, similar to
``A_a - (T g) C_a``, so any error in ``P`` or in the coefficients ``a_k`` is amplified by up to
``eps^{-(N-1)}`` exactly as with the raw gain. What reduces it is computing ``P`` and ``a``
accurately and consistently: the pair is balanced and time-normalised, reduced to
observer-Hessenberg form by Householder reflections, and ``a`` and ``P`` are then read off that
form by triangular recurrences -- no ``O^{-1}`` from matrix powers. The design reports the
spectrum error of the realised error matrix (:class:`PlacementConditioning`) and warns
(:class:`~nscontrol.errors.InaccurateCertificateWarning`) above ``1e-6`` relative, the accuracy
it promises (``SPECTRUM_RTOL``), not a roundoff estimate: see ``SPECTRUM_RTOL`` for the a
priori error bound and which spectra can reach it.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_real_scalar, as_square, as_vector, check_bool, check_positive
from ..errors import (
    DimensionError,
    InaccurateCertificateWarning,
    InfeasibleDesignError,
    ModelError,
)
from ..numerics.observability import pbh_observability
from ..numerics.scaling import balanced_unit_norm
from .impact_conditions import (
    EpsilonCertificate,
    Theorem1Result,
    alpha_limit,
    search_epsilon,
    theorem1_test,
)

if TYPE_CHECKING:   # imported where used at run time
    from ..systems.impacting_bodies import ImpactingBodies


__all__ = [
    "ImpactPlant",
    "PlacementConditioning",
    "ScaledPlacement",
    "ImpactObserverDesign",
    "DeadbeatEstimate",
    "impact_plant",
    "place_scaled",
    "certificate_velocity_scale",
    "design_impact_observer",
    "observer_jump",
    "deadbeat_n1",
    "deadbeat_1n",
]

FloatArray = NDArray[np.float64]

#: Relative spectrum error of the realised observer above which place_scaled warns. This is the
#: accuracy promised to the user, not a roundoff estimate. To first order the realised error is
#: at most ``max_i kappa_i (N u ||B||_F + ||residual||) / |lambda_i / eps|`` (``B`` the balanced
#: ``companion(Lambda1) / eps``, ``kappa_i`` its eigenvalue condition numbers, ``u`` the unit
#: roundoff, the residual that of the realised matrix against ``B``, up to ``N cond_P u
#: ||B||``). For spectra spread like ``-(0.5, 0.6, ...)`` that is 5e-12 at N = 4 and 1e-7 ..
#: 2e-6 at N = 8 (errors measured 1e-10 .. 1e-8 across BLAS kernels, 100x under the promise);
#: at N = 12 it is 2e-4 and the error (1e-7 .. 1e-6) may cross the promise; a spectrum
#: clustered within 0.005 misses it by ~1e-2 and always warns.
SPECTRUM_RTOL = 1e-6


# ----------------------------------------------------------------------------------------------
# The plant, as the design sees it
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ImpactPlant:
    """The matrices of an impacting-bodies plant that the observer designs need.

    Built by :func:`impact_plant` from an
    :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies`; not a model of its own.

    Attributes
    ----------
    A_a, B_a, C_a, A_b
        Flow, input and measurement matrices of body a (state ``[q_a; v_a]``), flow of body b.
    n_a, n_b
        Number of masses of each body.
    M
        Restitution matrix of the colliding pair (masses ``n_a`` and ``n_a + 1``).
    masses
        All masses, body a first.
    bodies
        The ``ImpactingBodies`` model it came from.
    """

    A_a: FloatArray
    B_a: FloatArray
    C_a: FloatArray
    A_b: FloatArray
    n_a: int
    n_b: int
    M: FloatArray
    masses: FloatArray
    bodies: Any

    @property
    def C_contact(self) -> FloatArray:
        """Row of ``x_a`` picking ``q_{n_a}``, the position of body a's contact mass."""
        row = np.zeros(2 * self.n_a)
        row[self.n_a - 1] = 1.0
        return row

    @property
    def equal_masses(self) -> bool:
        return bool(self.M[1, 1] == 0.0)

    @property
    def frequency(self) -> float:
        """``sqrt(max(||H_a^{-1} K_a||, ||H_b^{-1} K_b||))`` [1/time], 0 without springs: the
        velocity scale that makes the certificate's norms unit-free."""
        na, nb = self.n_a, self.n_b
        k2 = max(float(np.linalg.norm(self.A_a[na:, :na], 2)),
                 float(np.linalg.norm(self.A_b[nb:, :nb], 2)))
        return float(np.sqrt(k2))


def impact_plant(bodies: ImpactingBodies | ImpactPlant) -> ImpactPlant:
    """Extract :class:`ImpactPlant` from an
    :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The model (an ``ImpactPlant`` is returned as is).

    Returns
    -------
    ImpactPlant

    Raises
    ------
    ModelError
        ``bodies`` is not an ``ImpactingBodies`` model.
    """
    if isinstance(bodies, ImpactPlant):
        return bodies
    needed = ("A_a", "B_a", "C_a", "A_b", "H_a", "H_b", "restitution_matrix", "hybrid")
    missing = [k for k in needed if not hasattr(bodies, k)]
    if missing:
        raise ModelError(f"bodies: expected an ImpactingBodies model, got "
                         f"{type(bodies).__name__} (missing {', '.join(missing)})")
    masses = np.concatenate([np.diag(bodies.H_a), np.diag(bodies.H_b)])
    return ImpactPlant(np.asarray(bodies.A_a, float), np.ravel(bodies.B_a).astype(float),
                       np.ravel(bodies.C_a).astype(float), np.asarray(bodies.A_b, float),
                       int(bodies.n_a), int(bodies.n_b),
                       np.asarray(bodies.restitution_matrix, float), masses, bodies)


# ----------------------------------------------------------------------------------------------
# Gain placement in scaled observer-canonical coordinates
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlacementConditioning:
    """How well-conditioned the high-gain placement is.

    All spectrum errors are ``max_i |mu_i - lambda_i/eps| / |lambda_i/eps|`` after matching the
    computed eigenvalues ``mu_i`` to the wanted ones.

    Attributes
    ----------
    cond_P
        2-norm condition number of the observer-canonical transformation of the balanced,
        time-normalised pair (the unit-free part of ``P``; ``P`` itself adds only diagonal
        scalings).
    gain_norm
        ``||G_eps||`` in the original coordinates (grows like ``eps^-N``).
    spectrum_error
        Of the error dynamics the closed loop realises, ``T^{-1} A_a T - g (C_a T)`` formed
        from the stored ``T``, ``T^{-1}`` and ``g`` (``realisation="scaled"``).
    spectrum_error_original
        Of ``A_a - G_eps C_a`` formed in the original coordinates (``realisation=
        "original"``).
    spectrum_error_companion
        Of ``companion(Lambda_1) / eps`` itself: the floor set by the sensitivity of the
        wanted eigenvalues in companion form (clustered ``Lambda_1`` and large ``N`` raise it);
        no realisation can be expected to do better.
    """

    cond_P: float
    gain_norm: float
    spectrum_error: float
    spectrum_error_original: float
    spectrum_error_companion: float


def _companion_first_column(coeffs: FloatArray) -> FloatArray:
    """``[[-c1, 1, 0..], [-c2, 0, 1..], .., [-cN, 0..0]]``: char. poly ``s^N + c1 s^{N-1}..``."""
    n = coeffs.size
    F = np.zeros((n, n))
    F[:, 0] = -coeffs
    F[np.arange(n - 1), np.arange(1, n)] = 1.0
    return F


def _spectrum_error(computed: np.ndarray, wanted: np.ndarray) -> float:
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(computed[:, None] - wanted[None, :]) / np.abs(wanted)[None, :]
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


def _check_lambda(Lambda1: Any, size: int) -> np.ndarray:
    try:
        lam = np.asarray(Lambda1, dtype=complex)
    except (TypeError, ValueError):
        raise ModelError(f"Lambda1: expected {size} complex numbers, got {Lambda1!r}") from None
    if lam.ndim > 1:
        raise DimensionError(f"Lambda1: expected a 1-D sequence of {size} eigenvalues, got an "
                             f"array of shape {lam.shape}")
    lam = np.atleast_1d(lam)
    if lam.size != size:
        raise DimensionError(f"Lambda1: expected {size} eigenvalues (2 n_a, one per state of "
                             f"body a), got {lam.size}")
    if not np.all(np.isfinite(lam)):
        raise ModelError("Lambda1: expected finite eigenvalues, got NaN or inf")
    if np.any(lam.real >= 0.0):
        bad = lam[lam.real >= 0.0][0]
        raise ModelError(f"Lambda1: expected every eigenvalue with negative real part, got "
                         f"{bad:.6g}; the observer error would not decay")
    if not np.allclose(np.sort_complex(lam), np.sort_complex(lam.conj()), rtol=1e-12,
                       atol=0.0):
        raise ModelError("Lambda1: expected a set closed under complex conjugation (the gain "
                         f"is real), got {lam}")
    return lam


def _check_eps(eps: Any) -> float:
    v = as_real_scalar("eps", eps)          # refuses bool, complex, strings, arrays
    if not (np.isfinite(v) and 0.0 < v <= 1.0):
        raise ModelError(f"eps: expected a value in (0, 1] (smaller = faster, higher gain), got "
                         f"{eps!r}")
    return v


@dataclass(frozen=True, eq=False)
class ScaledPlacement:
    """Result of :func:`place_scaled`: the gain and the scaled realisation of the observer.

    Attributes
    ----------
    G
        Gain ``G_eps`` in the original coordinates.
    P
        Observer-canonical transformation, ``P^{-1} A_a P = A_c``, ``C_a P = e_1^T``.
    T, T_inv
        ``P S_eps^{-1}`` (``xh_a = T xi``) and its inverse ``S_eps P^{-1}``, each formed from
        the orthogonal/triangular factors (not by inverting the other).
    F
        ``companion(Lambda_1)``: the scaled flow matrix is ``F / eps``.
    g_scaled
        ``S_eps P^{-1} G_eps`` (the gain as it enters ``xi'``), computed without cancellation.
    a
        Characteristic coefficients of ``A_a`` (``s^N + a_1 s^{N-1} + ...``), consistent
        with ``P``.
    conditioning
        :class:`PlacementConditioning`.
    """

    G: FloatArray
    P: FloatArray
    T: FloatArray
    T_inv: FloatArray
    F: FloatArray
    g_scaled: FloatArray
    a: FloatArray
    conditioning: PlacementConditioning


def _observer_canonical(A: FloatArray, C: FloatArray
                        ) -> tuple[FloatArray, FloatArray, FloatArray, float, float]:
    """Factors of the observer canonical form of an observable single-output pair.

    Returns ``(left, right_inv, a_n, omega, cond_h)`` with ``P = left diag(omega^-k)``,
    ``P^{-1} = diag(omega^k) right_inv``, ``a_k = omega^k a_n[k-1]`` and ``cond_h`` the
    condition number of the canonical transformation of the balanced, normalised pair:

    1. balance and time-normalise, ``A = omega D A_n D^{-1}``, ``C_n = C D``;
    2. Householder: ``V`` orthogonal with ``V e_1 ~ C_n^T`` and ``V^T A_n V = L`` lower
       Hessenberg (Hessenberg reduction of ``H0 A_n^T H0``, ``H0`` reflecting ``C_n^T`` onto
       ``sigma e_1``), so ``C_n V = sigma e_1^T``;
    3. on ``(e_1^T, L)`` the observability rows ``r_k = e_1^T L^k`` are triangular; ``a_n``
       solves ``r_N + sum a_k r_{N-k} = 0`` (Cayley-Hamilton), and the rows of the canonical
       ``P_h^{-1}`` follow the Horner recurrence ``rho_1 = e_1^T``, ``rho_{k+1} = rho_k L +
       a_k e_1^T`` (``z_{k+1} = z_k' + a_k y``), lower triangular, inverted by substitution.
    """
    from scipy.linalg import hessenberg, solve_triangular

    n = A.shape[0]
    An, d, omega = balanced_unit_norm(A)
    c = C * d
    sigma = float(np.linalg.norm(c))
    v = c.copy()
    v[0] += np.copysign(sigma, c[0])
    H0 = np.eye(n) - 2.0 * np.outer(v, v) / float(v @ v)     # H0 c = -sign(c0) sigma e1
    sigma = -float(np.copysign(sigma, c[0]))
    Hs, Q = hessenberg(H0 @ An.T @ H0, calc_q=True)
    V = H0 @ Q
    L = Hs.T
    R = np.zeros((n + 1, n))
    R[0, 0] = 1.0
    for k in range(n):
        R[k + 1] = R[k] @ L
    a_n = np.linalg.solve(R[n - 1::-1].T, -R[n])
    rows = np.zeros((n, n))
    rows[0, 0] = 1.0
    for k in range(1, n):
        rows[k] = rows[k - 1] @ L
        rows[k, 0] += a_n[k - 1]
    P_h = solve_triangular(rows, np.eye(n), lower=True)
    left = d[:, None] * (V @ P_h) / sigma
    right_inv = sigma * (rows @ V.T) / d[None, :]
    return left, right_inv, a_n, omega, float(np.linalg.cond(rows))


def place_scaled(A: ArrayLike, C: ArrayLike, Lambda1: ArrayLike, eps: float) -> ScaledPlacement:
    """Place ``sigma(A - G C) = Lambda1 / eps`` for a single output, in scaled coordinates.

    Parameters
    ----------
    A : (N, N) array_like
    C : (N,) or (1, N) array_like
    Lambda1 : (N,) array_like of complex
        Eigenvalues for ``eps = 1``: negative real parts, closed under conjugation.
    eps : float
        In ``(0, 1]``.

    Returns
    -------
    ScaledPlacement

    Raises
    ------
    InfeasibleDesignError
        ``(C, A)`` unobservable (``status="unobservable"``).
    ModelError, DimensionError
        Bad ``Lambda1`` or ``eps``.

    Warns
    -----
    InaccurateCertificateWarning
        The realised error matrix misses ``Lambda1 / eps`` by more than ``1e-6`` relative.

    Notes
    -----
    Single output: the gain is unique (Ackermann). It is computed in observer canonical form,
    whose transformation ``P`` and coefficients ``a`` come from orthogonal transformations
    (balancing, Householder observer-Hessenberg form, triangular recurrences; see the module
    docstring), then scaled as in the chapter's equation (9): ``g = S_eps g_eps``,
    ``g[k] = p_k / eps - eps^{k-1} a_k``. ``conditioning`` reports the spectrum error of the
    error dynamics actually realised; ``T g`` is exactly the raw gain, so the scaled
    realisation is only as accurate as ``P`` and ``a`` are. Measured on chains (unit masses,
    ``k_11 = 4``, ``k_{h,h+1} = 6``, ``Lambda1 = -(0.5, 0.6, ...)``), realised spectrum error at
    ``eps = 0.1, 0.01``: ``n_a = 4``: 1.8e-8, 2.1e-4 with ``P = O^{-1} O_c`` from matrix powers,
    3.5e-10, 1.0e-9 here; ``n_a = 6``: 6.5e-2, 5.0 before, 4.4e-7, 2.2e-7 here (companion
    floor 1.2e-7).

    References
    ----------
    Chapter 2 of SICONOS D5.3, equation (9) (scaled observer canonical form) and Theorem 3;
    Ackermann's formula (Kailath, *Linear Systems*, 1980, section 3.2); observer-Hessenberg /
    staircase form: Van Dooren & Verhaegen, "On the use of unitary state-space transformations",
    Contemporary Mathematics 47 (1985); Golub & Van Loan, *Matrix Computations*, section 7.4.

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [-10, 6, 0, 0], [6, -6, 0, 0]])
    >>> sp = place_scaled(A, [1.0, 0, 0, 0], [-0.5, -0.6, -0.7, -0.8], 0.1)
    >>> np.sort(np.linalg.eigvals(A - np.outer(sp.G, [1.0, 0, 0, 0])).real).round(8)
    array([-8., -7., -6., -5.])
    >>> bool(sp.conditioning.spectrum_error < 1e-9)
    True
    """
    A = as_square("A_a", A)
    n = A.shape[0]
    C = as_vector("C_a", np.ravel(C), n)
    lam = _check_lambda(Lambda1, n)
    eps = _check_eps(eps)
    ok, margin, modes = pbh_observability(A, C.reshape(1, n))
    if not ok:
        raise InfeasibleDesignError(
            f"(C_a, A_a): unobservable (PBH margin {margin:.3g} at eigenvalue(s) "
            f"{', '.join(f'{m:.6g}' for m in modes)}); no gain places the observer spectrum -- "
            "measure another position or change the springs", status="unobservable")
    left, right_inv, a_n, omega, cond_h = _observer_canonical(A, C)
    k = np.arange(n)
    a = a_n * omega ** (k + 1)
    s = (omega * eps) ** k                          # S_eps Omega, Omega = diag(omega^k)
    T = left / s[None, :]
    T_inv = s[:, None] * right_inv
    P = left / (omega ** k)[None, :]
    p = np.real(np.poly(lam))[1:]
    g_scaled = p / eps - omega * s * a_n            # p_k / eps - eps^(k-1) a_k
    G = T @ g_scaled
    F = _companion_first_column(p)
    want = lam / eps
    realised = T_inv @ A @ T - np.outer(g_scaled, C @ T)
    err = _spectrum_error(np.linalg.eigvals(realised), want)
    err_orig = _spectrum_error(np.linalg.eigvals(A - np.outer(G, C)), want)
    err_comp = _spectrum_error(np.linalg.eigvals(F / eps), want)
    cond = PlacementConditioning(cond_h, float(np.linalg.norm(G)), err, err_orig, err_comp)
    if not err <= SPECTRUM_RTOL:
        warnings.warn(InaccurateCertificateWarning(
            f"place_scaled: the realised observer spectrum misses Lambda1/eps by {err:.2g} "
            f"relative (> {SPECTRUM_RTOL:g}) at eps = {eps:g}, N = {n} (companion form of "
            f"Lambda1 alone: {err_comp:.2g}, cond(P) = {cond.cond_P:.3g}); spread Lambda1 "
            "apart, use a larger eps, or fewer states"), stacklevel=2)
    return ScaledPlacement(G, P, T, T_inv, F, g_scaled, a, cond)


# ----------------------------------------------------------------------------------------------
# Observer jumps (7c)-(7g)
# ----------------------------------------------------------------------------------------------
def observer_jump(xh_a: ArrayLike, xh_b: ArrayLike, y: float,
                  M: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Jumps (7c)-(7g) of the observer at an impact of the plant ((n-1, 1) case).

    Parameters
    ----------
    xh_a : (2 n_a,) array_like
        Estimate ``[q^_a; v^_a]`` of body a just before the impact.
    xh_b : (2,) array_like
        Estimate ``[q^_n, v^_n]`` of the free mass just before the impact.
    y : float
        The measurement ``y(t_i) = q_1(t_i)`` at the impact.
    M : (2, 2) array_like
        Restitution matrix of the colliding pair (any ``e``, Remark 1).

    Returns
    -------
    xh_a_plus, xh_b_plus : ndarray
        The estimates just after the impact.

    Notes
    -----
    ``q^_1 <- y`` (7e); ``q^_n <- q^_{n-1}`` (7f: the two masses touch at an impact);
    ``[v^_{n-1}, v^_n] <- M [v^_{n-1}, v^_n]`` (7g); every other estimate unchanged (7c),
    (7d). Applied at the plant's impact times, which are assumed detected in real time
    (Remark 3). The map is linear in ``(xh_a, xh_b, y)``; the closed loop uses its matrix.

    References
    ----------
    Chapter 2 of SICONOS D5.3, equations (7c)-(7g) and Remarks 1 and 3 (Martinelli, Menini,
    Tornambe, ASME J. Dyn. Sys. Meas. Control 125(4), 2003).

    Examples
    --------
    Equal masses, ``e = 1``: the velocity estimates of the colliding pair are swapped.

    >>> import numpy as np
    >>> xa, xb = observer_jump([1.0, 2.0, 3.0, 4.0], [5.0, 6.0], -7.0, [[0, 1], [1, 0]])
    >>> xa.tolist(), xb.tolist()
    ([-7.0, 2.0, 3.0, 6.0], [2.0, 4.0])
    """
    xa = np.array(xh_a, dtype=float)
    xb = np.array(xh_b, dtype=float)
    na = xa.size // 2
    v_pair = np.asarray(M) @ np.array([xa[2 * na - 1], xb[1]])
    q_contact = xa[na - 1]
    xa[0] = y                                   # (7e) uses y(t_i)
    xa[2 * na - 1] = v_pair[0]                  # (7g)
    xb[0] = q_contact                           # (7f) uses q_{n-1} before the reset
    xb[1] = v_pair[1]
    return xa, xb


# ----------------------------------------------------------------------------------------------
# The design object
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ImpactObserverDesign:
    """The asymptotic observer (7) of chapter 2: gains, certificate and closed-loop builder.

    Attributes
    ----------
    plant
        :class:`ImpactPlant` the observer was designed for.
    Lambda1
        Eigenvalues for ``eps = 1``.
    eps
        The high-gain parameter in ``(0, 1]``.
    G_eps
        Observer gain (original coordinates).
    placement
        :class:`ScaledPlacement` (scaled realisation and conditioning).
    observability
        :class:`~nscontrol.design.impact_conditions.Theorem1Result` of the plant.
    alpha_L
        Rate limit ``-ln|M22| / delta_max`` (``inf`` for equal masses or unknown ``delta_max``).
    certificate
        :class:`~nscontrol.design.impact_conditions.EpsilonCertificate` when a target rate was
        given, else ``None``.
    """

    plant: ImpactPlant
    Lambda1: np.ndarray
    eps: float
    G_eps: FloatArray
    placement: ScaledPlacement
    observability: Theorem1Result
    alpha_L: float
    certificate: EpsilonCertificate | None = None

    @property
    def conditioning(self) -> PlacementConditioning:
        return self.placement.conditioning

    @property
    def n_observer(self) -> int:
        return 2 * (self.plant.n_a + self.plant.n_b)

    def closed_loop(self, u: Any = None, *,
                    realisation: Literal["scaled", "original"] = "scaled",
                    impacts: bool = True) -> Any:
        """Plant + observer + exosystem as ONE :class:`LinearHybridSystem`.

        Parameters
        ----------
        u : Exosystem, optional
            The input generator (``None``: no input).
        realisation : {"scaled", "original"}
            Observer state ``[xi; xh_b]`` with ``xh_a = T xi`` (default: the stacked matrix has
            entries ``O(1/eps)``), or ``[xh_a; xh_b]`` with the raw gain (entries
            ``O(eps^-N)``). Both realise the same error dynamics (see
            :class:`PlacementConditioning`); for the two-mass body a of the worked example the
            raw-gain realisation settles at a lower error floor at small ``eps`` (5.9e-11
            against 5.3e-9 at ``eps = 0.0049``, docs/ch02.md).
        impacts : bool
            ``False`` switches the contact off (body b moves on a parallel track, never hit):
            the demonstration that without impacts body b's state is not recovered.

        Returns
        -------
        LinearHybridSystem
            State ``[x_a; x_b; w; observer]``; guards and impacts are the plant's; at an impact
            the plant's restitution and the observer's jumps (7c)-(7g) apply together. Outputs
            ``"y"``, ``"xhat"`` and ``"error"`` (``x - xhat``) are recorded, plus the plant's.
        """
        from dataclasses import replace

        from ..simulate.lowering import stacked_model
        from ..systems.closed_loop import closed_loop

        plant_sys = self.plant.bodies.hybrid(u)
        if not check_bool("impacts", impacts):   # a guard never reaching zero: b out of reach
            plant_sys = replace(plant_sys, G=np.zeros_like(plant_sys.G),
                                g0=np.ones_like(plant_sys.g0))
        pl = self.plant
        y = np.zeros((1, plant_sys.n_states))
        y[0, :2 * pl.n_a] = pl.C_a
        loop = closed_loop(plant_sys, observer=self.observer(plant_sys.n_states, realisation),
                           output_matrix=y)
        return stacked_model(loop)

    def observer(self, n_plant: int | None = None,
                 realisation: Literal["scaled", "original"] = "scaled") -> Any:
        """This observer as a block for :func:`nscontrol.closed_loop`.

        The flow (7a)-(7b) — output injection on body a, body b's free motion — and the
        jumps (7c)-(7g) at the plant's impacts, which are linear in the observer state and
        the measurement ``y⁻``: a :class:`~nscontrol.systems.feedback.LinearObserver` with a
        ``jump``, stacked with the plant into one :class:`LinearHybridSystem` (exact flow,
        compiled event loop).

        Parameters
        ----------
        n_plant : int, optional
            Length of the plant state it reads (``[x_a; x_b; w]``: with an exosystem ``w``);
            default ``2 (n_a + n_b)``.
        realisation : {"scaled", "original"}
            See :meth:`closed_loop`.

        Returns
        -------
        LinearObserver
            Reads ``y = C_a x_a`` and the input ``u`` (through ``B``); estimates
            ``[x_a; x_b]`` (``error = [x_a; x_b] - x̂``).
        """
        from ..systems.feedback import LinearObserver

        pl = self.plant
        F_obs, g_obs, T, T_inv = self._observer_flow(realisation)
        na2, nb2 = 2 * pl.n_a, 2 * pl.n_b
        r = na2 + nb2
        n_plant = r if n_plant is None else int(n_plant)
        F = np.zeros((r, r))
        F[:na2, :na2], F[na2:, na2:] = F_obs, pl.A_b
        L = np.zeros((r, 1))
        L[:na2, 0] = g_obs
        B = np.zeros((r, 1))
        B[:na2, 0] = T_inv @ pl.B_a
        E = np.zeros((r, r))
        E[:na2, :na2], E[na2:, na2:] = T, np.eye(nb2)

        def jump(xo: FloatArray, y: float) -> FloatArray:
            xa_plus, xb_plus = observer_jump(T @ xo[:na2], xo[na2:], y, pl.M)
            return np.concatenate([T_inv @ xa_plus, xb_plus])

        # (7c)-(7g) are linear in (observer state, y): their matrices
        Jo = np.column_stack([jump(e, 0.0) for e in np.eye(r)])
        Jy = jump(np.zeros(r), 1.0)[:, None]
        estimates = np.hstack([np.eye(r), np.zeros((r, n_plant - r))])
        return LinearObserver(F, L, B=B, E=E, estimates=estimates, jump=(Jo, Jy),
                              names=self._observer_names(realisation))

    def _observer_flow(self, realisation: str
                       ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Flow matrix, output-injection gain and ``xh_a = T (observer state)``."""
        sp, pl = self.placement, self.plant
        if realisation == "scaled":
            return sp.F / self.eps, sp.g_scaled, sp.T, sp.T_inv
        if realisation == "original":
            eye = np.eye(2 * pl.n_a)
            return pl.A_a - np.outer(self.G_eps, pl.C_a), self.G_eps, eye, eye
        raise ModelError(f"realisation: expected 'scaled' or 'original', got {realisation!r}")

    def _observer_names(self, realisation: str) -> tuple[str, ...]:
        names = tuple(self.plant.bodies.state_names)
        na2, nb2 = 2 * self.plant.n_a, 2 * self.plant.n_b
        obs_a = (tuple(f"xi{i + 1}" for i in range(na2)) if realisation == "scaled"
                 else tuple(f"hat_{s}" for s in names[:na2]))
        return obs_a + tuple(f"hat_{s}" for s in names[na2:na2 + nb2])

    def initial_state(self, x_plant0: ArrayLike, xhat0: ArrayLike, *,
                      realisation: Literal["scaled", "original"] = "scaled") -> FloatArray:
        """Stack ``[x_plant0; observer state]`` for :meth:`closed_loop`.

        ``x_plant0`` is the plant's state ``[x_a; x_b; w]``, ``xhat0`` the estimate
        ``[xh_a; xh_b]``; ``realisation`` must match the one given to :meth:`closed_loop`.

        Raises
        ------
        InadmissibleStateError
            ``x_plant0`` penetrates, or touches with approaching velocities.
        """
        na2, nb2 = 2 * self.plant.n_a, 2 * self.plant.n_b
        xp = as_vector("x_plant0", x_plant0)
        if xp.size < na2 + nb2:
            raise DimensionError(f"x_plant0: expected at least {na2 + nb2} entries "
                                 f"([x_a; x_b; w]), got {xp.size}")
        xh = as_vector("xhat0", xhat0, na2 + nb2)
        self.plant.bodies.check_state(xp[:na2 + nb2], name="x_plant0")
        xa = self._observer_flow(realisation)[3] @ xh[:na2]
        return np.concatenate([xp, xa, xh[na2:]])

    def error_state(self, x_plant0: ArrayLike, xhat0: ArrayLike, *,
                    realisation: Literal["scaled", "original"] = "scaled") -> FloatArray:
        """The estimation error as a closed-loop state: :meth:`initial_state` minus the same
        with the observer at the true state.

        Its plant part is zero, so it moves no guard: it follows the closed loop's flow and
        jumps at the plant's impacts, and ``outputs["error"]`` maps it to ``x~``
        (:func:`~nscontrol.analysis.observability.impact_error_contraction` propagates it).

        Parameters
        ----------
        x_plant0, xhat0, realisation
            As for :meth:`initial_state`.

        Returns
        -------
        ndarray
        """
        xp = as_vector("x_plant0", x_plant0)
        truth = xp[:self.n_observer]
        return (self.initial_state(xp, xhat0, realisation=realisation)
                - self.initial_state(xp, truth, realisation=realisation))


def certificate_velocity_scale(plant: ImpactPlant, delta_max: float) -> float:
    """The velocity scale of the certificate's norms: the plant's ``frequency``, or
    ``1/delta_max`` when it has no springs.

    Parameters
    ----------
    plant : ImpactPlant
    delta_max : float
        Largest dwell time (only used without springs).

    Returns
    -------
    float
        ``omega`` [1/time]; the certificate bounds ``||[q~; v~ / omega]||``, which scales with
        the units like a length, so the certified ``eps`` is unit-free.
    """
    w = plant.frequency
    return w if w > 0.0 else 1.0 / check_positive("delta_max", delta_max)


def design_impact_observer(bodies: ImpactingBodies | ImpactPlant, Lambda1: ArrayLike,
                           eps: float | None = None, *, alpha: float | None = None,
                           delta_min: float | None = None, delta_max: float | None = None,
                           eps_min: float = 1e-4) -> ImpactObserverDesign:
    """Design the asymptotic observer (7) for an (n-1, 1) impacting-bodies plant.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant; body b must be one mass.
    Lambda1 : array_like of complex, length ``2 (n - 1)``
        Observer eigenvalues for ``eps = 1`` (negative real parts, closed under conjugation).
    eps : float, optional
        High-gain parameter in ``(0, 1]``. Give either ``eps`` or ``alpha``.
    alpha : float, optional
        Target decay rate: ``eps`` is then the largest value meeting the sufficient conditions
        of Theorem 3 (equal masses) or 4 (unequal), see
        :func:`~nscontrol.design.impact_conditions.search_epsilon`. Needs ``delta_min`` and
        ``delta_max``.
    delta_min, delta_max : float, optional
        Dwell-time bounds of Assumption 2 (``alpha_L`` is reported when ``delta_max`` is given).
    eps_min : float
        Smallest ``eps`` the search tries.

    Returns
    -------
    ImpactObserverDesign

    Raises
    ------
    InfeasibleDesignError
        ``(C_a, A_a)`` unobservable; ``alpha >= alpha_L`` with unequal masses; no certified
        ``eps``.
    ModelError, DimensionError
        ``eps`` outside ``(0, 1]``; ``Lambda1`` of the wrong size, not in the open left
        half-plane or not conjugate-closed; body b with more than one mass; neither or both of
        ``eps`` and ``alpha``.

    Notes
    -----
    Hypotheses: ``(C_a, A_a)`` observable (checked, PBH); Assumption 2 on dwell times (not
    checkable before simulating; the certificate holds only for records with dwell times in
    ``(delta_min, delta_max)``); Theorem 4 also needs ``k_nn >= 0`` (checked when ``alpha`` is
    given). Impacts are detected in real time (Remark 3): the closed loop resets the observer
    at the plant's exact impact times. Theorem 1's condition (1), ``W(s)`` not zero, is
    reported in ``observability`` but not required (the observer works whenever impacts occur).

    The certificate's norms weight the velocities by ``1/omega``,
    ``omega = sqrt(max ||H^{-1} K||)`` of the plant (``1/delta_max`` without springs), so that
    the certified ``eps`` does not depend on the units (a time- or mass-rescaled copy of the
    plant with ``Lambda1``, ``alpha``, ``delta`` rescaled accordingly gets the same ``eps``).

    References
    ----------
    Chapter 2 of SICONOS D5.3, equation (7), Theorems 3-4, Remark 1; Martinelli, Menini,
    Tornambe, ASME J. Dyn. Sys. Meas. Control 125(4), 2003.

    Examples
    --------
    The worked example with ``m_3 = 0.7`` (Theorem 4), dwell times in ``(0.6, 2.3)``:

    >>> from nscontrol.systems.impacting_bodies import ImpactingBodies
    >>> plant = ImpactingBodies.from_springs([1.0, 1.0], [0.7], {(0, 0): 4.0, (0, 1): 6.0},
    ...                                      {(0, 0): 2.8})
    >>> lam = [-0.5, -0.6, -0.7, -0.8]
    >>> d = design_impact_observer(plant, lam, alpha=0.3, delta_min=0.6, delta_max=2.3)
    >>> d.certificate.condition, round(d.alpha_L, 4), 0.0 < d.eps < 0.1
    ('theorem4', 0.7542, True)
    >>> design_impact_observer(plant, lam, alpha=0.8, delta_min=0.6,
    ...                        delta_max=2.3)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.InfeasibleDesignError: alpha: the target rate 0.8 is unreachable ...
    """
    plant = impact_plant(bodies)
    if plant.n_b != 1:
        raise ModelError(f"bodies: the asymptotic observer (7) is for the (n-1, 1) case, body b "
                         f"must be one mass, got n_b = {plant.n_b}; use deadbeat_1n for (1, n-1)")
    if (eps is None) == (alpha is None):
        raise ModelError("eps, alpha: give exactly one -- eps directly, or a target rate alpha "
                         "(with delta_min, delta_max) for the certified eps")
    lam = _check_lambda(Lambda1, 2 * plant.n_a)
    thm1 = theorem1_test(plant.A_a, plant.B_a, plant.C_a, plant.C_contact)
    alpha_L = np.inf if delta_max is None else alpha_limit(plant.M[1, 1], delta_max)
    cert = None
    if alpha is not None:
        if delta_min is None or delta_max is None:
            raise ModelError("delta_min, delta_max: a target rate alpha needs the dwell-time "
                             "bounds of Assumption 2")
        sp1 = place_scaled(plant.A_a, plant.C_a, lam, 1.0)   # raises if unobservable
        cert = search_epsilon(sp1.F, sp1.P, plant.A_b, plant.M, delta_min, delta_max, alpha,
                              eps_min=eps_min,
                              velocity_scale=certificate_velocity_scale(plant, delta_max))
        eps = cert.eps
    eps = _check_eps(eps)
    sp = place_scaled(plant.A_a, plant.C_a, lam, eps)
    return ImpactObserverDesign(plant, lam, eps, sp.G, sp, thm1, alpha_L, cert)


# ----------------------------------------------------------------------------------------------
# Dead-beat observers (section 4; construction is our choice)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeadbeatEstimate:
    """Estimates of a dead-beat observer at the query times.

    Attributes
    ----------
    t
        Query times.
    x_hat
        ``(len(t), 2 n)`` estimates ``[x_a; x_b]``; NaN rows where not yet available.
    valid
        Which rows hold an estimate.
    impacts_used
        Impact times the estimate of body b rests on (at the last valid query).
    impacts_needed
        How many impacts it took before body b was determined: 1 for
        :func:`deadbeat_n1`; for :func:`deadbeat_1n` the number of usable impacts after which
        the stacked impact equations first had full rank (``n - 1`` generically).
    rank
        :func:`deadbeat_n1`: smallest numerical rank of the window least-squares problems
        solved (``2 n_a`` when full); :func:`deadbeat_1n`: rank of the stacked impact equations
        of all usable impacts (``2 n_b`` when full).
    condition
        Condition number of the same problems (the largest over the windows for
        :func:`deadbeat_n1`; of the stacked impact equations for :func:`deadbeat_1n`).
    window_condition
        Largest condition number of the window least-squares problems (both observers).
    impact_amplification
        ``1/|M12|``: the factor by which the impact step ``v_n(t_i-) = (v_{n-1}(t_i+) - M11
        v_{n-1}(t_i-)) / M12`` amplifies errors of the reconstructed velocities.
    """

    t: FloatArray
    x_hat: FloatArray
    valid: np.ndarray
    impacts_used: FloatArray
    impacts_needed: int
    rank: int
    condition: float
    window_condition: float
    impact_amplification: float


class _WindowReconstructor:
    """``x_a(t_ref)`` from samples of ``y`` on an impact-free window (exact least squares).

    With the input generated by an exosystem, ``[x_a; w]`` is autonomous and ``w(t_ref)`` is
    known, so each sample ``y(s) = c e^{A (s - t_ref)} [x_a; w]`` is one linear equation on
    ``x_a(t_ref)``. The rows ``c e^{A tau}`` come from one decomposition of ``A^T``. The
    smallest rank and largest condition number met are kept in ``min_rank``, ``max_cond``.
    """

    def __init__(self, plant: ImpactPlant, u: Any, rtol: float = 1e-10) -> None:
        from ..numerics.lti import LTIFlow

        na2 = plant.A_a.shape[0]
        if u is None:
            A_aug = plant.A_a
        else:
            S = np.asarray(u.S, float)
            nw = S.shape[0]
            A_aug = np.zeros((na2 + nw, na2 + nw))
            A_aug[:na2, :na2] = plant.A_a
            A_aug[:na2, na2:] = np.outer(plant.B_a, np.ravel(u.Cu))
            A_aug[na2:, na2:] = S
        self.na2, self.u, self.rtol = na2, u, rtol
        self.flow_T = LTIFlow(A_aug.T)
        self.c = np.concatenate([plant.C_a, np.zeros(A_aug.shape[0] - na2)])
        self.min_rank, self.max_cond = na2, 0.0

    def state(self, ts: FloatArray, ys: FloatArray, t_ref: float) -> FloatArray:
        na2 = self.na2
        if ts.size < na2:
            raise InfeasibleDesignError(
                f"samples: a window holds {ts.size} samples of y, at least {na2} (= 2 n_a) are "
                "needed; sample y faster or lengthen the window", status="rank_deficient")
        rows = np.atleast_2d(self.flow_T.propagate(self.c, ts - t_ref))
        w_ref = np.zeros(0) if self.u is None else np.asarray(self.u.w(t_ref), float)
        rhs = ys - rows[:, na2:] @ w_ref
        sol, _, rank, sv = np.linalg.lstsq(rows[:, :na2], rhs, rcond=None)
        cond = float(sv[0] / sv[-1]) if sv[-1] > 0.0 else np.inf
        self.min_rank = min(self.min_rank, int(rank))
        self.max_cond = max(self.max_cond, cond)
        if rank < na2 or sv[-1] <= self.rtol * sv[0]:
            raise InfeasibleDesignError(
                f"window: the samples determine only {rank} of {na2} states of body a "
                f"(singular values {sv[0]:.3g} .. {sv[-1]:.3g}); lengthen the window",
                status="rank_deficient")
        return np.asarray(sol, dtype=float)

    def before(self, ts: FloatArray, ys: FloatArray, t: float, window: float) -> FloatArray:
        """``x_a(t)`` from the samples in ``(t - window, t]``."""
        keep = (ts > t - window) & (ts <= t)
        return self.state(ts[keep], ys[keep], t)

    def after(self, ts: FloatArray, ys: FloatArray, t: float, window: float) -> FloatArray:
        """``x_a(t+)`` from the samples in ``(t, t + window)``."""
        keep = (ts > t) & (ts < t + window)
        return self.state(ts[keep], ys[keep], t)


def _check_samples(t_samples: Any, y_samples: Any) -> tuple[FloatArray, FloatArray]:
    ts = as_vector("t_samples", t_samples)
    ys = as_vector("y_samples", y_samples, ts.size)
    step = np.diff(ts)
    if np.any(step < 0.0):
        raise ModelError("t_samples: expected non-decreasing sample times")
    keep = np.concatenate([[True], step > 0.0])   # y is continuous: duplicates carry nothing
    return ts[keep], ys[keep]


def _impact_pair(rec: _WindowReconstructor, ts: FloatArray, ys: FloatArray, t_i: float,
                 window: float) -> tuple[FloatArray, FloatArray]:
    """``x_a(t_i-)`` and ``x_a(t_i+)`` from the windows just before and just after ``t_i``
    (both open at ``t_i``)."""
    keep = (ts > t_i - window) & (ts < t_i)
    return rec.state(ts[keep], ys[keep], t_i), rec.after(ts, ys, t_i, window)


def deadbeat_n1(bodies: ImpactingBodies | ImpactPlant, t_samples: ArrayLike, y_samples: ArrayLike,
                impact_times: ArrayLike, t_query: Any, *, window: float,
                u: Any = None) -> DeadbeatEstimate:
    """Dead-beat observer for the (n-1, 1) case: exact state after one impact plus a window.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant (body b one mass).
    t_samples, y_samples : array_like
        Samples of ``y = q_1`` (noise-free), non-decreasing times (repeated event times are
        dropped).
    impact_times : array_like
        Detected impact times (Remark 3: impacts are detected in real time).
    t_query : array_like
        Times at which to estimate the state.
    window : float
        Length ``d`` of the reconstruction windows (Assumption: ``d < delta_min``).
    u : Exosystem, optional
        Generator of the known input.

    Returns
    -------
    DeadbeatEstimate
        Valid at ``t`` when an impact ``t_i <= t - d`` has an impact-free window of length
        ``d`` before it and no impact lies in ``(t_i, t]``; ``rank`` and ``condition`` are
        those of the window least-squares solves actually made.

    Raises
    ------
    InfeasibleDesignError
        A window with fewer than ``2 n_a`` samples or a singular window problem
        (``status="rank_deficient"``).

    Notes
    -----
    From the proof of Theorem 2 (**our choice** of implementation): ``x_a`` is reconstructed by
    least squares on the samples of the last impact-free window of length ``d`` (exact for
    noise-free data; needs ``(C_a, A_a)`` observable); at the last impact ``t_i``,
    ``x_a(t_i-)`` and ``x_a(t_i+)`` come from the windows on either side,
    ``q_n(t_i) = q_{n-1}(t_i)`` and ``v_n(t_i-) = (v_{n-1}(t_i+) - M11 v_{n-1}(t_i-)) / M12``,
    ``v_n(t_i+) = M21 v_{n-1}(t_i-) + M22 v_n(t_i-)``; the free mass is then propagated with
    ``A_b``. The reconstruction restarts at every impact.

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorem 2 and section on dead-beat observers.

    Examples
    --------
    The worked example (2, 1), no input, one impact at ``t = 0.5``:

    >>> import numpy as np
    >>> from nscontrol.simulate import simulate
    >>> from nscontrol.systems.impacting_bodies import ImpactingBodies
    >>> plant = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0, (0, 1): 6.0},
    ...                                      {(0, 0): 4.0})
    >>> x0 = [0.0, 0.0, 0.0, 1.0, 0.5, 0.0]                 # mass 2 moving towards mass 3
    >>> traj = simulate(plant.hybrid(), x0, (0.0, 1.5), dt=0.01, progress=False)
    >>> t_imp = traj.event_times("jump")
    >>> est = deadbeat_n1(plant, traj.t, traj.signal("y")[:, 0], t_imp, [1.0, 1.4],
    ...                   window=0.2)
    >>> err = np.abs(est.x_hat - traj.at(est.t)[:, :6]).max()
    >>> t_imp.size, bool(est.valid.all()), bool(err < 1e-9), est.rank
    (1, True, True, 4)
    """
    from ..numerics.lti import LTIFlow

    plant = impact_plant(bodies)
    if plant.n_b != 1:
        raise ModelError(f"bodies: deadbeat_n1 is for the (n-1, 1) case, got n_b = {plant.n_b}")
    window = check_positive("window", window)
    ts, ys = _check_samples(t_samples, y_samples)
    impacts = np.sort(as_vector("impact_times", np.atleast_1d(impact_times)))
    tq = np.atleast_1d(as_vector("t_query", t_query))
    na, M = plant.n_a, plant.M
    rec = _WindowReconstructor(plant, u)
    flow_b = LTIFlow(plant.A_b)
    out = np.full((tq.size, 2 * na + 2), np.nan)
    cache: dict[int, FloatArray] = {}
    used: set[float] = set()
    for k, t in enumerate(tq):
        i = int(np.searchsorted(impacts, t, side="right")) - 1
        if i < 0 or t - impacts[i] < window:
            continue
        t_i = impacts[i]
        if (i > 0 and t_i - impacts[i - 1] < window) or t_i - ts[0] < window:
            continue
        if i not in cache:
            pre, post = _impact_pair(rec, ts, ys, t_i, window)
            v_minus = (post[2 * na - 1] - M[0, 0] * pre[2 * na - 1]) / M[0, 1]
            v_plus = M[1, 0] * pre[2 * na - 1] + M[1, 1] * v_minus
            cache[i] = np.array([pre[na - 1], v_plus])
        used.add(float(t_i))
        out[k, :2 * na] = rec.before(ts, ys, t, window)
        out[k, 2 * na:] = flow_b.propagate(cache[i], t - t_i)
    valid = ~np.isnan(out[:, 0])
    solved = rec.max_cond > 0.0
    return DeadbeatEstimate(tq, out, valid, np.array(sorted(used)), 1,
                            rec.min_rank if solved else 0,
                            rec.max_cond if solved else np.nan,
                            rec.max_cond if solved else np.nan, float(1.0 / abs(M[0, 1])))


def _consecutive_usable(impacts: FloatArray, ts: FloatArray, window: float) -> list[float]:
    """Impacts from the first isolated one on, stopping before the first that is not isolated
    (closer than ``window`` to a neighbour or to the ends of the data): a skipped impact would
    break the chain of exact propagations between impacts."""
    out: list[float] = []
    for k, t in enumerate(impacts):
        ok = (t - ts[0] >= window and t + window <= ts[-1]
              and (k == 0 or t - impacts[k - 1] >= window)
              and (k + 1 == impacts.size or impacts[k + 1] - t >= window))
        if ok:
            out.append(float(t))
        elif out:
            break
    return out


def deadbeat_1n(bodies: ImpactingBodies | ImpactPlant, t_samples: ArrayLike, y_samples: ArrayLike,
                impact_times: ArrayLike, t_query: Any, *, window: float, u: Any = None,
                rtol: float = 1e-10) -> DeadbeatEstimate:
    """Dead-beat observer for the (1, n-1) case: body b recovered from its impacts.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant: body a is one measured mass, body b has ``n - 1`` masses.
    t_samples, y_samples : array_like
        Samples of ``y = q_1``.
    impact_times : array_like
        Detected impact times.
    t_query : array_like
        Times at which to estimate.
    window : float
        Length of the windows on either side of each impact used to get ``v_1(t_i-)``,
        ``v_1(t_i+)`` (and of the window reconstructing ``x_a`` at the query times).
    u : Exosystem, optional
        Generator of the known input.
    rtol : float
        Singular values below ``rtol * sigma_max`` count as zero (rank deficiency).

    Returns
    -------
    DeadbeatEstimate
        Valid after the impact at which the stacked equations first reach full rank (the
        ``impacts_needed``-th, ``n - 1`` generically), plus the window.

    Raises
    ------
    InfeasibleDesignError
        ``status="unobservable"``: the contact mass's position and velocity do not observe
        body b (a mass of b not coupled to it), so no number of impacts can determine it;
        ``status="too_few_impacts"``: fewer than ``n - 1`` usable impacts in the data;
        ``status="rank_deficient"``: the equations of all usable impacts are singular
        (degenerate impact times; a record with more impacts may cure it), or a window with
        too few samples.

    Notes
    -----
    Each impact ``t_i`` gives two linear equations on ``x_b``: ``q_2(t_i) = q_1(t_i)`` and
    ``v_2(t_i-) = (v_1(t_i+) - M11 v_1(t_i-)) / M12``; the jump ``x_b(t_i+) = x_b(t_i-) +
    e_v2 (v_2(t_i+) - v_2(t_i-))`` is then known, and ``x_b(t_{i+1}-) = e^{A_b delta}
    x_b(t_i+)`` chains the impacts into one linear system in ``x_b(t_1-)``. After impact
    ``j`` the equations of all usable impacts up to ``j`` are solved by least squares (causal:
    an estimate at ``t`` uses no impact after ``t``); ``n - 1`` impacts (``2(n-1)`` equations)
    are generically enough. Necessary: ``([e_q2; e_v2], A_b)`` observable (checked first, PBH).
    Construction is **our choice** (the seed's text is truncated).

    References
    ----------
    Chapter 2 of SICONOS D5.3, section 4 (the (1, n-1) case).

    Examples
    --------
    The (1, 2) variant of the worked example, pushed by ``u = 3 sin 2t``:

    >>> import numpy as np
    >>> from nscontrol.numerics.lti import Exosystem
    >>> from nscontrol.simulate import simulate
    >>> from nscontrol.systems.impacting_bodies import ImpactingBodies
    >>> plant = ImpactingBodies.from_springs([1.0], [1.0, 1.0], {(0, 0): 3.0},
    ...                                      {(0, 0): 2.0, (0, 1): 3.0, (1, 1): 1.0})
    >>> u = Exosystem.sinusoid(3.0, omega=2.0)
    >>> x0 = np.concatenate([[-1.0, 0.6, 0.0, 0.0, 0.0, 0.0], u.w0])
    >>> traj = simulate(plant.hybrid(u), x0, (0.0, 8.0), dt=0.01, progress=False)
    >>> t_imp = traj.event_times("jump")
    >>> t_q = np.arange(0.05, 7.5, 0.1)
    >>> est = deadbeat_1n(plant, traj.t, traj.signal("y")[:, 0], t_imp, t_q, window=0.25, u=u)
    >>> err = np.abs(est.x_hat[est.valid] - traj.at(est.t[est.valid])[:, :6]).max()
    >>> est.impacts_needed, est.rank, bool(err < 1e-9)
    (2, 4, True)
    """
    from ..numerics.lti import LTIFlow

    plant = impact_plant(bodies)
    if plant.n_a != 1:
        raise ModelError(f"bodies: deadbeat_1n is for the (1, n-1) case, body a must be one "
                         f"mass, got n_a = {plant.n_a}")
    window = check_positive("window", window)
    ts, ys = _check_samples(t_samples, y_samples)
    impacts = np.sort(as_vector("impact_times", np.atleast_1d(impact_times)))
    tq = np.atleast_1d(as_vector("t_query", t_query))
    nb, nb2, M = plant.n_b, 2 * plant.n_b, plant.M
    e_q2, e_v2 = np.eye(nb2)[0], np.eye(nb2)[nb]
    seen_ok, margin, modes = pbh_observability(plant.A_b, np.vstack([e_q2, e_v2]))
    if not seen_ok:
        raise InfeasibleDesignError(
            f"bodies: the contact mass's position and velocity do not observe body b "
            f"(([e_q2; e_v2], A_b) unobservable, PBH margin {margin:.3g} at eigenvalue(s) "
            f"{', '.join(f'{m:.6g}' for m in modes)}): part of body b is not coupled to the "
            "contact mass, and no number of impacts can determine it", status="unobservable")
    rec = _WindowReconstructor(plant, u)
    flow_b = LTIFlow(plant.A_b)
    need = nb
    usable = _consecutive_usable(impacts, ts, window)
    if len(usable) < need:
        raise InfeasibleDesignError(
            f"impact_times: {len(usable)} usable consecutive impact(s) (isolated by at least "
            f"the window {window:g}, inside the data), {need} (= n - 1) needed to determine the "
            f"{nb2} states of body b; record longer or make the bodies collide more often",
            status="too_few_impacts")
    rows, rhs, post = [], [], []
    Phi, offset = np.eye(nb2), np.zeros(nb2)   # x_b(t_i-) = Phi x_b(t_1-) + offset
    for k, t_i in enumerate(usable):
        if k > 0:
            step = flow_b.expm(t_i - usable[k - 1])
            Phi, offset = step @ Phi, step @ offset
        pre_a, post_a = _impact_pair(rec, ts, ys, t_i, window)
        v2_minus = (post_a[1] - M[0, 0] * pre_a[1]) / M[0, 1]
        v2_plus = M[1, 0] * pre_a[1] + M[1, 1] * v2_minus
        rows += [e_q2 @ Phi, e_v2 @ Phi]
        rhs += [pre_a[0] - e_q2 @ offset, v2_minus - e_v2 @ offset]
        offset = offset + e_v2 * (v2_plus - v2_minus)
        post.append((Phi.copy(), offset.copy()))      # x_b(t_i+) = Phi x_b(t_1-) + offset
    Amat, b = np.array(rows), np.array(rhs)
    sv_all = np.linalg.svd(Amat, compute_uv=False)
    rank = int(np.sum(sv_all > rtol * sv_all[0]))
    if rank < nb2:
        raise InfeasibleDesignError(
            f"impact_times: the equations of all {len(usable)} usable impacts determine only "
            f"{rank} of the {nb2} states of body b (singular values {sv_all[0]:.3g} .. "
            f"{sv_all[-1]:.3g}) although body b is observable from the contact mass: "
            "degenerate impact times (e.g. dwell times commensurate with body b's periods); "
            "a record with more impacts at other dwell times may cure it",
            status="rank_deficient")
    post_states: dict[int, FloatArray] = {}
    first_full = None
    for j in range(need - 1, len(usable)):
        sub = Amat[:2 * (j + 1)]
        sv = np.linalg.svd(sub, compute_uv=False)
        if np.sum(sv > rtol * sv[0]) < nb2:
            continue                                   # not yet determined
        first_full = j if first_full is None else first_full
        x1 = np.linalg.lstsq(sub, b[:2 * (j + 1)], rcond=None)[0]
        post_states[j] = post[j][0] @ x1 + post[j][1]
    out = np.full((tq.size, 2 + nb2), np.nan)
    last_used = -1
    for k, t in enumerate(tq):
        i = int(np.searchsorted(impacts, t, side="right")) - 1
        if i < 0 or t - impacts[i] < window or impacts[i] not in usable:
            continue
        j = usable.index(impacts[i])
        if j not in post_states:
            continue
        out[k, :2] = rec.before(ts, ys, t, window)
        out[k, 2:] = flow_b.propagate(post_states[j], t - usable[j])
        last_used = max(last_used, j)
    valid = ~np.isnan(out[:, 0])
    needed = len(usable) if first_full is None else first_full + 1   # None cannot happen
    return DeadbeatEstimate(tq, out, valid, np.array(usable[:last_used + 1]), needed,
                            rank, float(sv_all[0] / sv_all[-1]), rec.max_cond,
                            float(1.0 / abs(M[0, 1])))
