"""Compiled dispatch of the LCP methods: ``auto``'s order, its chain of verified runs, and the
compiled entry :func:`solve_lcp_kernel` for other ``@njit`` code.

:class:`~nscontrol.numerics.lcp.LCPSolver` and :func:`~nscontrol.numerics.lcp.solve_lcp` run
every method here except two, which need LAPACK or SuperLU through Python: ``auto``'s PGS
with its positive-semidefiniteness test (``n > 400``) and Howard's iteration with sparse LU
(scipy.sparse ``M``, or dense ``M`` with ``n >= 64`` and a narrow band). The chain
(:func:`run_chain`) runs methods until one is verified; when the next one needs Python it
returns :data:`HANDOFF` with that run, and the caller runs it and calls the chain again.
Which method comes next is decided in one place, :func:`next_run`, for both.

*Runs* (what the log records): :data:`LEMKE`, :data:`PGS`, :data:`BANDED`, and ``auto``'s
two forms of PGS, :data:`PGS_AUTO` (the probe and the definiteness test, large symmetric
``M``) and :data:`PGS_FALLBACK` (any matrix with a positive diagonal, 1000 sweeps).
*Families* (``auto`` runs each at most once): Lemke 1, PGS 2, banded 4.

The log: ``work[2 n:]`` holds :data:`LOG_ROWS` rows of :data:`LOG_WIDTH` numbers, one per run
in the order they ran: ``(run, status, iterations, residual, tolerance, limit)``; ``work[:2
n]`` receives ``(z, w)`` of a Lemke run that ended on a ray (``auto`` reports that
certificate of infeasibility when every method fails).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit, types

from ._lcp_kernels import (
    LEMKE_FULL_TABLEAU_MAX_SIZE,
    MAX_ITER,
    NO_REFCOUNT,
    NUMERICAL_FAILURE,
    Q_NOT_FINITE,
    RAY_TERMINATION,
    SOLVED,
    _lemke_into,
    _matvec_plus,
    _pgs_verified_in,
    _solve_principal_block,
    all_finite,
    csr_tridiagonal_bands,
    half_bandwidth,
    is_symmetric,
    lemke_verified,
    lemke_work_size,
    pgs_verified,
    pgs_work_size,
    tridiagonal_verified,
    verified_status,
    verify_dense,
)

#: Reference counting set explicitly on the functions that the entries without it call
#: (:func:`solve_dense_entry`): numba's callees inherit the caller's option unless they set
#: their own, and the chain allocates.
WITH_REFCOUNT: dict[str, Any] = {"_nrt": True}


#: ``auto`` uses PGS instead of Lemke for symmetric PSD problems larger than this.
AUTO_PGS_MIN_SIZE = 400
#: ``auto`` does not fall back to dense Lemke or PGS above this size (memory n^2, time n^3).
AUTO_LEMKE_MAX_SIZE = 3000
#: PGS's default budget of sweeps (``max_iter``).
PGS_SWEEPS = 10_000
#: Sweeps of PGS as a fallback of ``auto`` on a matrix it is not known to converge for
#: (a cost comparable to dense Lemke's O(n^3)).
AUTO_PGS_FALLBACK_SWEEPS = 1000
#: ``auto`` tries ``banded`` first on dense matrices this large with a narrow band.
AUTO_BANDED_MIN_SIZE = 64
#: ``auto`` falls back to Howard's iteration with dense LU (O(n^3) per iteration) up to here.
AUTO_DENSE_HOWARD_MAX_SIZE = 200

# runs
NO_RUN = -1
LEMKE = 0
PGS = 1
BANDED = 2
PGS_AUTO = 3
PGS_FALLBACK = 4
#: The ``method`` option ``"auto"`` (the explicit methods are their runs).
AUTO = 5
RUN_NAMES = ("lemke", "pgs", "banded", "pgs_auto", "pgs_fallback")
METHOD_CODES = {"lemke": LEMKE, "pgs": PGS, "banded": BANDED, "auto": AUTO}

#: Status of :func:`run_chain`: the next run needs Python (returned with that run).
HANDOFF = -3
#: Rows and columns of the log (at most one run per family, and ``auto``'s PGS probe).
LOG_ROWS = 4
LOG_WIDTH = 6


@njit(cache=True, inline='always')
def family(run):
    """The family of a run (1 Lemke, 2 PGS, 4 banded): ``auto`` runs each at most once."""
    if run == LEMKE:
        return 1
    if run == BANDED:
        return 4
    return 2


@njit(cache=True, inline='always')
def first_run(method, structured, large_symmetric):
    """The first run of ``method``: an explicit method is its own run; ``auto`` picks
    ``banded`` for structured ``M`` (tridiagonal, sparse or narrow-band, ``n > 2``), the PGS
    probe for large symmetric ``M`` with a positive diagonal (``n > 400``), else Lemke."""
    if method != AUTO:
        return method
    if structured:
        return BANDED
    if large_symmetric:
        return PGS_AUTO
    return LEMKE


@njit(cache=True, inline='always')
def next_run(method, tried, n, structured, large_symmetric, positive_diagonal):
    """``auto``'s next run after the families in the bit set ``tried`` failed, or
    :data:`NO_RUN` (always for an explicit method). The one place the order is decided:
    the PGS probe (after ``banded``), Lemke (``n <= 3000``), PGS on a positive diagonal
    (``n <= 3000``), Howard's iteration with dense LU (``n <= 200``)."""
    if method != AUTO:
        return NO_RUN
    if tried & 2 == 0 and structured and large_symmetric:
        return PGS_AUTO
    if tried & 1 == 0 and n <= AUTO_LEMKE_MAX_SIZE:
        return LEMKE
    if tried & 2 == 0 and n <= AUTO_LEMKE_MAX_SIZE and positive_diagonal:
        return PGS_FALLBACK
    if tried & 4 == 0 and n <= AUTO_DENSE_HOWARD_MAX_SIZE:
        return BANDED
    return NO_RUN


