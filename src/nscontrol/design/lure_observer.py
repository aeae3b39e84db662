"""Passivity-based observers for Lur'e systems with maximal monotone maps (chapter 8).

The plant is ``x' = A x + G w + B u``, ``z = H x + D w + g(t)``, ``w ∈ -φ(z)``, ``y = C x``
with ``φ`` maximal monotone. The observer copies it, with output injection ``L`` in the flow
and (extended variant) ``K`` inside the set-valued map::

    xhat' = (A - L C) xhat + G what + B u + L y
    zhat  = (H - K C) xhat + K y + D what + g(t),      what ∈ -φ(zhat)

The basic variant is ``K = 0``. The gains come from the LMIs of docs/ch08.md (in
``(P, Y = P L, K)``); the equality ``Gᵀ P = H - K C`` is enforced exactly by parametrising its
affine solution set (so the returned certificate satisfies it to round-off, whatever the SDP
solver's accuracy).
The closed loop "plant + observer" is one :class:`~nscontrol.systems.lure.LureSystem` with the
stacked state ``[x; xhat]`` and a product law, so implicit Euler steps both on the same step and
resolves the observer's inclusion exactly; then ``V_k = e_kᵀ P e_k`` obeys
``V_{k+1} <= V_k / (1 + 2 α h)`` (the implicit-Euler form of the theorem).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_matrix, check_bool, check_in_interval, check_positive
from ..errors import DimensionError, InfeasibleDesignError, ModelError

if TYPE_CHECKING:   # imported where used at run time
    from ..laws.base import SetValuedLaw
    from ..systems.closed_loop import ClosedLoop
    from ..systems.feedback import LinearObserver
    from ..systems.lure import LureSystem
    from ..systems.protocols import InputFunction, InputSignal

__all__ = [
    "LureObserverCertificate",
    "LureObserverDesign",
    "structural_infeasibility",
    "lure_observer_lmi",
    "max_observer_decay_rate",
    "design_lure_observer",
    "lure_from_statespace",
    "loop_transformed_lure_system",
    "observer_from_gains",
    "recheck_lure_certificate",
]

FloatArray = NDArray[np.float64]
Variant = Literal["basic", "extended"]

#: Relative tolerance of the exact-equality post-check (``GᵀP = H - KC``).
EQUALITY_RTOL = 1e-7
#: Largest decay rate the bisection tries before declaring the rate unbounded.
ALPHA_CAP = 1e4

#: ``design_lure_observer(alpha="max")`` without ``kappa`` keeps the output-injection gain
#: within ``GAIN_MULTIPLE · max(1, ‖A‖₂)``: the extended observer's rate is otherwise
#: unbounded, and its gains grow like a power of the rate (``‖L‖ ≈ 1.3e7`` at the capped rate
#: on a Coulomb oscillator), amplifying measurement noise by as much.
GAIN_MULTIPLE = 25.0


# -- plant matrices --------------------------------------------------------------------------
@dataclass(frozen=True)
class _Matrices:
    """The linear part ``(A, G, H, C, D)`` checked for shapes; ``D`` is ``m x m``."""

    A: FloatArray
    G: FloatArray
    H: FloatArray
    C: FloatArray
    D: FloatArray

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        return int(self.G.shape[1])

    @property
    def p(self) -> int:
        return int(self.C.shape[0])


def _matrices(A: Any, G: Any, H: Any, C: Any, D: Any = None) -> _Matrices:
    A = as_matrix("A", A)
    n = A.shape[0]
    if A.shape[1] != n:
        raise DimensionError(f"A: expected a square matrix, got shape {A.shape}")
    G = as_matrix("G", G, rows=n)
    m = G.shape[1]
    H = as_matrix("H", H, rows=m, cols=n)
    C = as_matrix("C", C, cols=n)
    D = np.zeros((m, m)) if D is None else as_matrix("D", D, rows=m, cols=m)
    sym_min = float(np.linalg.eigvalsh(D + D.T)[0]) if m else 0.0
    if sym_min < -1e-12 * max(1.0, float(np.abs(D).max(initial=0.0))):
        raise ModelError(f"D: expected D + D^T positive semidefinite (feedthrough of a monotone "
                         f"loop), got smallest eigenvalue {sym_min:.3g}; the observer's error "
                         f"dynamics are not dissipative with this D")
    return _Matrices(A, G, H, C, D)


def _check_variant(variant: str) -> None:
    if variant not in ("basic", "extended"):
        raise ModelError(f"variant: expected 'basic' (K = 0) or 'extended' (output injection "
                         f"into the set-valued map), got {variant!r}")


# -- structural pre-check --------------------------------------------------------------------
def _equality_space(mat: _Matrices, variant: str
                    ) -> tuple[FloatArray, FloatArray, list[FloatArray], list[FloatArray], float]:
    """Affine solution set of ``Gᵀ P + K C = H`` over symmetric ``P`` (and ``K``).

    Returns ``(P0, K0, P_basis, K_basis, residual)``: every solution is ``P0 + Σ θ_i P_i``,
    ``K0 + Σ θ_i K_i``; ``residual`` is the least-squares residual of the particular solution
    (non-zero: the equality has no solution at all).
    """
    n, m, p = mat.n, mat.m, mat.p
    columns: list[tuple[FloatArray, FloatArray]] = []
    for i in range(n):
        for j in range(i, n):
            E = np.zeros((n, n))
            E[i, j] = E[j, i] = 1.0
            columns.append((E, np.zeros((m, p))))
    if variant == "extended":
        for i in range(m):
            for j in range(p):
                E = np.zeros((m, p))
                E[i, j] = 1.0
                columns.append((np.zeros((n, n)), E))
    F = np.column_stack([(mat.G.T @ Pe + Ke @ mat.C).ravel() for Pe, Ke in columns])
    rhs = mat.H.ravel()
    sol, *_ = np.linalg.lstsq(F, rhs, rcond=None)
    residual = float(np.linalg.norm(F @ sol - rhs))
    _, s, Vt = np.linalg.svd(F)
    rank = int(np.sum(s > 1e-12 * max(1.0, s[0] if s.size else 0.0)))
    null = Vt[rank:]

    def unpack(u: np.ndarray) -> tuple[FloatArray, FloatArray]:
        P = sum((ui * Pe for ui, (Pe, _) in zip(u, columns, strict=True)), np.zeros((n, n)))
        K = sum((ui * Ke for ui, (_, Ke) in zip(u, columns, strict=True)), np.zeros((m, p)))
        return P, K

    P0, K0 = unpack(sol)
    basis = [unpack(v) for v in null]
    return P0, K0, [b[0] for b in basis], [b[1] for b in basis], residual


def _undetectable_mode(mat: _Matrices) -> complex | None:
    """An eigenvalue of ``A`` with ``Re >= 0`` that ``C`` does not see (PBH test), or None."""
    n = mat.n
    for lam in np.linalg.eigvals(mat.A):
        if lam.real < -1e-12:
            continue
        pbh = np.vstack([mat.A - lam * np.eye(n), mat.C.astype(complex)])
        if np.linalg.matrix_rank(pbh, tol=1e-9 * max(1.0, np.abs(pbh).max())) < n:
            return complex(lam)
    return None


def _restricted_sym(M: FloatArray, basis: FloatArray) -> FloatArray:
    """``sym(M)`` restricted to the subspace spanned by the columns of ``basis``."""
    S = 0.5 * (M + M.T)
    return basis.T @ S @ basis


def _null_space(M: FloatArray, k: int) -> FloatArray:
    """Orthonormal basis (columns) of the null space of ``M`` (``k`` columns of the domain)."""
    if M.size == 0:
        return np.eye(k)
    _, s, Vt = np.linalg.svd(M)
    rank = int(np.sum(s > 1e-10 * max(1.0, s[0] if s.size else 0.0)))
    return Vt[rank:].T


def _structural_reason(mat: _Matrices, variant: str) -> str | None:
    scale = max(1.0, float(np.linalg.norm(mat.H)))
    *_, residual = _equality_space(mat, variant)
    if residual > 1e-9 * scale:
        return (f"the equality G^T P = H - K C has no solution (least-squares residual "
                f"{residual:.3g}) for any symmetric P" + (" and any K" if variant == "extended"
                                                           else " with K = 0"))
    lam = _undetectable_mode(mat)
    if lam is not None:
        return (f"(A, C) is not detectable: the mode {lam:.4g} of A is invisible in y = C x, "
                f"so A - L C is not Hurwitz for any L")
    HG = mat.H @ mat.G
    full_rank = np.linalg.matrix_rank(mat.G) == mat.m
    # (H - K C) G = G^T P G must be symmetric PSD (PD for full column rank G); on ker(C G)
    # K has no influence, so H G restricted there must already be.
    ker_cg = _null_space(mat.C @ mat.G, mat.m) if variant == "extended" else np.eye(mat.m)
    if ker_cg.shape[1]:
        restricted = ker_cg.T @ HG @ ker_cg
        asym = float(np.abs(restricted - restricted.T).max())
        if asym > 1e-9 * scale * max(1.0, float(np.abs(HG).max())):
            return (f"H G = {np.array2string(HG, precision=4)} is not symmetric"
                    + ("" if variant == "basic" else " on ker(C G)") +
                    ", but the equality forces (H - K C) G = G^T P G (symmetric)")
        eig = np.linalg.eigvalsh(0.5 * (restricted + restricted.T))
        bad = eig[0] <= 1e-12 * scale if full_rank else eig[0] < -1e-12 * scale
        if bad:
            where = "" if variant == "basic" else " on ker(C G), where K has no effect,"
            kind = "definite" if full_rank else "semidefinite"
            return (f"H G{where} must be symmetric positive {kind} (it equals G^T P G); its "
                    f"smallest eigenvalue is {eig[0]:.4g}: the system is not passifiable by "
                    f"output injection")
    # On v = G s with C G s = 0 (and C A G s = 0 for the extended observer) the Lyapunov
    # inequality reads 2 sᵀ H A G s < 0 whatever L and K are.
    constraint = mat.C @ mat.G
    if variant == "extended":
        constraint = np.vstack([constraint, mat.C @ mat.A @ mat.G])
    S = _null_space(constraint, mat.m)
    if S.shape[1] and full_rank:  # (with rank-deficient G, G s = 0 would make the form 0)
        worst = float(np.linalg.eigvalsh(_restricted_sym(mat.H @ mat.A @ mat.G, S))[-1])
        if worst >= -1e-12 * scale:
            return ("along directions v = G s invisible to the output (C G s = 0"
                    + (", C A G s = 0" if variant == "extended" else "") +
                    f") the Lyapunov inequality needs sym(H A G) < 0 there, but its largest "
                    f"eigenvalue is {worst:.4g}: no L" + (", K" if variant == "extended" else "")
                    + " can make the error dynamics strictly passive")
    return None


def structural_infeasibility(A: ArrayLike, G: ArrayLike, H: ArrayLike, C: ArrayLike, *,
                             variant: Variant = "extended") -> str | None:
    """A certain reason why the observer LMIs have no solution, found without an SDP solver.

    Parameters
    ----------
    A, G, H, C : array_like
        Plant matrices (``n x n``, ``n x m``, ``m x n``, ``p x n``).
    variant : {"extended", "basic"}
        With or without the injection gain ``K`` in the set-valued map.

    Returns
    -------
    str or None
        The reason, or ``None`` when no structural obstruction was found (the LMI may still be
        infeasible).

    Notes
    -----
    Checks, each a necessary condition of the certificate (``(A - LC)ᵀP + P(A - LC) <= -2αP - εI``
    and ``GᵀP = H - KC``):

    * ``Gᵀ P + K C = H`` has a solution with ``P`` symmetric (``K = 0`` for the basic variant);
    * ``(A, C)`` is detectable (PBH test), else ``A - L C`` is never Hurwitz;
    * ``H G`` restricted to ``ker(C G)`` (all of ``R^m`` for the basic variant) is symmetric
      positive definite, since ``(H - K C) G = Gᵀ P G``; e.g. ``C G = 0`` with ``H G <= 0``
      ("not passifiable") or relative degree two or more (``H G = 0``);
    * on ``v = G s`` with ``C G s = 0`` (and ``C A G s = 0`` for the extended variant),
      ``vᵀ(A_Lᵀ P + P A_L) v = 2 sᵀ H A G s`` does not depend on ``L, K``; it must be negative.
      This is why the basic observer of an undamped Coulomb oscillator is infeasible.

    References
    ----------
    B. Brogliato, W.P.M.H. Heemels, IEEE TAC 54(8):1996–2001, 2009 (the passivity
    conditions); SICONOS D5.3, ch. 8.

    Examples
    --------
    >>> structural_infeasibility([[0, 1], [0, 0]], [[0], [1]], [[0, -1]], [[1, 0]]) is not None
    True
    """
    _check_variant(variant)
    return _structural_reason(_matrices(A, G, H, C), variant)


# -- certificate and design object ----------------------------------------------------------
@dataclass(frozen=True)
class LureObserverCertificate:
    """The numerical re-check of a solution of the observer LMIs (computed in NumPy).

    Attributes
    ----------
    equality_residual
        ``||Gᵀ P - (H - K C)||_F`` (round-off: the equality is parametrised exactly).
    lmi_max_eig
        Largest eigenvalue of ``sym(A_Lᵀ P + P A_L) + 2 α P``, ``A_L = A - L C``; negative.
    P_min_eig, P_cond
        Smallest eigenvalue and condition number of ``P``.
    hurwitz_abscissa
        Largest real part of the eigenvalues of ``A - L C``; negative.
    gain_norm
        ``||Y||_2 = ||P L||_2`` (bounded by ``kappa`` when one was given).
    solver, solver_status
        The SDP solver that produced the point and its status.
    """

    equality_residual: float
    lmi_max_eig: float
    P_min_eig: float
    P_cond: float
    hurwitz_abscissa: float
    gain_norm: float
    solver: str
    solver_status: str


@dataclass(frozen=True, eq=False)
class LureObserverDesign:
    """Gains of a passivity-based Lur'e observer with their re-checked certificate.

    Attributes
    ----------
    variant : {"basic", "extended"}
        ``K = 0`` or output injection into the set-valued map.
    L, K, P : ndarray
        Output-injection gain (``n x p``), map-injection gain (``m x p``; zero for the basic
        variant) and the storage matrix of ``V(e) = eᵀ P e``.
    alpha : float
        Guaranteed decay rate: ``V(t) <= exp(-2 α t) V(0)``.
    alpha_max : float or None
        Largest certified rate found by bisection (when the design maximised it).
    kappa : float or None
        Bound on ``||P L||_2`` imposed in the synthesis.
    eps, eps_P : float
        Strictness margins of the Lyapunov inequality and of ``P > 0``.
    certificate : LureObserverCertificate
        The NumPy re-check of the solution.
    A, G, H, C, D : ndarray
        The (possibly loop-transformed) linear part the design was made for.
    status : str
        ``"feasible"`` (infeasible designs raise :class:`InfeasibleDesignError`).
    gain_limit : float or None
        The design rule's bound on ``‖L‖₂`` (see :func:`design_lure_observer`): the rate
        search stayed within it, a given rate above it warned; ``None`` when ``kappa`` bounds
        the gain instead or ``max_gain=None``.
    """

    variant: str
    L: FloatArray
    K: FloatArray
    P: FloatArray
    alpha: float
    alpha_max: float | None
    kappa: float | None
    eps: float
    eps_P: float
    certificate: LureObserverCertificate
    A: FloatArray
    G: FloatArray
    H: FloatArray
    C: FloatArray
    D: FloatArray
    status: str = "feasible"
    gain_limit: float | None = None

    def __repr__(self) -> str:
        limit = "" if self.gain_limit is None else f" (limit {self.gain_limit:.3g})"
        best = "" if self.alpha_max is None else f", alpha_max={self.alpha_max:.4g}"
        return (f"LureObserverDesign(variant={self.variant!r}, alpha={self.alpha:.4g}{best}, "
                f"|L|={float(np.linalg.norm(self.L, 2)):.3g}{limit}, "
                f"|K|={float(np.linalg.norm(self.K, 2)):.3g}, "
                f"cond(P)={self.certificate.P_cond:.3g})")

    @property
    def A_L(self) -> FloatArray:
        """The observer's linear part ``A - L C``."""
        return self.A - self.L @ self.C

    def lyapunov(self, error: ArrayLike) -> FloatArray:
        """``V = eᵀ P e`` for one error vector or a time-major array of them."""
        e = np.asarray(error, dtype=np.float64)
        if e.shape[-1] != self.P.shape[0]:
            raise DimensionError(f"error: expected last dimension {self.P.shape[0]}, got "
                                 f"shape {e.shape}")
        return np.einsum("...i,ij,...j->...", e, self.P, e)

    def continuous_bound(self, t: ArrayLike, V0: float) -> FloatArray:
        """The guaranteed ``V(t) <= exp(-2 α t) V(0)`` (Brogliato & Heemels 2009)."""
        return V0 * np.exp(-2.0 * self.alpha * np.asarray(t, dtype=np.float64))

    def discrete_bound(self, k: ArrayLike, h: float, V0: float) -> FloatArray:
        """The implicit-Euler guarantee ``V_k <= V_0 / (1 + 2 α h)^k`` (implicit Euler on
        plant and observer together)."""
        return V0 * (1.0 + 2.0 * self.alpha * h) ** (-np.asarray(k, dtype=np.float64))

    def error_bound(self, t: ArrayLike, e0_norm: float) -> FloatArray:
        """``|e(t)| <= sqrt(cond P) exp(-α t) |e(0)|``."""
        return (np.sqrt(self.certificate.P_cond) * e0_norm
                * np.exp(-self.alpha * np.asarray(t, dtype=np.float64)))

    def closed_loop(self, plant: LureSystem) -> ClosedLoop:
        """The plant and this observer as one loop, ready for :func:`nscontrol.simulate`.

        The same as ``nscontrol.closed_loop(plant, observer=self.observer(plant))``: it runs as
        ONE stacked :class:`~nscontrol.systems.lure.LureSystem` of state ``[x; xhat]``
        (``2 n``) with the law ``φ × φ`` (``z_cl = [z; zhat]``), so implicit Euler steps plant
        and observer on the same grid with the same ``u(t_{k+1})``, ``g(t_{k+1})`` and
        ``y_{k+1} = C x_{k+1}``, and solves both inclusions exactly. The trajectory names the
        states after the plant's (the estimates ``<name>_hat``) and records the estimation
        error ``"e"`` ``= x - xhat`` (also kept as ``"error"``), the estimate ``"xhat"`` and
        the plant's measured output ``"y" = C x``. The stacked model itself is
        ``nscontrol.simulate.lowering.stacked_model(loop)``.

        Parameters
        ----------
        plant : LureSystem
            The plant the design was made for (same ``A, G, H, C, D``; for a non-monotone law
            the plant from :func:`loop_transformed_lure_system`).

        Returns
        -------
        ClosedLoop
        """
        return _closed_loop(self, plant)

    def observer(self, plant: LureSystem) -> LinearObserver:
        """This observer as a block for :func:`nscontrol.closed_loop`.

        ``xhat' = (A - L C) xhat + G what + B u + L y``,
        ``zhat = (H - K C) xhat + K y + D what + g(t)``, ``what ∈ -φ(zhat)``: a
        :class:`~nscontrol.systems.feedback.LinearObserver` with the plant's law, so the
        composition stacks it with the plant into one Lur'e system (both inclusions solved
        together, every step).

        Parameters
        ----------
        plant : LureSystem
            The plant the design was made for.
        """
        return _observer_block(self, plant)

    def observer_system(self, plant: LureSystem, y: InputFunction) -> LureSystem:
        """The observer alone as a :class:`LureSystem` driven by a measured output ``y(t)``.

        ``xhat' = (A - L C) xhat + G what + [B, L] [u; y]``,
        ``zhat = (H - K C) xhat + D what + K y(t) + g(t)``, ``what ∈ -φ(zhat)``: for running
        the observer on recorded measurements (its output is ``xhat`` itself).

        Parameters
        ----------
        plant : LureSystem
            The plant the design was made for (its ``B``, ``u``, ``g`` and law are reused).
        y : callable
            Measured output ``t -> (p,)`` (vectorised ``t -> (len(t), p)`` preferred).
        """
        return _observer_system(self, plant, y)


