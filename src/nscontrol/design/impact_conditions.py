"""The design conditions of chapter 2: when impacts make a body observable, and which
observer parameter ``eps`` certifies a decay rate.

The (n-1, 1) case of chapter 2: an actuated body ``a`` of ``n - 1`` masses, measured through
``y = q_1``, hits a free mass ``b`` that is unobservable between impacts. The observer design
(:mod:`nscontrol.design.impact_observer`) needs

* :func:`theorem1_test` -- ``W(s) = C_{n-1}(sI - A_a)^{-1} B_a`` not identically zero and
  ``(C_a, A_a)`` observable (Theorem 1), with the failing condition and its numbers when it
  fails;
* :func:`jury_second_order` -- both roots of ``z^2 - c1 z - c0`` inside the disc of radius rho;
* :func:`search_epsilon` -- the largest ``eps`` meeting the sufficient conditions of
  Theorems 3 and 4, with ``alpha_L = -ln|M22| / delta_max`` (:func:`alpha_limit`) for unequal
  masses; :func:`certified_rate` -- the largest rate those conditions certify for a given
  ``eps``.

All functions work on matrices (``A_a``, ``B_a``, ``C_a``, ``A_b``, the restitution matrix
``M``), so they apply to any model of the class. :mod:`nscontrol.analysis.observability`
re-exports them next to the tests on a model and on a simulated run (Theorem 2, measured
decay rates).

Units. Both tests of Theorem 1 are decided on a *balanced, dimensionless* copy of the
matrices: ``A = omega D A_n D^{-1}`` with ``D`` the diagonal balancing similarity
(:func:`~nscontrol.numerics.scaling.balanced_unit_norm`, powers of two) and
``omega = ||D^{-1} A D||_2`` (a time rescaling). For a mechanical ``A_a`` the balancing scales
the velocities by about ``1/sqrt(||H^{-1}K||)``; changing the units of time, length or mass
therefore leaves the verdicts and margins unchanged (up to the powers of two of ``D``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_square, as_vector, check_positive
from ..errors import InfeasibleDesignError, ModelError
from ..numerics.observability import RANK_RTOL, krylov_basis, pbh_observability
from ..numerics.scaling import balanced_unit_norm

if TYPE_CHECKING:   # imported where used at run time
    from ..numerics.lti import LTIFlow

__all__ = [
    "Theorem1Result",
    "EpsilonCertificate",
    "theorem1_test",
    "jury_second_order",
    "alpha_limit",
    "observer_flow_norms",
    "search_epsilon",
    "certified_rate",
]


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
        ``C_{n-1} A_a^k B_a``, ``k = 0..2n_a-1``, in the model's units (W vanishes iff all do);
        informative only -- the decision uses ``contact_projection``.
    krylov_dimension
        Dimension of the reachable (Krylov) space ``span{B_a, A_a B_a, ...}``, found by
        Arnoldi with re-orthogonalisation on the balanced matrices.
    contact_projection
        ``||C_{n-1} Q|| / ||C_{n-1}||`` for an orthonormal basis ``Q`` of that space, in
        balanced coordinates: 0 when the input cannot move the contact mass (``W = 0``).
    pbh_margin
        ``min_lambda sigma_min([A_n - lambda I; C_n])`` on the balanced, unit-norm pair
        (0: unobservable); see :func:`pbh_observability`.
    unobservable_modes
        Eigenvalues of ``A_a`` (model units) at which the PBH test fails.
    reason
        One sentence: why the test passed or which condition failed, with its numbers.
    """

    observable: bool
    transfer_nonzero: bool
    pair_observable: bool
    markov_parameters: FloatArray
    krylov_dimension: int
    contact_projection: float
    pbh_margin: float
    unobservable_modes: tuple[complex, ...]
    reason: str