@njit(cache=True, inline='always')
def run_limit(run, n, max_iter):
    """The budget of one run: ``max_iter`` when positive, else the run's default (Lemke
    ``50 (n + 1)`` pivots, banded ``n + 2`` iterations, PGS ``10^4`` sweeps, ``auto``'s PGS
    fallback 1000)."""
    if max_iter > 0:
        return max_iter
    if run == LEMKE:
        return 50 * (n + 1)
    if run == BANDED:
        return n + 2
    if run == PGS_FALLBACK:
        return AUTO_PGS_FALLBACK_SWEEPS
    return PGS_SWEEPS


# --------------------------------------------------------------------------------- analysis
@njit(cache=True, inline='always')
def analyse_dense(M):
    """One look at a dense square ``M`` (done once per matrix): ``(finite, tridiagonal,
    banded, large_symmetric, positive_diagonal)``. ``banded``: ``n >= 64`` and half-bandwidth
    ``<= max(2, sqrt(n))`` (Howard's iteration with sparse LU first); ``large_symmetric``:
    ``n > 400``, symmetric to ``1e-12 max(max|M|, 1)`` with a positive diagonal.

    It is part of every :func:`~nscontrol.numerics.lcp.solve_lcp` call, so each flag costs
    only what it needs: finiteness is the one full pass, a branch-free ``or`` over the rows
    (SIMD); the off-band scan stops at the first non-zero (row 0 of a dense ``M``); ``max|M|``
    and symmetry are read only above ``n = 400``."""
    n = M.shape[0]
    bad = False
    for i in range(n):
        for j in range(n):
            bad |= not (abs(M[i, j]) < np.inf)     # NaN compares False
    finite = not bad
    tridiagonal = True
    for i in range(n):
        for j in range(i + 2, n):
            if M[i, j] != 0.0 or M[j, i] != 0.0:
                tridiagonal = False
                break
        if not tridiagonal:
            break
    positive_diagonal = True
    for i in range(n):
        if not (M[i, i] > 0.0):
            positive_diagonal = False
    banded = False
    if finite and not tridiagonal and n >= AUTO_BANDED_MIN_SIZE:
        limit = max(2, int(np.sqrt(n)))
        banded = half_bandwidth(M, limit) <= limit
    large_symmetric = False
    if finite and n > AUTO_PGS_MIN_SIZE and positive_diagonal:
        big = 0.0
        for i in range(n):
            for j in range(n):
                big = max(big, abs(M[i, j]))
        large_symmetric = is_symmetric(M, 1e-12 * max(big, 1.0))
    return finite, tridiagonal, banded, large_symmetric, positive_diagonal


@njit(cache=True)
def dense_bands(M):
    """``(lower, diag, upper)`` of a dense matrix, as contiguous copies."""
    n = M.shape[0]
    lower = np.empty(max(n - 1, 0))
    diag = np.empty(n)
    upper = np.empty(max(n - 1, 0))
    for i in range(n):
        diag[i] = M[i, i]
        if i < n - 1:
            lower[i] = M[i + 1, i]
            upper[i] = M[i, i + 1]
    return lower, diag, upper


# --------------------------------------------------------------------------------- Howard
@njit(cache=True)
def howard_converged(z, w, eps):
    """Howard's stopping test: ``z, w >= -eps`` and ``min(z, w) <= eps`` (False on NaN)."""
    for i in range(z.shape[0]):
        if not (z[i] >= -eps and w[i] >= -eps and min(z[i], w[i]) <= eps):
            return False
    return True


@njit(cache=True)
def howard_cycle(z, w, active, seen, nseen):
    """Howard's next active set ``{w <= z}`` into ``active``; True when it equals one of
    ``seen[:nseen]`` (the next iterate depends only on the active set: a cycle), else it is
    recorded as ``seen[nseen]`` (the caller grows ``seen`` by :func:`grow_rows` first)."""
    n = z.shape[0]
    for i in range(n):
        active[i] = w[i] <= z[i]
    for k in range(nseen):
        same = True
        for i in range(n):
            if seen[k, i] != active[i]:
                same = False
                break
        if same:
            return True
    for i in range(n):
        seen[nseen, i] = active[i]
    return False


