"""Linear complementarity problems: ``w = M z + q,  0 <= z ⟂ w >= 0``.

Three entry points, one analysis and one compiled chain of methods
(:mod:`nscontrol.numerics._lcp_dispatch_kernels`):

- :class:`LCPSolver` validates and analyses ``M`` once (structure, method choice) and then
  solves for many right-hand sides: ``LCPSolver(M).solve(q)`` pays per call for a check of
  ``q`` and one compiled call (the methods, ``auto``'s fallbacks, the residual test).
- :func:`solve_lcp` solves one problem: it is ``LCPSolver(M, ...).solve(q)``, run for a
  clean dense ``M`` as one compiled call.
- :func:`solve_lcp_kernel` is ``auto`` for a dense ``M`` as a numba function, for other
  ``@njit`` kernels (no Python in between).

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
be called from other ``@njit`` code. See ``docs/lcp.md`` for the algorithms, the compiled
entry and the figures.
"""

from __future__ import annotations

import math
from functools import cached_property
from operator import itemgetter
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
from . import _lcp_dispatch_kernels as dispatch
from . import _lcp_kernels as kernels
from ._lcp_dispatch_kernels import AUTO_BANDED_MIN_SIZE as AUTO_BANDED_MIN_SIZE
from ._lcp_dispatch_kernels import AUTO_DENSE_HOWARD_MAX_SIZE as AUTO_DENSE_HOWARD_MAX_SIZE
from ._lcp_dispatch_kernels import AUTO_LEMKE_MAX_SIZE as AUTO_LEMKE_MAX_SIZE
from ._lcp_dispatch_kernels import AUTO_PGS_FALLBACK_SWEEPS as AUTO_PGS_FALLBACK_SWEEPS
from ._lcp_dispatch_kernels import AUTO_PGS_MIN_SIZE as AUTO_PGS_MIN_SIZE
from ._lcp_dispatch_kernels import PGS_SWEEPS as PGS_SWEEPS
from ._lcp_dispatch_kernels import solve_lcp_kernel as solve_lcp_kernel

__all__ = ["LCPResult", "LCPSolver", "solve_lcp", "solve_lcp_kernel", "residual"]

Method = Literal["auto", "lemke", "pgs", "banded"]
METHODS = ("auto", "lemke", "pgs", "banded")
STATUSES = ("solved", "ray_termination", "max_iter", "numerical_failure", "overflow")

#: Sweeps of ``auto``'s PGS before it pays for a definiteness test (see ``_run_pgs_auto``).
AUTO_PGS_PROBE_SWEEPS = 100
#: A failed solve is retried on the problem rescaled by powers of two (exact) when
#: ``max|M|``, ``max|q|`` or their ratio lies outside ``2^(+-this)``: the scales at which
#: the float64 arithmetic of a solver can overflow or underflow.
RESCALE_EXPONENT = dispatch.RESCALE_EXPONENT

_F64 = np.dtype(np.float64)
#: Read once (the per-call paths below are a few hundred nanoseconds of Python).
_empty = np.empty
_METHOD_CODES = dispatch.METHOD_CODES
_LOG_SIZE = dispatch.LOG_ROWS * dispatch.LOG_WIDTH
_EMPTY_1D = np.empty(0)
_EMPTY_1D.setflags(write=False)
_EMPTY_2D = np.empty((0, 0))
_NO_BANDS = (np.empty(0), np.empty(0), np.empty(0))
#: The method that a run reports (``auto``'s two forms of PGS are PGS).
_RUN_METHOD = ("lemke", "pgs", "banded", "pgs", "pgs")


