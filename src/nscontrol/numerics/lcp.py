"""Linear complementarity problems: ``w = M z + q,  0 <= z ⟂ w >= 0``.

Two entry points, one code path:

- :class:`LCPSolver` validates and analyses ``M`` once (structure, method choice, norms)
  and then solves for many right-hand sides: ``LCPSolver(M).solve(q)`` pays per call only
  for a check of ``q``, the compiled kernel and the residual check.
- :func:`solve_lcp` solves one problem: it is ``LCPSolver(M, ...).solve(q)``.

Four methods:

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
  large symmetric ``M`` that turns out positive semidefinite; then every other method that
  applies, in a fixed order, until one returns a verified solution (:class:`LCPSolver`).

A problem whose solution does not fit in float64 (``solve_lcp([[0.5]], [-1.7e308])``:
``z = 3.4e308``) is reported with status ``"overflow"`` and a message naming the scale of
``q``, not as infeasible.

The numba kernels behind the methods live in :mod:`nscontrol.numerics._lcp_kernels` and can
be called from other ``@njit`` code. See ``docs/lcp.md`` for the algorithms and figures.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import (
    as_float_array,
    as_square,
    as_vector,
    check_bool,
    check_finite,
    check_in_interval,
    check_integer,
    check_positive,
)
from ..errors import BudgetExceededError, DimensionError, ModelError, SolverError
from . import _lcp_kernels as kernels

__all__ = ["LCPResult", "LCPSolver", "solve_lcp", "residual"]

Method = Literal["auto", "lemke", "pgs", "banded"]
METHODS = ("auto", "lemke", "pgs", "banded")
STATUSES = ("solved", "ray_termination", "max_iter", "numerical_failure", "overflow")

#: ``auto`` uses PGS instead of Lemke for symmetric PSD problems larger than this.
AUTO_PGS_MIN_SIZE = 400
#: ``auto`` does not fall back to dense Lemke or PGS above this size (memory n^2, time n^3).
AUTO_LEMKE_MAX_SIZE = 3000
#: PGS's default budget of sweeps (``max_iter``).
PGS_SWEEPS = 10_000
#: Sweeps of ``auto``'s PGS before it pays for a definiteness test (see ``_run_pgs_auto``).
AUTO_PGS_PROBE_SWEEPS = 100
#: Sweeps of PGS as a fallback of ``auto`` on a matrix it is not known to converge for
#: (a cost comparable to dense Lemke's O(n^3)).
AUTO_PGS_FALLBACK_SWEEPS = 1000
#: ``auto`` tries ``banded`` first on dense matrices this large with a narrow band.
AUTO_BANDED_MIN_SIZE = 64
#: ``auto`` falls back to Howard's iteration with dense LU (O(n^3) per iteration) up to here.
AUTO_DENSE_HOWARD_MAX_SIZE = 200
#: A failed solve is retried on the problem rescaled by powers of two (exact) when
#: ``max|M|``, ``max|q|`` or their ratio lies outside ``2^(+-this)``: the scales at which
#: the float64 arithmetic of a solver can overflow or underflow.
RESCALE_EXPONENT = 64


@dataclass(frozen=True)
class LCPResult:
    """Outcome of :func:`solve_lcp` and :meth:`LCPSolver.solve`.

    Attributes
    ----------
    z, w : ndarray, shape (n,)
        The computed point and ``w = M z + q`` (recomputed from ``z``, never taken on trust).
        On failure: the last iterate of the method that ran last; on ``"overflow"``: ``inf``
        where the solution exceeds the float64 range.
    status : {"solved", "ray_termination", "max_iter", "numerical_failure", "overflow"}
        ``"solved"`` exactly when ``residual <= tolerance`` (on every path: the method's
        own claim does not count). ``"ray_termination"``: Lemke found no solution (for
        copositive-plus ``M`` the LCP is infeasible). ``"max_iter"``: the method spent its
        budget ``max_iter`` (the message names it, with the limit). ``"numerical_failure"``:
        a pivot or diagonal broke down, or the method claimed a solution whose residual
        does not pass. ``"overflow"``: the problem rescaled by powers of two was solved, but
        its solution scaled back exceeds float64.
    iterations : int
        Pivots (Lemke), sweeps (PGS) or active-set iterations (banded) of the last method.
    residual : float
        ``max_i |min(z_i, w_i)| / (1 + max|q|)``: zero exactly at a solution; it counts
        negative entries of ``z`` or ``w`` in full.
    method : str
        The method that produced ``z`` (for ``"auto"``: the one finally used).
    message : str
        Why it stopped, and which methods were tried (``"name: status (residual r, ...)"``
        joined by ``"; "``, in the order they ran).
    tolerance : float
        The acceptance threshold :attr:`residual` was tested against: ``tol`` plus the
        round-off bound of evaluating ``M z + q`` (see :func:`solve_lcp`); ``-inf`` when
        ``z`` is so large that ``M z + q`` cancels beyond half the float64 digits, where
        no residual certifies anything (a near-ray of a nearly singular ``M``).
    """

    z: NDArray[np.float64]
    w: NDArray[np.float64]
    status: str
    iterations: int
    residual: float
    method: str
    message: str = field(default="")
    tolerance: float = field(default=math.nan)

    @property
    def success(self) -> bool:
        """True when ``status == "solved"``."""
        return self.status == "solved"


def residual(M: Any, z: Any, q: Any) -> float:
    """Relative natural residual ``max_i |min(z_i, (Mz + q)_i)| / (1 + max|q|)`` of a point.

    Works for dense and scipy.sparse ``M``; zero exactly at solutions of LCP(M, q).

    Parameters
    ----------
    M : (n, n) array_like or scipy.sparse matrix
        The LCP matrix.
    z : (n,) array_like
        The point to measure.
    q : (n,) array_like
        The LCP vector.

    Raises
    ------
    DimensionError, ModelError
        As :func:`solve_lcp` for ``M`` and ``q``; ``z`` must be a real vector of length
        ``n`` (it may hold ``inf``, e.g. the ``z`` of an ``"overflow"`` result).
    """
    M = _as_lcp_matrix(M)
    n = M.shape[0]
    q = as_vector("q", q, size=n)
    z = as_float_array("z", z, shape=(n,), finite=False)
    with np.errstate(over="ignore", invalid="ignore"):
        w = np.asarray(M @ z + q, dtype=np.float64).ravel()
    return _natural_residual(z, w, q)


def solve_lcp(M: Any, q: Any, *, method: Method = "auto", tol: float = 1e-12,
              max_iter: int | None = None, strict: bool = False, z0: Any = None,
              omega: float = 1.0) -> LCPResult:
    """Solve the linear complementarity problem ``w = M z + q, 0 <= z ⟂ w >= 0``.

    Equivalent to ``LCPSolver(M, method, tol=tol, max_iter=max_iter, strict=strict,
    omega=omega).solve(q, z0=z0)``; to solve with one ``M`` for many ``q``, keep the
    :class:`LCPSolver`, which analyses ``M`` once.

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
        The solver's tolerance on :attr:`LCPResult.residual` (and PGS's stopping
        criterion). Every result, of every method, is accepted exactly when its residual,
        recomputed from ``z``, is at most ``tol + 2 k eps (max|M||z| + max|q|) / (1 +
        max|q|)``: ``tol`` plus twice the a-priori round-off bound of evaluating ``M z + q``
        with ``k`` terms per entry (``n + 1`` dense, ``4`` tridiagonal, the non-zeros of a
        row plus one sparse); never when ``max|M||z| > (1 + max|q|) / sqrt(eps)`` (Notes).
    max_iter : int, optional
        The budget of each method run (pivots, sweeps or iterations); spending it gives the
        status ``"max_iter"`` with a message naming ``max_iter`` and the limit. Defaults:
        Lemke ``50 (n + 1)`` pivots (also the cap that ends a cycling path), PGS ``10000``
        sweeps (``1000`` as a fallback of ``auto``), banded ``n + 2`` iterations. ``auto``
        runs each method at most once, so its chain is bounded by the sum of these.
    strict : bool
        Raise instead of returning a failed result: :class:`~nscontrol.errors.
        BudgetExceededError` (``budget="max_iter"``, ``limit``, ``used``, the result in
        ``partial``) when the budget was spent, :class:`~nscontrol.errors.SolverError`
        otherwise.
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
        NaN, infinite, complex or string entries, unknown ``method``, ``tol`` not a finite
        number ``> 0``, ``omega`` outside (0, 2), ``max_iter`` not an integer ``>= 1``
        (``2.7`` is refused, not truncated), ``strict`` not a bool (``"no"`` is truthy).
    BudgetExceededError
        With ``strict=True``, when the result's method spent its ``max_iter``.
    SolverError
        With ``strict=True``, when no method reached a verified solution (``err.status``).

    Notes
    -----
    ``"auto"`` first picks by structure: for ``n > 2``, tridiagonal ``M`` (dense or sparse),
    any other scipy.sparse ``M`` and dense ``M`` with ``n >= 64`` and half-bandwidth
    ``<= sqrt(n)`` → ``"banded"``; otherwise symmetric ``M`` with a positive diagonal and
    ``n > 400`` → ``"pgs"``, which gets 100 sweeps before ``M`` is tested for positive
    semidefiniteness (diagonal dominance, else a Cholesky factorisation of
    ``M + 1e-12 max|M| I``) and continues only if it passes; otherwise ``"lemke"``. Until a
    result passes the residual test, it then falls back, each method at most once, to:
    that PGS (after ``banded``), Lemke (``n <= 3000``), PGS on any matrix with a positive
    diagonal (``n <= 3000``, 1000 sweeps: exact in one sweep for a lower-triangular ``M``,
    where Lemke's path can be exponentially long), Howard's iteration with dense LU
    (``n <= 200``). :attr:`LCPResult.message` lists every method tried with its status.

    *Verification.* The tolerance above is an error estimate: ``w`` computed in float64
    differs from ``M z + q`` by at most ``gamma_k (|M||z| + |q|)`` entrywise (``gamma_k ~ k
    eps``), so a residual below it is a solution up to the round-off of its own evaluation.
    That bound grows with ``z``: where ``|M||z|`` exceeds ``(1 + max|q|) / sqrt(eps)``, half
    the digits of ``w`` are lost to cancellation and nothing is certified (status
    ``"numerical_failure"``, :attr:`LCPResult.tolerance` ``-inf``). A genuine solution has
    ``|M||z|`` at most about ``cond(M_aa) max|q|``; a direct solve on a numerically
    singular active block, such as PGS's polish on a positive semidefinite LCP without
    solution, gives ``|z| ~ 1e15`` and a cancellation near ``1 / eps`` — before this test,
    such a point was reported solved with a residual of 0.5.

    Lemke is guaranteed to find a solution for P-matrices (unique solution) and, for
    copositive-plus ``M``, ends in a ray only when the LCP is infeasible — but its path may
    need up to ``2^n`` pivots (Murty's unit lower-triangular matrices with 2 below the
    diagonal and ``q = -1``), beyond the default limit for ``n >= 9``. PGS converges for
    symmetric PSD ``M`` with positive diagonal. Banded is exact for M-matrices (e.g. the
    Delassus matrix of a stack); elsewhere it may stop with ``"max_iter"``.

    A failed solve of a problem with extreme scales (``max|M|``, ``max|q|`` or their ratio
    beyond ``2^64``) is retried on ``LCP(M / 2^a, q / 2^b)``, rescaled exactly by powers of
    two, whose solution is ``z / 2^(b - a)``; when that one is solved but ``z`` exceeds the
    float64 range, the status is ``"overflow"`` (not ``"ray_termination"``).

    References
    ----------
    R. W. Cottle, J.-S. Pang, R. E. Stone, *The Linear Complementarity Problem*, Academic
    Press, 1992 (§4.4 Lemke, §5.2 PGS). K. G. Murty, "Computational complexity of
    complementary pivot methods", Math. Programming Study 7, 1978 (the exponential family).
    O. Bokanowski, S. Maroso, H. Zidani, SIAM J. Numer. Anal. 47(4), 2009 (Howard's
    algorithm).

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.numerics.lcp import solve_lcp
    >>> res = solve_lcp(np.array([[2.0, 1.0], [1.0, 2.0]]), np.array([-5.0, -6.0]))
    >>> res.status, np.round(res.z, 12).tolist()
    ('solved', [1.333333333333, 2.333333333333])
    """
    solver = LCPSolver(M, method, tol=tol, max_iter=max_iter, strict=strict, omega=omega)
    return solver.solve(q, z0=z0)


# ----------------------------------------------------------------------------- the solver

class _Outcome(NamedTuple):
    """One method run, verified (its status reconciled with :func:`kernels.certify`)."""

    z: NDArray[np.float64]
    w: NDArray[np.float64]
    status: str
    iterations: int
    residual: float
    method: str
    tolerance: float
    limit: int          # the budget max_iter the run had (pivots, sweeps or iterations)
    note: str = ""      # why the budget was shorter than max_iter, if it was

    def describe(self) -> str:
        """``"name: status (residual r, ...)"``: why it stopped, the budget if spent."""
        text = f"{self.method}: {self.status} (residual {self.residual:.3g}"
        if self.status == "max_iter":
            unit = _UNITS.get(self.method, "iterations")
            text += self.note or f", budget max_iter = {self.limit} {unit} spent"
        elif self.status != "solved" and not math.isfinite(self.residual):
            text += ", the iterate is not finite"
        elif self.status != "solved" and self.tolerance == -math.inf:
            text += ", not certifiable: M z + q cancels beyond half the float64 digits"
        elif self.status == "numerical_failure" and self.residual > self.tolerance:
            text += f" above the tolerance {self.tolerance:.3g}"
        return text + ")"


_UNITS = {"lemke": "pivots", "pgs": "sweeps", "banded": "iterations"}


class LCPSolver:
    """An LCP solver for one matrix ``M`` and many right-hand sides ``q``.

    The constructor validates ``M`` and the options, reads its structure (tridiagonal
    bands, sparsity, bandwidth, symmetry where ``auto`` needs it), chooses ``auto``'s first
    method and computes ``||M||_inf`` for the residual check. :meth:`solve` then checks
    ``q`` (type, length, finiteness inside the compiled kernel), runs the kernel and
    verifies the residual: on a dense ``n = 10`` problem a few microseconds above the bare
    kernel (``docs/lcp.md`` has the figures). :func:`solve_lcp` is this class used once.

    Parameters
    ----------
    M : (n, n) array_like or scipy.sparse matrix
        Finite square matrix (copied only when it is not already a C-contiguous float64
        array; do not modify it afterwards).
    method, tol, max_iter, strict, omega
        As in :func:`solve_lcp`.

    Attributes
    ----------
    n : int
        The size of the problem.
    method : str
        The method asked for; :attr:`first_method` is the one ``solve`` runs first.

    Raises
    ------
    DimensionError, ModelError
        As :func:`solve_lcp`, for ``M`` and the options.

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.numerics.lcp import LCPSolver
    >>> solver = LCPSolver(np.array([[2.0, 1.0], [1.0, 2.0]]))
    >>> [solver.solve(np.array([-5.0, q2])).z.round(12).tolist() for q2 in (-6.0, 6.0)]
    [[1.333333333333, 2.333333333333], [2.5, 0.0]]
    """

    def __init__(self, M: Any, method: Method = "auto", *, tol: float = 1e-12,
                 max_iter: int | None = None, strict: bool = False, omega: float = 1.0):
        if not isinstance(method, str) or method not in METHODS:
            raise ModelError(f"method: expected one of {list(METHODS)}, got {method!r}")
        self.method = method
        # plain floats in range skip the general checks (solve_lcp pays these per call)
        self.tol = tol if type(tol) is float and 0.0 < tol < math.inf else check_positive(
            "tol", tol)
        self.omega = omega if type(omega) is float and 0.0 < omega < 2.0 else (
            check_in_interval("omega", omega, 0.0, 2.0, open_interval=True))
        self.max_iter = None if max_iter is None else check_integer("max_iter", max_iter,
                                                                     minimum=1)
        self.strict = check_bool("strict", strict)
        if (type(M) is np.ndarray and M.dtype == np.float64 and M.ndim == 2
                and M.flags.c_contiguous and M.flags.writeable and M.shape[0] == M.shape[1]):
            # the common case in one compiled scan: finiteness, tridiagonality
            finite, tridiagonal = kernels.dense_structure(M)
            if not finite:
                check_finite("M", M)
            self._M = self._dense = M
            self._bands = _bands_of(M) if tridiagonal else None
        else:
            self._M = _as_lcp_matrix(M)
            self._bands = _tridiagonal_bands(self._M)
        self.n: int = int(self._M.shape[0])
        self.first_method: str = self._first_method()
        self._fused = self._fused_first_call()
        self._rescaled_solvers: dict[int, LCPSolver] = {}

    def __getstate__(self) -> dict[str, Any]:
        # the fused call is a closure (not picklable): rebuilt on unpickling
        state = dict(self.__dict__)
        del state["_fused"]
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._fused = self._fused_first_call()

    def __repr__(self) -> str:
        kind = "sparse" if self._sparse else "dense"
        return (f"LCPSolver(n={self.n}, {kind}, method={self.method!r}, "
                f"first_method={self.first_method!r}, tol={self.tol:g})")

    # ------------------------------------------------------------------ solve

    def solve(self, q: Any, *, z0: Any = None) -> LCPResult:
        """Solve ``w = M z + q, 0 <= z ⟂ w >= 0`` for this solver's ``M``.

        Parameters
        ----------
        q : (n,) array_like
            Finite vector (a C-contiguous float64 array takes the fast path: no copy).
        z0 : (n,) array_like, optional
            Warm start for ``"pgs"`` and ``"banded"``.

        Returns
        -------
        LCPResult
            The same result as :func:`solve_lcp` with this solver's options.

        Raises
        ------
        DimensionError
            ``q`` or ``z0`` not a vector of length :attr:`n`.
        ModelError
            ``q`` or ``z0`` with NaN, infinite, complex or string entries.
        SolverError
            With ``strict=True``, when no method reached a verified solution.
        """
        if not (type(q) is np.ndarray and q.dtype == np.float64 and q.ndim == 1
                and q.flags.c_contiguous and q.flags.writeable and q.shape[0] == self.n):
            q = self._check_q(q)
        if z0 is None and self._fused is not None:
            # the per-call path of a reusable solver, kept short: one compiled call, whose
            # status is already reconciled with the residual test (kernels.certify)
            n = self.n
            z, w = np.empty(n), np.empty(n)
            code, its, res, tolerance = self._fused(q, z, w)
            if code == 0:
                z.setflags(write=False)
                w.setflags(write=False)
                method = self.first_method
                return LCPResult(z, w, "solved", its, res, method,
                                 f"{method}: solved (residual {res:.3g})", tolerance)
            if code == kernels.Q_NOT_FINITE:
                check_finite("q", q)
            first = self._outcome(z, w, code, its, res, tolerance, self.first_method,
                                  self._limit(self.first_method))
            z0v = None
        else:
            z0v = None if z0 is None else as_vector("z0", z0, size=self.n)
            first = _RUNNERS[self.first_method](self, q, z0v, self.max_iter)
        if first.status == "solved":
            return LCPResult(first.z, first.w, "solved", first.iterations, first.residual,
                             first.method, first.describe(), first.tolerance)
        result, chosen = self._run_fallbacks(q, z0v, first)
        if result.status != "solved":
            result = self._retry_rescaled(q, z0v, result)
        if self.strict and result.status == "max_iter":
            raise BudgetExceededError(
                f"max_iter: the LCP of size {self.n} was not solved within the budget "
                f"max_iter = {chosen.limit} {_UNITS.get(chosen.method, 'iterations')} of "
                f"{chosen.method} ({result.message}); raise max_iter, or try another method; "
                "the last iterate is in err.partial", budget="max_iter", limit=chosen.limit,
                used=chosen.iterations, partial=result)
        if self.strict and result.status != "solved":
            raise SolverError(f"no verified solution of the LCP of size {self.n} "
                              f"({result.message}); check that M is a P-matrix or "
                              f"copositive-plus, raise max_iter, or try another method",
                              status=result.status)
        return result

    def _fused_first_call(self) -> Callable[..., tuple[int, int, float, float]] | None:
        """``f(q, z, w) -> (code, iterations, residual, tolerance)``: the first method's
        kernel fused with its verification, when it has one (Lemke, PGS with its polish from zero,
        tridiagonal ``banded`` from its own start); None otherwise."""
        tol = self.tol
        limit = self._limit(self.first_method)
        if self.first_method == "lemke":
            M = self._dense
            lemke = kernels.lemke_verified
            return lambda q, z, w: lemke(M, q, z, w, limit, tol)
        if self.first_method == "pgs":
            M, omega = self._dense, self.omega
            pgs = kernels.pgs_verified
            return lambda q, z, w: pgs(M, q, z, w, tol, limit, omega, True)
        if self.first_method == "banded" and self._bands is not None:
            lower, diag, upper = self._bands
            howard = kernels.tridiagonal_verified
            return lambda q, z, w: howard(lower, diag, upper, q, z, w, limit, False, tol)
        return None

    def _limit(self, name: str, max_iter: int | None = None) -> int:
        """The budget of one run of method ``name``: ``max_iter`` when given (else the
        solver's), otherwise the method's default (see :func:`solve_lcp`)."""
        limit = max_iter or self.max_iter
        if limit:
            return int(limit)
        if name == "lemke":
            return 50 * (self.n + 1)
        if name == "banded":
            return self.n + 2
        if name == "pgs_fallback":
            return AUTO_PGS_FALLBACK_SWEEPS
        return PGS_SWEEPS

    def _run_fallbacks(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                       first: _Outcome) -> tuple[LCPResult, _Outcome]:
        """Run ``auto``'s fallbacks after a failed first method until one is verified;
        the message lists every method run, in order. When all fail, the result is Lemke's
        ray termination if there was one (for copositive-plus ``M`` a certificate that the
        LCP is infeasible), else the last method's. Returns it with the chosen run."""
        tried = [first]
        for name in self._fallbacks():
            tried.append(_RUNNERS[name](self, q, z0, self.max_iter))
            if tried[-1].status == "solved":
                break
        chosen = tried[-1]
        if chosen.status != "solved":
            chosen = next((o for o in tried if o.status == "ray_termination"), chosen)
        message = "; ".join(o.describe() for o in tried)
        return LCPResult(chosen.z, chosen.w, chosen.status, chosen.iterations,
                         chosen.residual, chosen.method, message, chosen.tolerance), chosen

    def _check_q(self, q: Any) -> NDArray[np.float64]:
        """``q`` as a writeable C-contiguous float64 vector of length n; finiteness is
        checked here only off the fast path (the fused kernels check it, and the runners
        raise)."""
        if not (type(q) is np.ndarray and q.dtype == np.float64 and q.ndim == 1):
            q = as_vector("q", q)
        elif not (q.flags.c_contiguous and q.flags.writeable):
            # a copy is cheaper than a numba specialisation for read-only arrays (e.g. the
            # read-only z of an earlier LCPResult passed as q)
            q = np.array(q, order="C")
        if q.shape[0] != self.n:
            raise DimensionError(f"q: expected a vector of length {self.n} (the size of "
                                 f"M), got length {q.shape[0]}")
        return q

    # ------------------------------------------------------------------ analysis

    @property
    def _sparse(self) -> bool:
        return not isinstance(self._M, np.ndarray)

    @cached_property
    def _dense(self) -> NDArray[np.float64]:
        """``M`` as a dense array (densified once, when a dense method first needs it)."""
        return self._M if isinstance(self._M, np.ndarray) else np.asarray(self._M.toarray())

    @cached_property
    def _banded_dense(self) -> bool:
        """Dense ``M`` with a narrow band (half-bandwidth ``<= sqrt(n)``, ``n >= 64``): worth
        Howard's iteration with sparse LU (O(n b^2) per step) before dense pivoting."""
        n = self.n
        if self._sparse or n < AUTO_BANDED_MIN_SIZE:
            return False
        limit = max(2, int(np.sqrt(n)))
        return bool(kernels.half_bandwidth(self._M, limit) <= limit)

    @cached_property
    def _symmetric_positive_diagonal(self) -> bool:
        M = self._dense
        scale = max(float(np.max(np.abs(M), initial=0.0)), 1.0)
        return bool(np.all(np.diagonal(M) > 0.0) and kernels.is_symmetric(M, 1e-12 * scale))

    @cached_property
    def _positive_diagonal(self) -> bool:
        return bool(np.all(self._M.diagonal() > 0.0))

    @cached_property
    def _symmetric_psd(self) -> bool:
        """Symmetric (to 1e-12 relative) and positive semidefinite, tested without
        eigenvalues: a diagonally dominant matrix with a nonnegative diagonal is PSD
        (Gershgorin), otherwise an attempted Cholesky factorisation of ``M + tiny I``
        decides (``tiny`` = 1e-12 relative, above the round-off of the factorisation). The
        residual test after the solve keeps a borderline answer honest."""
        M = self._dense
        n = self.n
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

    def _large_symmetric(self) -> bool:  # densifies sparse M: only evaluated when reached
        return self.n > AUTO_PGS_MIN_SIZE and self._symmetric_positive_diagonal

    def _structured(self) -> bool:
        """Tridiagonal, sparse or narrow-band (``auto`` starts with ``banded``)."""
        if self.n <= 2:
            return False
        if self._bands is not None or self._sparse:
            return True
        return self.n >= AUTO_BANDED_MIN_SIZE and self._banded_dense

    def _first_method(self) -> str:
        if self.method != "auto":
            return self.method
        if self._structured():
            return "banded"
        if self._large_symmetric():
            return "pgs_auto"
        return "lemke"

    def _fallbacks(self) -> Iterator[str]:
        """``auto``'s methods after the first, each decided only when reached."""
        if self.method != "auto":
            return
        n = self.n
        tried = {self.first_method.removesuffix("_auto")}
        candidates = (
            ("pgs_auto", lambda: self._structured() and self._large_symmetric()),
            ("lemke", lambda: n <= AUTO_LEMKE_MAX_SIZE),
            ("pgs_fallback", lambda: n <= AUTO_LEMKE_MAX_SIZE and self._positive_diagonal),
            ("banded", lambda: n <= AUTO_DENSE_HOWARD_MAX_SIZE),
        )
        for name, applies in candidates:
            family = name.split("_")[0]
            if family not in tried and applies():
                tried.add(family)
                yield name

    # ------------------------------------------------------------------ runners

    def _outcome(self, z: NDArray[np.float64], w: NDArray[np.float64], code: int,
                 iterations: int, res: float, tolerance: float, method: str, limit: int
                 ) -> _Outcome:
        """A run's outcome from a status already reconciled with the residual test."""
        z.setflags(write=False)
        w.setflags(write=False)
        return _Outcome(z, w, STATUSES[code], int(iterations), float(res), method,
                        float(tolerance), int(limit))

    def _verify(self, z: NDArray[np.float64], q: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], float, float, bool]:
        """``w = M z + q`` recomputed from ``z``, and :func:`kernels.certify`'s residual,
        tolerance and verdict."""
        w = np.empty_like(z)
        if self._bands is not None:
            lower, diag, upper = self._bands
            res, tolerance, ok = kernels.verify_tridiagonal(lower, diag, upper, q, z, w,
                                                            self.tol)
        elif isinstance(self._M, np.ndarray):
            res, tolerance, ok = kernels.verify_dense(self._M, q, z, w, self.tol)
        else:
            w = np.asarray(self._M @ z + q, dtype=np.float64).ravel()
            with np.errstate(over="ignore", invalid="ignore"):
                mz = float(np.max(abs(self._M) @ np.abs(z), initial=0.0))
            res, tolerance, ok = kernels.certify(z, w, q, mz, self._terms, self.tol)
        return w, float(res), float(tolerance), bool(ok)

    @cached_property
    def _terms(self) -> int:
        """Terms in one entry of ``M z + q`` for sparse ``M``: a row's non-zeros plus one."""
        csr: Any = self._M
        return int(np.max(np.diff(csr.indptr), initial=0)) + 1

    def _run_lemke(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                   max_iter: int | None) -> _Outcome:
        n = self.n
        z, w = np.empty(n), np.empty(n)
        limit = self._limit("lemke", max_iter)
        code, its, res, tolerance = kernels.lemke_verified(self._dense, q, z, w, limit,
                                                           self.tol)
        if code == kernels.Q_NOT_FINITE:
            check_finite("q", q)
        return self._outcome(z, w, code, its, res, tolerance, "lemke", limit)

    def _run_pgs(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                 max_iter: int | None) -> _Outcome:
        n = self.n
        z = np.zeros(n) if z0 is None else np.array(z0)   # the kernel clamps z0 to >= 0
        w = np.empty(n)
        limit = self._limit("pgs", max_iter)
        code, its, res, tolerance = kernels.pgs_verified(
            self._dense, q, z, w, self.tol, limit, self.omega, False)
        if code == kernels.Q_NOT_FINITE:
            check_finite("q", q)
        return self._outcome(z, w, code, its, res, tolerance, "pgs", limit)

    def _run_pgs_fallback(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                          max_iter: int | None) -> _Outcome:
        return self._run_pgs(q, z0, self._limit("pgs_fallback", max_iter))

    def _run_pgs_auto(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                      max_iter: int | None) -> _Outcome:
        """``auto``'s PGS: a probe of :data:`AUTO_PGS_PROBE_SWEEPS` sweeps first (a
        well-conditioned problem is solved there, and no definiteness test is paid); only if
        it has not converged is ``M`` tested for positive semidefiniteness (a Cholesky
        factorisation), and PGS continues from the probe's iterate for PSD ``M`` only (where
        it converges). Otherwise the probe's failure hands over to the fallbacks."""
        total = self._limit("pgs", max_iter)
        probe = min(AUTO_PGS_PROBE_SWEEPS, total)
        first = self._run_pgs(q, z0, probe)
        if first.status == "solved" or probe == total:
            return first
        if not self._symmetric_psd:
            return first._replace(note=f", stopped after the probe of {probe} sweeps: M is not "
                                       "positive semidefinite, where PGS need not converge")
        rest = self._run_pgs(q, np.array(first.z), total - probe)
        return rest._replace(iterations=probe + rest.iterations, limit=total)

    def _run_banded(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                    max_iter: int | None) -> _Outcome:
        n = self.n
        limit = self._limit("banded", max_iter)
        z = np.zeros(n) if z0 is None else z0.copy()
        if self._bands is None:
            check_finite("q", q)
            code, its, z = self._howard(q, z, limit)
            w, res, tolerance, ok = self._verify(z, q)
            return self._outcome(z, w, int(kernels.verified_status(code, ok)), its, res,
                                 tolerance, "banded", limit)
        lower, diag, upper = self._bands
        w = np.empty(n)
        code, its, res, tolerance = kernels.tridiagonal_verified(
            lower, diag, upper, q, z, w, limit, z0 is not None, self.tol)
        if code == kernels.Q_NOT_FINITE:
            check_finite("q", q)
        return self._outcome(z, w, code, its, res, tolerance, "banded", limit)

    @cached_property
    def _howard_matrix(self) -> Any:
        """``M`` for Howard's active-set solves: CSC for sparse or narrow-band ``M`` (SuperLU,
        O(n b^2)), the dense array otherwise (LAPACK)."""
        if self._sparse or self._banded_dense:
            import scipy.sparse as sp
            return sp.csc_matrix(self._M)
        return self._M

    def _howard(self, q: NDArray[np.float64], z: NDArray[np.float64], limit: int
                ) -> tuple[int, int, NDArray[np.float64]]:
        """Howard's policy iteration with a direct solve on the active set (non-tridiagonal M).

        The same iteration as :func:`~nscontrol.numerics._lcp_kernels.tridiagonal_howard`;
        each step factors ``M[a, a]`` (SuperLU for sparse or banded ``M``: O(n b^2) per
        step). The next iterate depends only on the active set, so a repeated active set is
        a cycle: it stops at once with ``"max_iter"`` (instead of running to the limit) and
        ``auto`` falls back to the next method.
        """
        M = self._howard_matrix
        solve_block = _sparse_block_solver if not isinstance(M, np.ndarray) else _dense_block_solve
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
                z_a = solve_block(M, idx, -q[idx])
                if z_a is None:                  # singular principal block
                    return kernels.NUMERICAL_FAILURE, it + 1, z
                z[idx] = z_a
            w = M @ z + q
            if not np.all(np.isfinite(z)):
                return kernels.NUMERICAL_FAILURE, it + 1, z
        return kernels.MAX_ITER, limit, z

    # ------------------------------------------------------------------ overflow

    def _retry_rescaled(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                        failed: LCPResult) -> LCPResult:
        """Retry a failed solve on ``LCP(M / 2^a, q / 2^b)`` when the scales are extreme
        (see :data:`RESCALE_EXPONENT`); its solution times ``2^(b - a)`` solves the
        original LCP. Report ``"overflow"`` when that product exceeds float64."""
        m_max = float(np.max(np.abs(self._dense if not self._sparse else self._M.data),
                             initial=0.0))
        q_max = float(np.max(np.abs(q), initial=0.0))
        if m_max == 0.0 or q_max == 0.0:
            return failed
        a, b = math.frexp(m_max)[1], math.frexp(q_max)[1]
        if max(abs(a), abs(b), abs(b - a)) <= RESCALE_EXPONENT:
            return failed
        scaled = self._rescaled_solvers.get(a)
        if scaled is None:
            M = self._M * math.ldexp(1.0, -a)
            scaled = LCPSolver(M, self.method, tol=self.tol, max_iter=self.max_iter,
                               omega=self.omega)
            self._rescaled_solvers[a] = scaled
        r = scaled.solve(np.ldexp(q, -b), z0=None if z0 is None else np.ldexp(z0, a - b))
        note = f"{failed.message}; rescaled by M / 2^{a}, q / 2^{b}: {r.message}"
        if not r.success:
            return _with_message(failed, note)
        with np.errstate(over="ignore", invalid="ignore"):
            z = np.ldexp(r.z, b - a)
            w, res, tolerance, ok = self._verify(z, q)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(w))):
            return self._overflow(z, w, r, (a, b), q_max, m_max, note)
        z.setflags(write=False)
        w.setflags(write=False)
        return LCPResult(z, w, "solved" if ok else failed.status, r.iterations, res, r.method,
                         note, tolerance)

    def _overflow(self, z: NDArray[np.float64], w: NDArray[np.float64], scaled: LCPResult,
                  exponents: tuple[int, int], q_max: float, m_max: float, note: str
                  ) -> LCPResult:
        """The ``"overflow"`` result: the rescaled problem ``LCP(M / 2^a, q / 2^b)`` was
        solved by ``scaled``, but ``2^(b - a)`` times its solution exceeds float64."""
        a, b = exponents
        z_scaled = float(np.max(np.abs(scaled.z), initial=0.0))
        log10_z = math.log10(z_scaled) + (b - a) * math.log10(2.0) if z_scaled else 0.0
        factor = 10.0 ** max(1, math.ceil(log10_z - 300))
        decade = math.floor(log10_z)
        z_text = f"{10.0 ** (log10_z - decade):.2g}e+{decade}"
        message = (f"q: the solution overflows float64 at this scale of q (max|q| = "
                   f"{q_max:.3g}, max|M| = {m_max:.3g}): max z ≈ {z_text}, beyond "
                   f"1.8e308. The LCP is feasible: LCP(M / 2^{a}, q / 2^{b}) is solved, and z "
                   f"= 2^{b - a} times its solution. Rescale the problem, e.g. solve with "
                   f"q / {factor:.0e} (z scales by the same factor). Tried: {note}")
        z.setflags(write=False)
        w.setflags(write=False)
        return LCPResult(z, w, "overflow", scaled.iterations, math.inf, scaled.method,
                         message, -math.inf)