@njit(cache=True)
def grow_rows(seen):
    """``seen`` with twice the rows (the first ones copied)."""
    rows, n = seen.shape
    out = np.empty((2 * rows, n), dtype=np.bool_)
    out[:rows] = seen
    return out


@njit(cache=True)
def howard_eps(q):
    """Howard's feasibility tolerance ``1e-13 (1 + max|q|)``."""
    qmax = 0.0
    for i in range(q.shape[0]):
        qmax = max(qmax, abs(q[i]))
    return 1e-13 * (1.0 + qmax)


@njit(cache=True)
def dense_howard(M, q, z, w, limit):
    """Howard's policy iteration from ``z`` for a dense ``M`` (Gaussian elimination with
    partial pivoting on the active block): the iteration of
    :func:`~nscontrol.numerics._lcp_kernels.tridiagonal_howard` without the tridiagonal
    structure, stopped at once when an active set repeats (a cycle: ``max_iter``). Returns
    ``(status_code, iterations)``; ``w`` receives ``M z + q``."""
    n = q.shape[0]
    eps = howard_eps(q)
    _matvec_plus(M, z, q, w)
    active = np.empty(n, dtype=np.bool_)
    seen = np.empty((min(limit + 1, 16), n), dtype=np.bool_)
    idx = np.empty(n, dtype=np.int64)
    x = np.empty(n)
    block = np.empty(n * (n + 1))       # every iteration's elimination, allocated once
    nseen = 0
    for it in range(limit + 1):
        if howard_converged(z, w, eps):
            return SOLVED, it
        if it == limit:
            break
        if nseen == seen.shape[0]:
            seen = grow_rows(seen)
        if howard_cycle(z, w, active, seen, nseen):
            return MAX_ITER, it
        nseen += 1
        k = 0
        for i in range(n):
            z[i] = 0.0
            if active[i]:
                idx[k] = i
                k += 1
        if k > 0:
            if not _solve_principal_block(M, q, idx, k, x, block):
                _matvec_plus(M, z, q, w)
                return NUMERICAL_FAILURE, it + 1
            for r in range(k):
                z[idx[r]] = x[r]
        _matvec_plus(M, z, q, w)
        if not all_finite(z):
            return NUMERICAL_FAILURE, it + 1
    return MAX_ITER, limit


# --------------------------------------------------------------------------------- the chain
@njit(cache=True, inline='always')
def _start(z, z0, warm):
    """``z`` set to the warm start ``z0`` (copied), or to zero."""
    for i in range(z.shape[0]):
        z[i] = z0[i] if warm else 0.0


@njit(cache=True, inline='always')
def run_one(run, M, lower, diag, upper, has_bands, q, z, w, z0, warm, limit, tol, omega):
    """One verified run that needs no Python: ``(status_code, iterations, residual,
    tolerance)``, the status reconciled with the residual test (``certify``)."""
    if run == LEMKE:
        return lemke_verified(M, q, z, w, limit, tol)
    if run == BANDED:
        _start(z, z0, warm)
        if has_bands:
            if diag.shape[0] != q.shape[0]:      # bands not given: read them from M
                lower, diag, upper = dense_bands(M)
            return tridiagonal_verified(lower, diag, upper, q, z, w, limit, warm, tol)
        code, its = dense_howard(M, q, z, w, limit)
        res, tolerance, ok = verify_dense(M, q, z, w, tol)
        return verified_status(code, ok), its, res, tolerance
    _start(z, z0, warm)   # PGS (the kernel clamps a warm start to z >= 0)
    return pgs_verified(M, q, z, w, tol, limit, omega, False)


@njit(cache=True, inline='always')
def needs_python(run, has_dense, has_bands, sparse_lu):
    """Whether a run must go through Python: ``auto``'s PGS probe (its definiteness test),
    Howard's iteration with sparse LU (``sparse_lu``: scipy.sparse or narrow-band ``M``
    without tridiagonal bands), a dense method while only a sparse ``M`` is at hand."""
    if run == PGS_AUTO:
        return True
    if run == BANDED:
        return not has_bands and (sparse_lu or not has_dense)
    return not has_dense


@njit(cache=True, inline='always')
def _log_run(work, n, nlog, run, code, its, res, tolerance, limit, z, w):
    """Row ``nlog`` of the log in ``work[2 n:]`` (module docstring); a ray's ``(z, w)`` is
    kept in ``work[:2 n]``."""
    row = 2 * n + LOG_WIDTH * nlog
    work[row] = run
    work[row + 1] = code
    work[row + 2] = its
    work[row + 3] = res
    work[row + 4] = tolerance
    work[row + 5] = limit
    if code == RAY_TERMINATION:
        for i in range(n):
            work[i] = z[i]
            work[n + i] = w[i]