class LCPResult(tuple):
    """Outcome of :func:`solve_lcp` and :meth:`LCPSolver.solve`.

    An immutable record (built in a few tens of nanoseconds: it is what a small LCP's call
    returns); its fields are read by name.

    Parameters
    ----------
    z, w : ndarray, shape (n,)
        The computed point and ``w = M z + q`` (recomputed from ``z``, never taken on trust).
        On failure: the last iterate of the method that ran last; on ``"overflow"``: ``inf``
        where the solution exceeds the float64 range. Read-only.
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
        joined by ``"; "``, in the order they ran); formatted when first read from the
        compiled chain's log.
    tolerance : float
        The acceptance threshold :attr:`residual` was tested against: ``tol`` plus the
        round-off bound of evaluating ``M z + q`` (see :func:`solve_lcp`); ``-inf`` when
        ``z`` is so large that ``M z + q`` cancels beyond half the float64 digits, where
        no residual certifies anything (a near-ray of a nearly singular ``M``).

    Attributes
    ----------
    z, w, status, iterations, residual, method, message, tolerance
        The parameters, read-only.
    success : bool
        True when ``status == "solved"``.
    """

    __slots__ = ()

    def __new__(cls, z: NDArray[np.float64], w: NDArray[np.float64], status: str,
                iterations: int, residual: float, method: str, message: str = "",
                tolerance: float = math.nan) -> LCPResult:
        return _tuple_new(cls, (z, w, status, iterations, residual, method, message,
                                tolerance, None))

    z = property(itemgetter(0), doc="The computed point (read-only).")
    w = property(itemgetter(1), doc="``M z + q``, recomputed from ``z`` (read-only).")
    status = property(itemgetter(2), doc="How the solve ended (see the class docstring).")
    iterations = property(itemgetter(3), doc="Pivots, sweeps or iterations of the last run.")
    residual = property(itemgetter(4), doc="``max |min(z, w)| / (1 + max|q|)``.")
    method = property(itemgetter(5), doc="The method that produced ``z``.")
    tolerance = property(itemgetter(7), doc="The threshold the residual was tested against.")

    @property
    def message(self) -> str:
        """Why it stopped, and which methods were tried, in the order they ran."""
        message = tuple.__getitem__(self, 6)
        if type(message) is str:
            return message
        return _log_message(tuple.__getitem__(self, 8), len(tuple.__getitem__(self, 0)),
                            message)

    @property
    def success(self) -> bool:
        """True when ``status == "solved"``."""
        return tuple.__getitem__(self, 2) == "solved"

    def __repr__(self) -> str:
        fields = ", ".join(f"{name}={getattr(self, name)!r}" for name in _RESULT_FIELDS)
        return f"LCPResult({fields})"

    def __getnewargs__(self) -> tuple[Any, ...]:
        return tuple(getattr(self, name) for name in _RESULT_FIELDS)

    # a record, not a sequence: its fields are read by name
    def __iter__(self) -> Any:
        raise TypeError("LCPResult: read its fields by name (res.z, res.status, ...)")

    def __len__(self) -> int:
        raise TypeError("LCPResult: read its fields by name (res.z, res.status, ...)")


_tuple_new = tuple.__new__
#: ``ndarray.setflags`` called as ``_read_only(a, False)`` (``write=False`` given by position:
#: no keyword parsing, ~0.1 µs less per call; numpy's stubs declare it keyword-only).
_read_only: Any = np.ndarray.setflags
_RESULT_FIELDS = ("z", "w", "status", "iterations", "residual", "method", "message",
                  "tolerance")


def _log_result(buf: NDArray[np.float64], n: int, state: int, its: int, res: float,
                tolerance: float, strict: bool) -> LCPResult | None:
    """The result of a compiled chain that needs nothing more from Python, or None when it
    does (a hand-off, the rescaled retry, ``strict`` on a failure): read from the entry's
    packed ``state`` (:func:`dispatch.pack_out`) and its buffer ``buf``
    (:func:`dispatch.buffer_size`), which becomes the result's, read-only: the last run if
    verified; otherwise Lemke's ray termination if there was one (for copositive-plus ``M``
    a certificate that the LCP is infeasible: the entry has chosen it,
    :data:`dispatch.RAY_CHOSEN`), else the last run (what :func:`_choose` picks). Its message
    is formatted from the log when read. What a state means is decoded once
    (:data:`_ENDINGS`)."""
    ending = _ENDINGS.get(state)
    if ending is None:
        if not _ended(state):
            return None
        ending = _ENDINGS[state] = _ending(state)
    ray, status, method, nlog = ending
    if strict and status != "solved":
        return None                      # the caller goes on in Python, which raises
    _read_only(buf, False)
    k = 2 * n if ray else 0
    return _tuple_new(LCPResult, (buf[k:k + n], buf[k + n:k + 2 * n], status, its, res, method,
                                  nlog, tolerance, buf))


#: What an entry's state that ends the call means: ``(ray, status, method, nlog)``, decoded
#: by :func:`_ending` the first time the state is met (a call then reads it with one lookup).
_ENDINGS: dict[int, tuple[bool, str, str, int]] = {}


def _ending(state: int) -> tuple[bool, str, str, int]:
    """``(ray, status, method, nlog)`` of a state that ends the call (:func:`_ended`)."""
    ray = bool(state & _RAY_CHOSEN)
    status = "ray_termination" if ray else STATUSES[(state & 15) - 8]
    return ray, status, _RUN_METHOD[((state >> 4) & 15) - 1], ((state >> 8) & 15) - 1


