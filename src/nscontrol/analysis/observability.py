"""Observability and reconstructibility of bodies that interact only through impacts (ch. 2).

The (n-1, 1) case of chapter 2: an actuated body ``a`` of ``n - 1`` masses, measured through
``y = q_1``, hits a free mass ``b`` that is unobservable between impacts. This module holds the
tests of Theorems 1 and 2 and the sufficient conditions behind Theorems 3 and 4, turned into a
design helper that searches the largest observer parameter ``eps`` certifying a decay rate:

* :func:`theorem1_test` -- ``W(s) = C_{n-1}(sI - A_a)^{-1} B_a`` not identically zero and
  ``(C_a, A_a)`` observable, with the failing condition and its numbers when it fails;
* :func:`reconstructibility` -- Theorem 2 for a given impact record;
* :func:`jury_second_order` -- both roots of ``z^2 - c1 z - c0`` inside the disc of radius rho;
* :func:`search_epsilon` -- the largest ``eps`` meeting the sufficient conditions, with
  ``alpha_L = -ln|M22| / delta_max`` for unequal masses.

All functions work on matrices (``A_a``, ``B_a``, ``C_a``, ``A_b``, the restitution matrix
``M``) so they apply to any model of the class; :mod:`nscontrol.design.impact_observer` feeds
them from an :class:`~nscontrol.systems.mechanical.ImpactingBodies`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import as_matrix, as_square, as_vector, check_positive
from ..errors import InfeasibleDesignError, ModelError

__all__ = [
    "Theorem1Result",
    "ReconstructibilityResult",
    "EpsilonCertificate",
    "theorem1_test",
    "impact_observability",
    "pbh_observability",
    "reconstructibility",
    "jury_second_order",
    "alpha_limit",
    "observer_flow_norms",
    "search_epsilon",
    "DecayMeasurement",
    "impact_decay_rate",
]

FloatArray = NDArray[np.float64]

#: Relative tolerance below which a Markov parameter / PBH singular value counts as zero.
RANK_RTOL = 1e-9


# ----------------------------------------------------------------------------------------------
# Theorem 1
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Theorem1Result:
    """Outcome of the Theorem 1 test (sufficient condition for observability).

    Attributes
    ----------
    observable
        Both conditions hold: the system with impacts is observable.
    transfer_nonzero
        Condition (1): ``W(s) = C_{n-1}(sI - A_a)^{-1} B_a`` is not identically zero.
    pair_observable
        Condition (2): ``(C_a, A_a)`` is observable.
    markov_parameters
        ``C_{n-1} A_a^k B_a``, ``k = 0..2n_a-1`` (W is zero iff all vanish).
    markov_relative
        Largest ``|C_{n-1} A_a^k B_a| / (|C_{n-1}| |A_a|^k |B_a|)`` (0 when W vanishes).
    pbh_margin
        ``min_lambda sigma_min([A_a - lambda I; C_a]) / max(1, |A_a|)`` (0: unobservable).
    unobservable_modes
        Eigenvalues of ``A_a`` at which the PBH test fails.
    reason
        One sentence: why the test passed or which condition failed, with its numbers.
    """

    observable: bool
    transfer_nonzero: bool
    pair_observable: bool
    markov_parameters: FloatArray
    markov_relative: float
    pbh_margin: float
    unobservable_modes: tuple[complex, ...]
    reason: str


def pbh_observability(A: Any, C: Any, *, rtol: float = RANK_RTOL
                      ) -> tuple[bool, float, tuple[complex, ...]]:
    """Popov-Belevitch-Hautus observability test of ``(C, A)``.

    Better conditioned than the rank of the observability matrix (no powers of ``A``).

    Returns
    -------
    observable : bool
    margin : float
        Smallest ``sigma_min([A - lambda I; C])`` over the eigenvalues, relative to
        ``max(1, ||A||)``.
    modes : tuple of complex
        Eigenvalues failing the test.
    """
    A = as_square("A", A)
    C = as_matrix("C", C, cols=A.shape[0])
    scale = max(1.0, float(np.linalg.norm(A, 2)))
    margin, modes = np.inf, []
    for lam in np.linalg.eigvals(A):
        stacked = np.vstack([A - lam * np.eye(A.shape[0]), C.astype(complex)])
        smin = float(np.linalg.svd(stacked, compute_uv=False)[-1]) / scale
        margin = min(margin, smin)
        if smin <= rtol:
            modes.append(complex(lam))
    return not modes, float(margin), tuple(modes)


def theorem1_test(A_a: Any, B_a: Any, C_a: Any, C_contact: Any, *,
                  rtol: float = RANK_RTOL) -> Theorem1Result:
    """Theorem 1 of chapter 2: is the (n-1, 1) system observable thanks to the impacts?

    Parameters
    ----------
    A_a : (N, N) array_like
        Flow matrix of the actuated body, ``N = 2 n_a``.
    B_a : (N,) or (N, 1) array_like
        Input matrix of the actuated body.
    C_a : (N,) or (1, N) array_like
        Measurement row (``q_1``).
    C_contact : (N,) or (1, N) array_like
        Row picking ``q_{n-1}``, the position of the mass that hits the free one.
    rtol : float
        Relative threshold under which a Markov parameter or a PBH singular value is zero.

    Returns
    -------
    Theorem1Result

    Notes
    -----
    Theorem 1 (sufficient): the system is observable if (1) ``W(s) = C_{n-1}(sI - A_a)^{-1}
    B_a`` is not identically zero -- then an input exists that forces an impact from every
    admissible state -- and (2) ``(C_a, A_a)`` is observable. Both are checked here: (1) through
    the Markov parameters ``C_{n-1} A_a^k B_a, k < N`` (Cayley-Hamilton), (2) with the PBH test.
    A failed test does not prove unobservability (the condition is only sufficient).

    References
    ----------
    Chapter 2 of SICONOS D5.3; F. Martinelli, L. Menini, A. Tornambe, ASME J. Dyn. Sys. Meas.
    Control 125(4), 2003, Theorem 1.
    """
    A = as_square("A_a", A_a)
    n = A.shape[0]
    B = as_vector("B_a", np.ravel(B_a), n)
    C = as_vector("C_a", np.ravel(C_a), n).reshape(1, n)
    Cc = as_vector("C_contact", np.ravel(C_contact), n)
    markov, rel = np.empty(n), np.empty(n)
    v = B.copy()
    normA = max(float(np.linalg.norm(A, 2)), 1e-300)
    base = max(float(np.linalg.norm(Cc) * np.linalg.norm(B)), 1e-300)
    for k in range(n):
        markov[k] = Cc @ v
        rel[k] = abs(markov[k]) / (base * normA**k)
        v = A @ v
    markov_relative = float(rel.max())
    w_nonzero = markov_relative > rtol
    pair_ok, margin, modes = pbh_observability(A, C, rtol=rtol)
    if not w_nonzero:
        reason = (f"condition (1) fails: W(s) = C_(n-1)(sI - A_a)^-1 B_a is identically zero "
                  f"(largest relative Markov parameter {markov_relative:.3g} <= {rtol:g}); the "
                  "input cannot move the contact mass, so no impact can be forced")
    elif not pair_ok:
        reason = (f"condition (2) fails: (C_a, A_a) is unobservable, PBH margin {margin:.3g} "
                  f"<= {rtol:g} at eigenvalue(s) {', '.join(f'{m:.6g}' for m in modes)}")
    else:
        reason = (f"observable: W(s) is not identically zero (largest relative Markov "
                  f"parameter {markov_relative:.3g}) and (C_a, A_a) is observable (PBH margin "
                  f"{margin:.3g})")
    return Theorem1Result(bool(w_nonzero and pair_ok), bool(w_nonzero), bool(pair_ok), markov,
                          markov_relative, margin, modes, reason)


def impact_observability(bodies: Any) -> Theorem1Result:
    """Theorem 1 for an :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model.

    Parameters
    ----------
    bodies : ImpactingBodies
        The plant; the contact mass is the last of body a.

    Returns
    -------
    Theorem1Result

    Examples
    --------
    >>> from nscontrol.systems.impacting_bodies import ImpactingBodies
    >>> chain = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0, (0, 1): 6.0},
    ...                                      {(0, 0): 4.0})
    >>> impact_observability(chain).observable
    True
    >>> cut = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0}, {(0, 0): 4.0})
    >>> impact_observability(cut).reason.split(":")[0]
    'condition (1) fails'
    """
    n_a = int(bodies.n_a)
    contact = np.zeros(2 * n_a)
    contact[n_a - 1] = 1.0
    return theorem1_test(bodies.A_a, bodies.B_a, bodies.C_a, contact)


# ----------------------------------------------------------------------------------------------
# Theorem 2
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReconstructibilityResult:
    """Outcome of the Theorem 2 test on one impact record.

    Attributes
    ----------
    reconstructible
        ``(C_a, A_a)`` observable and the record holds at least one and finitely many impacts
        in ``[t0, tf)``.
    n_impacts
        Impacts in ``[t0, tf)``.
    pair_observable
        Whether ``(C_a, A_a)`` is observable (PBH test).
    min_dwell
        Smallest interval between consecutive impacts (``inf`` with fewer than two).
    reason
        One sentence with the numbers.
    """

    reconstructible: bool
    n_impacts: int
    pair_observable: bool
    min_dwell: float
    reason: str


def reconstructibility(A_a: Any, C_a: Any, impacts: Any, t_span: Sequence[float], *,
                       min_dwell: float = 1e-9) -> ReconstructibilityResult:
    """Theorem 2 of chapter 2: is the state at ``tf`` determined by ``u`` and ``y`` on
    ``[t0, tf)`` for this input?

    Parameters
    ----------
    A_a, C_a : array_like
        Flow matrix and measurement row of the actuated body.
    impacts : array_like or Trajectory
        Impact times of the simulated record, or a trajectory whose ``"impact"`` events are used.
    t_span : (float, float)
        The interval ``[t0, tf)``.
    min_dwell : float
        Two impacts closer than this are taken as an accumulation (Zeno): not "finitely many".

    Returns
    -------
    ReconstructibilityResult

    Notes
    -----
    Theorem 2 (sufficient): if ``(C_a, A_a)`` is observable, the system is reconstructible on
    ``[t0, tf)`` for every input producing (a) at least one and (b) finitely many impacts there.
    Both hypotheses are checked on the record; an accumulation of impacts (dwell below
    ``min_dwell``) counts as failing (b).

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorem 2 (Martinelli, Menini, Tornambe 2003).
    """
    t0, tf = float(t_span[0]), float(t_span[1])
    if hasattr(impacts, "event_times"):
        impacts = impacts.event_times("impact")
    times = np.sort(np.asarray(impacts, dtype=float).ravel())
    times = times[(times >= t0) & (times < tf)]
    A = as_square("A_a", A_a)
    pair_ok, margin, modes = pbh_observability(A, np.reshape(C_a, (1, -1)))
    dwell = float(np.min(np.diff(times))) if times.size > 1 else np.inf
    if not pair_ok:
        ok, reason = False, (f"(C_a, A_a) is unobservable (PBH margin {margin:.3g} at "
                             f"{', '.join(f'{m:.6g}' for m in modes)})")
    elif times.size == 0:
        ok, reason = False, (f"no impact in [{t0:g}, {tf:g}): body b is never touched, its state "
                             "is not determined by u and y")
    elif dwell < min_dwell:
        ok, reason = False, (f"impacts accumulate (smallest dwell {dwell:.3g} < {min_dwell:g}): "
                             "not finitely many impacts")
    else:
        ok, reason = True, (f"reconstructible: {times.size} impact(s) in [{t0:g}, {tf:g}), "
                            f"smallest dwell {dwell:.4g}, (C_a, A_a) observable")
    return ReconstructibilityResult(ok, int(times.size), pair_ok, dwell, reason)


# ----------------------------------------------------------------------------------------------
# Sufficient conditions of Theorems 3 and 4
# ----------------------------------------------------------------------------------------------
def jury_second_order(c1: float, c0: float, rho: float) -> bool:
    """Whether both roots of ``z^2 - c1 z - c0`` have modulus ``< rho``.

    Notes
    -----
    Our restatement of the chapter's garbled (11a)-(11b), valid for any real ``c0, c1``:
    scaling ``z = rho * zeta`` gives ``zeta^2 + a1 zeta + a0`` with ``a1 = -c1/rho``,
    ``a0 = -c0/rho^2``, Schur-stable iff ``|a0| < 1`` and ``|a1| < 1 + a0``, i.e.
    ``|c0| < rho^2`` and ``|c1| < rho - c0/rho``. For ``c0, c1 >= 0`` this is the chapter's
    ``c1 < rho - c0/rho``, ``c0 < rho^2``.

    Examples
    --------
    >>> jury_second_order(0.5, 0.1, 1.0)        # roots 0.64, -0.14
    True
    >>> jury_second_order(0.5, 0.1, 0.6)
    False
    """
    rho = check_positive("rho", rho)
    return bool(abs(c0) < rho * rho and abs(c1) < rho - c0 / rho)


def alpha_limit(M22: float, delta_max: float) -> float:
    """``alpha_L = -ln|M22| / delta_max`` of Theorem 4 (``inf`` for equal masses, ``M22 = 0``)."""
    delta_max = check_positive("delta_max", delta_max)
    m = abs(float(M22))
    if m >= 1.0:
        raise ModelError(f"M22: expected |M22| < 1 (restitution with positive masses), got "
                         f"{M22!r}")
    return np.inf if m == 0.0 else float(-np.log(m) / delta_max)


def observer_flow_norms(F: Any, P: Any, eps: float, deltas: Any) -> FloatArray:
    """``||e^{A_O,eps delta}||_2`` for each ``delta``, computed in scaled coordinates.

    Parameters
    ----------
    F : (N, N) array_like or LTIFlow
        ``companion(Lambda_1)``, the observer-error matrix for ``eps = 1`` in observer
        canonical form (an :class:`~nscontrol.numerics.lti.LTIFlow` of it may be passed to
        reuse its decomposition).
    P : (N, N) array_like
        Observer-canonical transformation of ``(C_a, A_a)``.
    eps : float
        High-gain parameter.
    deltas : array_like
        Interval lengths.

    Notes
    -----
    ``A_O,eps = T (F / eps) T^{-1}`` with ``T = P S_eps^{-1}``, ``S_eps = diag(1, eps, ...,
    eps^{N-1})`` (the chapter's equation (9)): the exponential of the well-scaled
    ``F delta / eps`` is formed first, then mapped back, which avoids exponentiating the
    ``O(eps^-N)`` gain matrix.
    """
    from ..numerics.lti import LTIFlow

    flow = F if isinstance(F, LTIFlow) else LTIFlow(as_square("F", F))
    P = as_square("P", P, flow.n)
    powers = float(eps) ** np.arange(flow.n)
    T = P / powers[None, :]
    Tinv = np.linalg.inv(P) * powers[:, None]
    E = flow.expm(np.atleast_1d(np.asarray(deltas, float)) / float(eps))
    return np.linalg.norm(T[None] @ E @ Tinv[None], ord=2, axis=(1, 2))


@dataclass(frozen=True)
class EpsilonCertificate:
    """The largest ``eps`` found meeting the sufficient conditions for decay rate ``alpha``.

    Attributes
    ----------
    eps
        Largest certified ``eps`` (on the search grid, refined by bisection).
    alpha
        Target decay rate.
    alpha_L
        ``-ln|M22| / delta_max`` (``inf`` for equal masses).
    rho
        Contraction demanded per impact interval (``e^{-2 alpha delta_max}`` for equal masses,
        on squared norms; ``e^{-alpha delta_max}`` for unequal masses, on norms).
    b1, b0
        Coefficients of the comparison recursion at ``eps`` (equal masses), or the entries
        ``[[b1, q], [r, b0]]`` diagonal of the comparison matrix (unequal masses).
    spectral_radius
        Largest root modulus of the comparison recursion at ``eps`` (``< rho``).
    condition
        ``"theorem3"`` (equal masses) or ``"theorem4"`` (unequal).
    """

    eps: float
    alpha: float
    alpha_L: float
    rho: float
    b1: float
    b0: float
    spectral_radius: float
    condition: str


def _comparison_theorem3(norms_O: FloatArray, mu_b: float, rho: float
                         ) -> tuple[bool, float, float, float]:
    b1 = float(np.max(norms_O) ** 2)
    b0 = b1 * mu_b
    radius = float(np.max(np.abs(np.roots([1.0, -b1, -b0]))))
    return jury_second_order(b1, b0, rho), b1, b0, radius


def _comparison_theorem4(norms_O: FloatArray, blocks: dict[str, float], rho: float
                         ) -> tuple[bool, float, float, float]:
    beta = float(np.max(norms_O))
    p, q = beta * blocks["aa"], beta * blocks["ab"]
    r, s = blocks["ba"], blocks["bb"]
    c1, c0 = p + s, q * r - p * s  # char. poly of [[p, q], [r, s]]: z^2 - c1 z - c0
    radius = float(np.max(np.abs(np.roots([1.0, -c1, -c0]))))
    return jury_second_order(c1, c0, rho), p, s, radius


def search_epsilon(F: Any, P: Any, A_b: Any, M: Any, delta_min: float, delta_max: float,
                   alpha: float, *, n_delta: int = 64, eps_min: float = 1e-4,
                   n_grid: int = 41) -> EpsilonCertificate:
    """Largest ``eps`` in ``(0, 1]`` satisfying the sufficient conditions of Theorem 3 or 4.

    Parameters
    ----------
    F, P : (N, N) array_like
        ``companion(Lambda_1)`` and the observer-canonical transformation of ``(C_a, A_a)``
        (see :func:`observer_flow_norms` and
        :func:`~nscontrol.design.impact_observer.place_scaled`).
    A_b : (2, 2) array_like
        Flow matrix of the free mass.
    M : (2, 2) array_like
        Restitution matrix of the colliding pair.
    delta_min, delta_max : float
        Dwell-time bounds of Assumption 2, ``0 < delta_min < delta_max``.
    alpha : float
        Target decay rate ``> 0``.
    n_delta : int
        Points of the grid on ``[delta_min, delta_max]`` where the norms are maximised.
    eps_min : float
        Smallest ``eps`` tried.
    n_grid : int
        Log-spaced grid of ``eps`` in ``[eps_min, 1]``; the largest certified grid value is
        refined by bisection against the next larger one.

    Returns
    -------
    EpsilonCertificate

    Raises
    ------
    InfeasibleDesignError
        ``alpha >= alpha_L`` (unequal masses: unreachable whatever ``eps``), ``k_nn < 0`` with
        unequal masses (Theorem 4 does not apply), or no grid value of ``eps`` is certified.

    Notes
    -----
    Equal masses (``M22 = 0``, Theorem 3): with ``b1 = max_delta ||e^{A_O,eps delta}||^2``,
    ``b0 = b1 max_delta ||e^{A_b delta}||^2`` and ``rho = e^{-2 alpha delta_max}``, the squared
    error norm at the impacts is bounded by ``w(k+2) = b1 w(k+1) + b0 w(k)``; the rate is
    certified when both roots lie inside ``rho`` (:func:`jury_second_order`).

    Unequal masses (Theorem 4; the seed's proof is truncated, so the bound is **our
    choice**): at the impacts the error of body a depends on itself and on the free mass's
    velocity error only (``q_1`` is reset to ``y``, ``q_n`` to ``q_{n-1}``), so
    ``a_k = ||x~_a(t_k-)||``, ``s_k = |v~_n(t_k-)|`` obey ``[a, s]_{k+1} <= [[beta, beta |M12|],
    [r, gamma]] [a, s]_k`` with ``beta = max ||e^{A_O,eps delta}||``, ``gamma = |M22|
    max |e^{A_b delta}|_22`` (``= |M22|`` when ``k_nn >= 0``, ``cos`` or 1 otherwise) and ``r =
    max ||[Phi_21, Phi_22 M21]||`` from ``Phi = e^{A_b delta}``. The rate is certified when the
    spectral radius is ``< e^{-alpha delta_max}``; as ``eps -> 0``, ``beta -> 0`` and the
    radius tends to ``gamma``, hence the limit ``alpha_L``. Maxima over ``delta`` are taken on a
    grid of ``n_delta`` points (not a rigorous bound between grid points).

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorems 3 and 4, inequalities (10), (11), (16)-(18).
    """
    from scipy.linalg import expm

    delta_min = check_positive("delta_min", delta_min)
    delta_max = check_positive("delta_max", delta_max)
    if delta_max <= delta_min:
        raise ModelError(f"delta_max: expected > delta_min = {delta_min}, got {delta_max}")
    alpha = check_positive("alpha", alpha)
    A_b = as_square("A_b", A_b, 2)
    M = as_square("M", M, 2)
    alpha_L = alpha_limit(M[1, 1], delta_max)
    deltas = np.linspace(delta_min, delta_max, n_delta)
    Phis = [expm(A_b * d) for d in deltas]
    equal = M[1, 1] == 0.0
    if equal:
        rho = float(np.exp(-2.0 * alpha * delta_max))
        mu_b = max(float(np.linalg.norm(P, 2) ** 2) for P in Phis)

        def test(norms: FloatArray) -> tuple[bool, float, float, float]:
            return _comparison_theorem3(norms, mu_b, rho)
    else:
        if alpha >= alpha_L:
            raise InfeasibleDesignError(
                f"alpha: the target rate {alpha:g} is unreachable with unequal masses: Theorem 4 "
                f"caps it below alpha_L = -ln|M22|/delta_max = {alpha_L:.6g} (|M22| = "
                f"{abs(M[1, 1]):.4g}, delta_max = {delta_max:g}); ask for alpha < alpha_L, or "
                "make the colliding masses closer / the impacts more frequent",
                status="alpha_unreachable")
        if A_b[1, 0] > 0.0:
            raise InfeasibleDesignError(
                f"A_b: Theorem 4 needs k_nn >= 0 (free mass not exponentially unstable); got "
                f"-k_nn/m_n = {A_b[1, 0]:.4g} > 0", status="theorem4_hypothesis")
        rho = float(np.exp(-alpha * delta_max))
        blocks = {"aa": 1.0, "ab": abs(M[0, 1]),
                  "ba": max(float(np.hypot(P[1, 0], P[1, 1] * M[1, 0])) for P in Phis),
                  "bb": abs(M[1, 1]) * max(abs(P[1, 1]) for P in Phis)}

        def test(norms: FloatArray) -> tuple[bool, float, float, float]:
            return _comparison_theorem4(norms, blocks, rho)

    from ..numerics.lti import LTIFlow

    flow = LTIFlow(as_square("F", F))

    def evaluate(eps: float) -> tuple[bool, float, float, float]:
        return test(observer_flow_norms(flow, P, eps, deltas))

    grid = np.geomspace(1.0, eps_min, n_grid)
    k = 0
    for k in range(n_grid):
        eps = float(grid[k])
        ok, b1, b0, radius = evaluate(eps)
        if ok:
            break
    else:
        raise InfeasibleDesignError(
            f"eps: no eps in [{eps_min:g}, 1] meets the sufficient conditions for alpha = "
            f"{alpha:g} (last tried eps = {grid[-1]:.3g}: root modulus {radius:.4g} vs rho = "
            f"{rho:.4g}); lower alpha, widen eps_min, or pick faster Lambda_1",
            status="no_eps_certified")
    if k > 0:  # bisect between the certified grid value and the next larger, failing one
        lo, hi = float(eps), float(grid[k - 1])
        for _ in range(20):
            mid = float(np.sqrt(lo * hi))
            res = evaluate(mid)
            if res[0]:
                lo, (ok, b1, b0, radius) = mid, res
            else:
                hi = mid
        eps = lo
    return EpsilonCertificate(float(eps), alpha, alpha_L, rho, float(b1), float(b0), radius,
                              "theorem3" if equal else "theorem4")


# ----------------------------------------------------------------------------------------------
# Measured convergence of an observer along a simulated run
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DecayMeasurement:
    """Decay rate of ``||x~||`` fitted over impact cycles.

    Attributes
    ----------
    rate
        ``-slope`` of the least-squares line through ``(t_i, ln ||x~(t_i-)||)``.
    times, norms
        The pre-impact instants and error norms used (above the floor).
    initial_norm
        ``||x~(t0)||``.
    dwell_min, dwell_max
        Observed dwell times between the impacts of the run (Assumption 2's bounds, seen).
    """

    rate: float
    times: FloatArray
    norms: FloatArray
    initial_norm: float
    dwell_min: float
    dwell_max: float


def impact_decay_rate(trajectory: Any, error_matrix: Any, *, floor: float = 1e-10,
                      kind: str = "jump", skip: int = 0) -> DecayMeasurement:
    """Fit the decay rate of ``||x~(t_i-)||`` at the impacts of a closed-loop run.

    Parameters
    ----------
    trajectory : Trajectory
        A closed-loop run (events of ``kind`` are the plant's impacts).
    error_matrix : (k, n) array_like
        Maps the closed-loop state to the estimation error (``closed_loop.outputs["error"]``).
    floor : float
        Norms below ``floor * ||x~(t0)||`` are left out (rounding level, not convergence).
    kind : str
        Event kind marking impacts (``"jump"`` for linear hybrid systems).
    skip : int
        Impacts left out at the start (transient before the observer engages).

    Returns
    -------
    DecayMeasurement

    Raises
    ------
    ModelError
        Fewer than two pre-impact norms above the floor: no rate can be fitted.
    """
    E = np.asarray(error_matrix, float)
    events = trajectory.events_of(kind)[skip:]
    times = np.array([ev.time for ev in events])
    norms = np.array([np.linalg.norm(E @ ev.pre) for ev in events])
    e0 = float(np.linalg.norm(E @ trajectory.x[0]))
    keep = norms > floor * e0
    n_above = int(np.argmin(keep)) if not keep.all() else keep.size
    if n_above < 2:
        raise ModelError(f"trajectory: {n_above} pre-impact error norm(s) above the "
                         f"floor {floor:g} x ||x~(t0)||; need two to fit a rate -- simulate "
                         "longer or use a larger eps")
    below = np.flatnonzero(~keep)
    end = int(below[0]) if below.size else norms.size   # past the floor: rounding, not decay
    t_fit, n_fit = times[:end], norms[:end]
    slope = float(np.polyfit(t_fit, np.log(n_fit), 1)[0])
    dwell = np.diff(trajectory.event_times(kind))
    return DecayMeasurement(-slope, t_fit, n_fit, e0,
                            float(dwell.min()) if dwell.size else np.inf,
                            float(dwell.max()) if dwell.size else np.inf)
