"""Compiled kernels of the frictional contact problem ``u = W r + q``, ``r_i ∈ K_{μ_i}``,
``û_i = u_i + μ_i |u_{T,i}| e_N ∈ K*_{μ_i}``, ``r_i ⟂ û_i`` (De Saxcé's form of Coulomb's law).

Unknowns are ordered per contact (normal, then ``dim - 1`` tangents); ``W`` is given in CSR
form (``indptr, indices, data``). The exact local solvers enumerate the three cases of one
contact (take-off, stick, slip); the slip direction of a spatial contact is the root of a
scalar function of the slip angle, bracketed on a grid and bisected to machine precision.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._lcp_kernels import MAX_CANCELLATION, ROUNDOFF_FACTOR

#: Contact states written by the kernels.
OPEN, STICK, SLIP = 0, 1, 2
#: Unit roundoff.
_EPS = 2.220446049250313e-16
#: Grid of the slip-angle bracketing (a root of the slip equation in each bracket at most).
_ANGLE_GRID = 32
#: Default budget of the local projected fixed point (:func:`_local_fixed_point`), the
#: option ``max_local_iter`` of :func:`~nscontrol.numerics.friction_contact.
#: solve_friction_contact`.
MAX_LOCAL_ITER = 20_000
#: Steps of the Illinois regula falsi on one slip-angle bracket: a structural bound, not a
#: budget to tune (the bracket is at most 2 pi / 32 wide, and the iteration stops at its
#: machine resolution, which bisection alone reaches in 53 halvings).
_SLIP_ROOT_STEPS = 200


@njit(cache=True)
def cone_projection(x: np.ndarray, mu: float, out: np.ndarray) -> None:
    """Euclidean projection of ``x = (x_N, x_T)`` on ``K_μ = {|x_T| <= μ x_N}``."""
    d = x.shape[0]
    s = 0.0
    for k in range(1, d):
        s += x[k] * x[k]
    s = np.sqrt(s)
    if s <= mu * x[0]:
        for k in range(d):
            out[k] = x[k]
    elif mu * s <= -x[0]:
        for k in range(d):
            out[k] = 0.0
    else:
        a = (x[0] + mu * s) / (1.0 + mu * mu)
        out[0] = a
        for k in range(1, d):
            out[k] = mu * a * x[k] / s


@njit(cache=True)
def csr_matvec_add(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray,
                   r: np.ndarray, q: np.ndarray, u: np.ndarray) -> None:
    """``u = W r + q``."""
    for i in range(q.shape[0]):
        s = q[i]
        for p in range(indptr[i], indptr[i + 1]):
            s += data[p] * r[indices[p]]
        u[i] = s


@njit(cache=True)
def contact_error2(r: np.ndarray, b: int, u: np.ndarray, ub: int, mu: float, dim: int,
                   x: np.ndarray, p: np.ndarray) -> float:
    """``‖r_i - P_K(r_i - û_i)‖²`` for one contact: its impulse ``r[b:b+dim]``, its local
    velocity ``u[ub:ub+dim]`` (De Saxcé's ``û`` adds ``μ|u_T|`` to the normal row); ``x``
    and ``p`` are work arrays of length ``dim``."""
    ut = 0.0
    for k in range(1, dim):
        ut += u[ub + k] * u[ub + k]
    x[0] = r[b] - (u[ub] + mu * np.sqrt(ut))
    for k in range(1, dim):
        x[k] = r[b + k] - u[ub + k]
    if dim == 1:
        p[0] = max(x[0], 0.0)
    else:
        cone_projection(x, mu, p)
    total = 0.0
    for k in range(dim):
        e = r[b + k] - p[k]
        total += e * e
    return total


@njit(cache=True)
def natural_map_error(u: np.ndarray, r: np.ndarray, mu: np.ndarray, dim: int) -> float:
    """``sqrt(Σ_i ‖r_i - P_K(r_i - û_i)‖²)``: zero exactly at a solution."""
    x = np.empty(dim)
    p = np.empty(dim)
    total = 0.0
    for i in range(mu.shape[0]):
        total += contact_error2(r, i * dim, u, i * dim, mu[i], dim, x, p)
    return np.sqrt(total)


@njit(cache=True)
def relative_error(q: np.ndarray, r: np.ndarray, u: np.ndarray, mu: np.ndarray,
                   dim: int) -> float:
    """The natural-map error over ``max(‖q‖, ‖r‖, ‖u‖)`` (1 when all three vanish)."""
    scale = float(max(np.linalg.norm(q), np.linalg.norm(r), np.linalg.norm(u)))
    err = natural_map_error(u, r, mu, dim)
    return err / scale if scale > 0.0 else err


@njit(cache=True)
def certify(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, q: np.ndarray,
            r: np.ndarray, u: np.ndarray, mu: np.ndarray, dim: int, tol: float
            ) -> tuple[float, float, bool]:
    """The acceptance test of every frictional-contact path: ``u = W r + q`` recomputed
    from ``r``, then ``(error, tolerance, certified)`` with the relative natural-map
    :func:`relative_error` and the tolerance ``tol`` plus the round-off bound of ``u``.

    One entry of ``u`` from ``k`` terms (a row's non-zeros and ``q_i``) is off by at most
    ``gamma_k (|W||r| + |q|)_i``; ``û`` adds ``μ |u_T|`` (at most ``1 + max μ`` times that),
    and the 2-norm over ``n`` entries at most ``sqrt(n)`` times the largest. With the factor
    :data:`~nscontrol.numerics._lcp_kernels.ROUNDOFF_FACTOR`: ``2 k eps (1 + max μ) sqrt(n)
    max_i (|W||r| + |q|)_i / max(|q|, |r|, |u|)``. As for the LCP, the tolerance is ``-inf``
    (nothing certified) when ``|W||r|`` exceeds the scale by
    :data:`~nscontrol.numerics._lcp_kernels.MAX_CANCELLATION`.
    """
    n = q.shape[0]
    big = 0.0
    terms = 1
    for i in range(n):
        s = q[i]
        a = abs(q[i])
        for p in range(indptr[i], indptr[i + 1]):
            t = data[p] * r[indices[p]]
            s += t
            a += abs(t)
        u[i] = s
        if not (a <= big):     # also propagates NaN
            big = a
        terms = max(terms, indptr[i + 1] - indptr[i] + 1)
    err = relative_error(q, r, u, mu, dim)
    scale = float(max(np.linalg.norm(q), np.linalg.norm(r), np.linalg.norm(u)))
    cancellation = big / scale if scale > 0.0 else 0.0   # scale 0: r = u = q = 0, exact
    if not (cancellation <= MAX_CANCELLATION):     # also NaN and inf
        return err, -np.inf, False
    mu_max = 0.0
    for i in range(mu.shape[0]):
        mu_max = max(mu_max, mu[i])
    tolerance = tol + ROUNDOFF_FACTOR * terms * _EPS * (1.0 + mu_max) * np.sqrt(n) * cancellation
    return err, tolerance, bool(err <= tolerance)


@njit(cache=True)
def local_1d(w: float, qn: float, r: np.ndarray) -> int:
    """One frictionless contact: ``r = max(-q_N / w, 0)``."""
    r[0] = max(-qn / w, 0.0) if qn < 0.0 else 0.0
    return OPEN if r[0] == 0.0 else STICK


@njit(cache=True)
def local_2d(W: np.ndarray, q: np.ndarray, mu: float, r: np.ndarray) -> int:
    """Exact solution of one planar contact: take-off, stick, slip forward or backward."""
    if q[0] >= 0.0:
        r[0], r[1] = 0.0, 0.0
        return OPEN
    a, b, c = W[0, 0], W[0, 1], W[1, 1]
    det = a * c - b * W[1, 0]
    if det > 0.0:
        rn = -(c * q[0] - W[0, 1] * q[1]) / det
        rt = -(-W[1, 0] * q[0] + a * q[1]) / det
        if rn >= 0.0 and abs(rt) <= mu * rn * (1.0 + 4.0 * _EPS):
            r[0], r[1] = rn, rt
            return STICK
    best, best_rn, best_rt = np.inf, 0.0, 0.0
    for sgn in (1.0, -1.0):   # slip with u_T of sign sgn, r_T = -sgn μ r_N
        den = a - sgn * mu * b
        if den <= 0.0:
            continue
        rn = -q[0] / den
        rt = -sgn * mu * rn
        ut = W[1, 0] * rn + c * rt + q[1]
        violation = max(-sgn * ut, 0.0)
        if violation < best:
            best, best_rn, best_rt = violation, rn, rt
    r[0], r[1] = best_rn, best_rt
    return SLIP


@njit(cache=True)
def _slip_residual(W: np.ndarray, q: np.ndarray, mu: float, phi: float
                   ) -> tuple[float, float, float, float]:
    """For slip along ``t = (cos φ, sin φ)`` (``r_T = -μ r_N t``, ``u_N = 0``): ``(u_T × t,
    u_T · t, r_N, den)``; a root with ``u_T · t > 0`` and ``den > 0`` is a slip solution."""
    c, s = np.cos(phi), np.sin(phi)
    den = W[0, 0] - mu * (W[0, 1] * c + W[0, 2] * s)
    if den <= 0.0:
        return 0.0, -1.0, 0.0, den
    rn = -q[0] / den
    r1, r2 = -mu * rn * c, -mu * rn * s
    u1 = W[1, 0] * rn + W[1, 1] * r1 + W[1, 2] * r2 + q[1]
    u2 = W[2, 0] * rn + W[2, 1] * r1 + W[2, 2] * r2 + q[2]
    return u1 * s - u2 * c, u1 * c + u2 * s, rn, den


@njit(cache=True)
def _bracketed_slip(W: np.ndarray, q: np.ndarray, mu: float, lo: float, hi: float
                    ) -> tuple[bool, float, float]:
    """A slip root in ``[lo, hi]`` by the Illinois variant of regula falsi (superlinear,
    never leaves the bracket), to the bracket's machine resolution: ``(found, φ, r_N)``."""
    fa, pa, _, da = _slip_residual(W, q, mu, lo)
    fb, pb, _, db = _slip_residual(W, q, mu, hi)
    if not (da > 0.0 and db > 0.0 and (pa > 0.0 or pb > 0.0)):
        return False, 0.0, 0.0
    if fa == 0.0:
        phi = lo
    elif fb == 0.0:
        phi = hi
    elif fa * fb > 0.0:
        return False, 0.0, 0.0
    else:
        a, b, side = lo, hi, 0
        phi = lo
        for _ in range(_SLIP_ROOT_STEPS):
            phi = (a * fb - b * fa) / (fb - fa)
            if phi == a or phi == b or abs(b - a) <= 4.0 * _EPS * (1.0 + abs(phi)):
                break
            fm, _, _, _ = _slip_residual(W, q, mu, phi)
            if fm == 0.0:
                break
            if fm * fb > 0.0:      # phi replaces b; halve fa if b moved twice in a row
                b, fb = phi, fm
                if side == -1:
                    fa *= 0.5
                side = -1
            else:                  # phi replaces a
                a, fa = phi, fm
                if side == 1:
                    fb *= 0.5
                side = 1
    _, p, rn, den = _slip_residual(W, q, mu, phi)
    return (p > 0.0 and den > 0.0), phi, rn


@njit(cache=True)
def _local_fixed_point(W: np.ndarray, q: np.ndarray, mu: float, r: np.ndarray,
                       max_iter: int) -> tuple[int, int]:
    """The projected fixed point ``r <- P_K(r - ρ û(r))``, ``ρ = 1 / trace W``, from the
    current ``r``, until it stops moving or ``max_iter`` steps are spent (``r`` then holds
    the last iterate): the fallback of :func:`local_3d`. Returns ``(state, steps)``."""
    rho = 1.0 / (W[0, 0] + W[1, 1] + W[2, 2])
    u = np.empty(3)
    x = np.empty(3)
    nxt = np.empty(3)
    steps = 0
    for _ in range(max_iter):
        steps += 1
        for k in range(3):
            u[k] = W[k, 0] * r[0] + W[k, 1] * r[1] + W[k, 2] * r[2] + q[k]
        x[0] = r[0] - rho * (u[0] + mu * np.sqrt(u[1] ** 2 + u[2] ** 2))
        x[1] = r[1] - rho * u[1]
        x[2] = r[2] - rho * u[2]
        cone_projection(x, mu, nxt)
        change = abs(nxt[0] - r[0]) + abs(nxt[1] - r[1]) + abs(nxt[2] - r[2])
        r[0], r[1], r[2] = nxt[0], nxt[1], nxt[2]
        if change <= 4.0 * _EPS * (abs(r[0]) + abs(r[1]) + abs(r[2])):
            break
    if r[0] == 0.0:
        return OPEN, steps
    slip = np.sqrt(u[1] ** 2 + u[2] ** 2)
    return (SLIP if slip > 1e-12 * (abs(u[0]) + slip + abs(q[0])) else STICK), steps


@njit(cache=True)
def local_3d(W: np.ndarray, Winv: np.ndarray, q: np.ndarray, mu: float, r: np.ndarray,
             max_local_iter: int = MAX_LOCAL_ITER) -> int:
    """Exact solution of one spatial contact: take-off, stick, or slip (angle root); writes
    ``r`` (read as the fallback's start) and returns the state. When no slip root is
    bracketed, the projected fixed point runs for at most ``max_local_iter`` steps."""
    if q[0] >= 0.0:
        r[0], r[1], r[2] = 0.0, 0.0, 0.0
        return OPEN
    rs = np.empty(3)
    for k in range(3):
        rs[k] = -(Winv[k, 0] * q[0] + Winv[k, 1] * q[1] + Winv[k, 2] * q[2])
    if rs[0] >= 0.0 and np.sqrt(rs[1] ** 2 + rs[2] ** 2) <= mu * rs[0] * (1.0 + 4.0 * _EPS):
        r[0], r[1], r[2] = rs[0], rs[1], rs[2]
        return STICK
    best_rn, best_phi, found = 0.0, 0.0, False
    if r[0] > 0.0 and r[1] * r[1] + r[2] * r[2] > 0.0:
        # the previous sweep's slip direction: the root is usually within a narrow bracket
        phi_w = np.arctan2(-r[2], -r[1])
        for width in (1e-6, 1e-3, 0.1):
            found, best_phi, best_rn = _bracketed_slip(W, q, mu, phi_w - width,
                                                       phi_w + width)
            if found:
                break
    if not found:
        step = 2.0 * np.pi / _ANGLE_GRID
        # centre the first bracket on the direction of -r_T of the stick guess (the slip
        # direction when W is isotropic): that root is then inside it, never at a node
        phi0 = np.arctan2(-rs[2], -rs[1]) - 0.5 * step
        for g in range(_ANGLE_GRID):
            found, best_phi, best_rn = _bracketed_slip(W, q, mu, phi0 + g * step,
                                                       phi0 + (g + 1) * step)
            if found:
                break
    if not found:   # no bracketed slip root (strong normal-tangent coupling, large μ)
        state, _ = _local_fixed_point(W, q, mu, r, max_local_iter)
        return state
    r[0] = best_rn
    r[1] = -mu * best_rn * np.cos(best_phi)
    r[2] = -mu * best_rn * np.sin(best_phi)
    return SLIP


@njit(cache=True)
def diagonal_blocks(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, m: int,
                    dim: int) -> np.ndarray:
    """The ``(m, dim, dim)`` diagonal blocks of ``W``."""
    blocks = np.zeros((m, dim, dim))
    for i in range(m):
        for k in range(dim):
            row = i * dim + k
            for p in range(indptr[row], indptr[row + 1]):
                col = indices[p]
                if i * dim <= col < (i + 1) * dim:
                    blocks[i, k, col - i * dim] += data[p]
    return blocks


@njit(cache=True)
def nsgs_kernel(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, q: np.ndarray,
                mu: np.ndarray, dim: int, r: np.ndarray, u: np.ndarray, states: np.ndarray,
                tol: float, max_sweeps: int, max_local_iter: int = MAX_LOCAL_ITER
                ) -> tuple[int, int, float]:
    """Non-smooth Gauss–Seidel over contacts, exact local solves; stops when the relative
    natural-map error (checked on the whole problem after every sweep) is ``<= tol``, or
    after ``max_sweeps`` sweeps (the budget; ``max_local_iter`` is that of a spatial
    contact's projected fixed point, :func:`local_3d`).

    Returns ``(code, sweeps, error)``: code 0 converged, 2 sweep limit, 3 a diagonal block
    not positive definite. :func:`certify` then decides whether ``r`` solves the problem.
    """
    m = mu.shape[0]
    blocks = diagonal_blocks(indptr, indices, data, m, dim)
    inverses = np.zeros((m, dim, dim))
    for i in range(m):
        if blocks[i, 0, 0] <= 0.0:
            return 3, 0, np.inf
        if dim == 3:
            scale = blocks[i, 0, 0] + blocks[i, 1, 1] + blocks[i, 2, 2]
            if np.linalg.det(blocks[i]) > 1e3 * _EPS * scale ** 3:
                inverses[i] = np.linalg.inv(blocks[i])
            else:   # no unique stick impulse: NaN makes the stick test fail, slip decides
                inverses[i, 0, 0] = np.nan
    qloc = np.empty(dim)
    rloc = np.empty(dim)
    err = np.inf
    for sweep in range(1, max_sweeps + 1):
        for i in range(m):
            b = i * dim
            for k in range(dim):
                row = b + k
                s = q[row]
                for p in range(indptr[row], indptr[row + 1]):
                    col = indices[p]
                    if col < b or col >= b + dim:
                        s += data[p] * r[col]
                qloc[k] = s
                rloc[k] = r[row]   # the local fallback's start
            if dim == 1:
                states[i] = local_1d(blocks[i, 0, 0], qloc[0], rloc)
            elif dim == 2:
                states[i] = local_2d(blocks[i], qloc, mu[i], rloc)
            else:
                states[i] = local_3d(blocks[i], inverses[i], qloc, mu[i], rloc,
                                     max_local_iter)
            for k in range(dim):
                r[b + k] = rloc[k]
        csr_matvec_add(indptr, indices, data, r, q, u)
        err = relative_error(q, r, u, mu, dim)
        if err <= tol:
            return 0, sweep, err
    return 2, max_sweeps, err