def _ended(state: int) -> bool:
    """Whether a checked entry's chain (its packed ``state``) ended with nothing left for
    Python but ``strict``: at least one run, no hand-off, and either verified or not at
    extreme scales (the rescaled retry)."""
    code = (state & 15) - 8
    return (state >> 8) & 15 > 1 and code >= 0 and (code == 0 or not state & _EXTREME)


_EXTREME = dispatch.EXTREME
_RAY_CHOSEN = dispatch.RAY_CHOSEN


def _log_message(buf: NDArray[np.float64], n: int, nlog: int) -> str:
    """The message of the ``nlog`` runs logged in ``buf`` (:func:`_log_result`)."""
    log = buf[4 * n:4 * n + _LOG_SIZE].reshape(dispatch.LOG_ROWS, dispatch.LOG_WIDTH)
    parts = []
    for run, code, _, res, tolerance, limit in log[:nlog].tolist():
        parts.append(_describe(_RUN_METHOD[int(run)], STATUSES[int(code)], res, tolerance,
                               int(limit)))
    return "; ".join(parts)


def _describe(method: str, status: str, res: float, tolerance: float, limit: int,
              note: str = "") -> str:
    """``"name: status (residual r, ...)"``: why a run stopped, the budget if spent."""
    text = f"{method}: {status} (residual {res:.3g}"
    if status == "max_iter":
        unit = _UNITS.get(method, "iterations")
        text += note or f", budget max_iter = {limit} {unit} spent"
    elif status != "solved" and not math.isfinite(res):
        text += ", the iterate is not finite"
    elif status != "solved" and tolerance == -math.inf:
        text += ", not certifiable: M z + q cancels beyond half the float64 digits"
    elif status == "numerical_failure" and res > tolerance:
        text += f" above the tolerance {tolerance:.3g}"
    return text + ")"


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
    if (z0 is None and type(q) is _ndarray and type(tol) is float and type(omega) is float
            and (strict is False or strict is True) and type(method) is str):
        # the per-call path: LCPSolver's analysis and chain, in one compiled call whose
        # signature checks the types of M and q (a TypeError sends other kinds to the
        # general path) and whose first lines check the shapes and the options
        entry = _dense_entry
        if entry is _UNLOADED:
            entry = _ENTRIES.load().dense
        code = _METHOD_CODES.get(method, -1)
        limit = 0 if max_iter is None else (
            max_iter if type(max_iter) is int and max_iter >= 1 else -1)
        # only an array M reaches the compiled call: anything else (a sparse M, lists) fails
        # its signature, and numba's search for a conversion before the TypeError costs ~70 µs
        if entry is not None and code >= 0 and limit >= 0 and type(M) is _ndarray:
            n = q.size
            try:
                buf = _empty(_BUFFER_SIZES[n])
            except IndexError:
                buf = _empty(_buffer_size(n))
            try:
                state, its, res, tolerance = entry(M, q, buf, code, tol, limit, omega)
            except TypeError:
                state, its, res, tolerance = _UNCHECKED
            first = _FIRST_SOLVED.get(state)
            if first is not None:
                # the first run was verified: the buffer is the result's (z, w and the log)
                _read_only(buf, False)
                return _tuple_new(LCPResult, (buf[:n], buf[n:2 * n], "solved", its, res,
                                              first, 1, tolerance, buf))
            # the chain ended (verified after fallbacks, or every run failed and no
            # rescaled retry applies): the log has every run, nothing is left to do
            result = _log_result(buf, n, state, its, res, tolerance, strict)
            if result is not None:
                return result
            code, run, tried, nlog, extreme = dispatch.unpack_state(state)
            if nlog >= 0 and code != kernels.Q_NOT_FINITE and code != dispatch.UNCHECKED:
                # the runs done are kept: the solver goes on from where the chain stopped
                solver = LCPSolver(M, method, tol=tol, max_iter=max_iter, strict=strict,
                                   omega=omega)
                return solver._finish(q, None, buf[:n], buf[n:2 * n], buf[2 * n:],
                                      (code, run, tried, nlog))
        elif type(M) in _CSR_TYPES and (code == dispatch.AUTO or code == dispatch.BANDED):
            result = _solve_csr(M, q, tol, limit)
            if result is not None:
                return result
    solver = LCPSolver(M, method, tol=tol, max_iter=max_iter, strict=strict, omega=omega)
    return solver.solve(q, z0=z0)


#: scipy's CSR classes (``csr_matrix``, ``csr_array``), recorded when the general path first
#: meets a scipy.sparse ``M`` (:func:`_as_lcp_matrix`; nscontrol does not import scipy.sparse
#: itself): the types that :func:`solve_lcp` tries on its compiled CSR path.
_CSR_TYPES: set[type] = set()
#: The state of a CSR call whose banded run was verified (:func:`_solve_csr`).
_BANDED_SOLVED = dispatch.first_run_solved_state(dispatch.BANDED)


