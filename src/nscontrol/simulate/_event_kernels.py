"""numba event loop of :mod:`nscontrol.simulate.event_driven` for linear flows with linear
jumps.

Between events the flow is ``x' = A x`` (exact, :func:`nscontrol.numerics._lti_kernels.propagate`),
events are located by the compiled search :func:`nscontrol.numerics._lti_kernels.search`, and an
event of a single guard ``i`` whose jump is linear (``x+ = J_i x``) is applied here — a bouncing
ball in free flight, the impacts of a chapter-2 plant and its observer. The loop writes samples
(regular grid points, optionally the pre-event state) and events into caller buffers and hands
back to Python every event it does not settle unambiguously:

* several guards at once, a tangential touch, a guard whose jump is not linear;
* another guard at (or within ``1e-9`` relative of) zero at the event (a contact closed
  elsewhere: the multi-contact law decides);
* a jumped guard that would not leave its surface (rest, persistent contact);
* an accumulation of events (too close, or geometrically shrinking intervals), or the event
  budget exhausted.

Python then runs its general code for that event exactly as without this loop, so the loop is an
acceleration, never a change of semantics.

The loop (:func:`run_linear_jumps`)
-----------------------------------
Every flight from a state the integrator computed — after a settled jump, and the first one
too when ``restart`` (``x`` comes from an earlier call, not from the user) — starts with the
round-off projection :func:`nscontrol.numerics._lti_kernels.project_restart` (counts in
``proj``); ``INADMISSIBLE``: a guard negative at the start, beyond that tolerance
(``proj[3:5]``) or, for the user's state, beyond the search's. A flight's end state is
propagated by the event's own offset ``τ`` from the flight's start, never by a difference of
absolute times (whose rounding, ``eps·t``, would carry the state past its event); the time
labels carry their rounding in ``clock = [t, lo]``
(:func:`nscontrol.numerics._lti_kernels.clock_advance`). Samples written: grid points
``t_grid0 + k dt`` strictly inside each flight, the pre-event state when ``sample_pre``, the
post-jump state of every settled event and the final state at ``tf``. ``FULL``: a buffer is
full, resume from the returned ``(t, x)``: the start of the flight whose samples did not fit
(the run is then the same as with a larger buffer), or, when even an empty buffer is too
small for one flight, the last grid point written.

The loop is one compiled function and its parts are inlined (``inline="always"``): numba
links every callee's machine code into its caller and optimises it again there, so each
extra level of calls would cost another optimisation of everything below it on a cold cache.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..numerics._lti_kernels import (
    EVENT,
    NEGATIVE,
    copy_into,
    flight_end,
    guard_taylor_coefficients,
    project_restart,
    propagate,
    search,
    sum_squares,
)

#: Return codes of :func:`run_linear_jumps`.
DONE, HANDOFF, FULL, INADMISSIBLE = 0, 1, 2, 3
#: Return codes of :func:`zeno_status`.
ZENO_NONE, ZENO_CLOSE, ZENO_DUE = 0, 1, 2

_CLOSED_TOL = 1e-9  # relative: a guard this close to zero counts as closed


@njit(cache=True)
def zeno_status(hist, count, first, slot, t, geometric, ratio_tol, horizon, rel,
                min_interval):  # pragma: no cover - compiled
    """Whether an event of history row ``slot`` at ``t`` belongs to an accumulation.

    Returns ``(ZENO_CLOSE, 0)`` when it is closer than ``min_interval`` to the previous one,
    ``(ZENO_DUE, t_acc)`` when (``geometric``) it ends five or six event times whose
    intervals shrink with ratios equal within ``ratio_tol`` and the remaining time
    ``Δ r / (1 - r)`` is below ``horizon`` — or, when ``horizon < 0``, below ``rel`` times
    the duration ``t_acc - first[slot]`` of the sequence (``t_acc = t + Δ r / (1 - r)``) —
    else ``(ZENO_NONE, 0)``. The history itself is not changed (see :func:`zeno_push`).
    """
    m = count[slot]
    if m > 0 and t - hist[slot, m - 1] < min_interval:
        return ZENO_CLOSE, 0.0
    if not geometric or m < 4:
        return ZENO_NONE, 0.0
    k = min(m, 5)  # with t: k + 1 times, k differences
    d = np.empty(k)
    prev = hist[slot, m - k]
    for j in range(k):
        cur = hist[slot, m - k + j + 1] if j < k - 1 else t
        d[j] = cur - prev
        prev = cur
        if d[j] <= 0.0:
            return ZENO_NONE, 0.0
    r_min = np.inf
    r_max = -np.inf
    for j in range(k - 1):
        r = d[j + 1] / d[j]
        if r >= 1.0:
            return ZENO_NONE, 0.0
        r_min = min(r_min, r)
        r_max = max(r_max, r)
    r_last = d[k - 1] / d[k - 2]
    if r_max - r_min > ratio_tol * r_last:
        return ZENO_NONE, 0.0
    remaining = d[k - 1] * r_last / (1.0 - r_last)
    limit = horizon if horizon >= 0.0 else rel * (t + remaining - first[slot])
    if remaining <= limit:
        return ZENO_DUE, t + remaining
    return ZENO_NONE, 0.0


@njit(cache=True, inline="always")
def zeno_push(hist, count, first, slot, t):  # pragma: no cover - compiled
    """Append ``t`` to history row ``slot`` (the last six times are kept; ``first[slot]`` is
    the first time since the row was last emptied)."""
    m = count[slot]
    if m == 0:
        first[slot] = t
    if m == hist.shape[1]:
        for j in range(m - 1):
            hist[slot, j] = hist[slot, j + 1]
        hist[slot, m - 1] = t
    else:
        hist[slot, m] = t
        count[slot] = m + 1


@njit(cache=True, inline="always")
def _grid_count(t, t_next, t_grid0, dt, k):  # pragma: no cover - compiled
    """Number of grid points ``t_grid0 + j dt`` (``j >= k``) strictly inside ``(t, t_next)``."""
    count = 0
    while True:
        tg = t_grid0 + dt * k
        if tg >= t_next:
            return count
        if tg > t:
            count += 1
        k += 1


@njit(cache=True, inline="always")  # a named part of the loop, at no call cost
def _sample_grid(kind, lam, V, Vinv, phi, T, d, h, x, t, lo, t_next, t_grid0, dt, k, s_t,
                 s_x, n_s, xn):  # pragma: no cover - compiled
    """Write the exact states at the grid points ``t_grid0 + j dt`` (``j >= k``) strictly
    inside ``(t, t_next)`` from ``n_s`` on. Returns ``(n_s, full, t_full)``: ``full`` when the
    buffer ran out, after the grid point ``t_full`` (its state then copied into ``x``)."""
    cap_s = s_t.shape[0]
    while True:
        tg = t_grid0 + dt * k
        if tg >= t_next:
            return n_s, False, 0.0
        if tg > t:
            full = n_s + 3 > cap_s
            propagate(kind, lam, V, Vinv, phi, T, d, h, x, (tg - t) - lo, xn)
            s_t[n_s] = tg
            copy_into(s_x[n_s], xn)
            n_s += 1
            if full:
                copy_into(x, xn)
                return n_s, True, tg
        k += 1


@njit(cache=True, inline="always")
def _simple_jump(W, g0, row_norm, d, J, jump_ok, zeno_slot, hist, count, first, geometric,
                 ratio_tol, horizon, rel, min_interval, x, t, hit, graze, xn, y, a
                 ):  # pragma: no cover - compiled
    """The guard of an event at ``(t, x)`` that the loop settles itself — the only one hit,
    crossing, with a linear jump, no other guard closed, no accumulation, and leaving its
    surface after the jump ``xn = J_i x`` — or ``-1`` (hand the event back)."""
    n = x.shape[0]
    p = g0.shape[0]
    i = -1
    n_hit = 0
    for j in range(p):
        if hit[j]:
            n_hit += 1
            i = j
    if n_hit != 1 or graze[i] or not jump_ok[i]:
        return -1
    for j in range(n):
        y[j] = x[j] / d[j]
    ynorm = np.sqrt(sum_squares(y))
    for j in range(p):
        if j != i:
            guard_taylor_coefficients(W, g0, j, y, a)
            if a[0] <= _CLOSED_TOL * (row_norm[j] * ynorm + abs(g0[j])):
                return -1  # a contact closed elsewhere: the multi-contact law decides
    status, _ = zeno_status(hist, count, first, zeno_slot[i], t, geometric, ratio_tol,
                            horizon, rel, min_interval)
    if status != ZENO_NONE:
        return -1
    for r in range(n):
        s = 0.0
        for c in range(n):
            s += J[i, r, c] * x[c]
        xn[r] = s
    for j in range(n):
        y[j] = xn[j] / d[j]
    guard_taylor_coefficients(W, g0, i, y, a)
    if a[1] <= _CLOSED_TOL * (row_norm[i] * np.sqrt(sum_squares(y)) + abs(g0[i])):
        return -1  # it would not leave its surface (rest, persistent contact)
    return i


@njit(cache=True, inline="always")
def _restart_inadmissible(W, g0, kappa, h, t, n_free, d, x, y, a, proj, project
                          ):  # pragma: no cover - compiled
    """Set the balanced state ``y = x / d`` of a flight's start; when ``project`` (a state
    the integrator computed), first apply the round-off projection
    :func:`nscontrol.numerics._lti_kernels.project_restart` to it (and to ``x``). Returns
    whether a guard is negative beyond that tolerance."""
    n = x.shape[0]
    for j in range(n):
        y[j] = x[j] / d[j]
    if not project:
        return False
    done = proj[0]
    if project_restart(W, g0, kappa, h, t, n_free, y, a, proj) >= 0:
        return True
    if proj[0] > done:  # projected: the state is the balanced one moved
        for j in range(n):
            x[j] = y[j] * d[j]
    return False


@njit(cache=True, inline="always")
def _add_sample(s_t, s_x, n_s, t, x):  # pragma: no cover - compiled
    """Write the sample ``(t, x)`` at row ``n_s``; returns the new count."""
    s_t[n_s] = t
    copy_into(s_x[n_s], x)
    return n_s + 1


@njit(cache=True, inline="always")
def _add_event(e_t, e_i, e_pre, e_post, n_e, t, i, pre, post):  # pragma: no cover - compiled
    """Write the settled event of guard ``i`` at ``t`` at row ``n_e``; returns the new count."""
    e_t[n_e] = t
    e_i[n_e] = i
    copy_into(e_pre[n_e], pre)
    copy_into(e_post[n_e], post)
    return n_e + 1


@njit(cache=True, inline="always")
def _set_clock(clock, t, lo):  # pragma: no cover - compiled
    clock[0] = t
    clock[1] = lo


@njit(cache=True)
def run_linear_jumps(W, g0, row_norm, graze_tol, sim_tol, remainder, phi, bern,
                     kind, lam, V, Vinv, T, d, h, kappa, n_free,
                     J, jump_ok, zeno_slot, hist, count, first, geometric, ratio_tol,
                     horizon, rel, min_interval, budget,
                     x, t, tf, dt, t_grid0, sample_pre, restart, proj, clock,
                     s_t, s_x, e_t, e_i, e_pre, e_post, hit, graze):  # pragma: no cover
    """Flow from ``(t, x)`` and settle the simple events until ``tf`` or a hand-off.

    Returns ``(code, t, n_samples, n_events)``; ``x`` is overwritten with the state at the
    returned ``t`` (pre-event state for ``HANDOFF``, with ``hit``/``graze`` describing the
    event). The time labels carry their rounding in ``clock = [t, lo]``, read when
    ``clock[0]`` is the ``t`` passed and kept equal to the returned ``(t, lo)``. Restarts,
    samples and ``FULL``: see "The loop" in the module docstring.
    """
    n, p = x.shape[0], g0.shape[0]
    n_s = n_e = 0
    xn, y, a = np.empty(n), np.empty(n), np.empty(W.shape[0])
    lo = clock[1] if clock[0] == t else 0.0
    _set_clock(clock, t, lo)
    while t < tf:
        if n_s + 4 > s_t.shape[0] or n_e + 1 > e_t.shape[0]:
            return FULL, t, n_s, n_e
        if _restart_inadmissible(W, g0, kappa, h, t, n_free, d, x, y, a, proj,
                                 p > 0 and restart):
            return INADMISSIBLE, t, n_s, n_e
        restart = True
        if p:
            code, tau, _ = search(W, g0, row_norm, graze_tol, sim_tol, remainder, phi, bern,
                                  y, h, (tf - t) - lo, kind, lam, V, Vinv, T, d, hit, graze)
        else:
            code, tau = 0, 0.0
        if code == NEGATIVE:
            return INADMISSIBLE, t, n_s, n_e
        dur, t_next, lo_next = flight_end(code == EVENT, tau, t, lo, tf)
        # grid samples strictly inside (t, t_next)
        k = int(np.floor((t - t_grid0) / dt)) + 1
        if n_s and n_s + _grid_count(t, t_next, t_grid0, dt, k) + 3 > s_t.shape[0]:
            # this flight's samples do not fit: hand the buffer back first and redo the flight
            # from the same state, so that emptying the buffer changes nothing
            return FULL, t, n_s, n_e
        n_s, full, t_full = _sample_grid(kind, lam, V, Vinv, phi, T, d, h, x, t, lo, t_next,
                                         t_grid0, dt, k, s_t, s_x, n_s, xn)
        if full:  # resume from the last grid point written: its exact state is in x
            _set_clock(clock, t_full, 0.0)
            return FULL, t_full, n_s, n_e
        if dur > 0.0:
            propagate(kind, lam, V, Vinv, phi, T, d, h, x, dur, xn)
            copy_into(x, xn)
        t, lo = t_next, lo_next
        _set_clock(clock, t, lo)
        if code != EVENT:
            return DONE, t, _add_sample(s_t, s_x, n_s, t, x), n_e
        if sample_pre:
            n_s = _add_sample(s_t, s_x, n_s, t, x)
        if budget <= n_e:
            return HANDOFF, t, n_s, n_e
        i = _simple_jump(W, g0, row_norm, d, J, jump_ok, zeno_slot, hist, count, first,
                         geometric, ratio_tol, horizon, rel, min_interval, x, t, hit, graze,
                         xn, y, a)
        if i < 0:
            return HANDOFF, t, n_s, n_e
        zeno_push(hist, count, first, zeno_slot[i], t)
        n_e = _add_event(e_t, e_i, e_pre, e_post, n_e, t, i, x, xn)
        copy_into(x, xn)
        n_s = _add_sample(s_t, s_x, n_s, t, x)
    return DONE, t, n_s, n_e


@njit(cache=True)
def contact_state(G, g0, z, n, closed, still):  # pragma: no cover - compiled
    """Per contact ``j`` of the gaps ``G q + g0`` at the state ``z = [q; v; ...]``: whether it
    is closed (``|g_j| <= 1e-12 (1 + max|q|)``) and whether its normal velocity is zero
    (``|G_j v| <= 1e-12 (1 + max|v|)``, in ``still[j]``). Returns the number ``k`` of closed
    contacts, their indices ascending in ``closed[:k]``. One call instead of a dozen small
    numpy operations per event handled in Python."""
    q_max = 0.0
    v_max = 0.0
    for c in range(n):
        q_max = max(q_max, abs(z[c]))
        v_max = max(v_max, abs(z[n + c]))
    k = 0
    for j in range(G.shape[0]):
        g = 0.0
        u = 0.0
        for c in range(n):
            g += G[j, c] * z[c]
            u += G[j, c] * z[n + c]
        if abs(g + g0[j]) <= 1e-12 * (1.0 + q_max):
            closed[k] = j
            k += 1
        still[j] = abs(u) <= 1e-12 * (1.0 + v_max)
    return k


@njit(cache=True)
def open_and_finite(G, g0, x, n):  # pragma: no cover - compiled
    """Whether ``x = [q; v]`` is finite with every gap ``G q + g0`` open beyond
    ``1e-12 max(1, max|q|)``: such a state is admissible whatever its velocity (the check of
    ``LagrangianSystem.check_state`` accepts it), so the full check can be skipped."""
    scale = 1.0
    for k in range(x.shape[0]):
        if not np.isfinite(x[k]):
            return False
    for k in range(n):
        scale = max(scale, abs(x[k]))
    for j in range(G.shape[0]):
        g = g0[j]
        for k in range(n):
            g += G[j, k] * x[k]
        if not g > 1e-12 * scale:
            return False
    return True


@njit(cache=True)
def bounce_impulses(G, W_diag, ids, idx, pre, post, n, js, P):  # pragma: no cover
    """The contacts and impulses of the bounces settled by :func:`run_linear_jumps`: event
    ``r`` of guard ``idx[r]`` is contact ``js[r] = ids[idx[r]]`` with impulse
    ``P[r, j] = G_j (v+ - v-) / W_jj`` (``v`` = entries ``n..2n`` of the state; the other
    entries of the row zero)."""
    for r in range(idx.shape[0]):
        j = ids[idx[r]]
        js[r] = j
        s = 0.0
        for c in range(n):
            s += G[j, c] * (post[r, n + c] - pre[r, n + c])
        P[r, :] = 0.0
        P[r, j] = s / W_diag[j]