def theorem1_test(A_a: ArrayLike, B_a: ArrayLike, C_a: ArrayLike, C_contact: ArrayLike, *,
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
        Relative threshold (on the balanced, unit-norm matrices) under which a Krylov step,
        the contact projection or a PBH singular value counts as zero.

    Returns
    -------
    Theorem1Result

    Notes
    -----
    Theorem 1 (sufficient): the system is observable if (1) ``W(s) = C_{n-1}(sI - A_a)^{-1}
    B_a`` is not identically zero -- then an input exists that forces an impact from every
    admissible state -- and (2) ``(C_a, A_a)`` is observable. Both are checked here, on the
    balanced dimensionless matrices (module docstring), so that the verdict does not depend
    on the units:

    (1) ``W = sum_k C_{n-1} A^k B s^{-k-1}`` vanishes iff ``C_{n-1}`` is orthogonal to the
        Krylov space of ``(A_a, B_a)``. An orthonormal basis of that space is built by Arnoldi
        with re-orthogonalisation; the test is the norm of ``C_{n-1}``'s projection onto it.
        (Markov parameters compared with ``||A||^k`` would be the same test in exact arithmetic
        but call a long or stiff chain "W = 0": the first non-zero parameter of an ``n_a``-mass
        chain is ``~ k^{n_a-1}`` against ``||A||^{2 n_a - 1}``.)
    (2) The PBH test of :func:`pbh_observability`.

    A failed test does not prove unobservability (the condition is only sufficient).

    References
    ----------
    Chapter 2 of SICONOS D5.3; F. Martinelli, L. Menini, A. Tornambe, ASME J. Dyn. Sys. Meas.
    Control 125(4), 2003, Theorem 1. Arnoldi with re-orthogonalisation: Golub & Van Loan,
    *Matrix Computations*, 4th ed., section 10.5.

    Examples
    --------
    The worked example of chapter 2 (force on mass 1, springs ``k11 = 4``, ``k12 = 6``):

    >>> import numpy as np
    >>> A = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [-10, 6, 0, 0], [6, -6, 0, 0]])
    >>> B, C, C2 = [0.0, 0, 1, 0], [1.0, 0, 0, 0], [0.0, 1, 0, 0]
    >>> res = theorem1_test(A, B, C, C2)
    >>> res.observable, res.krylov_dimension
    (True, 4)

    The same plant in other units (springs x 1e6: time x 1e-3) gets the same verdict:

    >>> A6 = A.copy(); A6[2:, :2] *= 1e6
    >>> theorem1_test(A6, B, C, C2).observable
    True

    No input reaches the contact mass (``B = 0``): condition (1) fails, with its numbers.

    >>> theorem1_test(A, [0.0, 0, 0, 0], C, C2).reason.split(":")[0]
    'condition (1) fails'
    """
    A = as_square("A_a", A_a)
    n = A.shape[0]
    B = as_vector("B_a", np.ravel(B_a), n)
    C = as_vector("C_a", np.ravel(C_a), n).reshape(1, n)
    Cc = as_vector("C_contact", np.ravel(C_contact), n)
    markov = np.empty(n)
    v = B.copy()
    for k in range(n):
        markov[k] = Cc @ v
        v = A @ v
    An, d, _ = balanced_unit_norm(A)
    Bn, Ccn = B / d, Cc * d
    Q = krylov_basis(An, Bn, rtol)
    cc_norm = float(np.linalg.norm(Ccn))
    projection = float(np.linalg.norm(Ccn @ Q) / cc_norm) if cc_norm > 0.0 and Q.size else 0.0
    w_nonzero = projection > rtol
    pair_ok, margin, modes = pbh_observability(A, C, rtol=rtol)
    if not w_nonzero:
        reason = (f"condition (1) fails: W(s) = C_(n-1)(sI - A_a)^-1 B_a is identically zero "
                  f"(the input reaches a {Q.shape[1]}-dimensional subspace of the {n} states "
                  f"of body a, and the contact position's projection onto it is "
                  f"{projection:.3g} <= {rtol:g}); the input cannot move the contact mass, so "
                  "no impact can be forced")
    elif not pair_ok:
        reason = (f"condition (2) fails: (C_a, A_a) is unobservable, PBH margin {margin:.3g} "
                  f"<= {rtol:g} at eigenvalue(s) {', '.join(f'{m:.6g}' for m in modes)}")
    else:
        reason = (f"observable: W(s) is not identically zero (contact-position projection "
                  f"{projection:.3g} onto the {Q.shape[1]}-dimensional reachable space) and "
                  f"(C_a, A_a) is observable (PBH margin {margin:.3g})")
    return Theorem1Result(bool(w_nonzero and pair_ok), bool(w_nonzero), bool(pair_ok), markov,
                          int(Q.shape[1]), projection, margin, modes, reason)



# ----------------------------------------------------------------------------------------------
# Sufficient conditions of Theorems 3 and 4
# ----------------------------------------------------------------------------------------------
def jury_second_order(c1: float, c0: float, rho: float) -> bool:
    """Whether both roots of ``z^2 - c1 z - c0`` have modulus ``< rho``.

    Parameters
    ----------
    c1, c0 : float
        The polynomial's coefficients.
    rho : float
        The radius (> 0).

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
    """``alpha_L = -ln|M22| / delta_max`` of Theorem 4 (``inf`` for equal masses, ``M22 = 0``).

    Parameters
    ----------
    M22 : float
        Entry ``M22`` of the impact map (the velocity of the impacting mass after the
        impact per unit before it), ``|M22| < 1``.
    delta_max : float
        The longest interval between two impacts, ``δ_max > 0``.

    Examples
    --------
    >>> round(alpha_limit(-0.3 / 1.7, 2.0), 6)        # m_n = 0.7, m_{n-1} = 1, e = 1
    0.867301
    """
    delta_max = check_positive("delta_max", delta_max)
    m = abs(float(M22))
    if m >= 1.0:
        raise ModelError(f"M22: expected |M22| < 1 (restitution with positive masses), got "
                         f"{M22!r}")
    return np.inf if m == 0.0 else float(-np.log(m) / delta_max)


