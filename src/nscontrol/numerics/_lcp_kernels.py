"""numba kernels for the linear complementarity problem ``w = M z + q, 0 <= z ⟂ w >= 0``.

Every kernel is ``@njit(cache=True)`` and callable from other ``@njit`` code (the Moreau–Jean
and event-driven integrators call them inside their step loops). They write the answer into
caller-provided arrays and return ``(status_code, iterations)``:

====  =======================================================================
code  meaning
====  =======================================================================
0     solved
1     ray termination: Lemke found no complementary solution (LCP infeasible
      for copositive-plus ``M``)
2     iteration limit reached
3     numerical failure (zero/negative pivot, non-positive diagonal, NaN) or
      the kernel's structural assumption does not hold
====  =======================================================================

The kernels do not raise; :func:`nscontrol.numerics.solve_lcp` validates input, checks the
residual of what a kernel returns and falls back to another method on failure.

**One acceptance test.** :func:`certify` decides whether a point solves the LCP, from its
natural residual against ``tol`` plus the round-off bound of evaluating ``M z + q``; every
path of :mod:`nscontrol.numerics.lcp` and the fused ``*_verified`` kernels (which return
``(status_code, iterations, residual, tolerance)``) reconcile their status with it by
:func:`verified_status`: "solved" exactly when the residual passes. The bare kernels
(``lemke_kernel``, ``pgs_kernel``, ``tridiagonal_lcp_kernel``) report what their iteration
reached; a compiled caller verifies with :func:`verify_dense` or :func:`verify_tridiagonal`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

SOLVED = 0
RAY_TERMINATION = 1
MAX_ITER = 2
NUMERICAL_FAILURE = 3

#: Relative threshold below which a Lemke pivot element counts as zero.
_PIVOT_TOL = 1e-12
#: Relative tolerance for ties in Lemke's ratio test (degenerate problems).
_TIE_TOL = 1e-12
_EPS = np.finfo(np.float64).eps

#: numba's option that compiles a kernel without reference counting (a private option of
#: ``njit``). The helpers of the Lemke path take it: they allocate nothing, and compiled with
#: reference counting each of their array arguments cost an atomic ``NRT_incref`` and
#: ``NRT_decref`` per call, which at n = 10 was 40 % of a solve (6 pivots, 2.3 µs -> 1.4 µs).
NO_REFCOUNT: dict[str, Any] = {"_nrt": False}


@njit(cache=True, inline='always')
def natural_residual(z, w, q):
    """``max_i |min(z_i, w_i)| / (1 + max|q|)``: zero exactly at solutions of the LCP.

    Negative entries of ``z`` or ``w`` count in full (``min`` picks them), so a small value
    certifies feasibility and complementarity at once.
    """
    n = z.shape[0]
    res = 0.0
    qmax = 0.0
    for i in range(n):
        m = abs(min(z[i], w[i]))
        if not (m <= res):  # also propagates NaN
            res = m
        qmax = max(qmax, abs(q[i]))
    return res / (1.0 + qmax)


#: Factor on the a-priori bound of the round-off in one entry of ``w = M z + q`` computed in
#: float64 from ``k`` terms (``k - 1`` products and ``q_i``): ``|fl(w_i) - w_i| <= gamma_k
#: (|M| |z| + |q|)_i`` with ``gamma_k = k eps / (1 - k eps)``, for any summation order
#: (Higham, *Accuracy and Stability of Numerical Algorithms*, 2002, §3.1). The factor 2
#: covers ``1 / (1 - k eps)`` and the rounding of the solver's own last update of ``z``.
ROUNDOFF_FACTOR = 2.0
#: Largest cancellation ``max_i (|M| |z|)_i / (1 + max|q|)`` in ``w = M z + q`` at which a
#: residual still certifies a solution: ``1 / sqrt(eps)`` (at least half of the digits of
#: every ``w_i`` survive). At a solution ``z_a = -M_aa^{-1} q_a`` the cancellation is at most
#: the condition number of ``M_aa`` (<= 1e7 in the tested families); a direct solve on a
#: numerically singular block (a near-ray of a PSD LCP without solution) gives
#: ``|z| ~ |q| / (eps |M|)``, a cancellation near ``1 / eps``, where the float residual of
#: any point is round-off and certifies nothing.
MAX_CANCELLATION = 1.0 / np.sqrt(_EPS)


@njit(cache=True, inline='always')
def certify(z, w, q, mz_abs_max, terms, tol):
    """The one acceptance test of every LCP path: ``(residual, tolerance, certified)``.

    ``w`` must hold ``M z + q`` computed from ``z``, ``mz_abs_max`` the largest entry of
    ``|M| |z|`` and ``terms`` the largest number of terms in one entry of ``w`` (non-zeros
    of a row of ``M`` plus one). The tolerance is ``tol`` plus the round-off bound of
    evaluating ``w`` (:data:`ROUNDOFF_FACTOR` ``terms eps (max|M||z| + max|q|) / (1 +
    max|q|)``, relative as :func:`natural_residual`); ``-inf`` when the cancellation in
    ``M z + q`` exceeds :data:`MAX_CANCELLATION` (nothing can be certified there).
    ``certified`` is ``residual <= tolerance`` (False for NaN).
    """
    n = q.shape[0]
    qmax = 0.0
    for i in range(n):
        qmax = max(qmax, abs(q[i]))
    res = natural_residual(z, w, q)
    scale = 1.0 + qmax
    cancellation = mz_abs_max / scale     # divided first: no overflow near 1e308
    if not (cancellation <= MAX_CANCELLATION):   # also NaN and inf
        return res, -np.inf, False
    tolerance = tol + ROUNDOFF_FACTOR * terms * _EPS * (cancellation + qmax / scale)
    return res, tolerance, bool(res <= tolerance)


@njit(cache=True, inline='always')
def verified_status(code, certified):
    """A kernel's status reconciled with the residual test: solved exactly when certified
    (also after an iteration limit or a ray, if the point passes); a kernel's "solved" that
    does not pass becomes a numerical failure."""
    if certified:
        return SOLVED
    if code == SOLVED:
        return NUMERICAL_FAILURE
    return code


@njit(cache=True, **NO_REFCOUNT)
def _row_dot(M, i, z, n):
    """``M[i, :] @ z`` with four independent accumulators: a single running sum is bound by
    the latency of one add per element (it cannot vectorise without reassociation)."""
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    m = n - n % 4
    for j in range(0, m, 4):
        s0 += M[i, j] * z[j]
        s1 += M[i, j + 1] * z[j + 1]
        s2 += M[i, j + 2] * z[j + 2]
        s3 += M[i, j + 3] * z[j + 3]
    for j in range(m, n):
        s0 += M[i, j] * z[j]
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, **NO_REFCOUNT)
def _matvec_plus(M, z, q, w_out):
    n = q.shape[0]
    for i in range(n):
        w_out[i] = q[i] + _row_dot(M, i, z, n)


@njit(cache=True, **NO_REFCOUNT)
def _matvec_plus_abs(M, z, q, w_out):
    """``w_out = M z + q`` and ``max_i (|M| |z|)_i`` (the cancellation of :func:`certify`)
    in one pass over ``M``, with the four accumulators of :func:`_row_dot`."""
    n = q.shape[0]
    big = 0.0
    m = n - n % 4
    for i in range(n):
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        for j in range(0, m, 4):
            p0 = M[i, j] * z[j]
            p1 = M[i, j + 1] * z[j + 1]
            p2 = M[i, j + 2] * z[j + 2]
            p3 = M[i, j + 3] * z[j + 3]
            s0 += p0
            s1 += p1
            s2 += p2
            s3 += p3
            a0 += abs(p0)
            a1 += abs(p1)
            a2 += abs(p2)
            a3 += abs(p3)
        for j in range(m, n):
            p0 = M[i, j] * z[j]
            s0 += p0
            a0 += abs(p0)
        w_out[i] = q[i] + ((s0 + s1) + (s2 + s3))
        a = (a0 + a1) + (a2 + a3)
        if not (a <= big):   # also propagates NaN
            big = a
    return big


# --------------------------------------------------------------------------------- Lemke
#: Up to this size Lemke pivots the full tableau ``B^{-1} [I, -M, -1]`` (``2 n + 1``
#: columns): an entering column is read off it, and a pivot is one rank-one update of long
#: contiguous rows; above it (memory), only ``B^{-1}`` is kept and an entering column
#: ``-B^{-1} M[:, j]`` is computed when it enters (the same pivots, at O(n^2) each either way).
#: The helpers of one pivot (the entering column, the ratio test, the pivot) are inlined into
#: the path's loop (``inline='always'``, within its compilation without reference counting):
#: a numba call of a function with several array arguments costs ~15 ns, three per pivot, and
#: inlining them took a whole ``solve_lcp`` call at n = 10 from 2.70 to 2.60 µs (6 pivots) and
#: from 3.22 to 3.04 µs (11 pivots).
LEMKE_FULL_TABLEAU_MAX_SIZE = 48


@njit(cache=True, inline='always')
def _lemke_gemv_size(n):
    """Whether an entering column ``-B^{-1} M[:, j]`` is computed by BLAS gemv: 2-3x faster
    than the loop for mid-sized n; for tiny n its call overhead dominates, and for large n
    OpenBLAS goes multithreaded, which on a shared machine was measured 6x slower than the
    loop (n = 1000)."""
    return 32 <= n <= 400


@njit(cache=True, inline='always', **NO_REFCOUNT)
def _lemke_entering_column(M, binv, var, n, col, mcol):
    """Column of the current tableau for variable ``var`` (w_j: j, z_j: n + j, z0: 2n);
    ``mcol`` is scratch of length n (a contiguous copy of ``M[:, j]``). Not for a ``z_j``
    with ``B^{-1}`` alone at :func:`_lemke_gemv_size` (the kernel calls BLAS there).
    ``binv`` is ``B^{-1}`` (``n`` columns), or the full tableau ``B^{-1} [I, -M, -1]``
    (``2 n + 1`` columns, :data:`LEMKE_FULL_TABLEAU_MAX_SIZE`) whose column ``var`` is the
    one asked for, read off here; from ``B^{-1}`` alone it is computed by
    :func:`_lemke_computed_column` (a call: inlined, its O(n^2) loops ran ~8 % slower at
    n = 1000)."""
    if binv.shape[1] > n:
        for i in range(n):
            col[i] = binv[i, var]
    else:
        _lemke_computed_column(M, binv, var, n, col, mcol)


@njit(cache=True, **NO_REFCOUNT)
def _lemke_computed_column(M, binv, var, n, col, mcol):
    """:func:`_lemke_entering_column` from ``B^{-1}`` alone: ``e_j`` (w_j), ``-M[:, j]``
    (z_j) or ``-1`` (z0) times ``B^{-1}``."""
    if var < n:
        for i in range(n):
            col[i] = binv[i, var]
    elif var < 2 * n:
        j = var - n
        for k in range(n):
            mcol[k] = M[k, j]
        for i in range(n):
            col[i] = -_row_dot(binv, i, mcol, n)
    else:
        for i in range(n):
            s = 0.0
            for k in range(n):
                s -= binv[i, k]
            col[i] = s


@njit(cache=True, inline='always', **NO_REFCOUNT)
def _lemke_ratio_test(binv, rhs, col, basis, n, cand, ratio):
    """Lexicographic minimum-ratio row, or -1 when the column has no positive entry (ray).
    ``ratio`` is scratch of length n (each ratio computed once).

    The rows compared are ``(rhs_i, Binv[i, :]) / col_i``: the lexicographic order of the
    perturbed right-hand side ``q + (eps, eps^2, ...)`` which makes every basis
    non-degenerate and Lemke's path finite.
    """
    scale = 0.0
    for i in range(n):
        scale = max(scale, abs(col[i]))
    if not (scale > 0.0):
        return -1
    ncand = 0
    best = np.inf
    threshold = _PIVOT_TOL * scale
    for i in range(n):
        r = rhs[i] / col[i] if col[i] > threshold else np.inf
        ratio[i] = r
        if r < best:
            best = r
    if best == np.inf:
        return -1
    tie = _TIE_TOL * (1.0 + abs(best))
    for i in range(n):
        if ratio[i] <= best + tie:
            cand[ncand] = i
            ncand += 1
    # z0 leaving ends the path: prefer it among ties.
    for c in range(ncand):
        if basis[cand[c]] == 2 * n:
            return cand[c]
    k = 0
    while ncand > 1 and k < n:
        best = np.inf
        for c in range(ncand):
            i = cand[c]
            r = binv[i, k] / col[i]
            if r < best:
                best = r
        tie = _TIE_TOL * (1.0 + abs(best))
        kept = 0
        for c in range(ncand):
            i = cand[c]
            if binv[i, k] / col[i] <= best + tie:
                cand[kept] = i
                kept += 1
        ncand = kept
        k += 1
    return cand[0]


@njit(cache=True, inline='always', **NO_REFCOUNT)
def _lemke_pivot(binv, rhs, col, r, n, prow):
    """Gauss–Jordan pivot on row ``r`` of ``[B^{-1} | B^{-1} q]`` (or of the full tableau:
    every column of ``binv``) with column ``col``.

    The pivot row is copied to ``prow`` first, so the row updates provably do not alias and
    compile to SIMD loops (this halves the cost of a pivot).
    """
    width = binv.shape[1]
    inv = 1.0 / col[r]
    for k in range(width):
        prow[k] = binv[r, k] * inv
    prhs = rhs[r] * inv
    for i in range(n):
        f = col[i]
        if i == r or f == 0.0:
            continue
        row = binv[i]
        for k in range(width):
            row[k] -= f * prow[k]
        rhs[i] -= f * prhs
    for k in range(width):
        binv[r, k] = prow[k]
    rhs[r] = prhs


@njit(cache=True, **NO_REFCOUNT)
def _lemke_refine(M, q, binv, rhs, basis, n, r, scale):
    """At most two steps of iterative refinement of the basic solution ``x = B^{-1} q``,
    each taken only while the residual of ``B x = q`` is above its own round-off.

    ``B^{-1}`` accumulates round-off over the pivots; the basis itself is exact, so
    ``x += B^{-1}(q - B x)`` (with ``B`` rebuilt from the basis: column ``e_j`` for ``w_j``,
    ``-M[:, j]`` for ``z_j``, ``-1`` for ``z0``) restores full accuracy at O(n^2) cost.
    The refinement stops instead when every ``|q_i - (B x)_i|`` is at most
    :data:`REFINE_STOP_FACTOR` ``(n + 1) eps (|q_i| + (|B| |x|)_i)``: ``x`` is then
    componentwise backward stable, and a step in the same precision would move it by no
    more than the round-off of its own residual (LAPACK's stopping test for refinement,
    ``berr <= eps``, with the ``n + 1`` terms of each residual entry). Most small bases pass
    at once, which saves the two ``B^{-1} r`` products (254 -> 66 ns at n = 10).
    ``r`` and ``scale`` are scratch of length n.
    """
    bound = REFINE_STOP_FACTOR * (n + 1) * _EPS
    for _ in range(2):
        for i in range(n):
            r[i] = q[i]
            scale[i] = abs(q[i])
        for k in range(n):
            v = basis[k]
            x = rhs[k]
            if v < n:
                r[v] -= x
                scale[v] += abs(x)
            elif v < 2 * n:
                j = v - n
                for i in range(n):
                    t = M[i, j] * x
                    r[i] += t
                    scale[i] += abs(t)
            else:
                for i in range(n):
                    r[i] += x
                    scale[i] += abs(x)
        converged = True
        for i in range(n):
            if abs(r[i]) > bound * scale[i]:
                converged = False
        if converged:
            return
        for i in range(n):
            rhs[i] += _row_dot(binv, i, r, n)   # B^{-1} is binv[:, :n]


#: The factor of :func:`_lemke_refine`'s stopping test beyond the ``(n + 1) eps`` of
#: evaluating the residual: 2, so that the residual's own round-off does not fail it.
REFINE_STOP_FACTOR = 2.0


@njit(cache=True, inline='always')
def _lemke_width(n):
    """Columns of Lemke's tableau: the full ``B^{-1} [I, -M, -1]`` up to
    :data:`LEMKE_FULL_TABLEAU_MAX_SIZE`, else ``B^{-1}`` alone."""
    return 2 * n + 1 if n <= LEMKE_FULL_TABLEAU_MAX_SIZE else n


@njit(cache=True, inline='always')
def lemke_work_size(n):
    """Floats of Lemke's workspace: the tableau, ``B^{-1} q``, the entering column, ``M[:,
    j]``, scratch, the pivot row, and ``2 n`` int64 (the basis, the ratio test's candidates)
    stored in the same buffer."""
    width = _lemke_width(n)
    return n * width + 6 * n + width


@njit(cache=True, inline='always')
def _lemke_views(work, n):
    """The pieces of Lemke's workspace (:func:`lemke_work_size`): ``binv`` (the tableau),
    ``rhs``, ``col``, ``mcol``, ``scratch``, ``prow`` and the int64 ``basis``, ``cand`` (row
    ``i`` of the tableau holds variable ``basis[i]``: ``w_i = i``, ``z_i = n + i``, ``z0 =
    2n``)."""
    width = _lemke_width(n)
    size = n * width
    binv = work[:size].reshape((n, width))
    rhs = work[size:size + n]
    col = work[size + n:size + 2 * n]
    mcol = work[size + 2 * n:size + 3 * n]
    scratch = work[size + 3 * n:size + 4 * n]
    prow = work[size + 4 * n:size + 4 * n + width]
    iwork = work[size + 4 * n + width:size + 6 * n + width].view(np.int64)
    return binv, rhs, col, mcol, scratch, prow, iwork[:n], iwork[n:]


#: Status of :func:`_lemke_start`: the path is to be followed (the first pivot is done).
_PATH = -2
#: Status of :func:`_lemke_path`: the next entering column is computed by BLAS gemv.
_NEED_COLUMN = -1


@njit(cache=True, **NO_REFCOUNT)
def _lemke_start(M, q, z_out, w_out, work):
    """``z_out = 0``, ``w_out = q``; ``(SOLVED, -1)`` when ``q >= 0`` (or ``n = 0``),
    ``(NUMERICAL_FAILURE, -1)`` when ``q`` is not finite; else the tableau is set up in
    ``work``, ``z0`` has entered by the first pivot and ``(_PATH, leaving)`` is returned."""
    n = q.shape[0]
    for i in range(n):
        z_out[i] = 0.0
        w_out[i] = q[i]
    if n == 0:
        return SOLVED, -1
    qmin = np.inf
    for i in range(n):
        if not np.isfinite(q[i]):
            return NUMERICAL_FAILURE, -1
        qmin = min(qmin, q[i])
    if qmin >= 0.0:
        return SOLVED, -1
    binv, rhs, col, mcol, scratch, prow, basis, cand = _lemke_views(work, n)
    width = binv.shape[1]
    for i in range(n):
        rhs[i] = q[i]
        for j in range(n):
            binv[i, j] = 1.0 if i == j else 0.0
        if width > n:
            for j in range(n):
                binv[i, n + j] = -M[i, j]
            binv[i, 2 * n] = -1.0
    for i in range(n):
        basis[i] = i
    # First pivot: z0 enters at the row of the most negative q (largest index among ties is
    # the lexicographic choice for the column -d = -1).
    tie = _TIE_TOL * (1.0 + abs(qmin))
    r = 0
    for i in range(n):
        if q[i] <= qmin + tie:
            r = i
    for i in range(n):
        col[i] = -1.0
    leaving = basis[r]
    _lemke_pivot(binv, rhs, col, r, n, prow)
    basis[r] = 2 * n
    return _PATH, leaving


@njit(cache=True, **NO_REFCOUNT)
def _lemke_path(M, work, it, leaving, max_iter, have_column):
    """Lemke's pivots after the first (``it`` done, ``leaving`` the variable that left last),
    until the path ends or ``max_iter`` pivots: ``(status_code, it, leaving)``. The entering
    variable is the complement of ``leaving``; its column is computed here, or given in
    ``col`` (``have_column``), except that a ``z_j`` column at :func:`_lemke_gemv_size`
    with ``B^{-1}`` alone returns :data:`_NEED_COLUMN` for the kernel to compute by BLAS
    (which allocates: this loop is compiled without reference counting)."""
    n = M.shape[0]
    binv, rhs, col, mcol, scratch, prow, basis, cand = _lemke_views(work, n)
    gemv = binv.shape[1] == n and _lemke_gemv_size(n)
    while it < max_iter:
        entering = leaving + n if leaving < n else leaving - n
        if not have_column:
            if gemv and n <= entering < 2 * n:
                return _NEED_COLUMN, it, leaving
            _lemke_entering_column(M, binv, entering, n, col, mcol)
        have_column = False
        r = _lemke_ratio_test(binv, rhs, col, basis, n, cand, scratch)
        if r < 0:
            return RAY_TERMINATION, it, leaving
        if not np.isfinite(col[r]) or col[r] == 0.0:
            return NUMERICAL_FAILURE, it, leaving
        leaving = basis[r]
        _lemke_pivot(binv, rhs, col, r, n, prow)
        basis[r] = entering
        it += 1
        if leaving == 2 * n:
            return SOLVED, it, leaving
    return MAX_ITER, it, leaving


@njit(cache=True, **NO_REFCOUNT)
def _lemke_end(M, q, z_out, w_out, work, status, it, with_w):
    """The end of Lemke's path: the basis refined (when solved), ``z_out`` read off the
    tableau, ``w_out = M z + q`` unless not ``with_w`` (a verified caller recomputes it with
    ``|M| |z|`` in one pass, :func:`verify_dense`, whose test also fails a non-finite
    residual); ``(status_code, it)``."""
    n = q.shape[0]
    binv, rhs, col, mcol, scratch, prow, basis, cand = _lemke_views(work, n)
    if status == SOLVED:
        _lemke_refine(M, q, binv, rhs, basis, n, scratch, mcol)
    # Read the basic point off the tableau.
    for i in range(n):
        z_out[i] = 0.0
    for i in range(n):
        if n <= basis[i] < 2 * n:
            z_out[basis[i] - n] = rhs[i]
    if not with_w:
        return status, it
    _matvec_plus(M, z_out, q, w_out)
    if status == SOLVED and not np.isfinite(natural_residual(z_out, w_out, q)):
        return NUMERICAL_FAILURE, it
    return status, it


@njit(cache=True)
def lemke_kernel(M, q, z_out, w_out, max_iter):
    """Lemke's complementary pivoting with covering vector ``d = 1`` and lexicographic
    anti-cycling.

    Parameters
    ----------
    M : (n, n) float64 array
    q : (n,) float64 array
    z_out, w_out : (n,) float64 arrays
        Receive the solution (also on failure: the last basic point, or zeros).
    max_iter : int
        Pivot limit; ``<= 0`` means ``50 (n + 1)``.

    Returns
    -------
    (status_code, iterations) : (int, int)

    Notes
    -----
    The tableau is kept as the basis inverse ``B^{-1}`` (n x n) and ``B^{-1} q``; entering
    columns are computed on demand, so a pivot costs O(n^2) and memory is n^2 floats. Up to
    :data:`LEMKE_FULL_TABLEAU_MAX_SIZE` the whole tableau ``B^{-1} [I, -M, -1]`` is pivoted
    instead (entering columns read off it, 2n^2 floats).
    Ties in the ratio test are broken lexicographically on ``B^{-1}[q, I]``, which guarantees
    termination on degenerate problems. For P-matrices the path ends with a solution; for
    copositive-plus ``M`` a ray certifies that the LCP has no solution. The final basis is
    refined by iterative refinement against the exact basis to remove accumulated round-off.
    """
    return _lemke_solve(M, q, z_out, w_out, max_iter, True)


@njit(cache=True)
def _lemke_solve(M, q, z_out, w_out, max_iter, with_w):
    """:func:`lemke_kernel`, ``w_out`` computed only ``with_w`` (:func:`_lemke_end`)."""
    n = q.shape[0]
    if max_iter <= 0:
        max_iter = 50 * (n + 1)
    # one allocation (on small problems the allocations cost more than the pivots)
    work = np.empty(lemke_work_size(n))
    status, leaving = _lemke_start(M, q, z_out, w_out, work)
    if status != _PATH:
        return status, 0
    status, it, leaving = _lemke_path(M, work, 1, leaving, max_iter, False)
    while status == _NEED_COLUMN:
        # -B^{-1} M[:, j] by BLAS gemv (it allocates: here, not in the path, which is
        # compiled without reference counting)
        binv, rhs, col, mcol, scratch, prow, basis, cand = _lemke_views(work, n)
        j = leaving          # w_j left: z_j enters
        for k in range(n):
            mcol[k] = M[k, j]
        prod = np.dot(binv, mcol)
        for i in range(n):
            col[i] = -prod[i]
        status, it, leaving = _lemke_path(M, work, it, leaving, max_iter, True)
    return _lemke_end(M, q, z_out, w_out, work, status, it, with_w)


@njit(cache=True, **NO_REFCOUNT)
def lemke_into(M, q, z_out, w_out, max_iter, work):
    """:func:`lemke_kernel` in a workspace ``work`` of :func:`lemke_work_size` floats given by
    the caller, for ``n <=`` :data:`LEMKE_FULL_TABLEAU_MAX_SIZE` (no allocation, no reference
    counting: the per-call path of a small LCP). The same pivots, bit for bit."""
    return _lemke_into(M, q, z_out, w_out, max_iter, work, True)


@njit(cache=True, **NO_REFCOUNT)
def _lemke_into(M, q, z_out, w_out, max_iter, work, with_w):
    """:func:`lemke_into`, ``w_out`` computed only ``with_w`` (:func:`_lemke_end`)."""
    n = q.shape[0]
    if max_iter <= 0:
        max_iter = 50 * (n + 1)
    status, leaving = _lemke_start(M, q, z_out, w_out, work)
    if status != _PATH:
        return status, 0
    status, it, leaving = _lemke_path(M, work, 1, leaving, max_iter, False)
    return _lemke_end(M, q, z_out, w_out, work, status, it, with_w)


# --------------------------------------------------------------------------------- PGS
@njit(cache=True, **NO_REFCOUNT)
def _pgs_sweep(M, q, z, step, inv_omega):
    """One Gauss–Seidel sweep ``z_i <- max(0, z_i - step_i (M z + q)_i)`` (``step_i = omega /
    M_ii``); returns the proxy of the residual, the largest ``|min(z_i / step_i, s_i)|`` met
    during the sweep (the caller computes the exact residual, one more matvec, only once the
    proxy is small).

    Each new ``z_i`` is stored one row late: row ``i``'s dot product reads the old
    ``z_{i-1}`` and adds ``M[i, i-1] (z_{i-1}^new - z_{i-1}^old)``, which is the same sum.
    The dot product then no longer waits for the previous row's update, which is the
    latency chain of a sweep: one multiply-add and the update per row, instead of the whole
    dot product (about 3x fewer cycles per row at n = 10)."""
    n = q.shape[0]
    proxy = 0.0
    new_prev = 0.0
    old_prev = 0.0
    for i in range(n):
        s = q[i] + _row_dot(M, i, z, n)
        if i > 0:
            s += M[i, i - 1] * (new_prev - old_prev)
            z[i - 1] = new_prev
        zi = z[i]
        proxy = max(proxy, abs(min(zi * M[i, i] * inv_omega, s)))
        new = zi - step[i] * s
        old_prev = zi
        new_prev = new if new > 0.0 else 0.0
    if n > 0:
        z[n - 1] = new_prev
    return proxy


@njit(cache=True)
def pgs_kernel(M, q, z_inout, w_out, tol, max_iter, omega):
    """Projected Gauss–Seidel with over-relaxation (PSOR), warm-started from ``z_inout``.

    ``z_i <- max(0, z_i - omega (M z + q)_i / M_ii)`` row by row. Converges for symmetric
    positive semidefinite ``M`` with positive diagonal and ``0 < omega < 2`` (Cryer 1971;
    Cottle, Pang & Stone 1992, §5.2) — linearly, with a rate that degrades with the condition
    number, so it suits large well-conditioned problems, not stiff chains.

    Stops when :func:`natural_residual` ``<= tol``, computed on a fresh ``w = M z + q`` once
    the row residuals met during a sweep are all below ``tol`` (saves a matvec per sweep).
    Returns ``(status_code, sweeps)``; code 3 for a non-positive diagonal or a non-finite
    iterate.
    """
    return _pgs_run(M, q, z_inout, w_out, tol, max_iter, omega, np.empty(q.shape[0]))


@njit(cache=True, **NO_REFCOUNT)
def _pgs_run(M, q, z_inout, w_out, tol, max_iter, omega, step):
    """:func:`pgs_kernel` with its scratch ``step`` (length n) given by the caller."""
    n = q.shape[0]
    for i in range(n):
        if not (M[i, i] > 0.0):
            _matvec_plus(M, z_inout, q, w_out)
            return NUMERICAL_FAILURE, 0
        if z_inout[i] < 0.0:
            z_inout[i] = 0.0
    _matvec_plus(M, z_inout, q, w_out)
    res = natural_residual(z_inout, w_out, q)
    if res <= tol:
        return SOLVED, 0
    qscale = 1.0
    for i in range(n):
        qscale = max(qscale, 1.0 + abs(q[i]))
    for i in range(n):          # omega / M_ii: a product per row instead of a division
        step[i] = omega / M[i, i]
    for sweep in range(1, max_iter + 1):
        proxy = _pgs_sweep(M, q, z_inout, step, 1.0 / omega)
        if not np.isfinite(proxy):
            _matvec_plus(M, z_inout, q, w_out)
            return NUMERICAL_FAILURE, sweep
        if proxy <= tol * qscale or sweep == max_iter:
            _matvec_plus(M, z_inout, q, w_out)
            res = natural_residual(z_inout, w_out, q)
            if not np.isfinite(res):
                return NUMERICAL_FAILURE, sweep
            if res <= tol:
                return SOLVED, sweep
    return MAX_ITER, max_iter


# --------------------------------------------------------------------------------- tridiagonal
@njit(cache=True)
def _tridiag_active_solve(lower, diag, upper, q, active, z, cp, dp):
    """Solve ``M[a, a] z_a = -q_a`` (a = active set), z = 0 elsewhere, by one Thomas sweep.

    The principal block of a tridiagonal matrix is block-diagonal with tridiagonal blocks on
    the runs of consecutive active indices; the sweep restarts at each run. No pivoting:
    returns False on a non-positive pivot (the block is not an M-matrix / not positive
    definite), which the caller reports as status 3.
    """
    n = q.shape[0]
    for i in range(n):
        if not active[i]:
            z[i] = 0.0
            continue
        b = diag[i]
        rhs = -q[i]
        if i > 0 and active[i - 1]:
            b -= lower[i - 1] * cp[i - 1]
            rhs -= lower[i - 1] * dp[i - 1]
        if not (b > 1e-14 * abs(diag[i])) or not (diag[i] > 0.0):
            return False
        cp[i] = upper[i] / b if i < n - 1 else 0.0
        dp[i] = rhs / b
    for i in range(n - 1, -1, -1):
        if active[i]:
            if i < n - 1 and active[i + 1]:
                z[i] = dp[i] - cp[i] * z[i + 1]
            else:
                z[i] = dp[i]
    return True


@njit(cache=True)
def _tridiag_w(lower, diag, upper, q, z, w):
    n = q.shape[0]
    for i in range(n):
        s = q[i] + diag[i] * z[i]
        if i > 0:
            s += lower[i - 1] * z[i - 1]
        if i < n - 1:
            s += upper[i] * z[i + 1]
        w[i] = s


@njit(cache=True)
def _projected_thomas(lower, diag, upper, q, z, dp, rp, reverse):
    """One projected Thomas sweep (Brennan–Schwartz): eliminate in one direction without
    pivoting, back-substitute in the other with ``z_i = max(0, ...)``.

    Exact for an M-matrix when the solution's zero set lies at the end where the
    back-substitution starts (one free boundary, the American-option structure); elsewhere a
    guess. ``reverse=True`` runs bottom-up. Returns False on a non-positive or non-finite
    pivot (``M`` is not an M-matrix), leaving ``z`` unspecified.
    """
    n = q.shape[0]
    for k in range(n):
        i = n - 1 - k if reverse else k
        d = diag[i]
        r = -q[i]
        if k > 0:
            j = i + 1 if reverse else i - 1                 # the row eliminated before
            a = upper[i] if reverse else lower[i - 1]       # M[i, j]
            c = lower[i] if reverse else upper[i - 1]       # M[j, i]
            m = a / dp[j]
            d -= m * c
            r -= m * rp[j]
        if not (d > 0.0) or not np.isfinite(d):
            return False
        dp[i] = d
        rp[i] = r
    for k in range(n - 1, -1, -1):
        i = n - 1 - k if reverse else k
        r = rp[i]
        if k < n - 1:
            j = i - 1 if reverse else i + 1
            r -= (lower[j] if reverse else upper[i]) * z[j]
        v = r / dp[i]
        z[i] = v if v > 0.0 else 0.0
    return True


@njit(cache=True)
def tridiagonal_start(lower, diag, upper, q, z):
    """Starting point for Howard's iteration: the larger of the two projected Thomas sweeps.

    Each sweep (:func:`_projected_thomas`) is exact when the solution has a single free
    boundary on its side (an impact travelling down a chain or up a stack, a stack at rest),
    where Howard's iteration from ``z = 0`` moves the boundary by one index per iteration
    (``n`` iterations); their componentwise maximum is a good start when there are several.
    O(n); ``z = 0`` when neither sweep applies (not an M-matrix).
    """
    n = q.shape[0]
    dp = np.empty(n)
    rp = np.empty(n)
    up = np.empty(n)
    ok_down = _projected_thomas(lower, diag, upper, q, z, dp, rp, False)
    ok_up = _projected_thomas(lower, diag, upper, q, up, dp, rp, True)
    for i in range(n):
        if ok_down and ok_up:
            z[i] = max(z[i], up[i])
        elif ok_up:
            z[i] = up[i]
        elif not ok_down:
            z[i] = 0.0
        if not np.isfinite(z[i]):
            z[i] = 0.0


@njit(cache=True)
def tridiagonal_lcp_kernel(lower, diag, upper, q, z_out, w_out, max_iter):
    """LCP with tridiagonal ``M`` by Howard's policy iteration (semismooth Newton on
    ``min(z, M z + q) = 0``) with Thomas solves: O(n) per iteration.

    Parameters
    ----------
    lower, upper : (n-1,) float64 arrays
        ``lower[i] = M[i+1, i]``, ``upper[i] = M[i, i+1]``.
    diag : (n,) float64 array
    q : (n,) float64 array
    z_out, w_out : (n,) float64 arrays
        Receive the solution (on failure: the last iterate).
    max_iter : int
        Iteration limit; ``<= 0`` means ``n + 2``.

    Returns
    -------
    (status_code, iterations) : (int, int)

    Notes
    -----
    Start from :func:`tridiagonal_start` (two projected Thomas sweeps, O(n)). Each iteration
    picks, for every ``i``, the branch of ``min(z_i, w_i)`` that is smaller at the current
    iterate (``w_i <= z_i``: impose ``w_i = 0``, i.e. ``i`` active; else ``z_i = 0``), solves
    the principal system on the active set by a Thomas sweep restarted at each run of
    consecutive active indices, and stops as soon as ``z >= 0``, ``w >= 0`` and
    ``min(z, w) = 0`` (to ``1e-13 (1 + max|q|) + 64 eps ||M|| max|z|``).

    *When it is exact.* For an M-matrix ``M`` (positive diagonal, non-positive off-diagonals,
    positive definite or diagonally dominant — e.g. the Delassus matrix ``W^T M^{-1} W`` of a
    chain or stack of masses with contacts between neighbours) the iteration converges to the
    unique solution in at most ``n`` iterations from any start (Bokanowski, Maroso & Zidani
    2009, Thm. 2.1) and every Thomas pivot is positive; the result is exact up to round-off of
    the final direct solve. *Cost.* O(n) per iteration, so O(n^2) in the worst case; the
    starting sweeps are exact for a stack at rest and for a single impact travelling through
    a chain (0 iterations where ``z = 0`` needed ``n``), and leave a few iterations for
    scattered impacts (see ``docs/lcp.md`` for the measured counts).

    *When it fails.* For other tridiagonal matrices the iteration may cycle or meet a
    non-positive pivot; it then stops with status 2 (iteration limit) or 3 (pivot), never
    with a wrong ``z`` marked solved. ``solve_lcp`` falls back to Lemke.

    References
    ----------
    O. Bokanowski, S. Maroso, H. Zidani, "Some convergence results for Howard's algorithm",
    SIAM J. Numer. Anal. 47(4):3001–3026, 2009. M. J. Brennan, E. S. Schwartz, "The valuation
    of American put options", J. Finance 32(2):449–462, 1977 (the projected sweep).
    """
    n = q.shape[0]
    if n == 0:
        return SOLVED, 0
    tridiagonal_start(lower, diag, upper, q, z_out)
    return tridiagonal_howard(lower, diag, upper, q, z_out, w_out, max_iter)


@njit(cache=True)
def tridiagonal_howard(lower, diag, upper, q, z, w, max_iter):
    """Howard's iteration of :func:`tridiagonal_lcp_kernel` warm-started from ``z``
    (overwritten with the result; ``w`` receives ``M z + q``). The convergence bound of at
    most ``n`` iterations for M-matrices holds from any starting point.
    """
    n = q.shape[0]
    if max_iter <= 0:
        max_iter = n + 2
    qmax = 0.0
    for i in range(n):
        if not np.isfinite(q[i]) or not np.isfinite(diag[i]) or not np.isfinite(z[i]):
            _tridiag_w(lower, diag, upper, q, z, w)
            return NUMERICAL_FAILURE, 0
        qmax = max(qmax, abs(q[i]))
    _tridiag_w(lower, diag, upper, q, z, w)
    row_max = tridiagonal_inf_norm(lower, diag, upper)
    active = np.empty(n, dtype=np.bool_)
    cp = np.empty(n)
    dp = np.empty(n)
    for it in range(max_iter + 1):
        # feasibility tolerance: relative to q, widened by the round-off of M z for large z
        zmax = 0.0
        for i in range(n):
            zmax = max(zmax, abs(z[i]))
        eps = 1e-13 * (1.0 + qmax) + 64.0 * _EPS * row_max * zmax
        # a solution: feasible and complementary (Howard's own iterates are complementary by
        # construction, a warm start or the starting sweeps need not be)
        solved = True
        for i in range(n):
            if z[i] < -eps or w[i] < -eps or min(z[i], w[i]) > eps:
                solved = False
                break
        if solved:
            return SOLVED, it
        if it == max_iter:
            break
        for i in range(n):
            active[i] = w[i] <= z[i]
        ok = _tridiag_active_solve(lower, diag, upper, q, active, z, cp, dp)
        _tridiag_w(lower, diag, upper, q, z, w)
        if not ok:
            return NUMERICAL_FAILURE, it + 1
        # Exact zeros on the active set (round-off would otherwise flip the branch choice).
        for i in range(n):
            if active[i] and abs(w[i]) <= eps:
                w[i] = 0.0
    return MAX_ITER, max_iter


@njit(cache=True)
def is_tridiagonal(M):
    """True when the dense matrix ``M`` has no non-zero entry beyond its first off-diagonals
    (checked in place, without temporaries)."""
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            if (j > i + 1 or j < i - 1) and M[i, j] != 0.0:
                return False
    return True


@njit(cache=True)
def half_bandwidth(M, limit):
    """Largest ``|i - j|`` with ``M[i, j] != 0`` for a dense ``M``, or ``limit + 1`` as soon as
    it exceeds ``limit`` (early exit: O(n limit) for banded matrices)."""
    n = M.shape[0]
    b = 0
    for i in range(n):
        for j in range(n):
            if M[i, j] != 0.0 and abs(i - j) > b:
                b = abs(i - j)
                if b > limit:
                    return limit + 1
    return b


@njit(cache=True)
def is_symmetric(M, atol):
    """True when ``|M[i, j] - M[j, i]| <= atol`` for all ``i, j`` (early exit, no copies)."""
    n = M.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            if not (abs(M[i, j] - M[j, i]) <= atol):
                return False
    return True


@njit(cache=True)
def nonnegative_diagonally_dominant(M):
    """True when ``M[i, i] >= sum_{j != i} |M[i, j]|`` for every row: with ``M`` symmetric this
    makes it positive semidefinite (Gershgorin's theorem)."""
    n = M.shape[0]
    for i in range(n):
        s = 0.0
        for j in range(n):
            if j != i:
                s += abs(M[i, j])
        if not (M[i, i] >= s):
            return False
    return True


@njit(cache=True)
def csr_tridiagonal_bands(indptr, indices, data, lower, diag, upper):
    """Fill ``(lower, diag, upper)`` from a CSR matrix; False when an entry lies beyond the
    first off-diagonals (the matrix is not tridiagonal)."""
    n = diag.shape[0]
    diag[:] = 0.0
    lower[:] = 0.0
    upper[:] = 0.0
    for i in range(n):
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            v = data[k]
            if j == i:
                diag[i] += v
            elif j == i + 1 and j < n:
                upper[i] += v
            elif j == i - 1:
                lower[j] += v
            elif v != 0.0:
                return False
    return True


# --------------------------------------------------------------------------------- verification


@njit(cache=True, inline='always')
def verify_dense(M, q, z, w_out, tol):
    """``w_out = M z + q`` recomputed from ``z``, then :func:`certify`: returns
    ``(residual, tolerance, certified)``."""
    mz = _matvec_plus_abs(M, z, q, w_out)
    return certify(z, w_out, q, mz, q.shape[0] + 1, tol)


@njit(cache=True)
def verify_tridiagonal(lower, diag, upper, q, z, w_out, tol):
    """:func:`verify_dense` for the tridiagonal ``M`` with bands ``(lower, diag, upper)``."""
    n = q.shape[0]
    _tridiag_w(lower, diag, upper, q, z, w_out)
    mz = 0.0
    for i in range(n):
        a = abs(diag[i] * z[i])
        if i > 0:
            a += abs(lower[i - 1] * z[i - 1])
        if i < n - 1:
            a += abs(upper[i] * z[i + 1])
        if not (a <= mz):
            mz = a
    return certify(z, w_out, q, mz, 4, tol)


@njit(cache=True, inline='always')
def all_finite(a):
    """True when every entry of the 1-d array ``a`` is finite (no temporaries)."""
    for i in range(a.shape[0]):
        if not np.isfinite(a[i]):
            return False
    return True


# --------------------------------------------------------------------------------- fused solves
#: Status of the fused kernels below when ``q`` holds NaN or an infinite entry (the caller
#: raises; the kernels themselves never do).
Q_NOT_FINITE = -1


@njit(cache=True, inline='always')
def lemke_verified(M, q, z_out, w_out, max_iter, tol):
    """:func:`lemke_kernel` and its verification in one compiled call (a reusable solver's
    per-call path: one dispatch instead of three).

    Returns ``(status_code, iterations, residual, tolerance)`` with ``w_out = M z + q``
    recomputed from ``z_out``, the status reconciled with :func:`certify` by
    :func:`verified_status`; :data:`Q_NOT_FINITE` when ``q`` is not finite.
    """
    if not all_finite(q):
        return Q_NOT_FINITE, 0, np.nan, np.nan
    code, its = _lemke_solve(M, q, z_out, w_out, max_iter, False)
    res, tolerance, ok = verify_dense(M, q, z_out, w_out, tol)
    return verified_status(code, ok), its, res, tolerance


@njit(cache=True)
def tridiagonal_verified(lower, diag, upper, q, z_inout, w_out, max_iter, warm, tol):
    """:func:`tridiagonal_lcp_kernel` (``warm=False``: from the projected Thomas sweeps) or
    :func:`tridiagonal_howard` from ``z_inout`` (``warm=True``), then the verification of
    :func:`verify_tridiagonal`, in one compiled call. Returns ``(status_code, iterations,
    residual, tolerance)`` as :func:`lemke_verified`."""
    if not all_finite(q):
        return Q_NOT_FINITE, 0, np.nan, np.nan
    if warm:
        code, its = tridiagonal_howard(lower, diag, upper, q, z_inout, w_out, max_iter)
    else:
        code, its = tridiagonal_lcp_kernel(lower, diag, upper, q, z_inout, w_out, max_iter)
    res, tolerance, ok = verify_tridiagonal(lower, diag, upper, q, z_inout, w_out, tol)
    return verified_status(code, ok), its, res, tolerance


@njit(cache=True)
def inf_norm(M):
    """``||M||_inf = max_i sum_j |M[i, j]|`` of a dense matrix (no temporaries)."""
    best = 0.0
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(M.shape[1]):
            s += abs(M[i, j])
        best = max(best, s)
    return best


@njit(cache=True)
def tridiagonal_inf_norm(lower, diag, upper):
    """``||M||_inf`` of the tridiagonal matrix with bands ``(lower, diag, upper)``."""
    n = diag.shape[0]
    best = 0.0
    for i in range(n):
        a = abs(diag[i])
        if i > 0:
            a += abs(lower[i - 1])
        if i < n - 1:
            a += abs(upper[i])
        best = max(best, a)
    return best


# --------------------------------------------------------------------------------- PGS polish
@njit(cache=True)
def _solve_principal_block(M, q, idx, k, x, scratch):
    """Solve ``M[a, a] x = -q[a]`` (``a = idx[:k]``) by Gaussian elimination with partial
    pivoting (backward stable, as LAPACK's ``gesv``), in ``scratch`` (at least ``k (k + 1)``
    floats: the caller's, allocated once for all the blocks it solves). False on a zero or
    non-finite pivot."""
    A = scratch[:k * k].reshape((k, k))
    b = scratch[k * k:k * (k + 1)]
    for r in range(k):
        i = idx[r]
        b[r] = -q[i]
        for c in range(k):
            A[r, c] = M[i, idx[c]]
    for col in range(k):
        p = col
        big = abs(A[col, col])
        for r in range(col + 1, k):
            if abs(A[r, col]) > big:
                big = abs(A[r, col])
                p = r
        if not (big > 0.0) or not np.isfinite(big):
            return False
        if p != col:
            for c in range(k):
                A[p, c], A[col, c] = A[col, c], A[p, c]
            b[p], b[col] = b[col], b[p]
        inv = 1.0 / A[col, col]
        for r in range(col + 1, k):
            f = A[r, col] * inv
            if f != 0.0:
                for c in range(col + 1, k):
                    A[r, c] -= f * A[col, c]
                b[r] -= f * b[col]
    for r in range(k - 1, -1, -1):
        s = b[r]
        for c in range(r + 1, k):
            s -= A[r, c] * x[c]
        x[r] = s / A[r, r]
    return True


@njit(cache=True)
def pgs_polish(M, q, z, w):
    """Replace ``z`` by the direct solution on the active set it has identified, if better.

    PGS converges linearly, and its error in ``z`` is up to ``residual / lambda_min(M)``;
    once the active set ``{z_i > w_i}`` is right, one solve of ``M[a, a] z_a = -q_a`` gives
    the solution to round-off. ``w`` must hold ``M z + q``; both are overwritten when the
    polished point has a smaller natural residual that :func:`certify` can trust (its
    cancellation below :data:`MAX_CANCELLATION`). Returns whether it did.
    """
    return _pgs_polish_in(M, q, z, w, np.empty(pgs_work_size(q.shape[0])))


@njit(cache=True, inline='always')
def pgs_work_size(n):
    """Floats of the scratch of :func:`_pgs_verified_in`: ``step``, the active indices (int64),
    the polished point, its ``w``, the block's solution and its elimination (``n (n + 1)``)."""
    return 5 * n + n * (n + 1)


@njit(cache=True, **NO_REFCOUNT)
def _pgs_polish_in(M, q, z, w, work):
    """:func:`pgs_polish` in the caller's scratch ``work`` (at least ``4 n + n (n + 1)``
    floats)."""
    n = q.shape[0]
    idx = work[:n].view(np.int64)
    p = work[n:2 * n]
    wp = work[2 * n:3 * n]
    k = 0
    for i in range(n):
        p[i] = 0.0
        if z[i] > w[i]:
            idx[k] = i
            k += 1
    if k > 0:
        x = work[3 * n:3 * n + k]
        if not _solve_principal_block(M, q, idx, k, x, work[4 * n:]):
            return False
        for r in range(k):
            p[idx[r]] = x[r]
    mz = _matvec_plus_abs(M, p, q, wp)
    qmax = 0.0
    for i in range(n):
        qmax = max(qmax, abs(q[i]))
    if not (mz <= MAX_CANCELLATION * (1.0 + qmax)):
        # a singular active block: the float residual of that point is round-off, and
        # a comparison with it means nothing (see certify)
        return False
    after = natural_residual(p, wp, q)
    if np.isfinite(after) and after < natural_residual(z, w, q):
        for i in range(n):
            z[i] = p[i]
            w[i] = wp[i]
        return True
    return False


@njit(cache=True)
def pgs_verified(M, q, z_inout, w_out, tol, max_iter, omega, cold_start):
    """:func:`pgs_kernel` (from zero with ``cold_start``, else from ``z_inout``), the
    active-set polish of :func:`pgs_polish` and the verification of :func:`verify_dense`,
    in one compiled call. Returns ``(status_code, sweeps, residual, tolerance)`` as
    :func:`lemke_verified`."""
    return _pgs_verified_in(M, q, z_inout, w_out, tol, max_iter, omega, cold_start,
                            np.empty(pgs_work_size(q.shape[0])))


@njit(cache=True, **NO_REFCOUNT)
def _pgs_verified_in(M, q, z_inout, w_out, tol, max_iter, omega, cold_start, work):
    """:func:`pgs_verified` in the caller's scratch ``work`` of :func:`pgs_work_size` floats
    (the per-call path of a small LCP: no allocation)."""
    if not all_finite(q):
        return Q_NOT_FINITE, 0, np.nan, np.nan
    if cold_start:
        z_inout[:] = 0.0
    n = q.shape[0]
    code, its = _pgs_run(M, q, z_inout, w_out, tol, max_iter, omega, work[:n])
    if code == SOLVED or code == MAX_ITER:
        _matvec_plus(M, z_inout, q, w_out)
        _pgs_polish_in(M, q, z_inout, w_out, work[n:])
    res, tolerance, ok = verify_dense(M, q, z_inout, w_out, tol)
    return verified_status(code, ok), its, res, tolerance