_RUNNERS = {"lemke": LCPSolver._run_lemke, "pgs": LCPSolver._run_pgs,
            "banded": LCPSolver._run_banded, "pgs_auto": LCPSolver._run_pgs_auto,
            "pgs_fallback": LCPSolver._run_pgs_fallback}


def _with_message(result: LCPResult, message: str) -> LCPResult:
    return LCPResult(result.z, result.w, result.status, result.iterations, result.residual,
                     result.method, message, result.tolerance)


def _sparse_block_solver(M: Any, idx: NDArray[np.intp], rhs: NDArray[np.float64]
                         ) -> NDArray[np.float64] | None:
    from scipy.sparse.linalg import splu
    try:
        return splu(M[idx][:, idx].tocsc()).solve(rhs)
    except RuntimeError:  # singular principal block
        return None


def _dense_block_solve(M: NDArray[np.float64], idx: NDArray[np.intp],
                       rhs: NDArray[np.float64]) -> NDArray[np.float64] | None:
    try:
        return np.linalg.solve(M[np.ix_(idx, idx)], rhs).astype(np.float64, copy=False)
    except np.linalg.LinAlgError:
        return None


# ----------------------------------------------------------------------------- input


def _as_lcp_matrix(M: Any) -> Any:
    """A finite square dense float array, or a finite square scipy.sparse CSR matrix."""
    if _clean(M, 2) and M.shape[0] == M.shape[1]:
        return M
    if hasattr(M, "tocsr") and not isinstance(M, np.ndarray):
        csr = M.tocsr()
        if csr.dtype != np.float64:
            if csr.dtype.kind not in "fiub":
                raise ModelError(f"M: expected a real sparse matrix, got dtype {csr.dtype}")
            csr = csr.astype(np.float64)
        if csr.ndim != 2 or csr.shape[0] != csr.shape[1]:
            raise DimensionError(f"M: expected a square matrix, got shape {csr.shape}")
        if not kernels.all_finite(np.ascontiguousarray(csr.data)):
            check_finite("M", csr.data)        # raises, with the count of bad entries
        return csr
    if np.ndim(M) == 0:  # a scalar is a 1x1 LCP
        M = np.reshape(as_float_array("M", M), (1, 1))
    return np.ascontiguousarray(as_square("M", M))