def _solve_csr(M: Any, q: NDArray[np.float64], tol: float, limit: int) -> LCPResult | None:
    """:func:`solve_lcp` of a tridiagonal ``n x n`` CSR ``M`` (``n > 2``) as one compiled
    call (:func:`dispatch.solve_csr_entry`: the bands read, Howard's tridiagonal iteration,
    its verification), or None for the general path: any other ``M``, int64 indices, a
    banded run that was not verified (the general path then runs ``auto``'s fallbacks)."""
    n = q.size
    entry = _csr_entry
    if entry is _UNLOADED:
        entry = _ENTRIES.load().csr
    if entry is None or n <= 2 or M.shape != (n, n):
        return None
    try:
        buf = _empty(_CSR_BUFFER_SIZES[n])
    except IndexError:
        buf = _empty(int(dispatch.csr_buffer_size(n)))
    try:
        state, its, res, tolerance = entry(M.indptr, M.indices, M.data, q, buf, tol, limit)
    except TypeError:
        return None
    # only a verified banded run is an answer here (any other end: the general path)
    return (_log_result(buf, n, state, its, res, tolerance, False)
            if state == _BANDED_SOLVED else None)


def _buffer_size(n: int) -> int:
    """Floats of the buffer of the per-call entries (:func:`dispatch.buffer_size`)."""
    return int(dispatch.buffer_size(n))


#: :func:`_buffer_size` for ``n < _TABULATED`` (a list read costs less than the call;
#: read in ``try``, an ``IndexError`` for larger ``n``), filled when the entries are loaded
#: (:meth:`_Entries.load`, before any solve).
_TABULATED = 2 * dispatch.LEMKE_FULL_TABLEAU_MAX_SIZE
_BUFFER_SIZES: list[int] = []
#: ``dispatch.csr_buffer_size(n)`` for ``n < _TABULATED``, filled with :data:`_BUFFER_SIZES`.
_CSR_BUFFER_SIZES: list[int] = []


class _Entries:
    """The compiled entries of the per-call paths (:func:`dispatch.exact_entry`), made on
    first use (loaded from numba's cache, not at import): ``dense`` for :func:`solve_lcp`,
    ``packed`` for :meth:`LCPSolver.solve`; None with numba's JIT disabled."""

    loaded = False
    dense: Any = None
    packed: Any = None
    csr: Any = None

    @classmethod
    def load(cls) -> type[_Entries]:
        cls.dense = dispatch.exact_entry(dispatch.solve_dense_entry,
                                         dispatch.SOLVE_DENSE_SIGNATURE)
        cls.packed = dispatch.exact_entry(dispatch.solve_packed_entry,
                                          dispatch.SOLVE_PACKED_SIGNATURE)
        cls.csr = dispatch.exact_entry(dispatch.solve_csr_entry, dispatch.SOLVE_CSR_SIGNATURE)
        _BUFFER_SIZES[:] = [_buffer_size(n) for n in range(_TABULATED)]
        _CSR_BUFFER_SIZES[:] = [int(dispatch.csr_buffer_size(n)) for n in range(_TABULATED)]
        cls.loaded = True
        global _dense_entry, _csr_entry
        _dense_entry, _csr_entry = cls.dense, cls.csr
        return cls


#: ``_Entries.dense`` and ``_Entries.csr`` as module globals, :data:`_UNLOADED` until
#: :meth:`_Entries.load` (one global read per call; a class attribute holding a dispatcher
#: is a descriptor, bound on every read).
_UNLOADED: Any = object()
_dense_entry: Any = _UNLOADED
_csr_entry: Any = _UNLOADED
#: ``np.ndarray`` (one global read in the per-call type checks instead of two lookups).
_ndarray = np.ndarray


_ENTRIES = _Entries
#: The state (:func:`dispatch.pack_out`) of a call whose arguments fail the entry's checks.
_UNCHECKED_STATE = (dispatch.UNCHECKED + 8) | (dispatch.NO_RUN + 1) << 4
_UNCHECKED = (_UNCHECKED_STATE, 0, math.nan, math.nan)
#: The method name by the state of a call whose first run was verified.
_FIRST_SOLVED = {dispatch.first_run_solved_state(run): _RUN_METHOD[run]
                 for run in range(len(_RUN_METHOD))}


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
        return _describe(self.method, self.status, self.residual, self.tolerance, self.limit,
                         self.note)