# -- the LMIs (cvxpy) -------------------------------------------------------------------------
def _default_margin(mat: _Matrices) -> float:
    return 1e-6 * max(1.0, float(np.linalg.norm(mat.H)) / max(float(np.linalg.norm(mat.G)),
                                                                1e-300))


class _ObserverLMI:
    """The observer LMIs compiled once, with the decay rate as a CVXPY parameter.

    Not built on :class:`nscontrol.numerics.lmi.LMIProblem`, which compiles a new CVXPY
    problem per solve: with the rate as a parameter a bisection step costs 2.7 ms instead of
    15.5 ms (measured on 5.2). The re-check is the problem-specific one of
    :func:`recheck_lure_certificate` (equality residual, Hurwitz ``A - L C``, gain bound).
    """

    def __init__(self, mat: _Matrices, variant: str, kappa: float | None, eps: float,
                 eps_P: float, solver: str | None) -> None:
        import cvxpy as cp

        from ..numerics.lmi import solver_order, sym

        self.mat, self.variant, self.kappa = mat, variant, kappa
        self.eps, self.eps_P = eps, eps_P
        self.solvers = solver_order(solver)
        n, p = mat.n, mat.p
        P0, K0, P_basis, K_basis, _ = _equality_space(mat, variant)
        self._P0, self._K0 = P0, K0
        self._P_basis, self._K_basis = np.array(P_basis), np.array(K_basis)
        r = len(P_basis)
        self.theta = cp.Variable(r) if r else None
        P = cp.Constant(P0)
        if self.theta is not None:
            basis = np.column_stack([Pb.ravel() for Pb in P_basis])
            P = P + cp.reshape(basis @ self.theta, (n, n), order="C")
        self.Y = cp.Variable((n, p))
        self.alpha = cp.Parameter(nonneg=True)
        A, C = mat.A, mat.C
        lyap = A.T @ P + P @ A - C.T @ self.Y.T - self.Y @ C + 2.0 * self.alpha * P
        constraints = [sym(lyap) << -eps * np.eye(n), sym(P) >> eps_P * np.eye(n)]
        if kappa is not None:
            constraints.append(cp.bmat([[kappa * np.eye(n), self.Y],
                                        [self.Y.T, kappa * np.eye(p)]]) >> 0)
        self.problem = cp.Problem(cp.Minimize(0), constraints)

    def solve(self, alpha: float) -> tuple[LureObserverCertificate | None, dict[str, Any], str]:
        """Solve at rate ``alpha``; returns (certificate or None, gains, status)."""
        import cvxpy as cp

        from ..numerics.lmi import solver_options

        self.alpha.value = float(alpha)
        status = "not_solved"
        for name in self.solvers:
            options = solver_options(name)
            try:
                with warnings.catch_warnings():
                    # inaccurate statuses are handled below by the NumPy re-check
                    warnings.simplefilter("ignore", UserWarning)
                    self.problem.solve(solver=name, **options)
            except cp.error.SolverError as exc:
                status = f"solver_error ({name}: {exc})"
                continue
            status = str(self.problem.status)
            if status in ("infeasible", "infeasible_inaccurate"):
                return None, {}, f"{status} ({name})"
            if status in ("optimal", "optimal_inaccurate"):
                cert, gains = self._recheck(float(alpha), name, status)
                if cert is not None:
                    return cert, gains, status
                status = f"{status} but the re-check failed ({name})"
        from ..numerics.lmi import fallback_hint

        return None, {}, status + fallback_hint(self.solvers)

    def _recheck(self, alpha: float, solver: str, status: str
                 ) -> tuple[LureObserverCertificate | None, dict[str, Any]]:
        mat = self.mat
        theta = np.zeros(0) if self.theta is None else np.asarray(self.theta.value, float)
        P = self._P0 + np.tensordot(theta, self._P_basis, axes=1) if theta.size else self._P0
        K = self._K0 + np.tensordot(theta, self._K_basis, axes=1) if theta.size else self._K0
        P = 0.5 * (P + P.T)
        Y = np.asarray(self.Y.value, float)
        if not (np.all(np.isfinite(P)) and np.all(np.isfinite(Y))):
            return None, {}
        cert = recheck_lure_certificate(mat.A, mat.G, mat.H, mat.C, P,
                                        np.linalg.solve(P, Y) if _is_pd(P) else Y, K, alpha,
                                        solver=solver, solver_status=status)
        scale = max(1.0, float(np.linalg.norm(mat.H)))
        ok = (cert.P_min_eig >= 0.5 * self.eps_P and cert.lmi_max_eig <= -0.5 * self.eps
              and cert.equality_residual <= EQUALITY_RTOL * scale
              and cert.hurwitz_abscissa < 0.0
              and (self.kappa is None or cert.gain_norm <= self.kappa * (1 + 1e-6)))
        if not ok:
            return None, {}
        return cert, {"P": P, "L": np.linalg.solve(P, Y), "K": K}


