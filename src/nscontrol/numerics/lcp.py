"""Linear complementarity problems: ``w = M z + q,  0 <= z ⟂ w >= 0``.

One verb, :func:`solve_lcp`, with four methods:

- ``"lemke"``: Lemke's complementary pivoting with lexicographic anti-cycling (dense, O(n^2)
  per pivot). Exact up to round-off; terminates on degenerate problems; a ray termination
  means "no solution" for copositive-plus ``M`` (e.g. positive semidefinite).
- ``"pgs"``: projected Gauss–Seidel / SOR, for symmetric positive semidefinite ``M``;
  iterative (stops on the residual ``tol``), warm-startable with ``z0``.
- ``"banded"``: Howard's policy iteration (semismooth Newton on ``min(z, Mz + q) = 0``) with
  direct solves on the active set: O(n) per iteration for tridiagonal ``M`` (Thomas sweeps,
  numba, started from two projected Thomas sweeps) and sparse LU for other sparse/banded
  ``M``. Exact in at most ``n`` iterations for M-matrices such as the Delassus matrix of a
  chain or stack of contacts (so O(n^2) in the worst case; see ``docs/lcp.md``).
- ``"auto"``: banded for sparse or banded ``M``, Lemke for small or general ``M``, PGS for
  large symmetric ``M`` that turns out positive semidefinite; the residual is verified and
  Lemke is the fallback.

The numba kernels behind the methods live in :mod:`nscontrol.numerics._lcp_kernels` and can
be called from other ``@njit`` code. See ``docs/lcp.md`` for the algorithms and figures.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .._validation import (
    as_float_array,
    as_square,
    as_vector,
    check_finite,
    check_in_interval,
    check_integer,
    check_positive,
)
from ..errors import DimensionError, ModelError, SolverError
from . import _lcp_kernels as kernels

__all__ = ["LCPResult", "solve_lcp", "residual"]

Method = Literal["auto", "lemke", "pgs", "banded"]
METHODS = ("auto", "lemke", "pgs", "banded")
STATUSES = ("solved", "ray_termination", "max_iter", "numerical_failure")

#: ``auto`` uses PGS instead of Lemke for symmetric PSD problems larger than this.
AUTO_PGS_MIN_SIZE = 400
#: ``auto`` does not fall back to dense Lemke above this size (memory n^2, time n^3).
AUTO_LEMKE_MAX_SIZE = 3000
#: Sweeps of ``auto``'s PGS before it pays for a definiteness test (see ``_run_pgs_auto``).
AUTO_PGS_PROBE_SWEEPS = 100
#: ``auto`` tries ``banded`` first on dense matrices this large with a narrow band.
AUTO_BANDED_MIN_SIZE = 64


@dataclass(frozen=True)
class LCPResult:
    """Outcome of :func:`solve_lcp`.

    Attributes
    ----------
    z, w : ndarray, shape (n,)
        The computed point and ``w = M z + q`` (recomputed from ``z``, never taken on trust).
        On failure: the last iterate of the method that ran last.
    status : {"solved", "ray_termination", "max_iter", "numerical_failure"}
        ``"solved"`` only when :attr:`residual` passed the acceptance test (see
        :func:`solve_lcp`). ``"ray_termination"``: Lemke found no solution (for
        copositive-plus ``M`` the LCP is infeasible).
    iterations : int
        Pivots (Lemke), sweeps (PGS) or active-set iterations (banded) of the last method.
    residual : float
        ``max_i |min(z_i, w_i)| / (1 + max|q|)``: zero exactly at a solution; it counts
        negative entries of ``z`` or ``w`` in full.
    method : str
        The method that produced ``z`` (for ``"auto"``: the one finally used).
    message : str
        Why it stopped, and which methods were tried.
    """

    z: NDArray[np.float64]
    w: NDArray[np.float64]
    status: str
    iterations: int
    residual: float
    method: str
    message: str = field(default="")

    @property
    def success(self) -> bool:
        """True when ``status == "solved"``."""
        return self.status == "solved"


def residual(M: Any, z: Any, q: Any) -> float:
    """Relative natural residual ``max_i |min(z_i, (Mz + q)_i)| / (1 + max|q|)`` of a point.

    Works for dense and scipy.sparse ``M``; zero exactly at solutions of LCP(M, q).
    """
    z = np.asarray(z, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    return _natural_residual(z, np.asarray(M @ z + q, dtype=np.float64).ravel(), q)


def solve_lcp(M: Any, q: Any, *, method: Method = "auto", tol: float = 1e-12,
              max_iter: int | None = None, strict: bool = False, z0: Any = None,
              omega: float = 1.0) -> LCPResult:
    """Solve the linear complementarity problem ``w = M z + q, 0 <= z ⟂ w >= 0``.

    Parameters
    ----------
    M : (n, n) array_like or scipy.sparse matrix
        Finite square matrix. Sparse input is kept sparse by ``"banded"`` (where ``"auto"``
        sends it first) and densified by ``"lemke"`` and ``"pgs"``.
    q : (n,) array_like
        Finite vector.
    method : {"auto", "lemke", "pgs", "banded"}
        See the module docstring; ``"auto"`` picks and verifies (Notes).
    tol : float
        Acceptance threshold on :attr:`LCPResult.residual` (and PGS's stopping criterion).
        A direct method's result is accepted when its residual is below ``tol`` or below the
        round-off floor ``64 eps (||M||_inf ||z||_inf + ||q||_inf) / (1 + ||q||_inf)`` of
        evaluating ``M z + q``.
    max_iter : int, optional
        Iteration limit of the chosen method. Defaults: Lemke ``50 (n + 1)`` pivots, PGS
        ``10000`` sweeps, banded ``n + 2`` iterations.
    strict : bool
        Raise :class:`~nscontrol.errors.SolverError` instead of returning a failed result.
    z0 : (n,) array_like, optional
        Starting point for ``"pgs"`` and ``"banded"`` (warm start); Lemke ignores it.
    omega : float
        PGS relaxation factor in ``(0, 2)``; ``1`` is plain Gauss–Seidel.

    Returns
    -------
    LCPResult

    Raises
    ------
    DimensionError
        ``M`` not square, or ``q`` / ``z0`` of the wrong length.
    ModelError
        NaN, infinite or complex entries, unknown ``method``, ``tol`` not a finite number
        ``> 0``, ``omega`` outside (0, 2), ``max_iter`` not an integer ``>= 1`` (``2.7`` is
        refused, not truncated).
    SolverError
        With ``strict=True``, when no method reached a verified solution (``err.status``).

    Notes
    -----
    ``"auto"``: for ``n > 2``, tridiagonal ``M`` (dense or sparse), any other scipy.sparse
    ``M`` and dense ``M`` with ``n >= 64`` and half-bandwidth ``<= sqrt(n)`` → ``"banded"``;
    otherwise symmetric ``M`` with a positive diagonal and ``n > 400`` → ``"pgs"``, which
    gets 100 sweeps before ``M`` is tested for positive semidefiniteness (diagonal dominance,
    else a Cholesky factorisation of ``M + 1e-12 max|M| I``) and continues only if it
    passes; otherwise ``"lemke"``. When a choice fails (status or residual) the next one
    runs: after ``"banded"``, PGS under the same conditions, then Lemke on the dense matrix
    if ``n <= 3000``. A result is never marked solved without passing the residual test.

    Lemke is guaranteed to find a solution for P-matrices (unique solution) and, for
    copositive-plus ``M``, ends in a ray only when the LCP is infeasible. PGS converges for
    symmetric PSD ``M`` with positive diagonal. Banded is exact for M-matrices (e.g. the
    Delassus matrix of a stack); elsewhere it may stop with ``"max_iter"``.

    References
    ----------
    R. W. Cottle, J.-S. Pang, R. E. Stone, *The Linear Complementarity Problem*, Academic
    Press, 1992 (§4.4 Lemke, §5.2 PGS). O. Bokanowski, S. Maroso, H. Zidani, SIAM J. Numer.
    Anal. 47(4), 2009 (Howard's algorithm).

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.numerics.lcp import solve_lcp
    >>> res = solve_lcp(np.array([[2.0, 1.0], [1.0, 2.0]]), np.array([-5.0, -6.0]))
    >>> res.status, np.round(res.z, 12).tolist()
    ('solved', [1.333333333333, 2.333333333333])
    """
    if not isinstance(method, str) or method not in METHODS:
        raise ModelError(f"method: expected one of {list(METHODS)}, got {method!r}")
    tol = check_positive("tol", tol)
    omega = check_in_interval("omega", omega, 0.0, 2.0, open_interval=True)
    if max_iter is not None:
        max_iter = check_integer("max_iter", max_iter, minimum=1)
    problem = _Problem.build(M, q, z0)
    chain = _method_chain(problem, method)
    tried: list[str] = []
    result: LCPResult | None = None
    for name in chain:
        result = _RUNNERS[name](problem, tol, max_iter, omega)
        tried.append(f"{result.method}: {result.status} (residual {result.residual:.3g})")
        if result.success:
            break
    assert result is not None
    result = LCPResult(result.z, result.w, result.status, result.iterations, result.residual,
                       result.method, "; ".join(tried))
    if strict and not result.success:
        raise SolverError(f"solve_lcp: no verified solution of the LCP of size {problem.n} "
                          f"({result.message}); check that M is a P-matrix or copositive-plus, "
                          f"raise max_iter, or try another method", status=result.status)
    return result


# ----------------------------------------------------------------------------- problem


@dataclass(frozen=True)
class _Problem:
    """Validated input, with the structure ``auto`` dispatches on computed once."""

    M: Any  # dense ndarray or scipy.sparse matrix (CSR)
    q: NDArray[np.float64]
    z0: NDArray[np.float64] | None
    bands: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None

    @property
    def n(self) -> int:
        return self.q.shape[0]

    @property
    def sparse(self) -> bool:
        return not isinstance(self.M, np.ndarray)

    def dense(self) -> NDArray[np.float64]:
        return self.M if isinstance(self.M, np.ndarray) else np.asarray(self.M.toarray())

    @classmethod
    def build(cls, M: Any, q: Any, z0: Any) -> _Problem:
        if not _clean(q, 1):
            q = as_vector("q", q)
        M = _as_lcp_matrix(M)
        if M.shape[0] != q.shape[0]:
            raise DimensionError(f"q: expected a vector of length {M.shape[0]} (the size of "
                                 f"M), got length {q.shape[0]}")
        z0v = None if z0 is None else as_vector("z0", z0, size=q.shape[0])
        return cls(M, q, z0v, _tridiagonal_bands(M))


def _as_lcp_matrix(M: Any) -> Any:
    """A finite square dense float array, or a finite square scipy.sparse CSR matrix."""
    if hasattr(M, "tocsr") and not isinstance(M, np.ndarray):
        csr = M.tocsr()
        if csr.dtype != np.float64:
            if csr.dtype.kind not in "fiub":
                raise ModelError(f"M: expected a real sparse matrix, got dtype {csr.dtype}")
            csr = csr.astype(np.float64)
        if csr.ndim != 2 or csr.shape[0] != csr.shape[1]:
            raise DimensionError(f"M: expected a square matrix, got shape {csr.shape}")
        check_finite("M", csr.data)
        return csr
    if _clean(M, 2) and M.shape[0] == M.shape[1]:
        return M
    if np.ndim(M) == 0:  # a scalar is a 1x1 LCP
        M = np.reshape(as_float_array("M", M), (1, 1))
    return np.ascontiguousarray(as_square("M", M))


def _clean(a: Any, ndim: int) -> bool:
    """Fast path: already a C-contiguous finite float64 array of rank ``ndim`` (the checks of
    ``nscontrol._validation`` run otherwise, and raise their specific errors)."""
    return (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == ndim
            and a.flags.c_contiguous and bool(kernels.all_finite(a.reshape(-1))))


def _tridiagonal_bands(M: Any) -> tuple[NDArray[np.float64], ...] | None:
    """``(lower, diag, upper)`` when ``M`` is tridiagonal (no entry beyond the first
    off-diagonals), else None."""
    if isinstance(M, np.ndarray):
        if not kernels.is_tridiagonal(M):
            return None
        return (np.ascontiguousarray(np.diagonal(M, -1)), np.ascontiguousarray(np.diagonal(M)),
                np.ascontiguousarray(np.diagonal(M, 1)))
    n = M.shape[0]
    lower, diag, upper = np.empty(max(n - 1, 0)), np.empty(n), np.empty(max(n - 1, 0))
    if not kernels.csr_tridiagonal_bands(M.indptr, M.indices, M.data, lower, diag, upper):
        return None
    return lower, diag, upper


def _method_chain(problem: _Problem, method: str) -> Iterator[str]:
    """The methods to try in order (``auto``'s fallbacks are decided only when reached)."""
    if method != "auto":
        yield method
        return
    n = problem.n

    def large_symmetric() -> bool:    # densifies sparse M: only evaluated when reached
        return n > AUTO_PGS_MIN_SIZE and _symmetric_positive_diagonal(problem)

    if n > 2 and (problem.bands is not None or problem.sparse or _is_banded(problem)):
        yield "banded"
        if large_symmetric():
            yield "pgs_auto"
    elif large_symmetric():
        yield "pgs_auto"
    else:
        yield "lemke"
        return
    if n <= AUTO_LEMKE_MAX_SIZE:
        yield "lemke"


def _symmetric_positive_diagonal(problem: _Problem) -> bool:
    M = problem.dense()
    scale = max(float(np.max(np.abs(M), initial=0.0)), 1.0)
    return bool(np.all(np.diagonal(M) > 0.0) and kernels.is_symmetric(M, 1e-12 * scale))


def _is_banded(problem: _Problem) -> bool:
    """Dense ``M`` with a narrow band (half-bandwidth ``<= sqrt(n)``, ``n >= 64``): worth
    Howard's iteration with sparse LU (O(n b^2) per step) before dense pivoting."""
    n = problem.n
    if problem.sparse or n < AUTO_BANDED_MIN_SIZE:
        return False
    limit = max(2, int(np.sqrt(n)))
    return bool(kernels.half_bandwidth(problem.M, limit) <= limit)


def _symmetric_psd(problem: _Problem) -> bool:
    """Symmetric (to 1e-12 relative) and positive semidefinite, tested without eigenvalues:
    a diagonally dominant matrix with a nonnegative diagonal is PSD (Gershgorin), otherwise
    an attempted Cholesky factorisation of ``M + tiny I`` decides (``tiny`` = 1e-12 relative,
    above the round-off of the factorisation). The residual test after the solve keeps a
    borderline answer honest."""
    M = problem.dense()
    n = problem.n
    scale = max(float(np.max(np.abs(M), initial=0.0)), 1.0)
    if not kernels.is_symmetric(M, 1e-12 * scale):
        return False
    if kernels.nonnegative_diagonally_dominant(M):
        return True
    tiny = max(1e-12, 8.0 * n * np.finfo(np.float64).eps) * scale
    try:
        np.linalg.cholesky(M + tiny * np.eye(n))
    except np.linalg.LinAlgError:
        return False
    return True


# ----------------------------------------------------------------------------- runners


def _run_lemke(problem: _Problem, tol: float, max_iter: int | None, omega: float) -> LCPResult:
    M = problem.dense()
    n = problem.n
    z = np.zeros(n)
    w = np.empty(n)
    code, its = kernels.lemke_kernel(M, problem.q, z, w, int(max_iter or 0))
    return _result(problem, z, code, its, "lemke", tol)


def _run_pgs(problem: _Problem, tol: float, max_iter: int | None, omega: float) -> LCPResult:
    M = problem.dense()
    n = problem.n
    z = np.zeros(n) if problem.z0 is None else np.maximum(problem.z0, 0.0)
    w = np.empty(n)
    code, its = kernels.pgs_kernel(M, problem.q, z, w, float(tol), int(max_iter or 10_000),
                                   float(omega))
    if code in (kernels.SOLVED, kernels.MAX_ITER):
        polished = _polish(M, problem.q, z, w)
        if polished is not None:
            return _result(problem, polished, kernels.SOLVED, its, "pgs", tol)
    return _result(problem, z, code, its, "pgs", tol)


def _polish(M: NDArray[np.float64], q: NDArray[np.float64], z: NDArray[np.float64],
            w: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """Direct solve on the active set an iterate has identified, if that solves the LCP.

    PGS converges linearly, and its error in ``z`` is up to ``residual / lambda_min(M)``;
    once the active set ``{z_i > w_i}`` is right, one solve of ``M[a, a] z_a = -q_a`` gives
    the solution to round-off. Returns None when the polished point is not better.
    """
    active = np.flatnonzero(z > w)
    polished = np.zeros_like(z)
    if active.size:
        try:
            polished[active] = np.linalg.solve(M[np.ix_(active, active)], -q[active])
        except np.linalg.LinAlgError:
            return None
    before = _natural_residual(z, M @ z + q, q)
    after = _natural_residual(polished, M @ polished + q, q)
    return polished if np.isfinite(after) and after < before else None


def _run_banded(problem: _Problem, tol: float, max_iter: int | None, omega: float) -> LCPResult:
    n = problem.n
    limit = int(max_iter or n + 2)
    z = np.zeros(n) if problem.z0 is None else problem.z0.copy()
    if problem.bands is not None:
        lower, diag, upper = problem.bands
        w = np.empty(n)
        if problem.z0 is None:    # start from the projected Thomas sweeps
            code, its = kernels.tridiagonal_lcp_kernel(lower, diag, upper, problem.q, z, w,
                                                       limit)
        else:
            code, its = kernels.tridiagonal_howard(lower, diag, upper, problem.q, z, w, limit)
    else:
        code, its, z = _sparse_howard(problem, z, limit)
    return _result(problem, z, code, its, "banded", tol)


def _sparse_howard(problem: _Problem, z: NDArray[np.float64], limit: int
                   ) -> tuple[int, int, NDArray[np.float64]]:
    """Howard's policy iteration with sparse LU on the active set (non-tridiagonal M).

    The same iteration as :func:`~nscontrol.numerics._lcp_kernels.tridiagonal_howard`;
    each step factors ``M[a, a]`` with SuperLU, so banded ``M`` costs O(n b^2) per step.
    The next iterate depends only on the active set, so a repeated active set is a cycle:
    it stops at once with ``"max_iter"`` (instead of running to the limit) and ``auto`` falls
    back to the next method.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    M = sp.csc_matrix(problem.M)
    q = problem.q
    eps = 1e-13 * (1.0 + float(np.max(np.abs(q), initial=0.0)))
    w = M @ z + q
    seen: set[bytes] = set()
    for it in range(limit + 1):
        if np.all(z >= -eps) and np.all(w >= -eps) and np.all(np.minimum(z, w) <= eps):
            return kernels.SOLVED, it, z
        if it == limit:
            break
        active = w <= z
        key = np.packbits(active).tobytes()
        if key in seen:                      # Howard's iteration is cycling
            return kernels.MAX_ITER, it, z
        seen.add(key)
        z = np.zeros_like(z)
        idx = np.flatnonzero(active)
        if idx.size:
            try:
                z_a = splu(M[idx][:, idx].tocsc()).solve(-q[idx])
            except RuntimeError:  # singular principal block
                return kernels.NUMERICAL_FAILURE, it + 1, z
            z[idx] = z_a
        w = M @ z + q
        if not np.all(np.isfinite(z)):
            return kernels.NUMERICAL_FAILURE, it + 1, z
    return kernels.MAX_ITER, limit, z


def _run_pgs_auto(problem: _Problem, tol: float, max_iter: int | None,
                  omega: float) -> LCPResult:
    """``auto``'s PGS: a probe of :data:`AUTO_PGS_PROBE_SWEEPS` sweeps first (a
    well-conditioned problem is solved there, and no definiteness test is paid); only if it
    has not converged is ``M`` tested for positive semidefiniteness (:func:`_symmetric_psd`,
    a Cholesky factorisation), and PGS continues from the probe's iterate for PSD ``M`` only
    (where it converges). Otherwise the probe's failure hands over to Lemke."""
    total = int(max_iter or 10_000)
    probe = min(AUTO_PGS_PROBE_SWEEPS, total)
    first = _run_pgs(problem, tol, probe, omega)
    if first.success or probe == total or not _symmetric_psd(problem):
        return first
    rest = _run_pgs(replace(problem, z0=np.array(first.z)), tol, total - probe, omega)
    return replace(rest, iterations=probe + rest.iterations)


_RUNNERS = {"lemke": _run_lemke, "pgs": _run_pgs, "banded": _run_banded,
            "pgs_auto": _run_pgs_auto}


# ----------------------------------------------------------------------------- verification


def _natural_residual(z: NDArray[np.float64], w: NDArray[np.float64],
                      q: NDArray[np.float64]) -> float:
    if z.size == 0:
        return 0.0
    return float(kernels.natural_residual(z, w, q))


def _verify(problem: _Problem, z: NDArray[np.float64]) -> tuple[NDArray[np.float64], float,
                                                                 float]:
    """``w = M z + q`` recomputed, the residual and the round-off floor (see solve_lcp)."""
    w = np.empty_like(z)
    if problem.n == 0:
        return w, 0.0, 0.0
    if problem.bands is not None:
        lower, diag, upper = problem.bands
        res, floor = kernels.verify_tridiagonal(lower, diag, upper, problem.q, z, w)
    elif isinstance(problem.M, np.ndarray):
        res, floor = kernels.verify_dense(problem.M, problem.q, z, w)
    else:
        w = np.asarray(problem.M @ z + problem.q, dtype=np.float64)
        row_sum_max = float(np.asarray(abs(problem.M).sum(axis=1)).max())
        res, floor = kernels._residual_and_floor(z, w, problem.q, row_sum_max)
    return w, float(res), float(floor)


def _result(problem: _Problem, z: NDArray[np.float64], code: int, iterations: int,
            method: str, tol: float) -> LCPResult:
    """Recompute ``w`` from ``z`` and accept "solved" only if the residual passes."""
    z = np.array(z, dtype=np.float64)
    w, res, floor = _verify(problem, z)
    status = STATUSES[int(code)]
    if status == "solved" and not (res <= max(tol, floor)):
        status = "numerical_failure"
    z.setflags(write=False)
    w.setflags(write=False)
    return LCPResult(z=z, w=w, status=status, iterations=int(iterations), residual=res,
                     method=method)