_UNITS = {"lemke": "pivots", "pgs": "sweeps", "banded": "iterations"}


class LCPSolver:
    """An LCP solver for one matrix ``M`` and many right-hand sides ``q``.

    The constructor validates ``M`` and the options and reads its structure once, in one
    compiled scan for a dense ``M`` (finiteness, tridiagonal bands, bandwidth, symmetry and
    diagonal where ``auto`` needs them): ``auto``'s first method and its fallbacks follow
    from it. :meth:`solve` then checks ``q`` and makes one compiled call that runs the
    methods and verifies the residual (``auto``'s fallbacks included; only ``auto``'s PGS
    for large symmetric ``M`` and Howard's iteration with sparse LU go through Python).
    :func:`solve_lcp` runs the same analysis and the same compiled chain.

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
        self._method_code: int = dispatch.METHOD_CODES[method]
        # plain floats in range skip the general checks (solve_lcp pays these per call)
        self.tol = tol if type(tol) is float and 0.0 < tol < math.inf else check_positive(
            "tol", tol)
        self.omega = omega if type(omega) is float and 0.0 < omega < 2.0 else (
            check_in_interval("omega", omega, 0.0, 2.0, open_interval=True))
        self.max_iter = None if max_iter is None else check_integer("max_iter", max_iter,
                                                                     minimum=1)
        self.strict = check_bool("strict", strict)
        M = M if _clean(M, 2, finite=False) else _as_lcp_matrix(M)
        self._M = M
        self.n: int = int(M.shape[0])
        if isinstance(M, np.ndarray):
            # one compiled scan: finiteness, tridiagonality, band, symmetry, diagonal
            finite, tridiagonal, banded, large_symmetric, positive_diagonal = (
                dispatch.analyse_dense(M))
            if not finite:
                check_finite("M", M)               # raises, with the count of bad entries
            self._bands = _bands_of(M) if tridiagonal else None
            self._banded_dense = bool(banded)
            self._flags: tuple[bool, bool] | None = (bool(large_symmetric),
                                                     bool(positive_diagonal))
        else:
            self._bands = _tridiagonal_bands(M)
            self._banded_dense = False
            self._flags = None                     # read when a fallback needs them
        self._structured = self.n > 2 and (self._bands is not None or self._sparse
                                           or self._banded_dense)
        large_symmetric = self._flags[0] if self._flags is not None else False
        self._first_run: int = int(dispatch.first_run(self._method_code, self._structured,
                                                      large_symmetric))
        self.first_method: str = dispatch.RUN_NAMES[self._first_run]
        self._rescaled_solvers: dict[int, LCPSolver] = {}
        self._max_iter0: int = self.max_iter or 0
        self._entry = (_ENTRIES if _ENTRIES.loaded else _ENTRIES.load()).__dict__["packed"]
        # the per-call arguments of dispatch.solve_packed, fixed once
        flags = self._flags or (False, False)
        self._packed = (
            _EMPTY_2D if self._sparse else M, *(self._bands or _NO_BANDS),
            dispatch.pack_state(self._method_code if self._flags else self._first_run,
                                self._first_run, not self._sparse, self._bands is not None,
                                self._sparse or self._banded_dense, self._structured, *flags))

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
        n = self.n
        if z0 is None:
            # the per-call path of a reusable solver: one compiled call, whose status is
            # already reconciled with the residual test (kernels.certify); its signature
            # checks the type of q (TypeError otherwise) and its first line q's length
            M, lower, diag, upper, bits = self._packed
            try:
                buf = _empty(_BUFFER_SIZES[n])
            except IndexError:
                buf = _empty(_buffer_size(n))
            entry = self._entry
            try:     # only an array q reaches the compiled call (see solve_lcp)
                out = (entry(M, lower, diag, upper, q, buf, bits, self.tol, self._max_iter0,
                             self.omega) if entry is not None and type(q) is _ndarray
                       else _UNCHECKED)
            except TypeError:
                out = _UNCHECKED
            state, its, res, tolerance = out
            first = _FIRST_SOLVED.get(state)
            if first is not None:
                _read_only(buf, False)           # z, w and the log are the result's
                return _tuple_new(LCPResult, (buf[:n], buf[n:2 * n], "solved", its, res,
                                              first, 1, tolerance, buf))
            if state == _UNCHECKED_STATE:
                q = self._check_q(q)               # raises, or a clean copy of q
                state, its, res, tolerance = dispatch.solve_packed_checked(
                    M, lower, diag, upper, q, buf, bits, self.tol, self._max_iter0,
                    self.omega)
            result = _log_result(buf, n, state, its, res, tolerance, self.strict)
            if result is not None:
                return result
            code, run, tried, nlog, extreme = dispatch.unpack_state(state)
            z, w, work = buf[:n], buf[n:2 * n], buf[2 * n:]
            z0v = None
        else:
            if not (type(q) is np.ndarray and q.dtype == _F64 and q.ndim == 1
                    and q.flags.c_contiguous and q.flags.writeable and q.shape[0] == n):
                q = self._check_q(q)
            z, w = np.empty(n), np.empty(n)
            work = np.empty(2 * n + _LOG_SIZE)
            z0v = as_vector("z0", z0, size=n)
            code, run, its, res, tolerance, tried, nlog = self._chain(
                q, z, w, z0v, True, self._first_run, 0, work, 0)
        if code == kernels.Q_NOT_FINITE:
            check_finite("q", q)
        return self._finish(q, z0v, z, w, work, (code, run, tried, nlog))

    def _chain(self, q: NDArray[np.float64], z: NDArray[np.float64], w: NDArray[np.float64],
               z0: NDArray[np.float64], warm: bool, run: int, tried: int,
               work: NDArray[np.float64], nlog: int) -> tuple[int, int, int, float, float,
                                                               int, int]:
        """:func:`_lcp_dispatch_kernels.run_chain` from ``run`` with this solver's matrix and
        flags. A sparse ``M``'s flags are read only once its first run has failed: until
        then the chain runs that run alone."""
        has_dense = not self._sparse or "_dense" in self.__dict__
        M = self._dense if has_dense else _EMPTY_2D
        lower, diag, upper = self._bands if self._bands is not None else _NO_BANDS
        if self._flags is None:
            method, large_symmetric, positive_diagonal = run, False, False
        else:
            method = self._method_code
            large_symmetric, positive_diagonal = self._flags
        return dispatch.run_chain(
            M, has_dense, lower, diag, upper, self._bands is not None,
            self._sparse or self._banded_dense, q, z, w, z0, warm, method, run, tried,
            self._structured, large_symmetric, positive_diagonal, self.tol,
            self.max_iter or 0, self.omega, work, nlog, False)

    def _finish(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                z: NDArray[np.float64], w: NDArray[np.float64], work: NDArray[np.float64],
                state: tuple[int, int, int, int]) -> LCPResult:
        """The rest of a solve whose first run was not verified: the runs that need Python
        (handed over by the chain), the chain again after them, then the choice of the
        result, the rescaled retry and ``strict``."""
        code, run, tried, nlog = state
        tried_runs = self._logged(work, 0, nlog, z, w)
        while True:
            if code == dispatch.HANDOFF:
                if run == dispatch.PGS_AUTO or (run == dispatch.BANDED and self._bands is None):
                    outcome = (self._run_pgs_auto(q, z0, self.max_iter)
                               if run == dispatch.PGS_AUTO else self._run_banded_lu(q, z0))
                    tried_runs.append(outcome)
                    tried |= int(dispatch.family(run))
                    if outcome.status == "solved":
                        break
                    run = self._next_run(tried)
                else:
                    self.__dict__.setdefault("_dense", self._dense)   # densify sparse M once
            elif code == 0:
                break
            elif self._flags is None and self._method_code == dispatch.AUTO:
                run = self._next_run(tried)        # a sparse M's first run failed
            else:
                break
            if run == dispatch.NO_RUN:
                break
            z0v, warm = (z, False) if z0 is None else (z0, True)
            code, run, _, _, _, tried, end = self._chain(q, z, w, z0v, warm, run, tried,
                                                         work, nlog)
            tried_runs += self._logged(work, nlog, end, z, w)
            nlog = end
        result, chosen = _choose(tried_runs)
        if result.status != "solved":
            result = self._retry_rescaled(q, z0, result)
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

    def _next_run(self, tried: int) -> int:
        """``auto``'s next run (:func:`_lcp_dispatch_kernels.next_run`), the flags read first."""
        if self._flags is None:
            large = self.n > AUTO_PGS_MIN_SIZE and self._symmetric_positive_diagonal
            self._flags = (bool(large), bool(np.all(self._M.diagonal() > 0.0)))
        return int(dispatch.next_run(self._method_code, tried, self.n, self._structured,
                                     *self._flags))

    def _logged(self, work: NDArray[np.float64], start: int, end: int,
                z: NDArray[np.float64], w: NDArray[np.float64]) -> list[_Outcome]:
        return _logged_runs(work, self.n, start, end, z, w)

    def _limit(self, name: str, max_iter: int | None = None) -> int:
        """The budget of one run of method ``name``: ``max_iter`` when given (else the
        solver's), otherwise the method's default (see :func:`solve_lcp`)."""
        run = dispatch.RUN_NAMES.index(name)
        return int(dispatch.run_limit(run, self.n, max_iter or self.max_iter or 0))

    def _check_q(self, q: Any) -> NDArray[np.float64]:
        """``q`` as a writeable C-contiguous float64 vector of length n; finiteness is
        checked here only off the fast path (the compiled chain checks it, and the caller
        raises)."""
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
    def _symmetric_positive_diagonal(self) -> bool:
        M = self._dense
        scale = max(float(np.max(np.abs(M), initial=0.0)), 1.0)
        return bool(np.all(np.diagonal(M) > 0.0) and kernels.is_symmetric(M, 1e-12 * scale))

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

    # ------------------------------------------------------------------ runners in Python

    def _outcome(self, z: NDArray[np.float64], w: NDArray[np.float64], code: int,
                 iterations: int, res: float, tolerance: float, method: str, limit: int
                 ) -> _Outcome:
        return _make_outcome(z, w, code, iterations, res, tolerance, method, limit)

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

    def _run_pgs(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                 max_iter: int | None) -> _Outcome:
        n = self.n
        z = np.zeros(n) if z0 is None else np.array(z0)   # the kernel clamps z0 to >= 0
        w = np.empty(n)
        limit = self._limit("pgs", max_iter)
        code, its, res, tolerance = kernels.pgs_verified(
            self._dense, q, z, w, self.tol, limit, self.omega, False)
        return self._outcome(z, w, code, its, res, tolerance, "pgs", limit)

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

    def _run_banded_lu(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None
                       ) -> _Outcome:
        """Howard's iteration with sparse LU (sparse or narrow-band ``M`` without
        tridiagonal bands), verified."""
        limit = self._limit("banded")
        z = np.zeros(self.n) if z0 is None else z0.copy()
        code, its, z = self._howard(q, z, limit)
        w, res, tolerance, ok = self._verify(z, q)
        return self._outcome(z, w, int(kernels.verified_status(code, ok)), its, res,
                             tolerance, "banded", limit)

    @cached_property
    def _howard_matrix(self) -> Any:
        """``M`` for Howard's active-set solves with SuperLU (O(n b^2) per step)."""
        import scipy.sparse as sp
        return sp.csc_matrix(self._M)

    def _howard(self, q: NDArray[np.float64], z: NDArray[np.float64], limit: int
                ) -> tuple[int, int, NDArray[np.float64]]:
        """Howard's policy iteration with SuperLU on the active set (sparse or narrow-band
        ``M``): the iteration of :func:`~nscontrol.numerics._lcp_dispatch_kernels.dense_howard`,
        whose stopping test and cycle detection it shares (``howard_converged``,
        ``howard_cycle``: a repeated active set is a cycle, it stops at once with
        ``"max_iter"`` and ``auto`` falls back to the next method)."""
        M = self._howard_matrix
        n = self.n
        eps = float(dispatch.howard_eps(q))
        w = np.ascontiguousarray(M @ z + q, dtype=np.float64)
        active = np.empty(n, dtype=np.bool_)
        seen = np.empty((min(limit + 1, 16), n), dtype=np.bool_)
        nseen = 0
        for it in range(limit + 1):
            if dispatch.howard_converged(z, w, eps):
                return kernels.SOLVED, it, z
            if it == limit:
                break
            if nseen == seen.shape[0]:
                seen = dispatch.grow_rows(seen)
            if dispatch.howard_cycle(z, w, active, seen, nseen):
                return kernels.MAX_ITER, it, z
            nseen += 1
            z = np.zeros_like(z)
            idx = np.flatnonzero(active)
            if idx.size:
                z_a = _sparse_block_solver(M, idx, -q[idx])
                if z_a is None:                  # singular principal block
                    return kernels.NUMERICAL_FAILURE, it + 1, z
                z[idx] = z_a
            w = np.ascontiguousarray(M @ z + q, dtype=np.float64)
            if not np.all(np.isfinite(z)):
                return kernels.NUMERICAL_FAILURE, it + 1, z
        return kernels.MAX_ITER, limit, z

    # ------------------------------------------------------------------ overflow

    def _retry_rescaled(self, q: NDArray[np.float64], z0: NDArray[np.float64] | None,
                        failed: LCPResult) -> LCPResult:
        """Retry a failed solve on ``LCP(M / 2^a, q / 2^b)`` when the scales are extreme
        (see :data:`RESCALE_EXPONENT`); its solution times ``2^(b - a)`` solves the
        original LCP. Report ``"overflow"`` when that product exceeds float64."""
        a, b, extreme = dispatch.scale_exponents(
            self._dense if not self._sparse else np.ascontiguousarray(self._M.data), q)
        if not extreme:
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
            m_max = float(np.max(np.abs(self._dense if not self._sparse else self._M.data),
                                 initial=0.0))
            q_max = float(np.max(np.abs(q), initial=0.0))
            return self._overflow(z, w, r, (int(a), int(b)), q_max, m_max, note)
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