def _is_pd(P: FloatArray) -> bool:
    return bool(np.linalg.eigvalsh(P)[0] > 0.0)


def recheck_lure_certificate(A: ArrayLike, G: ArrayLike, H: ArrayLike, C: ArrayLike, P: ArrayLike,
                             L: ArrayLike, K: ArrayLike, alpha: float, *, solver: str = "given",
                             solver_status: str = "given") -> LureObserverCertificate:
    """Re-check observer gains ``(P, L, K)`` against the certificate, in NumPy.

    Useful for certificates from elsewhere (a paper, the Siconos example's ``P = I``). It
    measures, it does not decide: :func:`observer_from_gains` and the synthesis functions
    apply the acceptance thresholds.

    Parameters
    ----------
    A, G, H, C : array_like
        Plant matrices (``n x n``, ``n x m``, ``m x n``, ``p x n``).
    P, L, K : array_like
        Storage matrix (``n x n``), gains ``L`` (``n x p``) and ``K`` (``m x p``).
    alpha : float
        The decay rate the Lyapunov matrix is tested with.
    solver, solver_status : str
        Recorded in the certificate (where the point came from).

    Returns
    -------
    LureObserverCertificate
        Residual of ``Gᵀ P = H - K C``, eigenvalues of the Lyapunov matrix and of ``P``, the
        Hurwitz abscissa of ``A - L C`` and ``||P L||_2``.

    Notes
    -----
    Computed: ``‖Gᵀ P - (H - K C)‖_F``; ``λ_max(sym(A_Lᵀ P + P A_L) + 2 α P)`` with
    ``A_L = A - L C``; ``λ_min(sym P)`` and ``cond P``; ``max Re λ(A_L)``; ``‖P L‖_2``. With the
    equality, a negative Lyapunov eigenvalue and ``P ≻ 0``, the theorem (Brogliato & Heemels 2009)
    gives ``V(t) <= exp(-2 α t) V(0)`` for every maximal monotone law (hypotheses as in
    :func:`design_lure_observer`).

    References
    ----------
    B. Brogliato, W.P.M.H. Heemels, IEEE TAC 54(8), 2009.

    Examples
    --------
    ``P = 2 I`` breaks the equality of the Siconos example (``Gᵀ P = 2 H``):

    >>> c = recheck_lure_certificate([[1, 1], [3, 1]], [[-1], [1]], [[-1, 1]], [[2, 2]],
    ...                              P=[[2, 0], [0, 2]], L=[[1], [1]], K=[[0]], alpha=1.0)
    >>> round(c.equality_residual, 12), c.lmi_max_eig
    (1.414213562373, 0.0)
    """
    mat = _matrices(A, G, H, C)
    P = as_matrix("P", P, rows=mat.n, cols=mat.n)
    L = as_matrix("L", L, rows=mat.n, cols=mat.p)
    K = as_matrix("K", K, rows=mat.m, cols=mat.p)
    A_L = mat.A - L @ mat.C
    lyap = A_L.T @ P + P @ A_L
    eig_P = np.linalg.eigvalsh(0.5 * (P + P.T))
    return LureObserverCertificate(
        equality_residual=float(np.linalg.norm(mat.G.T @ P - (mat.H - K @ mat.C))),
        lmi_max_eig=float(np.linalg.eigvalsh(0.5 * (lyap + lyap.T) + 2.0 * alpha * P)[-1]),
        P_min_eig=float(eig_P[0]),
        P_cond=float(eig_P[-1] / eig_P[0]) if eig_P[0] > 0 else float("inf"),
        hurwitz_abscissa=float(np.max(np.linalg.eigvals(A_L).real)),
        gain_norm=float(np.linalg.norm(P @ L, 2)),
        solver=solver, solver_status=solver_status)