def _clean(a: Any, ndim: int) -> bool:
    """Fast path: already a writeable C-contiguous finite float64 array of rank ``ndim``
    (the checks of ``nscontrol._validation`` run otherwise, and raise their specific errors;
    a read-only array is copied rather than given its own numba specialisation)."""
    return (type(a) is np.ndarray and a.dtype == np.float64 and a.ndim == ndim
            and a.flags.c_contiguous and a.flags.writeable
            and bool(kernels.all_finite(a.reshape(-1))))


def _tridiagonal_bands(M: Any) -> tuple[NDArray[np.float64], ...] | None:
    """``(lower, diag, upper)`` when ``M`` is tridiagonal (no entry beyond the first
    off-diagonals), else None."""
    if isinstance(M, np.ndarray):
        return _bands_of(M) if kernels.is_tridiagonal(M) else None
    n = M.shape[0]
    lower, diag, upper = np.empty(max(n - 1, 0)), np.empty(n), np.empty(max(n - 1, 0))
    if not kernels.csr_tridiagonal_bands(M.indptr, M.indices, M.data, lower, diag, upper):
        return None
    return lower, diag, upper


def _bands_of(M: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
    """``(lower, diag, upper)`` of a dense matrix, as contiguous copies."""
    return (np.ascontiguousarray(np.diagonal(M, -1)), np.ascontiguousarray(np.diagonal(M)),
            np.ascontiguousarray(np.diagonal(M, 1)))


# ----------------------------------------------------------------------------- residual


def _natural_residual(z: NDArray[np.float64], w: NDArray[np.float64],
                      q: NDArray[np.float64]) -> float:
    if z.size == 0:
        return 0.0
    return float(kernels.natural_residual(z, w, q))