def _make_outcome(z: NDArray[np.float64], w: NDArray[np.float64], code: int,
                  iterations: int, res: float, tolerance: float, method: str, limit: int
                  ) -> _Outcome:
    """A run's outcome from a status already reconciled with the residual test."""
    z.setflags(write=False)
    w.setflags(write=False)
    return _Outcome(z, w, STATUSES[code], int(iterations), float(res), method,
                    float(tolerance), int(limit))


def _logged_runs(work: NDArray[np.float64], n: int, start: int, end: int,
                 z: NDArray[np.float64], w: NDArray[np.float64]) -> list[_Outcome]:
    """The runs the chain logged in rows ``start:end`` of ``work``, as outcomes. Only the
    last one's point (``z, w``) and a ray's (kept in ``work``) can be the answer: the
    others' are not kept."""
    log = work[2 * n:2 * n + _LOG_SIZE].reshape(dispatch.LOG_ROWS, dispatch.LOG_WIDTH)
    out = []
    for k in range(start, end):
        run, code, its, res, tolerance, limit = log[k].tolist()
        if k == end - 1:
            zk, wk = z.copy(), w.copy()
        elif int(code) == kernels.RAY_TERMINATION:
            zk, wk = work[:n].copy(), work[n:2 * n].copy()
        else:
            zk = wk = _EMPTY_1D
        out.append(_make_outcome(zk, wk, int(code), int(its), res, tolerance,
                                 _RUN_METHOD[int(run)], int(limit)))
    return out