# -- public synthesis entry points ------------------------------------------------------------
def _prepare(A: Any, G: Any, H: Any, C: Any, D: Any, variant: str, kappa: Any, eps: Any,
             eps_P: Any, solver: Any) -> tuple[_Matrices, float | None, float, float]:
    from ..numerics.lmi import solver_order

    _check_variant(variant)
    solver_order(solver)  # a misspelt or missing solver is bad input, found before any work
    mat = _matrices(A, G, H, C, D)
    if mat.p == 0:
        raise DimensionError("C: expected at least one measured output (p >= 1), got 0 rows")
    kappa_v = None if kappa is None else check_positive("kappa", kappa)
    margin = _default_margin(mat)
    eps_v = margin if eps is None else check_positive("eps", eps)
    eps_P_v = margin if eps_P is None else check_positive("eps_P", eps_P)
    return mat, kappa_v, eps_v, eps_P_v


def _raise_structural(mat: _Matrices, variant: str) -> None:
    reason = _structural_reason(mat, variant)
    if reason is not None:
        raise InfeasibleDesignError(f"{variant} Lur'e observer: infeasible for structural "
                                    f"reasons (no solver called): {reason}",
                                    status="structural")


def _design(mat: _Matrices, lmi: _ObserverLMI, cert: LureObserverCertificate,
            gains: dict[str, Any], alpha: float, alpha_max: float | None) -> LureObserverDesign:
    return LureObserverDesign(
        variant=lmi.variant, L=gains["L"], K=gains["K"], P=gains["P"], alpha=float(alpha),
        alpha_max=alpha_max, kappa=lmi.kappa, eps=lmi.eps, eps_P=lmi.eps_P, certificate=cert,
        A=mat.A, G=mat.G, H=mat.H, C=mat.C, D=mat.D)


def _bisect(problem: _ObserverLMI, tol: float, max_gain: float | None = None
            ) -> tuple[float, LureObserverCertificate, dict[str, Any]]:
    """Largest certified rate: a geometric bracket (x4 up from 1, or /4 down), then bisection
    (:func:`nscontrol.numerics.lmi.bisect_max`) to ``tol`` relative to the bracket. With
    ``max_gain``, a rate counts as feasible only when its gain has ``‖L‖₂ <= max_gain``."""
    lmi: _ObserverLMI | _GainLimited = (problem if max_gain is None
                                        else _GainLimited(problem, max_gain))
    cert, gains, status = lmi.solve(0.0)
    if cert is None:
        if max_gain is not None and status == "gain":
            raise InfeasibleDesignError(
                f"max_gain: even the rate-0 design needs ‖L‖₂ above {max_gain:.3g}; pass a "
                f"larger max_gain, or max_gain=None for no bound", status="gain_limit")
        raise InfeasibleDesignError(
            f"{lmi.variant} Lur'e observer: LMIs infeasible even at decay rate 0 (solver "
            f"status: {status}); try the extended variant, a larger kappa, or other outputs",
            status=status)
    best = (cert, gains)
    cert, gains, _ = lmi.solve(1.0)
    if cert is not None:
        lo, hi = 1.0, 4.0
        while True:
            best = (cert, gains)
            cert, gains, _ = lmi.solve(hi)
            if cert is None:
                break
            lo, hi = hi, 4.0 * hi
            if hi > ALPHA_CAP:
                from ..errors import InaccurateCertificateWarning

                warnings.warn(f"decay rate certified up to {lo:g}: it is unbounded without a "
                              f"gain bound; pass kappa", InaccurateCertificateWarning,
                              stacklevel=3)
                return lo, cert, gains
    else:
        lo, hi = 0.0, 1.0
        while hi > 1e-6 and lo == 0.0:
            if lmi.solve(hi / 4.0)[0] is not None:
                lo = hi / 4.0
            else:
                hi = hi / 4.0
    if lo == 0.0:
        return 0.0, *best
    from ..numerics.lmi import bisect_max

    def attempt(a: float) -> tuple[LureObserverCertificate, dict[str, Any]] | None:
        cert, gains, _ = lmi.solve(a)
        return None if cert is None else (cert, gains)

    found = bisect_max(attempt, lo, hi, tol=tol * lo)
    return found.value, *found.result


