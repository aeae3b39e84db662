"""numba loop of the exact piecewise-affine integrator (:mod:`._pwa`).

In region ``i`` the augmented state ``ξ = [x; ω; 1]`` flows by ``ξ' = M_i ξ``: a piece is
``e^{M_i τ} ξ`` (:func:`nscontrol.numerics._lti_kernels.propagate`) and its end is the first
zero of the region's facet slacks, found by the compiled search
:func:`nscontrol.numerics._lti_kernels.search`. The loop writes the requested samples, settles
every plain crossing itself — one region's field points into its region (:func:`choose_region`,
the same test Python uses), the event is not a tangential touch and does not involve the
domain — and multiplies the piece exponentials and saltation matrices into ``Φ`` when the
sensitivity is asked. Anything else is handed back to Python at the event, whose general code
then runs exactly as without this loop (grazing, domain exits, no region to enter, a zero
``nᵀF⁻``), so the loop changes the speed, not the semantics.

A region whose flow is not prepared yet (flows are built lazily, as they are visited) is
handed back as ``NEED_FLOW`` before the piece starts.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...numerics._lti_kernels import (
    EVENT,
    NEGATIVE,
    flight_end,
    matmul_into,
    project_restart,
    propagate,
    search,
)

#: Return codes of :func:`run_pieces`.
DONE, HANDOFF, FULL, NEED_FLOW, INADMISSIBLE, STUCK = 0, 1, 2, 3, 4, 5

#: Consecutive events without progress before the run is declared stuck (a Zeno point).
MAX_STUCK = 50


@njit(cache=True)
def entering(H, h, nf, aug, j, xi, n, tol):  # pragma: no cover - compiled
    """Whether the flow of region ``j`` from ``ξ`` (inside or on its boundary) moves into it.

    ``H[j, :nf[j]]``, ``h[j, :nf[j]]`` are its facets ``H x <= h``: a slack below
    ``-tol·scale`` means outside; at an active facet the first nonzero time derivative of the
    slack (of ``x', x'', x'''`` of region ``j``'s flow; zero below ``1e-12`` relative) must not
    be negative.
    """
    m = xi.shape[0]
    k = nf[j]
    active = np.zeros(k, dtype=np.bool_)
    n_active = 0
    for r in range(k):
        s = h[j, r]
        scale = 1.0 + abs(h[j, r])
        for c in range(n):
            s -= H[j, r, c] * xi[c]
            scale += abs(H[j, r, c]) * abs(xi[c])
        if s < -tol * scale:
            return False
        if abs(s) <= tol * scale:
            active[r] = True
            n_active += 1
    if n_active == 0:
        return True
    ders = np.empty((3, m))
    prev = xi
    for q in range(3):  # ξ', ξ'', ξ''' of region j's flow
        for a in range(m):
            s = 0.0
            for b in range(m):
                s += aug[j, a, b] * prev[b]
            ders[q, a] = s
        prev = ders[q]
    for r in range(k):
        if not active[r]:
            continue
        for q in range(3):  # the first nonzero derivative of h_r - H_r x decides
            v = 0.0
            size = 0.0
            for c in range(n):
                v -= H[j, r, c] * ders[q, c]
                size += abs(H[j, r, c]) * abs(ders[q, c])
            if abs(v) > 1e-12 * (size + 1e-300):
                if v < 0.0:
                    return False
                break
    return True


@njit(cache=True)
def choose_region(H, h, nf, aug, xi, n, exclude):  # pragma: no cover - compiled
    """The first region (other than ``exclude``) whose flow from ``ξ`` enters it, trying a
    tight (``1e-12``) then a loose (``1e-9``) boundary tolerance; ``-1`` for none."""
    for tol in (1e-12, 1e-9):
        for j in range(nf.shape[0]):
            if j != exclude and entering(H, h, nf, aug, j, xi, n, tol):
                return j
    return -1


@njit(cache=True)
def _field(aug, i, xi, n, out):  # pragma: no cover - compiled
    """``out = x'`` of region ``i`` at ``ξ``."""
    m = xi.shape[0]
    for a in range(n):
        s = 0.0
        for b in range(m):
            s += aug[i, a, b] * xi[b]
        out[a] = s


@njit(cache=True)
def _times_expm(kind, lam, V, Vinv, phi, T, d, h, tau, n, Phi, unit, col, E, tmp
                ):  # pragma: no cover - compiled
    """``Φ <- e^{A_i τ} Φ``: the x-block of the augmented exponential, column by column."""
    for k in range(n):
        unit[k] = 1.0
        propagate(kind, lam, V, Vinv, phi, T, d, h, unit, tau, col)
        unit[k] = 0.0
        for r in range(n):
            E[r, k] = col[r]
    _premultiply(E, Phi, tmp)


@njit(cache=True)
def _premultiply(F, Phi, tmp):  # pragma: no cover - compiled
    """``Φ <- F Φ``."""
    matmul_into(F, Phi, tmp)
    Phi[:, :] = tmp


@njit(cache=True)
def run_pieces(kinds, lams, Vs, Vinvs, phis, taylors, ds, hs, kappas, ready, Ws, g0s,
               row_norms, bern, remainder, graze_tol, sim_tol, H, h, nf, aug,
               xi, t, tf, i, Phi, sens, t_eval, ptr, s_x,
               e_t, e_row, e_from, e_to, e_x, e_S, e_ptr, budget, hit, graze, stuck,
               restart, proj, clock):  # pragma: no cover - compiled
    """Flow from ``(t, ξ)`` in region ``i`` and settle the plain crossings until ``tf`` or a
    hand-off.

    Returns ``(code, t, i, ptr, n_events, stuck, pieces, index)``; ``ξ`` and ``Φ`` are
    overwritten with their values at the returned ``t``:

    * ``DONE``: ``t = tf``;
    * ``HANDOFF``: ``ξ`` is the state at an event of region ``i`` that Python settles
      (``hit``/``graze`` flag its guards: facets of ``i`` first, then the domain's);
    * ``FULL``: the event buffer is full or the ``budget`` of events is spent, resume;
    * ``NEED_FLOW``: region ``i``'s flow is not prepared (``ready[i]`` false), prepare it and
      resume;
    * ``INADMISSIBLE``: guard ``index`` of region ``i`` is negative at the start of a
      piece: beyond the round-off tolerance of
      :func:`nscontrol.numerics._lti_kernels.project_restart` (``proj[3:5]``) for a state
      the run computed, or beyond the search's for the user's ``x0``;
    * ``STUCK``: more than :data:`MAX_STUCK` consecutive events without progress.

    Samples: the requested times ``t_eval[ptr:]`` up to each piece's end go to the same rows
    of ``s_x``; settled crossings to ``e_*`` with ``e_ptr`` the sample count at the event (the
    samples up to and including the event time precede it).

    Every piece that starts from a state the run computed (after a crossing, and the first
    one too when ``restart``) starts with that projection (counted in ``proj``); a piece
    ends at the event's own offset ``τ`` from its start, never at a difference of absolute
    times (whose rounding, ``eps·t``, would carry the state past its facet); the time
    labels carry their rounding in ``clock = [t, lo]``
    (:func:`nscontrol.numerics._lti_kernels.clock_advance`), read when ``clock[0]`` is the
    ``t`` passed, written at every return.
    """
    lo = clock[1] if clock[0] == t else 0.0
    out = _pieces(kinds, lams, Vs, Vinvs, phis, taylors, ds, hs, kappas, ready, Ws, g0s,
                  row_norms, bern, remainder, graze_tol, sim_tol, H, h, nf, aug, xi, t, lo,
                  tf, i, Phi, sens, t_eval, ptr, s_x, e_t, e_row, e_from, e_to, e_x, e_S,
                  e_ptr, budget, hit, graze, stuck, restart, proj)
    clock[0] = out[1]
    clock[1] = out[8]
    return out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7]