@njit(cache=True, inline='always')
def buffer_size(n):
    """Floats of the buffer of the per-call entries (:func:`solve_dense_into`,
    :func:`solve_packed`): ``z``, ``w``, the work array of :func:`run_chain` (``2 n`` and the
    log), and up to ``n =`` :data:`~nscontrol.numerics._lcp_kernels.LEMKE_FULL_TABLEAU_MAX_SIZE`
    the workspace of Lemke's or PGS's (the larger), where a first run of either
    (:func:`first_in_buffer`) needs no allocation."""
    size = 4 * n + LOG_ROWS * LOG_WIDTH
    if n <= LEMKE_FULL_TABLEAU_MAX_SIZE:
        size += max(lemke_work_size(n), pgs_work_size(n))
    return size


@njit(cache=True, **NO_REFCOUNT)
def first_in_buffer(run, M, q, buf, tol, limit, omega):
    """A first run that is Lemke's or PGS's (cold) on a dense ``M``, in a buffer of
    :func:`buffer_size` floats with its workspace (``n <=``
    :data:`~nscontrol.numerics._lcp_kernels.LEMKE_FULL_TABLEAU_MAX_SIZE`), without
    allocation or reference counting: what :func:`run_one` computes for ``run``, bit for bit
    (:func:`~nscontrol.numerics._lcp_kernels.lemke_into` is ``lemke_kernel``, and
    ``_pgs_verified_in`` is ``pgs_verified``, in a given workspace), logged as
    :func:`run_chain` logs it, as row 0. Returns
    ``(status_code, iterations, residual, tolerance)`` (the status reconciled with the
    residual test), :data:`~nscontrol.numerics._lcp_kernels.Q_NOT_FINITE` for a ``q`` that
    is not finite (nothing logged)."""
    n = q.shape[0]
    if not all_finite(q):
        return Q_NOT_FINITE, 0, np.nan, np.nan
    z = buf[:n]
    w = buf[n:2 * n]
    work = buf[4 * n + LOG_ROWS * LOG_WIDTH:]
    if run == LEMKE:
        code, its = _lemke_into(M, q, z, w, limit, work, False)
        res, tolerance, ok = verify_dense(M, q, z, w, tol)
        code = verified_status(code, ok)
    else:
        code, its, res, tolerance = _pgs_verified_in(M, q, z, w, tol, limit, omega, True,
                                                     work)
    _log_run(buf[2 * n:], n, 0, run, code, its, res, tolerance, limit, z, w)
    return code, its, res, tolerance


@njit(cache=True, inline='always')
def run_chain(M, has_dense, lower, diag, upper, has_bands, sparse_lu, q, z, w, z0, warm,
              method, run, tried, structured, large_symmetric, positive_diagonal, tol,
              max_iter, omega, work, nlog, skip_python):
    """Run ``run``, then ``auto``'s next runs (:func:`next_run`), until one is verified.

    Appends one log row per run to ``work`` (module docstring) from row ``nlog``. Returns
    ``(code, run, iterations, residual, tolerance, tried, nlog)``: ``code`` :data:`SOLVED`
    with the verified run and its figures; :data:`HANDOFF` with the run that needs Python
    (``needs_python``; with ``skip_python`` such runs are passed over instead);
    :data:`~nscontrol.numerics._lcp_kernels.Q_NOT_FINITE` when ``q`` is not finite; else
    the last run's status (no run verified, or no run at all: ``run`` :data:`NO_RUN`).
    ``z, w`` hold the last run's point.
    """
    n = q.shape[0]
    if not all_finite(q):
        return Q_NOT_FINITE, run, 0, np.nan, np.nan, tried, nlog
    code, its, res, tolerance = NUMERICAL_FAILURE, 0, np.nan, np.nan
    last = NO_RUN
    while run != NO_RUN:
        if needs_python(run, has_dense, has_bands, sparse_lu):
            if not skip_python:
                return HANDOFF, run, 0, np.nan, np.nan, tried, nlog
            tried |= family(run)
        else:
            limit = run_limit(run, n, max_iter)
            code, its, res, tolerance = run_one(run, M, lower, diag, upper, has_bands, q, z,
                                                w, z0, warm, limit, tol, omega)
            _log_run(work, n, nlog, run, code, its, res, tolerance, limit, z, w)
            nlog += 1
            last = run
            tried |= family(run)
            if code == SOLVED:
                return SOLVED, run, its, res, tolerance, tried, nlog
        run = next_run(method, tried, n, structured, large_symmetric, positive_diagonal)
    return code, last, its, res, tolerance, tried, nlog