class _GainLimited:
    """An observer LMI whose solutions with ``‖L‖₂ > max_gain`` count as infeasible (the
    gain grows with the rate, so the largest such rate is found by the same bisection)."""

    def __init__(self, lmi: _ObserverLMI, max_gain: float) -> None:
        self.lmi, self.max_gain, self.variant = lmi, max_gain, lmi.variant

    def solve(self, alpha: float) -> tuple[LureObserverCertificate | None, dict[str, Any], str]:
        cert, gains, status = self.lmi.solve(alpha)
        if cert is not None and float(np.linalg.norm(gains["L"], 2)) > self.max_gain:
            return None, {}, "gain"
        return cert, gains, status


def lure_observer_lmi(A: ArrayLike, G: ArrayLike, H: ArrayLike, C: ArrayLike, *,
                      D: ArrayLike | None = None, variant: Variant = "extended", alpha: float = 0.0,
                      kappa: float | None = None, eps: float | None = None,
                      eps_P: float | None = None, solver: str | None = None,
                      precheck: bool = True) -> LureObserverDesign:
    """Solve the observer LMIs (docs/ch08.md) at a fixed decay rate ``alpha``.

    Parameters
    ----------
    A, G, H, C : array_like
        Linear part of the plant ``x' = A x + G w``, ``z = H x + D w``, ``y = C x``.
    D : array_like, optional
        Feedthrough (``m x m``) with ``D + Dᵀ >= 0``; it does not enter the LMIs.
    variant : {"extended", "basic"}
        Free ``K`` or ``K = 0``.
    alpha : float
        Required decay rate, ``>= 0``.
    kappa : float, optional
        Bound on ``||Y||_2 = ||P L||_2``, ``> 0``.
    eps, eps_P : float, optional
        Strictness margins (default ``1e-6 max(1, ||H||_F / ||G||_F)``).
    solver : str, optional
        ``"auto"`` (default: Clarabel, then SCS with tight tolerances when Clarabel errors or
        gives no usable point) or one name of :data:`nscontrol.numerics.lmi.SDP_SOLVERS`.
    precheck : bool
        Run :func:`structural_infeasibility` first (no solver call for hopeless cases).

    Returns
    -------
    LureObserverDesign

    Raises
    ------
    InfeasibleDesignError
        No certificate (``status="structural"`` with the reason, or the solver's status).
    DimensionError, ModelError
        Wrong shapes, ``D + Dᵀ`` not PSD, negative ``kappa``/``alpha``/margins, an unknown
        or uninstalled ``solver`` (``ModelError("solver: ...")``).

    Notes
    -----
    Unknowns ``P = Pᵀ``, ``Y = P L``, ``K``::

        P >= eps_P I,   sym(Aᵀ P + P A - Cᵀ Yᵀ - Y C) + 2 α P <= -eps I,
        Gᵀ P = H - K C,   [[kappa I, Y], [Yᵀ, kappa I]] >= 0  (optional).

    The equality is eliminated: ``(P, K)`` ranges over its affine solution set (particular
    solution plus null-space basis computed by SVD), so it holds to round-off. Every returned
    point is re-checked in NumPy (:func:`recheck_lure_certificate`): equality residual
    ``<= 1e-7 max(1, ||H||_F)``, Lyapunov matrix ``<= -eps/2``, ``P >= eps_P/2``, ``A - L C``
    Hurwitz. Hypotheses of the theorem (Brogliato & Heemels 2009) not checked here:
    maximal monotonicity of ``φ`` (checked by :func:`design_lure_observer` through the law) and
    well-posedness of the plant.

    References
    ----------
    SICONOS D5.3, ch. 8 (Juloski, Heemels, Brogliato); B. Brogliato, W.P.M.H. Heemels,
    "Observer design for Lur'e systems with multivalued mappings: a passivity approach",
    IEEE TAC 54(8), 2009.

    Examples
    --------
    >>> d = lure_observer_lmi([[0, 1], [-1, 0]], [[0], [1]], [[0, 1]], [[1, 0]], alpha=0.2,
    ...                       kappa=20)
    >>> bool(d.certificate.lmi_max_eig < 0 and d.certificate.hurwitz_abscissa < 0)
    True
    """
    mat, kappa_v, eps_v, eps_P_v = _prepare(A, G, H, C, D, variant, kappa, eps, eps_P,
                                                solver)
    alpha_v = check_positive("alpha", alpha, allow_zero=True)
    if check_bool("precheck", precheck):
        _raise_structural(mat, variant)
    lmi = _ObserverLMI(mat, variant, kappa_v, eps_v, eps_P_v, solver)
    cert, gains, status = lmi.solve(alpha_v)
    if cert is None:
        raise InfeasibleDesignError(
            f"{variant} Lur'e observer: no certified solution at alpha = {alpha_v:g} (solver "
            f"status: {status}); lower alpha, raise kappa, or use the extended variant",
            status=status)
    return _design(mat, lmi, cert, gains, alpha_v, None)


def max_observer_decay_rate(A: ArrayLike, G: ArrayLike, H: ArrayLike, C: ArrayLike, *,
                            D: ArrayLike | None = None, variant: Variant = "extended",
                            kappa: float | None = None, eps: float | None = None,
                            eps_P: float | None = None, solver: str | None = None,
                            tol: float = 1e-3, precheck: bool = True,
                            max_gain: float | None = None) -> LureObserverDesign:
    """Maximise the certified decay rate by bisection; the design at ``alpha_max``.

    Parameters
    ----------
    A, G, H, C, D, variant, kappa, eps, eps_P, solver, precheck
        As in :func:`lure_observer_lmi`.
    tol : float
        Relative width of the final bracket (``hi - lo <= tol · lo``).
    max_gain : float, optional
        Count a rate as reached only when its output-injection gain has
        ``‖L‖₂ <= max_gain`` (the gain grows with the rate); default: no bound.

    Returns
    -------
    LureObserverDesign
        The certified design at ``alpha = alpha_max``, the largest rate proven feasible
        (a lower bound of the true supremum within ``tol``). It is the boundary point, with
        ``P`` near singular; simulate with a design at a fraction of it
        (:func:`design_lure_observer` does).

    Raises
    ------
    InfeasibleDesignError
        Structurally hopeless (``status="structural"``), or infeasible already at
        ``alpha = 0``.
    ModelError, DimensionError
        As in :func:`lure_observer_lmi`.

    Warns
    -----
    InaccurateCertificateWarning
        The rate is still certified at the cap ``1e4`` (unbounded without ``kappa``).

    Notes
    -----
    Feasibility of the observer LMIs is monotone in ``α`` (a certificate at ``α`` is one
    at every smaller rate), so bisection applies. The rate is a CVXPY parameter: the problem
    is compiled once. Bracket: ×4 up from 1 while feasible, or ÷4 down; then
    :func:`nscontrol.numerics.lmi.bisect_max`. An undecided solve counts as infeasible, so
    ``alpha_max`` is always a proven rate. Hypotheses of the theorem behind the rate: those of
    :func:`design_lure_observer` (maximal monotone law, ``D + Dᵀ >= 0``). Known values: the
    damped Coulomb oscillator's basic observer has ``alpha_max = c/m``; relay
    feedback measuring ``z`` is limited to 2 by the zero at ``-2``.

    References
    ----------
    SICONOS D5.3, ch. 8; S. Boyd et al., *Linear Matrix Inequalities in System and Control
    Theory*, SIAM 1994, §5.1 (decay rate).

    Examples
    --------
    Relay feedback with the multivalued input measured (``C = H``): the rate is 2.

    >>> d = max_observer_decay_rate([[0, 1], [-3, -4]], [[0], [1]], [[2, 1]], [[2, 1]],
    ...                             variant="basic", tol=1e-2)
    >>> bool(abs(d.alpha_max - 2.0) < 0.02), d.alpha == d.alpha_max
    (True, True)
    """
    mat, kappa_v, eps_v, eps_P_v = _prepare(A, G, H, C, D, variant, kappa, eps, eps_P,
                                                solver)
    tol = check_positive("tol", tol)
    if check_bool("precheck", precheck):
        _raise_structural(mat, variant)
    lmi = _ObserverLMI(mat, variant, kappa_v, eps_v, eps_P_v, solver)
    limit = None if max_gain is None else check_positive("max_gain", max_gain)
    alpha_max, cert, gains = _bisect(lmi, tol, limit)
    return _design(mat, lmi, cert, gains, alpha_max, alpha_max)