@njit(cache=True)
def _crossed_facet(hit, graze, n_facets):  # pragma: no cover - compiled
    """The first region facet hit, or -1 when the loop hands the event to Python: a domain
    facet was hit (Python decides whether the run ends), or every hit facet is grazed."""
    row = -1
    plain = True
    all_graze = True
    for r in range(hit.shape[0]):
        if hit[r]:
            if r >= n_facets:
                plain = False
            elif row < 0:
                row = r
            if not graze[r]:
                all_graze = False
    return -1 if (not plain or all_graze) else row


@njit(cache=True)
def _crossing_saltation(aug, normal, i, j, xi, n, fm, fp, S, Phi,
                        tmp):  # pragma: no cover - compiled
    """``S = I + (F⁺ - F⁻) nᵀ / (nᵀF⁻)`` of the crossing from region ``i`` to ``j`` at ``xi``
    into ``S``, and ``Φ ← S Φ``; False (nothing written) when ``nᵀF⁻ = 0``."""
    _field(aug, i, xi, n, fm)
    _field(aug, j, xi, n, fp)
    den = 0.0
    for c in range(n):
        den += normal[c] * fm[c]
    if den == 0.0:
        return False
    for r in range(n):
        for c in range(n):
            S[r, c] = (fp[r] - fm[r]) * normal[c] / den
        S[r, r] += 1.0
    _premultiply(S, Phi, tmp)
    return True