def _choose(tried: list[_Outcome]) -> tuple[LCPResult, _Outcome]:
    """The result of the runs ``tried`` (in the order they ran): the last one if verified;
    otherwise Lemke's ray termination if there was one (for copositive-plus ``M`` a
    certificate that the LCP is infeasible), else the last run's. The message lists every
    run. Returns it with the chosen run."""
    chosen = tried[-1]
    if chosen.status != "solved":
        chosen = next((o for o in tried if o.status == "ray_termination"), chosen)
    message = "; ".join(o.describe() for o in tried)
    return LCPResult(chosen.z, chosen.w, chosen.status, chosen.iterations, chosen.residual,
                     chosen.method, message, chosen.tolerance), chosen


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


# ----------------------------------------------------------------------------- input


def _as_lcp_matrix(M: Any) -> Any:
    """A finite square dense float array, or a finite square scipy.sparse CSR matrix."""
    if _clean(M, 2) and M.shape[0] == M.shape[1]:
        return M
    if hasattr(M, "tocsr") and not isinstance(M, np.ndarray):
        if not _CSR_TYPES:
            import scipy.sparse as sp
            _CSR_TYPES.update((sp.csr_matrix, sp.csr_array))
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


def _clean(a: Any, ndim: int, finite: bool = True) -> bool:
    """Fast path: already a writeable C-contiguous float64 array of rank ``ndim`` (square
    when ``ndim == 2``), finite unless ``finite=False`` (the caller's compiled scan checks it);
    the checks of ``nscontrol._validation`` run otherwise, and raise their specific errors.
    A read-only array is copied rather than given its own numba specialisation."""
    return (type(a) is np.ndarray and a.dtype == _F64 and a.ndim == ndim
            and a.flags.c_contiguous and a.flags.writeable
            and (ndim != 2 or a.shape[0] == a.shape[1])
            and (not finite or bool(kernels.all_finite(a.reshape(-1)))))


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
    """``(lower, diag, upper)`` of a dense matrix, as writeable contiguous copies (a band of
    one entry is contiguous, so ``np.ascontiguousarray`` would return numpy's read-only
    view: the solver's exact-signature entry refuses it, and every ``solve`` of a 2 x 2
    ``M`` took the general path, ~200 µs)."""
    return np.diagonal(M, -1).copy(), np.diagonal(M).copy(), np.diagonal(M, 1).copy()


# ----------------------------------------------------------------------------- residual


def _natural_residual(z: NDArray[np.float64], w: NDArray[np.float64],
                      q: NDArray[np.float64]) -> float:
    if z.size == 0:
        return 0.0
    return float(kernels.natural_residual(z, w, q))