def observer_from_gains(A: ArrayLike, G: ArrayLike, H: ArrayLike, C: ArrayLike, *, L: ArrayLike,
                        P: ArrayLike, alpha: float, K: ArrayLike | None = None,
                        D: ArrayLike | None = None) -> LureObserverDesign:
    """Wrap given gains ``(L, K)`` and certificate ``(P, alpha)`` after re-checking them.

    For certificates from elsewhere, e.g. the Siconos ObserverLCS example (``L = [1, 1]ᵀ``,
    ``K = 0``, ``P = I``, ``alpha = 1``).

    Parameters
    ----------
    A, G, H, C : array_like
        Plant matrices (``n x n``, ``n x m``, ``m x n``, ``p x n``).
    L : array_like
        Output-injection gain, ``n x p``.
    P : array_like
        Storage matrix of ``V(e) = eᵀ P e``, ``n x n``.
    alpha : float
        Claimed decay rate, ``>= 0``.
    K : array_like, optional
        Map-injection gain, ``m x p`` (default 0: the basic observer).
    D : array_like, optional
        Feedthrough, ``m x m``, ``D + Dᵀ >= 0``.

    Returns
    -------
    LureObserverDesign
        With ``eps = eps_P = 0`` (no margins were requested) and ``alpha_max = None``.

    Raises
    ------
    InfeasibleDesignError
        The gains are not a strict certificate (``status="recheck_failed"``; the message
        lists every condition that fails).
    DimensionError, ModelError
        Wrong shapes, ``D + Dᵀ`` not PSD, negative ``alpha``.

    Notes
    -----
    Accepted when the certificate's inequality and equality hold with rate ``alpha`` and the
    error provably converges: ``‖Gᵀ P - (H - K C)‖_F <= 1e-7 max(1, ‖H‖_F)``, ``P ≻ 0``,
    ``λ_max(sym(A_Lᵀ P + P A_L) + 2 α P) <= 0`` and either ``alpha > 0`` or, with
    ``alpha = 0``, the Lyapunov inequality strict (``λ_max < -1e-12 ‖P‖ ‖A_L‖``, round-off
    excluded); ``A - L C`` must be Hurwitz (implied by the rest; checked as a safeguard).
    A non-strict certificate with ``alpha = 0`` only proves that ``V`` does not increase.

    References
    ----------
    The Siconos ObserverLCS example (B. Brogliato, V. Acary, O. Pérignon, 2008);
    B. Brogliato, W.P.M.H. Heemels, IEEE TAC 54(8), 2009.

    Examples
    --------
    The public certificate of the Siconos ObserverLCS example, exact with ``Q = 2I``:

    >>> d = observer_from_gains([[1, 1], [3, 1]], [[-1], [1]], [[-1, 1]], [[2, 2]],
    ...                         L=[[1], [1]], P=[[1, 0], [0, 1]], alpha=1.0, D=[[1]])
    >>> d.certificate.equality_residual, d.certificate.hurwitz_abscissa
    (0.0, -1.0)
    """
    mat = _matrices(A, G, H, C, D)
    alpha_v = check_positive("alpha", alpha, allow_zero=True)
    K = np.zeros((mat.m, mat.p)) if K is None else as_matrix("K", K, rows=mat.m, cols=mat.p)
    cert = recheck_lure_certificate(mat.A, mat.G, mat.H, mat.C, P, L, K, alpha_v)
    P_arr, L_arr = as_matrix("P", P), as_matrix("L", L)
    scale = max(1.0, float(np.linalg.norm(mat.H)))
    failures = []
    if not cert.equality_residual <= EQUALITY_RTOL * scale:
        failures.append(f"G^T P = H - K C fails (residual {cert.equality_residual:.3g} > "
                        f"{EQUALITY_RTOL * scale:.3g})")
    if not cert.P_min_eig > 0.0:
        failures.append(f"P is not positive definite (smallest eigenvalue "
                        f"{cert.P_min_eig:.3g})")
    if not cert.lmi_max_eig <= 0.0:
        failures.append(f"sym(A_L^T P + P A_L) + 2 alpha P is not negative semidefinite "
                        f"(largest eigenvalue {cert.lmi_max_eig:.3g})")
    elif alpha_v == 0.0:
        A_L = mat.A - L_arr @ mat.C
        strict = -1e-12 * max(1.0, float(np.linalg.norm(P_arr, 2) * np.linalg.norm(A_L, 2)))
        if not cert.lmi_max_eig < strict:
            failures.append(f"with alpha = 0 the Lyapunov inequality must be strict, but "
                            f"the largest eigenvalue of sym(A_L^T P + P A_L) is "
                            f"{cert.lmi_max_eig:.3g} (not < {strict:.3g}): V need not "
                            f"decrease, the error need not converge")
    if not cert.hurwitz_abscissa < 0.0:
        failures.append(f"A - L C is not Hurwitz (largest real part of its eigenvalues "
                        f"{cert.hurwitz_abscissa:.3g})")
    if failures:
        raise InfeasibleDesignError(f"observer_from_gains: the gains are not a strict "
                                    f"certificate at alpha = {alpha_v:g}: "
                                    + "; ".join(failures), status="recheck_failed")
    return LureObserverDesign(
        variant="basic" if not np.any(K) else "extended", L=L_arr, K=K,
        P=P_arr, alpha=alpha_v, alpha_max=None, kappa=None, eps=0.0, eps_P=0.0,
        certificate=cert, A=mat.A, G=mat.G, H=mat.H, C=mat.C, D=mat.D)


def _plant_matrices(plant: Any, law: Any = None) -> tuple[_Matrices, Any]:
    from ..numerics.statespace import is_state_space
    from ..systems.lure import LureSystem

    if is_state_space(plant):
        if law is None:
            raise ModelError("law: a StateSpace plant (inputs [w; u], outputs [z; y]) needs "
                             "its law to say how many inputs are multipliers: pass "
                             "law=, e.g. law=nscontrol.laws.Relay(1.0)")
        plant = LureSystem(plant, law)
    elif law is not None:
        raise ModelError("law: only for a StateSpace plant; a LureSystem holds its own law")
    if not isinstance(plant, LureSystem):
        raise ModelError(f"plant: expected a nscontrol.systems.lure.LureSystem, got "
                         f"{type(plant).__name__}; build one from a python-control StateSpace "
                         f"with LureSystem(ss, law) (or lure_from_statespace(ss, law)), or, "
                         f"for a non-monotone law "
                         f"(Stribeck friction), with loop_transformed_lure_system(A, G, H, law)")
    return _matrices(plant.A, plant.G, plant.H, plant.C, plant.D), plant.law