@njit(cache=True, inline='always')
def _chain_from_first(M, has_dense, lower, diag, upper, has_bands, sparse_lu, q, buf, method,
                      run, structured, large_symmetric, positive_diagonal, tol, max_iter,
                      omega, skip_python):
    """:func:`run_chain` from the first run ``run``, the runs in ``buf`` (``z``, ``w``, the
    work array; :func:`buffer_size`). A first Lemke or PGS run on a dense ``M`` up to
    :data:`~nscontrol.numerics._lcp_kernels.LEMKE_FULL_TABLEAU_MAX_SIZE` is made by
    :func:`first_in_buffer` (the per-call path of a small LCP: no allocation); the chain goes
    on from there if it is not verified."""
    n = q.shape[0]
    tried = 0
    nlog = 0
    if ((run == LEMKE or run == PGS) and has_dense and n <= LEMKE_FULL_TABLEAU_MAX_SIZE
            and buf.shape[0] >= buffer_size(n)):
        limit = run_limit(run, n, max_iter)
        code, its, res, tolerance = first_in_buffer(run, M, q, buf, tol, limit, omega)
        if code == SOLVED:
            return SOLVED, run, its, res, tolerance, family(run), 1
        if code == Q_NOT_FINITE:
            return Q_NOT_FINITE, run, 0, np.nan, np.nan, 0, 0
        first = run
        tried = family(run)
        nlog = 1
        run = next_run(method, tried, n, structured, large_symmetric, positive_diagonal)
        if run == NO_RUN:
            return code, first, its, res, tolerance, tried, nlog
    z = buf[:n]
    return run_chain(M, has_dense, lower, diag, upper, has_bands, sparse_lu, q, z,
                     buf[n:2 * n], z, False, method, run, tried, structured, large_symmetric,
                     positive_diagonal, tol, max_iter, omega, buf[2 * n:], nlog, skip_python)


@njit(cache=True)
def solve_dense(M, q, buf, method, tol, max_iter, omega, skip_python):
    """:func:`analyse_dense` and :func:`run_chain` from the first run, in one call: what
    ``LCPSolver(M, method, ...).solve(q)`` computes for a dense ``M`` (the same analysis,
    the same chain), with ``z, w`` and the work array in one buffer of :func:`buffer_size`
    floats: ``buf[:n]`` receives ``z``, ``buf[n:2 n]`` ``w``. Returns the chain's tuple;
    :data:`NUMERICAL_FAILURE` with ``run`` :data:`NO_RUN` and ``nlog = -1`` when ``M`` is not
    finite."""
    finite, tridiagonal, banded, large_symmetric, positive_diagonal = analyse_dense(M)
    if not finite:
        return NUMERICAL_FAILURE, NO_RUN, 0, np.nan, np.nan, 0, -1
    n = q.shape[0]
    structured = n > 2 and (tridiagonal or banded)
    run = first_run(method, structured, large_symmetric)
    no_bands = q[:0]                     # read from M by run_one if banded runs
    return _chain_from_first(M, True, no_bands, no_bands, no_bands, tridiagonal, banded, q,
                             buf, method, run, structured, large_symmetric, positive_diagonal,
                             tol, max_iter, omega, skip_python)


def pack_state(method, run, has_dense, has_bands, sparse_lu, structured, large_symmetric,
               positive_diagonal):
    """A reusable solver's state for :func:`solve_packed`, in one integer (bits 0-2 the
    method, 3-5 the first run, then one bit per flag, in the order of the arguments)."""
    bits = int(method) | int(run) << 3
    for k, flag in enumerate((has_dense, has_bands, sparse_lu, structured, large_symmetric,
                              positive_diagonal)):
        bits |= int(bool(flag)) << (6 + k)
    return bits


@njit(cache=True)
def solve_packed(M, lower, diag, upper, q, buf, bits, tol, max_iter, omega):
    """:func:`run_chain` from a reusable solver's first run, without warm start, its state
    packed by :func:`pack_state` and ``z, w``, the work array in one buffer of
    :func:`buffer_size` floats (as :func:`solve_dense_into`): ten arguments for a caller in
    Python instead of twenty-four."""
    return _chain_from_first(M, (bits >> 6) & 1 == 1, lower, diag, upper, (bits >> 7) & 1 == 1,
                             (bits >> 8) & 1 == 1, q, buf, bits & 7, (bits >> 3) & 7,
                             (bits >> 9) & 1 == 1, (bits >> 10) & 1 == 1,
                             (bits >> 11) & 1 == 1, tol, max_iter, omega, False)


@njit(cache=True)
def solve_dense_into(M, q, buf, method, tol, max_iter, omega):
    """:func:`solve_dense` for a caller in Python (no run is passed over)."""
    return solve_dense(M, q, buf, method, tol, max_iter, omega, False)


#: Status of the checked entries below when an argument fails a check that the caller in
#: Python then makes again, with the error it raises.
UNCHECKED = -4
#: Exponent bounds of the rescaled retry: a failed solve is retried on the problem rescaled
#: by powers of two (exact) when ``max|M|``, ``max|q|`` or their ratio lies outside
#: ``2^(+-this)``, the scales at which the float64 arithmetic of a solver can overflow or
#: underflow (:func:`scale_exponents`).
RESCALE_EXPONENT = 64
#: Bit of a checked entry's state (:func:`pack_out`): the rescaled retry may apply (extreme
#: scales, or a matrix the entry could not look at).
EXTREME = 1 << 16
#: Bit of a checked entry's state (:func:`pack_out`): the answer is Lemke's ray, an earlier
#: run than the last.
RAY_CHOSEN = 1 << 17


