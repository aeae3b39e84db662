"""numba kernel of the cell scan of :func:`nscontrol.numerics.lti.first_event`.

The kernel walks the cells one by one (``y <- Φ y``), expands every active guard as its Taylor
polynomial on the cell, certifies root-free cells by Bernstein enclosures and, for a flagged
cell whose ``g'`` has one sign (Bernstein coefficients of ``g'``), finds the unique root by
safeguarded Newton. A flagged cell where ``g'`` may change sign is handed back to Python
(exact analysis with the critical points of ``g``). See the module docstring of ``lti``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Return codes of :func:`scan_cells`.
NO_EVENT, HITS, NEEDS_WALK = 0, 1, 2


@njit(cache=True)
def _horner2(a, m, x):  # pragma: no cover - compiled
    """Value and derivative at ``x`` of ``Σ_{j<m} a[j] x^j``."""
    r = 0.0
    d = 0.0
    for j in range(m - 1, -1, -1):
        d = d * x + r
        r = r * x + a[j]
    return r, d


@njit(cache=True)
def _root(a, m, lo, hi, f_lo, f_hi):  # pragma: no cover - compiled
    """Root of the monotone polynomial on [lo, hi] with P(lo) > 0 >= P(hi)."""
    eps = 2.220446049250313e-16
    x = lo + (hi - lo) * f_lo / (f_lo - f_hi) if f_lo > f_hi else 0.5 * (lo + hi)
    for _ in range(200):
        fx, d = _horner2(a, m, x)
        if fx == 0.0:
            return x
        if fx > 0.0:
            lo = x
        else:
            hi = x
        x_new = x - fx / d if d != 0.0 else 0.5 * (lo + hi)
        if not (lo < x_new < hi):
            x_new = 0.5 * (lo + hi)
        if abs(x_new - x) <= 2.0 * eps * abs(x) or hi - lo <= 4.0 * eps * abs(hi):
            return x_new
        x = x_new
    return x


@njit(cache=True)
def polish(a, s, grazing):  # pragma: no cover - compiled
    """Newton polish of a root of ``P = Σ a_j σ^j`` (of ``P'`` when ``grazing``) near ``s``;
    ``s`` is kept when the exact polynomial disagrees (a step above 1e-6)."""
    eps = 2.220446049250313e-16
    m = a.shape[0]
    c = np.empty(m)
    if grazing:
        for j in range(m - 1):
            c[j] = (j + 1) * a[j + 1]
        m -= 1
    else:
        c[:] = a
    x = s
    for _ in range(4):
        f, d = _horner2(c, m, x)
        if d == 0.0:
            break
        step = f / d
        if not np.isfinite(step) or abs(step) > 1e-6:
            return s
        x -= step
        if abs(step) <= 2.0 * eps * max(abs(x), 1.0):
            break
    return x


@njit(cache=True)
def scan_cells(W, g0, row_norm, graze_tol, remainder, phi, bern, bern_d, y, k_start,
               n_cells, h, t_max, active, skip0, sigma_out, hit_out):  # pragma: no cover
    """Scan cells ``k_start ..`` from cell-start state ``y`` (overwritten with the state at
    the returned cell). Returns ``(code, k)``; with ``HITS`` the hit guards have
    ``hit_out[i] = 1`` and their root ``sigma_out[i]`` (cell coordinate in [0, 1])."""
    K1, p, n = W.shape
    a = np.empty(K1)
    da = np.empty(K1 - 1)
    y_next = np.empty(n)
    for k in range(k_start, n_cells):
        ynorm = 0.0
        for l in range(n):
            ynorm += y[l] * y[l]
        ynorm = np.sqrt(ynorm)
        sigma_end = min(1.0, (t_max - k * h) / h)
        if sigma_end <= 0.0:
            return NO_EVENT, k
        any_hit = False
        for i in range(p):
            hit_out[i] = 0
            if not active[i]:
                continue
            for j in range(K1):
                s = 0.0
                for l in range(n):
                    s += W[j, i, l] * y[l]
                a[j] = s
            a[0] += g0[i]
            scale = row_norm[i] * ynorm + abs(g0[i])
            tol = graze_tol * scale
            bmin = np.inf
            for r in range(K1):
                s = 0.0
                for j in range(r + 1):
                    s += bern[r, j] * a[j]
                bmin = min(bmin, s)
            if bmin > tol + remainder * scale:
                continue  # certified: no zero of this guard on the cell
            for j in range(K1 - 1):
                da[j] = (j + 1) * a[j + 1]
            dmin = np.inf
            dmax = -np.inf
            for r in range(K1 - 1):
                s = 0.0
                for j in range(r + 1):
                    s += bern_d[r, j] * da[j]
                dmin = min(dmin, s)
                dmax = max(dmax, s)
            if not (dmin > 0.0 or dmax < 0.0):
                return NEEDS_WALK, k  # g' may vanish: exact analysis in Python
            skip = skip0[i] and k == 0
            v0, _ = _horner2(a, K1, 0.0)
            v1, _ = _horner2(a, K1, sigma_end)
            if not skip and v0 <= 0.0:
                sigma_out[i] = 0.0
                hit_out[i] = 1
                any_hit = True
            elif v1 <= 0.0:
                sigma_out[i] = _root(a, K1, 0.0, sigma_end, v0, v1)
                hit_out[i] = 1
                any_hit = True
        if any_hit:
            return HITS, k
        for r in range(n):
            s = 0.0
            for l in range(n):
                s += phi[r, l] * y[l]
            y_next[r] = s
        for r in range(n):
            y[r] = y_next[r]
    return NO_EVENT, n_cells