def design_lure_observer(plant: LureSystem | Any, *, law: SetValuedLaw | None = None,
                         variant: Variant = "extended",
                         alpha: float | Literal["max"] = "max", alpha_fraction: float = 0.5,
                         kappa: float | None = None, eps: float | None = None,
                         eps_P: float | None = None, solver: str | None = None,
                         tol: float = 1e-3, precheck: bool = True,
                         max_gain: float | Literal["auto"] | None = "auto"
                         ) -> LureObserverDesign:
    """Design a passivity-based observer for a Lur'e plant with a maximal monotone law.

    Parameters
    ----------
    plant : LureSystem
        ``x' = A x + G w + B u``, ``z = H x + D w + g(t)``, ``w ∈ -φ(z)``, ``y = C x``
        (a :class:`LureSystem` holds only maximal monotone laws), or a python-control
        ``StateSpace`` with inputs ``[w; u]`` and outputs ``[z; y]`` together with ``law``
        (as ``LureSystem(ss, law)``); a non-monotone law
        (Stribeck friction) through :func:`loop_transformed_lure_system`, which builds the
        split ``φ = φ_m - σ I`` from the law itself (the loop transformation of docs/ch08.md).
    law : SetValuedLaw, optional
        The plant's law, with a ``StateSpace`` plant only.
    variant : {"extended", "basic"}
        Output injection ``K`` into the set-valued map, or ``K = 0``.
    alpha : float or "max"
        Required decay rate; ``"max"`` bisects for the largest certified rate ``alpha_max``
        whose gain stays within ``max_gain`` and designs at ``alpha_fraction * alpha_max``
        (bisection drives ``P`` towards singularity; a fraction keeps margins comfortable).
    alpha_fraction : float in (0, 1]
        See ``alpha``.
    kappa : float, optional
        Bound on ``||P L||_2`` (without it the extended observer's rate may be unbounded).
    eps, eps_P, solver, tol, precheck
        As in :func:`lure_observer_lmi` and :func:`max_observer_decay_rate`.
    max_gain : float, "auto" or None
        Bound on ``‖L‖₂`` while ``alpha="max"`` searches the rate. ``"auto"`` (default):
        ``GAIN_MULTIPLE · max(1, ‖A‖₂)`` (``GAIN_MULTIPLE = 25``) when no ``kappa`` is given,
        none otherwise; ``None``: no bound (the extended observer's rate is then limited only
        by the cap ``1e4``, with gains to match). A design at a given ``alpha`` whose
        ``‖L‖₂`` exceeds the bound warns.

    Returns
    -------
    LureObserverDesign
        Gains, certificate and :meth:`~LureObserverDesign.closed_loop`.

    Raises
    ------
    InfeasibleDesignError
        Structurally hopeless (``status="structural"``, no solver called) or no certificate.
    ModelError
        ``plant`` not a :class:`LureSystem`, bad ``alpha``/``alpha_fraction``/``kappa``,
        unknown ``solver``...

    Notes
    -----
    Theorem (Brogliato & Heemels 2009): if ``φ`` is maximal monotone, ``D + Dᵀ >= 0``, and
    ``P > 0``, ``L``, ``K`` satisfy ``(A - LC)ᵀP + P(A - LC) <= -2αP - εI`` and
    ``GᵀP = H - KC``, then for every plant solution, input and observer initial state
    ``V(t) = eᵀPe <= exp(-2αt) V(0)``; with implicit Euler on plant and observer together
    ``V_{k+1} <= V_k / (1 + 2αh)``. Checked here:
    monotonicity of the law and ``D + Dᵀ >= 0`` (by :class:`LureSystem` at construction), the
    LMIs (re-checked in NumPy). Not checked: existence of plant solutions (the plant may be
    unstable) and a constraint qualification (the domain of ``φ`` reached with margin) for laws
    with a bounded domain.

    References
    ----------
    SICONOS D5.3, ch. 8; B. Brogliato, W.P.M.H. Heemels, IEEE TAC 54(8):1996–2001, 2009;
    M. Arcak, P. Kokotović, Automatica 37, 2001 (single-valued case).

    Examples
    --------
    A damped oscillator with Coulomb friction, position measured: the basic
    observer's best rate is ``c/m``.

    >>> from nscontrol.laws.set_valued import Relay
    >>> from nscontrol.systems.lure import LureSystem
    >>> plant = LureSystem([[0, 1], [-1, -0.1]], [[0], [1]], [[0, 1]], Relay(1.0),
    ...                    C=[[1, 0]])
    >>> d = design_lure_observer(plant, variant="basic", tol=1e-2)
    >>> bool(abs(d.alpha_max - 0.1) < 0.002), d.alpha == d.alpha_max / 2
    (True, True)
    """
    mat, _ = _plant_matrices(plant, law)  # a LureSystem: its law is maximal monotone
    frac = check_in_interval("alpha_fraction", alpha_fraction, 0.0, 1.0)
    if frac == 0.0:
        raise ModelError("alpha_fraction: expected a value in (0, 1], got 0; a zero rate "
                         "gives no convergence guarantee: pass e.g. 0.5")
    kwargs: dict[str, Any] = {"D": mat.D, "variant": variant, "kappa": kappa, "eps": eps,
                              "eps_P": eps_P, "solver": solver, "precheck": precheck}
    rule = GAIN_MULTIPLE * max(1.0, float(np.linalg.norm(mat.A, 2)))
    limit = _gain_bound(max_gain, rule, kappa)
    if isinstance(alpha, str):
        if alpha != "max":
            raise ModelError(f"alpha: expected a rate >= 0 or 'max', got {alpha!r}")
        best = max_observer_decay_rate(mat.A, mat.G, mat.H, mat.C, tol=tol, max_gain=limit,
                                       **kwargs)
        design = lure_observer_lmi(mat.A, mat.G, mat.H, mat.C, alpha=frac * best.alpha, **kwargs)
        alpha_max: float | None = best.alpha
    else:
        design = lure_observer_lmi(mat.A, mat.G, mat.H, mat.C, alpha=alpha, **kwargs)
        alpha_max = None
    from dataclasses import replace

    design = replace(design, alpha_max=alpha_max, gain_limit=limit)
    gain = float(np.linalg.norm(design.L, 2))
    if limit is not None and gain > limit:   # a given alpha beyond the rule's bound
        from ..errors import NscontrolWarning

        warnings.warn(f"L: ‖L‖₂ = {gain:.3g} exceeds {GAIN_MULTIPLE:g}·max(1, ‖A‖₂) = "
                      f"{rule:.3g}: the observer amplifies measurement noise as much; pass a "
                      f"smaller alpha, a kappa, or alpha='max' with max_gain='auto'",
                      NscontrolWarning, stacklevel=2)
    return design


def _gain_bound(max_gain: Any, rule: float, kappa: Any) -> float | None:
    """The bound on ``‖L‖₂`` of the rate search (see :func:`design_lure_observer`)."""
    if isinstance(max_gain, str):
        if max_gain != "auto":
            raise ModelError(f"max_gain: expected a positive number, 'auto' or None, got "
                             f"{max_gain!r}")
        return rule if kappa is None else None
    return None if max_gain is None else check_positive("max_gain", max_gain)


# -- closed loop ---------------------------------------------------------------------------
def _check_same_plant(design: LureObserverDesign, mat: _Matrices) -> None:
    for name in ("A", "G", "H", "C", "D"):
        if not np.allclose(getattr(mat, name), getattr(design, name), rtol=1e-12, atol=1e-12):
            raise ModelError(f"plant: its {name} differs from the one the observer was designed "
                             f"for; design for this plant (for a loop-transformed law pass the "
                             f"transformed plant)")


def _closed_loop(design: LureObserverDesign, plant: LureSystem) -> ClosedLoop:
    from ..systems.closed_loop import closed_loop

    return closed_loop(plant, observer=design.observer(plant))


def _observer_block(design: LureObserverDesign, plant: LureSystem) -> LinearObserver:
    from ..systems.feedback import LinearObserver

    mat, law = _plant_matrices(plant)
    _check_same_plant(design, mat)
    n = mat.n
    names = (tuple(f"{s}_hat" for s in plant.state_names) if plant.state_names
             else tuple(f"xhat{i + 1}" for i in range(n)))
    B = plant.B if getattr(plant, "B", None) is not None else None
    return LinearObserver(design.A_L, design.L, B=B, law=law, G=mat.G,
                          H=mat.H - design.K @ mat.C, K=design.K, D=mat.D, names=names)