@njit(cache=True)
def scale_exponents(values, q):
    """``(a, b, extreme)``: the binary exponents of ``max|values|`` (the entries of ``M``, any
    shape) and ``max|q|`` (``math.frexp``), and whether either, or ``b - a``, exceeds
    :data:`RESCALE_EXPONENT` in magnitude (never when one of them is zero)."""
    m_max = 0.0
    for v in values.flat:
        m_max = max(m_max, abs(v))
    q_max = 0.0
    for i in range(q.shape[0]):
        q_max = max(q_max, abs(q[i]))
    if m_max == 0.0 or q_max == 0.0:
        return 0, 0, False
    a = math.frexp(m_max)[1]
    b = math.frexp(q_max)[1]
    return a, b, max(abs(a), abs(b), abs(b - a)) > RESCALE_EXPONENT


@njit(cache=True, inline='always')
def ray_row(work, n, nlog, code):
    """The log row of the run that is the answer of a chain that verified none (``code``
    not :data:`SOLVED`) when it is Lemke's ray (for copositive-plus ``M`` a certificate that
    the LCP is infeasible; its point is kept in ``work[:2 n]``), else -1: the answer is
    then the last run's."""
    if code != SOLVED:
        for k in range(nlog):
            if work[2 * n + LOG_WIDTH * k + 1] == RAY_TERMINATION:
                return k
    return -1


@njit(cache=True, inline='always')
def pack_out(out, M, q, has_dense, buf):
    """A chain's tuple ``(code, run, iterations, residual, tolerance, tried, nlog)`` as the
    four numbers a caller in Python reads back, ``(state, iterations, residual,
    tolerance)``: ``state`` packs ``code + 8`` (bits 0-3), ``run + 1`` (4-7), ``nlog + 1``
    (8-11), ``tried`` (12-15) and :data:`EXTREME` when no run was verified and the rescaled
    retry may apply (:func:`scale_exponents`; always without a dense ``M`` to look at).
    Four boxed numbers instead of seven, and one comparison for the common outcome.

    When the chain ended without a verified run and the answer is Lemke's ray rather than
    the last run (:func:`ray_row`; the point in ``buf[2 n:4 n]``), ``state`` has
    :data:`RAY_CHOSEN`, and ``run``, ``iterations``, ``residual`` and ``tolerance`` are the
    ray's (unless :data:`EXTREME`: the caller in Python then reads the whole log)."""
    code, run, its, res, tolerance, tried, nlog = out
    extreme = False
    ray = -1
    if code != SOLVED and nlog > 0:
        extreme = not has_dense or scale_exponents(M, q)[2]
        if not extreme:
            n = q.shape[0]
            ray = ray_row(buf[2 * n:], n, nlog, code)
            if ray >= 0 and ray < nlog - 1:
                row = 4 * n + LOG_WIDTH * ray
                run, its, res, tolerance = int(buf[row]), int(buf[row + 2]), buf[row + 3], \
                    buf[row + 4]
            else:
                ray = -1
    state = (code + 8) | (run + 1) << 4 | (nlog + 1) << 8 | tried << 12
    if extreme:
        state |= EXTREME
    if ray >= 0:
        state |= RAY_CHOSEN
    return state, its, res, tolerance


def unpack_state(state):
    """``(code, run, tried, nlog, extreme)`` of a :func:`pack_out` state."""
    return ((state & 15) - 8, ((state >> 4) & 15) - 1, (state >> 12) & 15,
            ((state >> 8) & 15) - 1, bool(state & EXTREME))


def first_run_solved_state(run):
    """The state of a call whose first run ``run`` was verified (one log row)."""
    return (SOLVED + 8) | (run + 1) << 4 | 2 << 8 | getattr(family, "py_func", family)(run) << 12


@njit(cache=True)
def _options_ok(tol, max_iter, omega):
    """``0 < tol < inf``, ``max_iter >= 0`` (0: the defaults), ``0 < omega < 2``."""
    return 0.0 < tol < np.inf and max_iter >= 0 and 0.0 < omega < 2.0


@njit(cache=True, **WITH_REFCOUNT)
def solve_dense_checked(M, q, buf, method, tol, max_iter, omega):
    """:func:`solve_dense_into` for a caller in Python that has checked only the types
    (the compiled signature does, :func:`exact_entry`), its outcome packed by
    :func:`pack_out`: the shapes and the options are checked here, :data:`UNCHECKED`
    (``nlog = -1``) when one fails."""
    n = q.shape[0]
    if not (M.shape[0] == n and M.shape[1] == n and buf.shape[0] == buffer_size(n)
            and 0 <= method <= AUTO and method != PGS_AUTO and method != PGS_FALLBACK
            and _options_ok(tol, max_iter, omega)):
        return pack_out((UNCHECKED, NO_RUN, 0, np.nan, np.nan, 0, -1), M, q, True, buf)
    return pack_out(solve_dense_into(M, q, buf, method, tol, max_iter, omega), M, q, True,
                    buf)