@njit(cache=True)
def _sample_flight(kind, lam, V, Vinv, phi, T, d, hh, xi, t, lo, t_end, t_eval, ptr, s_x, xn,
                   n):  # pragma: no cover - compiled
    """The requested samples in ``(t, t_end]`` of the flight from ``xi`` at ``t + lo`` into
    ``s_x``; returns the next sample's index (``xn`` is scratch)."""
    while ptr < t_eval.shape[0] and t_eval[ptr] <= t_end:
        propagate(kind, lam, V, Vinv, phi, T, d, hh, xi, (t_eval[ptr] - t) - lo, xn)
        s_x[ptr, :] = xn[:n]
        ptr += 1
    return ptr


@njit(cache=True)
def _pieces(kinds, lams, Vs, Vinvs, phis, taylors, ds, hs, kappas, ready, Ws, g0s, row_norms,
            bern, remainder, graze_tol, sim_tol, H, h, nf, aug, xi, t, lo, tf, i, Phi, sens,
            t_eval, ptr, s_x, e_t, e_row, e_from, e_to, e_x, e_S, e_ptr, budget, hit, graze,
            stuck, restart, proj):  # pragma: no cover - compiled
    """The loop of :func:`run_pieces` on the clock ``t + lo``; returns its tuple and
    ``lo``."""
    m = xi.shape[0]
    n = Phi.shape[0]
    n_e = 0
    pieces = 0
    cap_e = e_t.shape[0]
    y = np.empty(m)
    a = np.empty(Ws.shape[1])
    xn = np.empty(m)
    unit = np.zeros(m)
    col = np.empty(m)
    E = np.empty((n, n))
    tmp = np.empty((n, n))
    fm = np.empty(n)
    fp = np.empty(n)
    while t < tf:
        if not ready[i]:
            return NEED_FLOW, t, i, ptr, n_e, stuck, pieces, -1, lo
        if n_e >= cap_e or n_e >= budget:
            return FULL, t, i, ptr, n_e, stuck, pieces, -1, lo
        kind, lam, V, Vinv = kinds[i], lams[i], Vs[i], Vinvs[i]
        phi, T, d, hh = phis[i], taylors[i], ds[i], hs[i]
        for c in range(m):
            y[c] = xi[c] / d[c]
        if restart:
            done = proj[0]
            index = project_restart(Ws[i], g0s[i], kappas[i], hh, t, n, y, a, proj)
            if index >= 0:
                return INADMISSIBLE, t, i, ptr, n_e, stuck, pieces, index, lo
            if proj[0] > done:  # projected: the state is the balanced one moved
                for c in range(m):
                    xi[c] = y[c] * d[c]
        restart = True
        code, tau, index = search(Ws[i], g0s[i], row_norms[i], graze_tol, sim_tol, remainder,
                                  phi, bern, y, hh, (tf - t) - lo, kind, lam, V, Vinv, T, d, hit,
                                  graze)
        if code == NEGATIVE:
            return INADMISSIBLE, t, i, ptr, n_e, stuck, pieces, index, lo
        event = code == EVENT
        piece, t_end, lo_end = flight_end(event, tau, t, lo, tf)
        ptr = _sample_flight(kind, lam, V, Vinv, phi, T, d, hh, xi, t, lo, t_end, t_eval, ptr,
                             s_x, xn, n)
        propagate(kind, lam, V, Vinv, phi, T, d, hh, xi, piece, xn)
        if sens:
            _times_expm(kind, lam, V, Vinv, phi, T, d, hh, piece, n, Phi, unit, col, E, tmp)
        pieces += 1
        if t_end <= t:   # no progress in time
            stuck += 1
            if stuck > MAX_STUCK:
                return STUCK, t_end, i, ptr, n_e, stuck, pieces, -1, lo
        else:
            stuck = 0
        xi[:] = xn
        t, lo = t_end, lo_end
        if not event or t >= tf:
            break
        row = _crossed_facet(hit, graze, nf[i])
        if row < 0:
            return HANDOFF, t, i, ptr, n_e, stuck, pieces, -1, lo
        j = choose_region(H, h, nf, aug, xi, n, i)
        if j < 0:
            return HANDOFF, t, i, ptr, n_e, stuck, pieces, -1, lo
        if sens and not _crossing_saltation(aug, H[i, row], i, j, xi, n, fm, fp, e_S[n_e],
                                            Phi, tmp):
            return HANDOFF, t, i, ptr, n_e, stuck, pieces, -1, lo
        e_t[n_e] = t
        e_row[n_e] = row
        e_from[n_e] = i
        e_to[n_e] = j
        e_x[n_e, :] = xi[:n]
        e_ptr[n_e] = ptr
        n_e += 1
        i = j
    return DONE, t, i, ptr, n_e, stuck, pieces, -1, lo
