"""numba kernels of the exact event search of :func:`nscontrol.numerics.lti.first_event`.

Everything the search does runs compiled, so that integrators can call it from their own
compiled loops (:mod:`nscontrol.simulate._event_kernels`):

* :func:`search` — the whole first-event search from a (balanced) start state: the
  classification of guards at zero at ``t = 0``, the cell scan (``y <- Φ y``, Taylor
  polynomial per cell and guard, Bernstein certificate of root-free cells), the exact analysis
  of a flagged cell (critical points of ``g`` isolated by Bernstein subdivision of ``g'``,
  then a walk over the monotone pieces), the re-polish on the exact start state of the event's
  cell and the gathering of simultaneous guards;
* :func:`propagate` — ``e^{At} x`` for one time: eigen-decomposition when well conditioned,
  otherwise ``Φ^k`` by binary powering followed by the Taylor polynomial inside the cell.

See the module docstring of :mod:`nscontrol.numerics.lti` for the strategy and its guarantees.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Return codes of :func:`search`.
NO_EVENT, EVENT, NEGATIVE = 0, 1, 2
#: Propagation kinds of :func:`propagate`.
KIND_EIG, KIND_CELLS = 0, 1

_EPS = 2.220446049250313e-16
_STACK = 96          # subdivision stack (depth <= 45 at width 1e-13)
_MIN_WIDTH = 1e-13   # below this a cluster of critical points counts as one


@njit(cache=True, inline="always")
def copy_into(dst, src):  # pragma: no cover - compiled
    """``dst[:] = src`` for vectors of one length, as a loop: numba's slice assignment
    compiles a shape-checked broadcast whose error message alone costs about 3 s of the
    first compile (string formatting kernels), for no check these callers need."""
    for j in range(dst.shape[0]):
        dst[j] = src[j]


@njit(cache=True, inline="always")
def sum_squares(y):  # pragma: no cover - compiled
    """``np.sum(y * y)`` (the same sequential sum) without the temporary array."""
    s = 0.0
    for j in range(y.shape[0]):
        s += y[j] * y[j]
    return s


@njit(cache=True, inline="always")
def _horner2(a, m, x):  # pragma: no cover - compiled
    """Value and derivative at ``x`` of ``Σ_{j<m} a[j] x^j``."""
    r = 0.0
    d = 0.0
    for j in range(m - 1, -1, -1):
        d = d * x + r
        r = r * x + a[j]
    return r, d


@njit(cache=True, inline="always")
def _horner(a, m, x):  # pragma: no cover - compiled
    r = 0.0
    for j in range(m - 1, -1, -1):
        r = r * x + a[j]
    return r


#: Iteration budget of the root refinement :func:`_root`. It cannot be spent: the bracket
#: at least halves every two iterations (an iterate that did not halve it is followed by
#: the midpoint), and the refinement stops once the bracket is below
#: ``4 eps max(|hi|, _ROOT_FLOOR)``; from a bracket within the cell ``[0, 1]`` that takes at
#: most ``2 (log2(1 / (4 eps _ROOT_FLOOR)) + 1) = 2·(70 + 1) = 142`` iterations.
ROOT_BUDGET = 160
#: Below this ``|σ|`` the root's bracket is refined to an absolute ``4 eps _ROOT_FLOOR``
#: (``8.5e-22`` of a cell), far below what moves the state (a cell moves it by at most its
#: norm, ``‖Ab h‖ = 1``): a relative bracket of a root at ``σ = 1e-300`` would need more
#: than 1000 bisections and say nothing more.
_ROOT_FLOOR = 2.0 ** -20


@njit(cache=True, inline="always")
def _root(a, m, lo, hi, f_lo, f_hi):  # pragma: no cover - compiled
    """Root of the monotone polynomial on [lo, hi] with P(lo) > 0 >= P(hi): safeguarded Newton
    from the secant point (bisection whenever Newton leaves the bracket or did not halve it
    over the last two iterations; see :data:`ROOT_BUDGET`)."""
    return root_iterations(a, m, lo, hi, f_lo, f_hi)[0]


@njit(cache=True, inline="always")
def root_iterations(a, m, lo, hi, f_lo, f_hi):  # pragma: no cover - compiled
    """:func:`_root` and the number of iterations it took (at most :data:`ROOT_BUDGET`)."""
    x = lo + (hi - lo) * f_lo / (f_lo - f_hi) if f_lo > f_hi else 0.5 * (lo + hi)
    width = hi - lo
    for it in range(ROOT_BUDGET):
        fx, d = _horner2(a, m, x)
        if fx == 0.0:
            return x, it + 1
        if fx > 0.0:
            lo = x
        else:
            hi = x
        # a Newton point that did not halve the bracket is followed by the midpoint, whose
        # evaluation halves it: the bracket halves at least every two iterations
        stalled = hi - lo > 0.5 * width
        width = hi - lo
        x_new = x - fx / d if d != 0.0 else 0.5 * (lo + hi)
        inside = lo < x_new < hi
        if inside and abs(x_new - x) <= 2.0 * _EPS * abs(x):
            return x_new, it + 1    # Newton converged
        if stalled or not inside:
            x_new = 0.5 * (lo + hi)
        if hi - lo <= 4.0 * _EPS * max(abs(hi), _ROOT_FLOOR):
            return x_new, it + 1    # the bracket is the root
        x = x_new
    return x, ROOT_BUDGET


@njit(cache=True, inline="always")
def _signed_root(a, m, lo, hi, sign, work):  # pragma: no cover - compiled
    """Root of ``sign · P`` (``P`` monotone, changing sign on [lo, hi])."""
    for j in range(m):
        work[j] = sign * a[j]
    f_lo = _horner(work, m, lo)
    f_hi = _horner(work, m, hi)
    if f_lo <= 0.0:
        return lo
    if f_hi >= 0.0:
        return hi
    return _root(work, m, lo, hi, f_lo, f_hi)


@njit(cache=True, inline="always")
def polish(a, s, grazing):  # pragma: no cover - compiled
    """Newton polish of a root of ``P = Σ a_j σ^j`` (of ``P'`` when ``grazing``) near ``s``;
    ``s`` is kept when the exact polynomial disagrees (a step above 1e-6)."""
    m = a.shape[0]
    c = np.empty(m)
    if grazing:
        for j in range(m - 1):
            c[j] = (j + 1) * a[j + 1]
        m -= 1
    else:
        copy_into(c, a)
    x = s
    for _ in range(4):
        f, d = _horner2(c, m, x)
        if d == 0.0:
            break
        step = f / d
        if not np.isfinite(step) or abs(step) > 1e-6:
            return s
        x -= step
        if abs(step) <= 2.0 * _EPS * max(abs(x), 1.0):
            break
    return x


@njit(cache=True, inline="always")
def _bernstein(B, a, m, out):  # pragma: no cover - compiled
    """Bernstein coefficients on [0, 1] of ``Σ_{j<m} a_j σ^j`` (``B`` of degree m - 1)."""
    for r in range(m):
        s = 0.0
        for j in range(r + 1):
            s += B[r, j] * a[j]
        out[r] = s


@njit(cache=True, inline="always")
def _sign_changes(b, m):  # pragma: no cover - compiled
    """Sign variations of ``b`` (zeros skipped): an upper bound on the number of roots in the
    open interval, with the same parity (Descartes' rule for the Bernstein basis)."""
    count = 0
    last = 0.0
    for j in range(m):
        if b[j] != 0.0:
            if last != 0.0 and (b[j] > 0.0) != (last > 0.0):
                count += 1
            last = b[j]
    return count


@njit(cache=True)
def _critical_points(da, m, bern_d, s_end, out, stack_b, stack_lo, stack_hi, work
                     ):  # pragma: no cover - compiled
    """Roots of ``P' = Σ_{j<m} da_j σ^j`` in ``(0, s_end)``, ascending, into ``out``.

    Isolated by subdivision of the Bernstein form (de Casteljau at the midpoint, left half
    first): no sign change -> no root; one -> exactly one root, refined by safeguarded Newton;
    several on an interval narrower than ``_MIN_WIDTH`` -> one (clustered) critical point.
    """
    count = 0
    _bernstein(bern_d, da, m, stack_b[0])
    stack_lo[0] = 0.0
    stack_hi[0] = 1.0
    top = 1
    while top > 0:
        top -= 1
        lo = stack_lo[top]
        hi = stack_hi[top]
        if lo >= s_end:
            continue
        b = stack_b[top]
        var = _sign_changes(b, m)
        if var == 0:
            continue
        if var == 1:
            sign = 1.0 if b[0] > 0.0 or (b[0] == 0.0 and b[m - 1] < 0.0) else -1.0
            r = _signed_root(da, m, lo, hi, sign, work)
            if 0.0 < r < s_end and count < out.shape[0]:
                out[count] = r
                count += 1
            continue
        if hi - lo <= _MIN_WIDTH or top + 2 > stack_b.shape[0]:
            r = 0.5 * (lo + hi)
            if 0.0 < r < s_end and count < out.shape[0]:
                out[count] = r
                count += 1
            continue
        # split: right half pushed first so that the left half is processed first
        mid = 0.5 * (lo + hi)
        for j in range(m):
            work[j] = b[j]
        left = stack_b[top + 1]
        right = stack_b[top]  # overwrites b, already copied to work
        left[0] = work[0]
        right[m - 1] = work[m - 1]
        for r_ in range(1, m):
            for j in range(m - r_):
                work[j] = 0.5 * (work[j] + work[j + 1])
            left[r_] = work[0]
            right[m - 1 - r_] = work[m - 1 - r_]
        stack_lo[top] = mid
        stack_hi[top] = hi
        stack_lo[top + 1] = lo
        stack_hi[top + 1] = mid
        top += 2
    return count


@njit(cache=True, inline="always")
def _touches_at_end(a, K1, v, tol):  # pragma: no cover - compiled
    """Whether ``P`` (decreasing to ``|P(1)| <= tol`` at the cell's end) only touches zero
    there: the minimum of its quadratic expansion at ``σ = 1`` stays within ``tol`` (the
    same test as for an interior minimum, whose critical point lies in the next cell)."""
    d1 = 0.0
    d2 = 0.0
    for j in range(1, K1):
        d1 += j * a[j]
        d2 += j * (j - 1) * a[j]
    return d2 > 0.0 and v - d1 * d1 / (2.0 * d2) >= -tol


@njit(cache=True)
def _walk(a, K1, s_end, tol, skip_start, bern, crit, stack_b, stack_lo, stack_hi, work,
          da):  # pragma: no cover - compiled
    """First zero of ``P(σ) = Σ_{j<K1} a_j σ^j`` on ``[0, s_end]``: ``(found, σ, grazing)``
    (``bern[d]``: the Bernstein matrix of degree ``d``).

    The critical points of ``P`` cut the cell into monotone pieces; walking them left to
    right, the first piece whose right end has ``P <= 0`` holds the first root; a local
    minimum with ``|P| <= tol`` is a tangential touch (reported at the minimum).
    """
    ncrit = 0
    if K1 >= 3:  # a linear P has no critical point
        for j in range(K1 - 1):
            da[j] = (j + 1) * a[j + 1]
        ncrit = _critical_points(da, K1 - 1, bern[K1 - 2], s_end, crit, stack_b, stack_lo,
                                 stack_hi, work)
    start = 0
    if skip_start:  # flat start of a guard leaving zero: not a touch
        while start < ncrit and _horner(a, K1, crit[start]) <= tol:
            start += 1
    prev_x = 0.0
    prev_v = _horner(a, K1, 0.0)
    if not skip_start and prev_v <= 0.0:
        return True, 0.0, False
    for j in range(start, ncrit + 1):
        x = crit[j] if j < ncrit else s_end
        v = _horner(a, K1, x)
        if j < ncrit and abs(v) <= tol:
            return True, x, True
        if j == ncrit and s_end == 1.0 and abs(v) <= tol and _touches_at_end(a, K1, v, tol):
            return True, 1.0, True  # a touch on the cell boundary: its minimum is next door
        if v <= 0.0:
            return True, _root(a, K1, prev_x, x, prev_v, v), False
        prev_x = x
        prev_v = v
    return False, 0.0, False


@njit(cache=True, inline="always")
def guard_taylor_coefficients(W, g0, i, y, a):  # pragma: no cover - compiled
    """Taylor coefficients on a cell of guard ``i`` from the cell-start state ``y``."""
    K1, _, n = W.shape
    for j in range(K1):
        s = 0.0
        for l in range(n):
            s += W[j, i, l] * y[l]
        a[j] = s
    a[0] += g0[i]


@njit(cache=True)
def taylor_tables(M, T, phi):  # pragma: no cover - compiled
    """``T[j] = M^j / j!`` for ``j < len(T)`` and ``phi = Σ_j T[j]``: with ``||M|| <= 1`` the
    sum is ``e^M`` to within ``e/len(T)!`` relative (summed from the smallest term up)."""
    K1, n, _ = T.shape
    for r in range(n):
        for c in range(n):
            T[0, r, c] = 1.0 if r == c else 0.0
    for j in range(1, K1):
        for r in range(n):
            for c in range(n):
                s = 0.0
                for q in range(n):
                    s += M[r, q] * T[j - 1, q, c]
                T[j, r, c] = s / j
    for r in range(n):
        for c in range(n):
            s = 0.0
            for j in range(K1 - 1, -1, -1):
                s += T[j, r, c]
            phi[r, c] = s


@njit(cache=True, inline="always")
def matmul_into(A, B, out):  # pragma: no cover - compiled
    """``out = A @ B`` for square matrices (loops: no BLAS threads for these small sizes)."""
    n = out.shape[0]
    for r in range(n):
        for c in range(n):
            s = 0.0
            for q in range(n):
                s += A[r, q] * B[q, c]
            out[r, c] = s


@njit(cache=True, inline="always")
def _matvec(M, x, out):  # pragma: no cover - compiled
    n = M.shape[0]
    for r in range(n):
        s = 0.0
        for c in range(M.shape[1]):
            s += M[r, c] * x[c]
        out[r] = s


@njit(cache=True)
def _power_apply(phi, k, y, out):  # pragma: no cover - compiled
    """``out = Φ^k y`` by binary powering (``log2 k`` squarings)."""
    n = y.shape[0]
    copy_into(out, y)
    if k <= 0:
        return
    P = np.empty((n, n))
    P2 = np.empty((n, n))
    for r in range(n):
        copy_into(P[r], phi[r])
    tmp = np.empty(n)
    while True:
        if k & 1:
            _matvec(P, out, tmp)
            copy_into(out, tmp)
        k >>= 1
        if k == 0:
            break
        matmul_into(P, P, P2)  # P <- P @ P
        for r in range(n):
            copy_into(P[r], P2[r])


@njit(cache=True)
def propagate(kind, lam, V, Vinv, phi, T, d, h, x, t, out):  # pragma: no cover - compiled
    """``out = e^{At} x`` for one time ``t >= 0``.

    ``KIND_EIG``: ``V diag(e^{λt}) V^{-1} x``. ``KIND_CELLS``: in balanced coordinates
    ``y = x / d``, ``t = k h + σ h``: ``y_k = Φ^k y`` by binary powering, then
    ``Σ_j T_j σ^j y_k`` (``T_j = (Ab h)^j / j!``, exact to rounding since ``||Ab h|| = 1``).
    """
    n = x.shape[0]
    if kind == KIND_EIG:
        c = np.empty(n, dtype=np.complex128)
        for j in range(n):
            s = 0j
            for l in range(n):
                s += Vinv[j, l] * x[l]
            c[j] = s * np.exp(lam[j] * t)
        for j in range(n):
            s = 0j
            for l in range(n):
                s += V[j, l] * c[l]
            out[j] = s.real
        return
    y = np.empty(n)
    for j in range(n):
        y[j] = x[j] / d[j]
    k = int(np.floor(t / h))
    sigma = t / h - k
    if sigma >= 1.0:  # rounding of t / h
        k += 1
        sigma = 0.0
    yk = np.empty(n)
    _power_apply(phi, k, y, yk)
    acc = np.zeros(n)
    tmp = np.empty(n)
    for j in range(T.shape[0] - 1, -1, -1):  # Horner in σ over the matrices T_j
        for r in range(n):
            acc[r] *= sigma
        _matvec(T[j], yk, tmp)
        for r in range(n):
            acc[r] += tmp[r]
    for j in range(n):
        out[j] = acc[j] * d[j]


@njit(cache=True, inline="always")
def clock_advance(t, lo, dur):  # pragma: no cover - compiled
    """The time label after a piece of duration ``dur`` from the clock ``t + lo``: returns
    ``(t', lo')`` with ``t' + lo' = t + lo + dur`` exactly (Knuth's two-sum; ``lo`` carries
    what ``t'`` cannot hold). An integrator that propagates its state by each event's own
    offset ``τ`` keeps its time labels this way: a plain ``t + τ`` rounds by ``eps·t`` per
    event, the same way at every period of a periodic motion, and the labels would drift
    from the state's own time by ``N·eps·t`` after ``N`` events."""
    s = t + dur
    bp = s - t
    lo = lo + ((t - (s - bp)) + (dur - bp))
    t_new = s + lo
    return t_new, lo - (t_new - s)


@njit(cache=True, inline="always")
def flight_end(event, tau, t, lo, tf):  # pragma: no cover - compiled
    """The duration of a flight (or piece) from the clock ``t + lo`` and the clock at its
    end, ``(dur, t', lo')``: with an event, its own offset ``τ`` (never a difference of
    labels, which rounds by ``eps·t``), the labels moved by :func:`clock_advance` and clipped
    at ``tf``; without one, up to ``tf``."""
    if event:
        t_end, lo_end = clock_advance(t, lo, tau)
        if t_end >= tf:
            return tau, tf, 0.0
        return tau, t_end, lo_end
    return (tf - t) - lo, tf, 0.0


@njit(cache=True, inline="always")
def restart_tolerance(W, i, kappa, ynorm, g0_i, a1, h, t):  # pragma: no cover - compiled
    """Bound on the round-off error of guard ``i`` at a state the integrator computed itself
    (after an event, at the restart of a chunk), with ``a1 = h ġ_i`` its first Taylor
    coefficient on a cell of width ``h``::

        tol = 4 (K + 1 + n) eps (κ (‖G_i D‖ ‖y‖ + |g0_i|) + |ġ_i| max(|t|, h)).

    The first term is the state's rounding carried into the guard: the propagated state is
    a sum of at most ``K + 1`` Taylor terms or ``n`` eigenmodes, each rounded to ``eps``
    relative, amplified by the propagation's condition ``κ`` (``cond(V)`` on the
    eigen-decomposition path; on the cell path the at most ``2·53`` products of binary
    powering); the guard's dot product, the jump and the recentring add no more than the
    stated factor 4. The second term is the state of a time known to ``eps·max(|t|, h)``:
    an event time ``t0 + τ`` or a sample time ``t_k`` rounded, over which the guard moves at
    ``|ġ_i|``."""
    K1, _, n = W.shape
    return 4.0 * (K1 + n) * _EPS * (kappa * (ynorm * abs_row(W, i) + abs(g0_i))
                                   + abs(a1) / h * max(abs(t), h))


@njit(cache=True, inline="always")
def abs_row(W, i):  # pragma: no cover - compiled
    """``‖G_i D‖``: the norm of guard ``i``'s row of ``W[0] = G D``."""
    s = 0.0
    for c in range(W.shape[2]):
        s += W[0, i, c] * W[0, i, c]
    return np.sqrt(s)


@njit(cache=True)
def project_restart(W, g0, kappa, h, t, n_free, y, a, proj):  # pragma: no cover - compiled
    """Project a restart state onto the admissible set ``{g >= 0}`` of its guards: the one
    shared step of every integrator that goes on from a state it computed itself (after an
    event or a jump, at the restart of a chunk), never from a user's ``x0``.

    ``y`` is the balanced state (``x = D y``), changed in place. A guard negative by at most
    :func:`restart_tolerance` is the integrator's own round-off (the event time rounded,
    the state propagated): ``y`` moves by the smallest step along the guard's row ``G_i D``
    that brings it to zero, on the first ``n_free`` entries only (the others — the constant
    and the input generator of an augmented state — are not the plant's and stay). Each
    projection adds one to ``proj[0]`` and keeps the largest ``|g|`` in ``proj[1]`` and the
    largest ``|g|/tol`` in ``proj[2]``.

    Returns ``-1``, or the index of the first guard negative beyond its tolerance (or with
    no free entry to move), with its value in ``proj[3]`` and the tolerance in ``proj[4]``.
    """
    K1, p, n = W.shape
    for i in range(p):
        guard_taylor_coefficients(W, g0, i, y, a)
        if a[0] >= 0.0:
            continue
        ynorm = np.sqrt(sum_squares(y))
        tol = restart_tolerance(W, i, kappa, ynorm, g0[i], a[1], h, t)
        w2 = 0.0
        for c in range(n_free):
            w2 += W[0, i, c] * W[0, i, c]
        if -a[0] > tol or w2 == 0.0:
            proj[3] = a[0]
            proj[4] = tol
            return i
        step = a[0] / w2
        for c in range(n_free):
            y[c] -= step * W[0, i, c]
        proj[0] += 1.0
        proj[1] = max(proj[1], -a[0])
        proj[2] = max(proj[2], -a[0] / tol)
    return -1


@njit(cache=True)
def search(W, g0, row_norm, graze_tol, sim_tol, remainder, phi, bern, y0, h, t_max,
           kind, lam, V, Vinv, T, d, hit_out, graze_out):  # pragma: no cover - compiled
    """The first event of the guards ``g_i(t) = (W[0] e^{Ab t} y0)_i + g0_i`` in
    ``(0, t_max]`` (balanced coordinates, cells of width ``h``; ``bern[d]`` is the Bernstein
    matrix of degree ``d``). A polynomial whose top coefficients are exactly zero (a flow
    with a nilpotent part: free flight is a parabola) is handled at its own degree.

    Returns ``(code, t, index)``: ``NO_EVENT``; ``EVENT`` with the event time ``t`` and
    ``hit_out[i] = 1`` for every guard at zero then (``graze_out[i] = 1`` when it only
    touches); ``NEGATIVE`` with the ``index`` of a guard negative at ``t = 0``.
    """
    K1, p, n = W.shape
    a = np.empty(K1)
    da = np.empty(K1 - 1)
    work = np.empty(K1)
    crit = np.empty(4 * K1)
    stack_b = np.empty((_STACK, K1 - 1))
    stack_lo = np.empty(_STACK)
    stack_hi = np.empty(_STACK)
    active = np.ones(p, dtype=np.bool_)
    skip0 = np.zeros(p, dtype=np.bool_)
    sigma = np.zeros(p)
    for i in range(p):
        hit_out[i] = 0
        graze_out[i] = 0
    # -- guards at zero at t = 0 ------------------------------------------------------
    ynorm = np.sqrt(sum_squares(y0))
    falling = False
    for i in range(p):
        guard_taylor_coefficients(W, g0, i, y0, a)
        tol = graze_tol * (row_norm[i] * ynorm + abs(g0[i]))
        if a[0] > tol:
            continue
        if a[0] < -tol:
            return NEGATIVE, 0.0, i
        first = -1
        for j in range(1, K1):
            if abs(a[j]) > tol:
                first = j
                break
        if first < 0:
            active[i] = False  # identically zero: moves along the surface
        elif a[first] < 0.0 and not (a[2] > 0.0 and a[0] - a[1] ** 2 / (4.0 * a[2]) >= -tol):
            hit_out[i] = 1
            falling = True
        else:
            skip0[i] = True  # leaving the surface (just after an impact)
    if falling:
        return EVENT, 0.0, -1
    # -- cell scan ---------------------------------------------------------------------
    n_cells = max(1, int(np.ceil(t_max / h)))
    y = np.empty(n)
    copy_into(y, y0)
    y_next = np.empty(n)
    k_hit = -1
    for k in range(n_cells):
        sigma_end = min(1.0, (t_max - k * h) / h)
        if sigma_end <= 0.0:
            break
        ynorm = np.sqrt(sum_squares(y))
        for i in range(p):
            if not active[i]:
                continue
            guard_taylor_coefficients(W, g0, i, y, a)
            m = K1
            while m > 1 and a[m - 1] == 0.0:
                m -= 1
            scale = row_norm[i] * ynorm + abs(g0[i])
            tol = graze_tol * scale
            _bernstein(bern[m - 1], a, m, work)
            bmin = np.inf
            for r in range(m):
                bmin = min(bmin, work[r])
            if bmin > tol + remainder * scale:
                continue  # certified: no zero of this guard on the cell
            found, s, grazing = _walk(a, m, sigma_end, tol, skip0[i] and k == 0, bern,
                                      crit, stack_b, stack_lo, stack_hi, work, da)
            if found:
                hit_out[i] = 1
                graze_out[i] = 1 if grazing else 0
                sigma[i] = s
                k_hit = k
        if k_hit >= 0:
            break
        _matvec(phi, y, y_next)
        copy_into(y, y_next)
    if k_hit < 0:
        return NO_EVENT, 0.0, -1
    # -- re-polish on the exact start state of the cell, simultaneous guards -------------
    k = k_hit
    if k > 0:
        x_start = np.empty(n)
        x0 = y0 * d
        propagate(kind, lam, V, Vinv, phi, T, d, h, x0, k * h, x_start)
        for l in range(n):
            y[l] = x_start[l] / d[l]
        for i in range(p):
            if hit_out[i]:
                guard_taylor_coefficients(W, g0, i, y, a)
                sigma[i] = polish(a, sigma[i], graze_out[i] == 1)
    s_first = np.inf
    for i in range(p):
        if hit_out[i]:
            s_first = min(s_first, sigma[i])
    t_first = k * h + s_first * h
    delta = sim_tol * max(t_first, h) / h
    for i in range(p):
        if hit_out[i] and sigma[i] > s_first + delta:
            hit_out[i] = 0
            graze_out[i] = 0
    for i in range(p):
        if hit_out[i] or not active[i] or (skip0[i] and k == 0):
            continue
        guard_taylor_coefficients(W, g0, i, y, a)
        if _horner(a, K1, s_first + delta) <= 0.0:
            hit_out[i] = 1
            graze_out[i] = 0
    return EVENT, min(t_first, t_max), -1