@njit(cache=True, **WITH_REFCOUNT)
def solve_packed_checked(M, lower, diag, upper, q, buf, bits, tol, max_iter, omega):
    """:func:`solve_packed` with the length of ``q`` checked against the buffer's
    (:func:`buffer_size`): :data:`UNCHECKED` when it differs; the outcome packed by
    :func:`pack_out`."""
    if buf.shape[0] != buffer_size(q.shape[0]):
        return pack_out((UNCHECKED, NO_RUN, 0, np.nan, np.nan, 0, -1), M, q, True, buf)
    return pack_out(solve_packed(M, lower, diag, upper, q, buf, bits, tol, max_iter, omega),
                    M, q, (bits >> 6) & 1 == 1, buf)


@njit(cache=True, **NO_REFCOUNT)
def solve_dense_entry(M, q, buf, method, tol, max_iter, omega):
    """:func:`solve_dense_checked` behind a wrapper compiled without reference counting: the
    entry of :func:`~nscontrol.numerics.lcp.solve_lcp` (:func:`exact_entry`). Compiled with
    reference counting, numba's wrapper gives each array argument a new ``MemInfo`` (a
    ``malloc``, two atomic counts and a ``free`` per call: ~0.13 µs of a 2.9 µs call at
    n = 10 with three arrays); without it the arrays are passed as they are. It allocates
    nothing itself: the chain, which may allocate, is a separate function with counting."""
    return solve_dense_checked(M, q, buf, method, tol, max_iter, omega)


@njit(cache=True, **NO_REFCOUNT)
def solve_packed_entry(M, lower, diag, upper, q, buf, bits, tol, max_iter, omega):
    """:func:`solve_packed_checked` behind a wrapper without reference counting (as
    :func:`solve_dense_entry`; six arrays): the entry of
    :meth:`~nscontrol.numerics.lcp.LCPSolver.solve`."""
    return solve_packed_checked(M, lower, diag, upper, q, buf, bits, tol, max_iter, omega)


@njit(cache=True, inline='always')
def csr_buffer_size(n):
    """Floats of the buffer of :func:`solve_csr_entry`: ``z``, ``w``, the work array of
    :func:`run_chain` (``2 n`` and the log), then the three bands of ``M``."""
    return 4 * n + LOG_ROWS * LOG_WIDTH + 3 * n


@njit(cache=True, **WITH_REFCOUNT)
def solve_csr_checked(indptr, indices, data, q, buf, tol, max_iter):
    """The per-call path of :func:`~nscontrol.numerics.lcp.solve_lcp` for a tridiagonal
    square CSR ``M`` (``n > 2``, where ``auto`` runs ``banded`` first): the bands read into
    the tail of ``buf`` (:func:`csr_buffer_size`), then Howard's tridiagonal iteration and
    its verification, the run that :class:`~nscontrol.numerics.lcp.LCPSolver` makes first
    for that ``M``, packed by :func:`pack_out`. :data:`UNCHECKED` when the caller in Python
    must take the general path instead: a length, a non-finite entry of ``M``, an entry
    beyond the first off-diagonals, or options out of range (it raises there). The caller
    has checked that ``M`` is ``n x n``."""
    n = q.shape[0]
    none = buf[:0].reshape((0, 0))          # no dense M
    head = 4 * n + LOG_ROWS * LOG_WIDTH
    if not (n > 2 and indptr.shape[0] == n + 1 and buf.shape[0] == csr_buffer_size(n)
            and indptr[n] <= indices.shape[0] and indptr[n] <= data.shape[0]
            and _options_ok(tol, max_iter, 1.0) and all_finite(data)):
        return pack_out((UNCHECKED, NO_RUN, 0, np.nan, np.nan, 0, -1), none, q, False, buf)
    lower = buf[head:head + n - 1]
    diag = buf[head + n - 1:head + 2 * n - 1]
    upper = buf[head + 2 * n - 1:head + 3 * n - 2]
    if not csr_tridiagonal_bands(indptr, indices, data, lower, diag, upper):
        return pack_out((UNCHECKED, NO_RUN, 0, np.nan, np.nan, 0, -1), none, q, False, buf)
    return pack_out(_chain_from_first(none, False, lower, diag, upper, True, True, q, buf,
                                      BANDED, BANDED, True, False, False, tol, max_iter, 1.0,
                                      False), none, q, False, buf)


@njit(cache=True, **NO_REFCOUNT)
def solve_csr_entry(indptr, indices, data, q, buf, tol, max_iter):
    """:func:`solve_csr_checked` behind a wrapper without reference counting (as
    :func:`solve_dense_entry`)."""
    return solve_csr_checked(indptr, indices, data, q, buf, tol, max_iter)