def _velocity_weights(n: int, velocity_scale: float) -> FloatArray:
    """Diagonal of ``W`` for a mechanical state ``[q; v]`` of size ``n``: 1 on the positions,
    ``1/velocity_scale`` on the velocities (``||W x||`` is unit-consistent)."""
    if velocity_scale == 1.0:
        return np.ones(n)
    if n % 2:
        raise ModelError(f"velocity_scale: a mechanical state [q; v] has an even size, got {n}")
    return np.concatenate([np.ones(n // 2), np.full(n // 2, 1.0 / velocity_scale)])


def observer_flow_norms(F: ArrayLike | LTIFlow, P: ArrayLike, eps: float, deltas: ArrayLike, *,
                        velocity_scale: float = 1.0) -> FloatArray:
    """``||W e^{A_O,eps delta} W^{-1}||_2`` for each ``delta``, computed in scaled coordinates.

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
    velocity_scale : float
        ``W = diag(1, ..., 1, 1/velocity_scale, ...)`` weights the velocities of the state
        ``[q; v]`` (1: the Euclidean norm in the model's units).

    Returns
    -------
    ndarray
        One norm per ``delta``.

    Notes
    -----
    ``A_O,eps = T (F / eps) T^{-1}`` with ``T = P S_eps^{-1}``, ``S_eps = diag(1, eps, ...,
    eps^{N-1})`` (the chapter's equation (9)): the exponential of the well-scaled
    ``F delta / eps`` is formed first, then mapped back, which avoids exponentiating the
    ``O(eps^-N)`` gain matrix.

    References
    ----------
    Chapter 2 of SICONOS D5.3, equation (9) and the bound on ``||e^{A_O,eps delta}||`` in the
    proof of Theorem 3.

    Examples
    --------
    >>> import numpy as np
    >>> F = np.array([[-3.0, 1.0], [-2.0, 0.0]])           # companion of {-1, -2}
    >>> norms = observer_flow_norms(F, np.eye(2), 0.5, [0.0, 1.0, 2.0])
    >>> bool(abs(norms[0] - 1.0) < 1e-12 and norms[2] < norms[1] < 1.0)
    True
    """
    from ..numerics.lti import LTIFlow

    flow = F if isinstance(F, LTIFlow) else LTIFlow(as_square("F", F))
    P = as_square("P", P, flow.n)
    velocity_scale = check_positive("velocity_scale", velocity_scale)
    w = _velocity_weights(flow.n, velocity_scale)
    eps = check_positive("eps", eps)
    powers = eps ** np.arange(flow.n)
    T = w[:, None] * P / powers[None, :]
    Tinv = np.linalg.inv(P) * powers[:, None] / w[None, :]
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
        Coefficients of the comparison recursion at ``eps`` (equal masses), or the diagonal
        entries ``beta``, ``gamma`` of the comparison matrix (unequal masses).
    spectral_radius
        Largest root modulus of the comparison recursion at ``eps`` (``< rho``).
    condition
        ``"theorem3"`` (equal masses) or ``"theorem4"`` (unequal).
    velocity_scale
        The norm the bounds use: ``||[q~; v~ / velocity_scale]||``.
    """

    eps: float
    alpha: float
    alpha_L: float
    rho: float
    b1: float
    b0: float
    spectral_radius: float
    condition: str
    velocity_scale: float = 1.0


class _Comparison:
    """The comparison system of Theorems 3 / 4 for given plant data, as a function of eps."""

    def __init__(self, F: Any, P: Any, A_b: Any, M: Any, delta_min: float, delta_max: float,
                 n_delta: int, velocity_scale: float) -> None:
        from scipy.linalg import expm

        from ..numerics.lti import LTIFlow

        self.delta_min = check_positive("delta_min", delta_min)
        self.delta_max = check_positive("delta_max", delta_max)
        if self.delta_max <= self.delta_min:
            raise ModelError(f"delta_max: expected > delta_min = {delta_min}, got {delta_max}")
        self.velocity_scale = check_positive("velocity_scale", velocity_scale)
        A_b = as_square("A_b", A_b, 2)
        self.M = M = as_square("M", M, 2)
        self.A_b = A_b
        self.alpha_L = alpha_limit(M[1, 1], self.delta_max)
        self.deltas = np.linspace(self.delta_min, self.delta_max, n_delta)
        wb = _velocity_weights(2, self.velocity_scale)
        Phis = [wb[:, None] * expm(A_b * d) / wb[None, :] for d in self.deltas]
        self.equal = bool(M[1, 1] == 0.0)
        self.mu_b = max(float(np.linalg.norm(Ph, 2) ** 2) for Ph in Phis)
        self.blocks = {"ab": abs(M[0, 1]),
                       "ba": max(float(np.hypot(Ph[1, 0], Ph[1, 1] * M[1, 0])) for Ph in Phis),
                       "bb": abs(M[1, 1]) * max(abs(Ph[1, 1]) for Ph in Phis)}
        self.flow = LTIFlow(as_square("F", F))
        self.P = as_square("P", P, self.flow.n)

    def coefficients(self, eps: float) -> tuple[float, float, float, float]:
        """``(c1, c0, d1, d2)``: the recursion ``z^2 - c1 z - c0`` and the two numbers the
        certificate reports (``b1, b0``, or ``beta, gamma``)."""
        norms = observer_flow_norms(self.flow, self.P, eps, self.deltas,
                                    velocity_scale=self.velocity_scale)
        if self.equal:
            b1 = float(np.max(norms) ** 2)
            b0 = b1 * self.mu_b
            return b1, b0, b1, b0
        beta = float(np.max(norms))
        p, q = beta, beta * self.blocks["ab"]
        r, s = self.blocks["ba"], self.blocks["bb"]
        return p + s, q * r - p * s, p, s      # char. poly of [[p, q], [r, s]]

    def rho(self, alpha: float) -> float:
        return float(np.exp(-(2.0 if self.equal else 1.0) * alpha * self.delta_max))

    def evaluate(self, eps: float, rho: float) -> tuple[bool, float, float, float]:
        c1, c0, d1, d2 = self.coefficients(eps)
        radius = float(np.max(np.abs(np.roots([1.0, -c1, -c0]))))
        return jury_second_order(c1, c0, rho), d1, d2, radius


def search_epsilon(F: ArrayLike, P: ArrayLike, A_b: ArrayLike, M: ArrayLike, delta_min: float,
                   delta_max: float, alpha: float, *, n_delta: int = 64, eps_min: float = 1e-4,
                   n_grid: int = 41, velocity_scale: float = 1.0) -> EpsilonCertificate:
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
    velocity_scale : float
        The bounds use the norm ``||[q~; v~ / velocity_scale]||`` (1: the model's units).
        :func:`~nscontrol.design.impact_observer.design_impact_observer` passes the plant's
        ``sqrt(||H^{-1} K||)``, which makes the certified ``eps`` independent of the units.

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
    grid of ``n_delta`` points (not a rigorous bound between grid points). All norms are
    ``||W .||`` with the velocity weighting ``W`` (any fixed norm certifies the same rate, with
    a different constant ``mu``).

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorems 3 and 4, inequalities (10), (11), (16)-(18).

    Examples
    --------
    The worked example (equal masses), dwell times between 0.3 and 3.6:

    >>> import numpy as np
    >>> from nscontrol.design.impact_observer import place_scaled
    >>> A_a = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [-10, 6, 0, 0], [6, -6, 0, 0]])
    >>> sp = place_scaled(A_a, [1.0, 0, 0, 0], [-0.5, -0.6, -0.7, -0.8], 1.0)
    >>> A_b = np.array([[0.0, 1.0], [-4.0, 0.0]])
    >>> M = np.array([[0.0, 1.0], [1.0, 0.0]])                # e = 1, equal masses
    >>> cert = search_epsilon(sp.F, sp.P, A_b, M, 0.3, 3.6, 0.2)
    >>> cert.condition, 0.0 < cert.eps < 1.0, cert.spectral_radius < cert.rho
    ('theorem3', True, True)
    """
    alpha = check_positive("alpha", alpha)
    comp = _Comparison(F, P, A_b, M, delta_min, delta_max, n_delta, velocity_scale)
    if not comp.equal:
        if alpha >= comp.alpha_L:
            raise InfeasibleDesignError(
                f"alpha: the target rate {alpha:g} is unreachable with unequal masses: Theorem 4 "
                f"caps it below alpha_L = -ln|M22|/delta_max = {comp.alpha_L:.6g} (|M22| = "
                f"{abs(comp.M[1, 1]):.4g}, delta_max = {comp.delta_max:g}); ask for alpha < "
                "alpha_L, or make the colliding masses closer / the impacts more frequent",
                status="alpha_unreachable")
        if comp.A_b[1, 0] > 0.0:
            raise InfeasibleDesignError(
                f"A_b: Theorem 4 needs k_nn >= 0 (free mass not exponentially unstable); got "
                f"-k_nn/m_n = {comp.A_b[1, 0]:.4g} > 0", status="theorem4_hypothesis")
    rho = comp.rho(alpha)
    grid = np.geomspace(1.0, eps_min, n_grid)
    k = 0
    for k in range(n_grid):
        eps = float(grid[k])
        ok, b1, b0, radius = comp.evaluate(eps, rho)
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
            res = comp.evaluate(mid, rho)
            if res[0]:
                lo, (ok, b1, b0, radius) = mid, res
            else:
                hi = mid
        eps = lo
    return EpsilonCertificate(float(eps), alpha, comp.alpha_L, rho, float(b1), float(b0),
                              radius, "theorem3" if comp.equal else "theorem4",
                              comp.velocity_scale)


def certified_rate(F: ArrayLike, P: ArrayLike, A_b: ArrayLike, M: ArrayLike, delta_min: float,
                   delta_max: float, eps: float, *, n_delta: int = 64,
                   velocity_scale: float = 1.0) -> float:
    """The supremum of the rates ``alpha`` that the sufficient conditions certify at ``eps``.

    The converse of :func:`search_epsilon`: same data and comparison system, ``eps`` given.

    Parameters
    ----------
    F, P, A_b, M, delta_min, delta_max, n_delta, velocity_scale
        As for :func:`search_epsilon`.
    eps : float
        High-gain parameter in ``(0, 1]``.

    Returns
    -------
    float
        ``-ln(radius) / (2 delta_max)`` (equal masses, recursion on squared norms) or
        ``min(-ln(radius) / delta_max, alpha_L)`` (unequal masses), ``radius`` the spectral
        radius of the comparison system at ``eps``; 0 when ``radius >= 1`` (nothing certified).
        Every ``alpha`` below the value is certified.

    Notes
    -----
    Both roots of ``z^2 - c1 z - c0`` with ``c0, c1 >= 0`` lie inside ``rho`` iff the spectral
    radius is below ``rho`` (:func:`jury_second_order`), so the certified rates form the
    interval ``(0, -ln(radius) / (k delta_max))``, ``k = 2`` or 1. Hypotheses as in
    :func:`search_epsilon` (Assumption 2 with these dwell bounds; ``k_nn >= 0`` for unequal
    masses, checked).

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorems 3 and 4.

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.design.impact_observer import place_scaled
    >>> A_a = np.array([[0.0, 0, 1, 0], [0, 0, 0, 1], [-10, 6, 0, 0], [6, -6, 0, 0]])
    >>> sp = place_scaled(A_a, [1.0, 0, 0, 0], [-0.5, -0.6, -0.7, -0.8], 1.0)
    >>> A_b, M = np.array([[0.0, 1.0], [-4.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]])
    >>> [round(certified_rate(sp.F, sp.P, A_b, M, 0.3, 3.6, e), 3) for e in (0.05, 0.01, 0.005)]
    [0.0, 0.068, 1.843]
    """
    comp = _Comparison(F, P, A_b, M, delta_min, delta_max, n_delta, velocity_scale)
    if not comp.equal and comp.A_b[1, 0] > 0.0:
        raise InfeasibleDesignError(
            f"A_b: Theorem 4 needs k_nn >= 0 (free mass not exponentially unstable); got "
            f"-k_nn/m_n = {comp.A_b[1, 0]:.4g} > 0", status="theorem4_hypothesis")
    eps = check_positive("eps", eps)
    c1, c0, _, _ = comp.coefficients(eps)
    radius = float(np.max(np.abs(np.roots([1.0, -c1, -c0]))))
    if radius >= 1.0:
        return 0.0
    if comp.equal:
        return float(-np.log(radius) / (2.0 * comp.delta_max))
    return float(min(-np.log(radius) / comp.delta_max, comp.alpha_L))