def _observer_system(design: LureObserverDesign, plant: LureSystem, y: InputFunction
                     ) -> LureSystem:
    from ..systems.lure import LureSystem

    mat, law = _plant_matrices(plant)
    _check_same_plant(design, mat)
    if not callable(y):
        raise ModelError(f"y: expected a function of time returning the measured output, got "
                         f"{type(y).__name__}")
    p, n = mat.p, mat.n
    q = plant.n_inputs if getattr(plant, "B", None) is not None else 0

    # y is called on an array of times first (a vectorised y answers at once), then, when
    # the shape says it is not vectorised, once per time
    y_vectorised = cast(Callable[[FloatArray], ArrayLike], y)

    def y_of(t: ArrayLike) -> FloatArray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.asarray(y_vectorised(t), dtype=float)
        if out.shape != (t.size, p):
            out = np.array([np.ravel(y(float(s))) for s in t]).reshape(t.size, p)
        return out

    def inputs(t: ArrayLike) -> FloatArray:
        u = plant.input_at(t) if q else np.zeros((np.size(t), 0))
        return np.hstack([u, y_of(t)])

    def shift(t: ArrayLike) -> FloatArray:
        return y_of(t) @ design.K.T + plant.shift_at(t)

    B = np.hstack([plant.B if plant.B is not None and q else np.zeros((n, 0)), design.L])
    names = tuple(f"{s}_hat" for s in (plant.state_names or
                                       tuple(f"x{i}" for i in range(n))))
    return LureSystem(design.A_L, mat.G, mat.H - design.K @ mat.C, law, B=B, C=np.eye(n),
                      D=mat.D if np.any(mat.D) else None, u=inputs, g=shift,
                      state_names=names)


def loop_transformed_lure_system(A: ArrayLike, G: ArrayLike, H: ArrayLike, law: SetValuedLaw, *,
                                 sigma: ArrayLike | None = None, B: ArrayLike | None = None,
                                 C: ArrayLike | None = None, D: ArrayLike | None = None,
                                 u: InputSignal = None, g: InputSignal = None,
                                 state_names: tuple[str, ...] = ()) -> LureSystem:
    """A :class:`LureSystem` for a non-monotone law through the loop transformation (§2.6).

    ``φ = φ_m - diag(σ)`` with ``φ_m`` maximal monotone gives ``x' = (A + G diag(σ) H) x +
    G w_m``, ``w_m ∈ -φ_m(z)`` (``D = 0``): the same trajectories, a monotone law. The split
    is the law's own (``law.loop_transformation(sigma)``), so the transformed system always
    describes the plant with ``law``.

    Parameters
    ----------
    A, G, H : array_like
        Linear part with the original law (``n x n``, ``n x m``, ``m x n``).
    law : SetValuedLaw
        The (possibly non-monotone) law, e.g. ``Stribeck``.
    sigma : float or array_like, optional
        Slopes to use, one per component; the law checks that ``φ + diag(σ)`` is monotone
        (for Stribeck friction ``σ >= sigma_tan``). Default: the law's own bound, the
        smallest slope that works (zero for a monotone law).
    B, C, u, g, state_names
        As in :class:`LureSystem`.
    D : array_like, optional
        Must be absent or zero: with a feedthrough the transformation also changes ``D``.

    Returns
    -------
    LureSystem
        ``(A + G diag(σ) H, G, H)`` with the monotone part ``φ + diag(σ)`` as its law.

    Raises
    ------
    ModelError
        ``law`` is not a set-valued law; ``sigma`` too small (``law − σ`` would not be made
        monotone) or non-zero for a law that is monotone already; a non-zero ``D``.

    Notes
    -----
    Hypothesis: ``φ + diag(σ)`` maximal monotone, i.e. the negative slope of ``φ`` is bounded
    by ``σ`` (Stribeck with ``delta >= 1``; ``delta < 1`` has an unbounded slope at 0 and is
    refused). With ``w = w_m + diag(σ) z`` and ``z = H x`` the substitution is exact: the
    transformed system has the same solutions. The extra ``G σ H`` acts as negative damping;
    observers for it usually need the extended variant.

    References
    ----------
    A. Doris et al., IEEE TCST 16(6), 2008 (rotor with non-monotone friction); chapter 7's
    friction model for ``sigma_tan`` (docs/ch07.md).

    Examples
    --------
    The two-inertia rotor, Stribeck friction on the lower disc (``J_l = 0.05``):

    >>> from nscontrol.laws.set_valued import Stribeck
    >>> law = Stribeck(static=0.3, coulomb=0.1, stribeck_velocity=1.0, delta=2.0,
    ...                viscous=0.01)
    >>> A = [[0, 1, -1], [-0.16, -4, 0], [1.6, 0, 0]]
    >>> plant = loop_transformed_lure_system(A, [[0], [0], [20]], [[0, 0, 1]], law,
    ...                                      C=[[1, 0, 0]])
    >>> round(float(plant.A[2, 2]), 4), plant.law.monotone   # sigma_tan / J_l
    (3.2311, True)
    >>> loop_transformed_lure_system(A, [[0], [0], [20]], [[0, 0, 1]], law, sigma=0.1)
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    nscontrol.errors.ModelError: sigma: expected sigma >= sigma_tan = ...
    """
    from ..laws.set_valued import SetValuedLaw, require_monotone
    from ..systems.lure import LureSystem

    if not isinstance(law, SetValuedLaw):
        raise ModelError(f"law: expected a SetValuedLaw from nscontrol.laws, got "
                         f"{type(law).__name__}")
    if D is not None and np.any(np.asarray(D, dtype=float)):
        raise ModelError("D: the loop transformation is implemented for D = 0 only (with a "
                         "feedthrough it changes D too), got a non-zero D")
    lt = law.loop_transformation(sigma)  # validates sigma against the law's own slope bound
    part = require_monotone(law, who="loop_transformed_lure_system", loop_transformation=lt)
    return LureSystem(lt.transform_A(A, G, H), G, H, part, B=B, C=C, u=u, g=g,
                      state_names=state_names)


def lure_from_statespace(ss: Any, law: SetValuedLaw, *, u: InputSignal = None,
                         g: InputSignal = None) -> LureSystem:
    """A :class:`LureSystem` from a python-control ``StateSpace`` and a law.

    The ``StateSpace`` has inputs ``[w; u]`` (the first ``m = law.dim`` are the multipliers)
    and outputs ``[z; y]`` (the first ``m`` feed the law, the rest are measured), i.e.
    ``B_ss = [G, B]``, ``C_ss = [H; C]``, ``D_ss = [[D, 0], [0, 0]]``. The same as
    ``LureSystem(ss, law, u=u, g=g)``; a model with only the ``m`` outputs ``z`` measures the
    whole state.

    Parameters
    ----------
    ss : control.StateSpace
        Continuous-time linear part (``dt = 0``).
    law : SetValuedLaw
        Maximal monotone law of dimension ``m``.
    u : callable or array_like, optional
        External input for the inputs after the first ``m`` (requires such inputs).
    g : callable or array_like, optional
        Known shift of the law's argument, ``z = H x + D w + g(t)``.

    Returns
    -------
    LureSystem

    Raises
    ------
    ModelError
        Not a state-space object, discrete-time system, feedthrough from ``u`` or into ``y``
        (not in the model), or ``u`` given while the system has no input besides ``w``.
    DimensionError
        Fewer inputs or outputs than ``m``.

    Notes
    -----
    Hypotheses of the model (checked by :class:`LureSystem`): ``law`` maximal monotone and
    ``D + Dᵀ >= 0``. A non-monotone law must be loop-transformed first
    (:func:`loop_transformed_lure_system` on the matrices).

    References
    ----------
    SICONOS D5.3, ch. 8 (the system class); python-control ``StateSpace``
    (R. M. Murray et al., python-control documentation).

    Examples
    --------
    The damped Coulomb oscillator, inputs ``[w; u]``, outputs ``[z; y] = [q'; q]``:

    >>> import control
    >>> from nscontrol.laws.set_valued import Relay
    >>> ss = control.ss([[0, 1], [-1, -0.1]], [[0, 0], [1, 1]], [[0, 1], [1, 0]], 0)
    >>> plant = lure_from_statespace(ss, Relay(1.0), u=lambda t: 2 * np.sin(t))
    >>> plant.G.ravel().tolist(), plant.B.ravel().tolist(), plant.C.tolist()
    ([0.0, 1.0], [0.0, 1.0], [[1.0, 0.0]])
    """
    from ..numerics.statespace import is_state_space
    from ..systems.lure import LureSystem

    if not is_state_space(ss):
        raise ModelError(f"ss: expected a python-control StateSpace, got {type(ss).__name__}")
    return LureSystem(ss, law=law, u=u, g=g)