_F64_2D = types.Array(types.float64, 2, "C")
_F64_1D = types.Array(types.float64, 1, "C")
#: The argument types of :func:`solve_dense_entry` for :func:`exact_entry`: writeable
#: C-contiguous float64 arrays and the options as Python ints and floats.
SOLVE_DENSE_SIGNATURE = (_F64_2D, _F64_1D, _F64_1D, types.int64, types.float64, types.int64,
                         types.float64)
#: The argument types of :func:`solve_csr_entry` for :func:`exact_entry`: scipy's int32
#: index arrays (a matrix with int64 indices takes the general path).
SOLVE_CSR_SIGNATURE = (types.Array(types.int32, 1, "C"), types.Array(types.int32, 1, "C"),
                       _F64_1D, _F64_1D, _F64_1D, types.float64, types.int64)
#: The argument types of :func:`solve_packed_entry` for :func:`exact_entry`.
SOLVE_PACKED_SIGNATURE = (_F64_2D, _F64_1D, _F64_1D, _F64_1D, _F64_1D, _F64_1D, types.int64,
                          types.float64, types.int64, types.float64)


def exact_entry(kernel, signature):
    """``kernel`` compiled for ``signature`` alone, with compilation disabled: a call with
    arguments of any other type (a read-only, non-contiguous or integer array, a list)
    raises ``TypeError`` at once instead of compiling another specialisation, so a caller
    in Python can leave the type checks of its fast path to numba's dispatcher (in C) and
    take its general path on ``TypeError``. Loaded from numba's cache like ``kernel``; None
    when numba's JIT is disabled (no type is checked then: the caller has no fast path).
    Compiled with ``kernel``'s own reference counting option (the same flags as ``kernel``:
    both share numba's cache entry for ``signature``)."""
    py_func = getattr(kernel, "py_func", None)
    if py_func is None:                      # NUMBA_DISABLE_JIT
        return None
    flags = {k: v for k, v in kernel.targetoptions.items() if k == "_nrt"}
    entry = njit([signature], cache=True, **flags)(py_func)
    entry.disable_compile()
    return entry


@njit(cache=True)
def solve_lcp_kernel(M, q, z, w, tol, max_iter):
    """``solve_lcp(M, q, tol=tol, max_iter=max_iter)`` for a dense ``M``, callable from
    ``@njit`` code (no Python in between): ``auto``'s choice, its fallbacks and the residual
    test, compiled.

    Parameters
    ----------
    M : (n, n) float64 array
    q : (n,) float64 array
    z, w : (n,) float64 arrays
        Receive the solution and ``w = M z + q`` (recomputed from ``z``). On failure: the
        last method's point, or Lemke's ray point when there was one.
    tol : float
        As in ``solve_lcp`` (``1e-12`` there).
    max_iter : int
        The budget of each method run; ``<= 0``: the methods' defaults.

    Returns
    -------
    (status, method, iterations, residual, tolerance) : (int, int, int, float, float)
        ``status``: 0 solved (verified), 1 ray termination, 2 max_iter, 3 numerical failure
        (also for non-finite ``M`` or ``q``); ``method`` the run that produced ``z``
        (:data:`RUN_NAMES`, -1 when none ran).

    Notes
    -----
    Bit-identical to :func:`~nscontrol.numerics.lcp.solve_lcp` whenever that one needs no
    Python step: every dense ``M`` with ``n < 64``, tridiagonal ``M`` of any size, and any
    ``M`` up to ``n = 400`` that is not narrow-band. Otherwise the runs that need Python
    (``auto``'s PGS with its definiteness test for symmetric ``M`` above ``n = 400``,
    Howard's iteration with sparse LU first for narrow-band ``M`` with ``n >= 64``) are
    passed over and the chain goes on with the next method; there is no rescaled retry
    for extreme scales. Allocates :func:`buffer_size` floats of work per call.
    """
    n = q.shape[0]
    buf = np.empty(buffer_size(n))
    code, run, its, res, tolerance, tried, nlog = solve_dense(
        M, q, buf, AUTO, tol, max_iter, 1.0, True)
    if code == Q_NOT_FINITE or nlog < 0:
        return NUMERICAL_FAILURE, NO_RUN, 0, np.nan, np.nan
    work = buf[2 * n:]
    ray = ray_row(work, n, nlog, code)
    if ray >= 0:
        # Lemke's ray is the answer (for copositive-plus M: infeasible)
        log = work[2 * n:]
        row = LOG_WIDTH * ray
        for i in range(n):
            z[i] = work[i]
            w[i] = work[n + i]
        return (RAY_TERMINATION, int(log[row]), int(log[row + 2]), log[row + 3],
                log[row + 4])
    for i in range(n):
        z[i] = buf[i]
        w[i] = buf[n + i]
    return code, run, its, res, tolerance
