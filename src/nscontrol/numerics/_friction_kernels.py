"""Compiled kernels of the frictional contact problem ``u = W r + q``, ``r_i ∈ K_{μ_i}``,
``û_i = u_i + μ_i |u_{T,i}| e_N ∈ K*_{μ_i}``, ``r_i ⟂ û_i`` (De Saxcé's form of Coulomb's law).

Unknowns are ordered per contact (normal, then ``dim - 1`` tangents). The solver reads ``W``
by columns, dense or CSC (:func:`add_columns`); a CSR matrix is turned into blocks in the
compiled call (:func:`csr_to_blocks`). The exact local solvers enumerate the three cases of one
contact (take-off, stick, slip); the slip direction of a spatial contact is the root of a
scalar function of the slip angle, bracketed on a grid and bisected to machine precision.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

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
#: Newton steps on the slip angle before the brackets take over (from a good start it
#: settles in 2 to 5).
_NEWTON_STEPS = 12


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


@njit(cache=True, inline="always")
def _error2(r0: float, r1: float, r2: float, u0: float, u1: float, u2: float, mu: float,
            dim: int) -> float:
    """``‖r - P_K(r - û)‖²`` of one contact from its entries (``r2 = u2 = 0`` when
    ``dim = 2``, ``r1 = u1 = 0`` too when ``dim = 1``): :func:`cone_projection` written on
    scalars, which the error of a whole problem evaluates once per contact and sweep."""
    # |(u1, 0)| is |u1| (sqrt(x²) = |x| in IEEE arithmetic, and no overflow this way)
    x0 = r0 - (u0 + mu * (np.sqrt(u1 * u1 + u2 * u2) if dim > 2 else abs(u1)))
    if dim == 1:
        p0 = max(x0, 0.0)
        return (r0 - p0) * (r0 - p0)
    x1 = r1 - u1
    x2 = r2 - u2
    s = np.sqrt(x1 * x1 + x2 * x2) if dim > 2 else abs(x1)
    if s <= mu * x0:
        p0, p1, p2 = x0, x1, x2
    elif mu * s <= -x0:
        p0, p1, p2 = 0.0, 0.0, 0.0
    else:
        a = (x0 + mu * s) / (1.0 + mu * mu)
        p0 = a
        p1 = mu * a * x1 / s
        p2 = mu * a * x2 / s
    return (r0 - p0) * (r0 - p0) + (r1 - p1) * (r1 - p1) + (r2 - p2) * (r2 - p2)


@njit(cache=True)
def contact_error2(r: np.ndarray, b: int, u: np.ndarray, ub: int, mu: float, dim: int,
                   x: np.ndarray, p: np.ndarray) -> float:
    """``‖r_i - P_K(r_i - û_i)‖²`` for one contact: its impulse ``r[b:b+dim]``, its local
    velocity ``u[ub:ub+dim]`` (De Saxcé's ``û`` adds ``μ|u_T|`` to the normal row); ``x``
    and ``p`` (work arrays of length ``dim``) are not used any more."""
    r1 = r[b + 1] if dim > 1 else 0.0
    u1 = u[ub + 1] if dim > 1 else 0.0
    r2 = r[b + 2] if dim > 2 else 0.0
    u2 = u[ub + 2] if dim > 2 else 0.0
    return _error2(r[b], r1, r2, u[ub], u1, u2, mu, dim)


@njit(cache=True, inline="always")
def natural_map_error(u: np.ndarray, r: np.ndarray, mu: np.ndarray, dim: int) -> float:
    """``sqrt(Σ_i ‖r_i - P_K(r_i - û_i)‖²)``: zero exactly at a solution."""
    total = 0.0
    for i in range(mu.shape[0]):
        b = i * dim
        r1 = r[b + 1] if dim > 1 else 0.0
        u1 = u[b + 1] if dim > 1 else 0.0
        r2 = r[b + 2] if dim > 2 else 0.0
        u2 = u[b + 2] if dim > 2 else 0.0
        total += _error2(r[b], r1, r2, u[b], u1, u2, mu[i], dim)
    return np.sqrt(total)


@njit(cache=True, inline="always")
def _norm(x: np.ndarray) -> float:
    """The 2-norm of a vector by a plain loop (``np.linalg.norm`` costs a BLAS call's setup,
    more than a small problem's whole sweep)."""
    total = 0.0
    for v in x:
        total += v * v
    return np.sqrt(total)


@njit(cache=True, inline="always")
def relative_error(q: np.ndarray, r: np.ndarray, u: np.ndarray, mu: np.ndarray,
                   dim: int) -> float:
    """The natural-map error over ``max(‖q‖, ‖r‖, ‖u‖)`` (the error itself when all three
    vanish)."""
    return _relative_error(_norm(q), r, u, mu, dim)


@njit(cache=True, inline="always")
def _relative_error(q_norm: float, r: np.ndarray, u: np.ndarray, mu: np.ndarray,
                    dim: int) -> float:
    """:func:`relative_error` with ``‖q‖`` given (a sweep's check computes it once), the
    error and the norms of ``r`` and ``u`` summed in one pass over the contacts, in the
    order of :func:`natural_map_error` and :func:`_norm` (the same figures)."""
    total = 0.0
    r_sq = 0.0
    u_sq = 0.0
    for i in range(mu.shape[0]):
        b = i * dim
        r0, u0 = r[b], u[b]
        r1 = r[b + 1] if dim > 1 else 0.0
        u1 = u[b + 1] if dim > 1 else 0.0
        r2 = r[b + 2] if dim > 2 else 0.0
        u2 = u[b + 2] if dim > 2 else 0.0
        total += _error2(r0, r1, r2, u0, u1, u2, mu[i], dim)
        r_sq += r0 * r0
        u_sq += u0 * u0
        if dim > 1:
            r_sq += r1 * r1
            u_sq += u1 * u1
        if dim > 2:
            r_sq += r2 * r2
            u_sq += u2 * u2
    scale = max(q_norm, np.sqrt(r_sq), np.sqrt(u_sq))
    err = np.sqrt(total)
    return err / scale if scale > 0.0 else err


@njit(cache=True, inline="always")
def _local_1d_scalar(w: float, qn: float) -> tuple[int, float]:
    """One frictionless contact on scalars: ``(state, r_N)``, ``r_N = max(-q_N / w, 0)``."""
    rn = max(-qn / w, 0.0) if qn < 0.0 else 0.0
    return (OPEN if rn == 0.0 else STICK), rn


@njit(cache=True)
def local_1d(w: float, qn: float, r: np.ndarray) -> int:
    """One frictionless contact: ``r = max(-q_N / w, 0)``."""
    state, r[0] = _local_1d_scalar(w, qn)
    return state


@njit(cache=True, inline="always")
def _local_2d_scalars(w00: float, w01: float, w10: float, w11: float, q0: float, q1: float,
                      mu: float) -> tuple[int, float, float]:
    """Exact solution of one planar contact of block ``[[w00, w01], [w10, w11]]`` and local
    free velocity ``(q0, q1)``, on scalars: ``(state, r_N, r_T)``. Take-off, stick, or slip
    forward or backward (the one whose slip velocity has the assumed sign; the least
    violation when round-off leaves neither exact). Written on scalars, inlined into the
    sweep: a call with arrays costs more than the contact's whole solve."""
    if q0 >= 0.0:
        return OPEN, 0.0, 0.0
    det = w00 * w11 - w01 * w10
    if det > 0.0:
        rn = -(w11 * q0 - w01 * q1) / det
        rt = -(-w10 * q0 + w00 * q1) / det
        if rn >= 0.0 and abs(rt) <= mu * rn * (1.0 + 4.0 * _EPS):
            return STICK, rn, rt
    best, best_rn, best_rt = np.inf, 0.0, 0.0
    for sgn in (1.0, -1.0):   # slip with u_T of sign sgn, r_T = -sgn μ r_N
        den = w00 - sgn * mu * w01
        if den <= 0.0:
            continue
        rn = -q0 / den
        rt = -sgn * mu * rn
        ut = w10 * rn + w11 * rt + q1
        violation = max(-sgn * ut, 0.0)
        if violation < best:
            best, best_rn, best_rt = violation, rn, rt
    return SLIP, best_rn, best_rt


@njit(cache=True)
def local_2d(W: np.ndarray, q: np.ndarray, mu: float, r: np.ndarray) -> int:
    """Exact solution of one planar contact: take-off, stick, slip forward or backward
    (:func:`_local_2d_scalars` on ``W``'s entries), written into ``r``."""
    state, r[0], r[1] = _local_2d_scalars(W[0, 0], W[0, 1], W[1, 0], W[1, 1], q[0], q[1], mu)
    return state


@njit(cache=True)
def _slip_residual(W: np.ndarray, q: np.ndarray, mu: float, phi: float
                   ) -> tuple[float, float, float, float, float, float]:
    """For slip along ``t = (cos φ, sin φ)`` (``r_T = -μ r_N t``, ``u_N = 0``): ``(u_T × t,
    u_T · t, r_N, den, r_T)``; a root with ``u_T · t > 0`` and ``den > 0`` is a slip
    solution (``r_T`` returned with it: the caller needs no cosine and sine again)."""
    c, s = np.cos(phi), np.sin(phi)
    den = W[0, 0] - mu * (W[0, 1] * c + W[0, 2] * s)
    if den <= 0.0:
        return 0.0, -1.0, 0.0, den, 0.0, 0.0
    rn = -q[0] / den
    r1, r2 = -mu * rn * c, -mu * rn * s
    u1 = W[1, 0] * rn + W[1, 1] * r1 + W[1, 2] * r2 + q[1]
    u2 = W[2, 0] * rn + W[2, 1] * r1 + W[2, 2] * r2 + q[2]
    return u1 * s - u2 * c, u1 * c + u2 * s, rn, den, r1, r2


@njit(cache=True)
def _bracketed_slip(W: np.ndarray, q: np.ndarray, mu: float, lo: float, hi: float
                    ) -> tuple[bool, float, float, float, float]:
    """A slip root in ``[lo, hi]`` by the Illinois variant of regula falsi (superlinear,
    never leaves the bracket), to the bracket's machine resolution: ``(found, φ, r_N,
    r_T)``."""
    fa, pa, _, da, _, _ = _slip_residual(W, q, mu, lo)
    fb, pb, _, db, _, _ = _slip_residual(W, q, mu, hi)
    if not (da > 0.0 and db > 0.0 and (pa > 0.0 or pb > 0.0)):
        return False, 0.0, 0.0, 0.0, 0.0
    if fa == 0.0:
        phi = lo
    elif fb == 0.0:
        phi = hi
    elif fa * fb > 0.0:
        return False, 0.0, 0.0, 0.0, 0.0
    else:
        a, b, side = lo, hi, 0
        phi = lo
        for _ in range(_SLIP_ROOT_STEPS):
            phi = (a * fb - b * fa) / (fb - fa)
            if phi == a or phi == b or abs(b - a) <= 4.0 * _EPS * (1.0 + abs(phi)):
                break
            fm, _, _, _, _, _ = _slip_residual(W, q, mu, phi)
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
    _, p, rn, den, r1, r2 = _slip_residual(W, q, mu, phi)
    return (p > 0.0 and den > 0.0), phi, rn, r1, r2


@njit(cache=True)
def _newton_slip(W: np.ndarray, q: np.ndarray, mu: float, phi: float
                 ) -> tuple[bool, float, float, float, float]:
    """A slip root (:func:`_slip_residual`) by Newton's method on the slip angle from
    ``phi``, to machine resolution: ``(found, φ, r_N, r_T)``; not found when a step leaves the
    slip conditions (``den > 0``, ``u_T · t > 0``), the derivative vanishes or
    :data:`_NEWTON_STEPS` steps do not settle."""
    for _ in range(_NEWTON_STEPS):
        c, s = np.cos(phi), np.sin(phi)
        den = W[0, 0] - mu * (W[0, 1] * c + W[0, 2] * s)
        if not (den > 0.0):
            return False, phi, 0.0, 0.0, 0.0
        rn = -q[0] / den
        r1, r2 = -mu * rn * c, -mu * rn * s
        u1 = W[1, 0] * rn + W[1, 1] * r1 + W[1, 2] * r2 + q[1]
        u2 = W[2, 0] * rn + W[2, 1] * r1 + W[2, 2] * r2 + q[2]
        f = u1 * s - u2 * c
        along = u1 * c + u2 * s
        # derivatives in φ: t' = (-s, c), den' = -μ W_0T t', r_N' = -r_N den' / den,
        # r_T' = -μ (r_N' t + r_N t'), u_T' = W_TN r_N' + W_TT r_T'
        dden = -mu * (-W[0, 1] * s + W[0, 2] * c)
        drn = -rn * dden / den
        dr1 = -mu * (drn * c - rn * s)
        dr2 = -mu * (drn * s + rn * c)
        du1 = W[1, 0] * drn + W[1, 1] * dr1 + W[1, 2] * dr2
        du2 = W[2, 0] * drn + W[2, 1] * dr1 + W[2, 2] * dr2
        df = du1 * s - du2 * c + along
        if f == 0.0:
            return along > 0.0, phi, rn, r1, r2
        if not (df != 0.0 and np.isfinite(df)):
            return False, phi, 0.0, 0.0, 0.0
        step = f / df
        phi -= step
        if abs(step) <= 4.0 * _EPS * (1.0 + abs(phi)):
            _, p, rn, den, r1, r2 = _slip_residual(W, q, mu, phi)
            return (p > 0.0 and den > 0.0), phi, rn, r1, r2
    return False, phi, 0.0, 0.0, 0.0


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
    state, r0, r1, r2 = _quick_3d(Winv.reshape((1, 3, 3)), 0, q[0], q[1], q[2], mu)
    if state == SLIP:
        return _slip_3d(W, q, mu, r, r1, r2, max_local_iter)
    r[0], r[1], r[2] = r0, r1, r2
    return state


@njit(cache=True, inline="always")
def _quick_3d(inverses: np.ndarray, i: int, q0: float, q1: float, q2: float, mu: float
              ) -> tuple[int, float, float, float]:
    """Take-off or stick of spatial contact ``i`` (``inverses[i]`` its block's inverse),
    on scalars: ``(state, r0, r1, r2)``; state :data:`SLIP` means neither, and then
    ``(r1, r2)`` is the tangential stick guess, where the slip search starts. Written on
    scalars because a call with arrays costs more than these two cases (~0.1 µs)."""
    if q0 >= 0.0:
        return OPEN, 0.0, 0.0, 0.0
    rs0 = -(inverses[i, 0, 0] * q0 + inverses[i, 0, 1] * q1 + inverses[i, 0, 2] * q2)
    rs1 = -(inverses[i, 1, 0] * q0 + inverses[i, 1, 1] * q1 + inverses[i, 1, 2] * q2)
    rs2 = -(inverses[i, 2, 0] * q0 + inverses[i, 2, 1] * q1 + inverses[i, 2, 2] * q2)
    if rs0 >= 0.0 and np.sqrt(rs1 ** 2 + rs2 ** 2) <= mu * rs0 * (1.0 + 4.0 * _EPS):
        return STICK, rs0, rs1, rs2
    return SLIP, 0.0, rs1, rs2


@njit(cache=True)
def _slip_3d(W: np.ndarray, q: np.ndarray, mu: float, r: np.ndarray, rs1: float, rs2: float,
             max_local_iter: int) -> int:
    """The slip case of :func:`local_3d` (neither take-off nor stick): the slip angle's
    root, ``(rs1, rs2)`` the tangential stick guess. Kept apart so that the two quick cases
    stay a short function."""
    warm = r[0] > 0.0 and r[1] * r[1] + r[2] * r[2] > 0.0
    # Newton from the previous sweep's slip direction, else from the stick guess's (the
    # slip direction when W is isotropic); the brackets below when it does not converge
    phi_w = np.arctan2(-r[2], -r[1]) if warm else np.arctan2(-rs2, -rs1)
    found, best_phi, best_rn, best_r1, best_r2 = _newton_slip(W, q, mu, phi_w)
    if not found and warm:
        # the root is usually within a narrow bracket around the previous direction
        for width in (1e-6, 1e-3, 0.1):
            found, best_phi, best_rn, best_r1, best_r2 = _bracketed_slip(
                W, q, mu, phi_w - width, phi_w + width)
            if found:
                break
    if not found:
        step = 2.0 * np.pi / _ANGLE_GRID
        # centre the first bracket on the direction of -r_T of the stick guess (the slip
        # direction when W is isotropic): that root is then inside it, never at a node
        phi0 = np.arctan2(-rs2, -rs1) - 0.5 * step
        for g in range(_ANGLE_GRID):
            found, best_phi, best_rn, best_r1, best_r2 = _bracketed_slip(
                W, q, mu, phi0 + g * step, phi0 + (g + 1) * step)
            if found:
                break
    if not found:   # no bracketed slip root (strong normal-tangent coupling, large μ)
        state, _ = _local_fixed_point(W, q, mu, r, max_local_iter)
        return state
    r[0] = best_rn        # the tangents as the root's last evaluation computed them
    r[1] = best_r1
    r[2] = best_r2
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




# -- the Gauss–Seidel solver on W's columns ---------------------------------------------------
# ``W`` reaches the solver by columns, dense or sparse, through one set of arguments: either
# ``WT``, the dense (n, n) C-contiguous transpose of ``W`` (:func:`dense_columns`: ``W``
# itself when it is symmetric, as a Delassus matrix is), whose rows ``i dim ... i dim + dim
# - 1`` are contact ``i``'s columns, contiguous in memory, with empty
# block arrays, or an empty (0, 0) ``WT`` with W by block columns: contact ``i``'s
# columns hold the ``dim x dim`` blocks ``bdata[p]`` at block rows ``brow[p]``,
# ``bptr[i] <= p < bptr[i + 1]`` (:func:`csc_to_blocks`; one index per block instead of one
# per entry). The sweep keeps ``u = W r + q`` up to date by adding a contact's columns times
# the change of its impulse; a contact's local free velocity is then ``u_i - W_ii r_i``, and
# the error of the whole problem is known after every sweep without a product by W.

#: Sweeps between two exact recomputations of ``u = W r + q`` (the running update drifts by
#: round-off: one exact product every so many sweeps costs a few per cent of them).
REFRESH_SWEEPS = 64
#: Codes of :func:`solve_columns`: converged, sweep budget spent, a non-finite ``q`` or ``r0``,
#: a non-finite ``W``, a ``μ`` not finite and ``>= 0`` (:func:`solve_dense_once`);
#: ``BAD_DIAGONAL + i``: contact ``i``'s normal diagonal entry is not
#: positive.
CONVERGED, SWEEP_LIMIT, NOT_FINITE, W_NOT_FINITE, MU_INVALID, BAD_DIAGONAL = 0, 2, 4, 5, 6, 16


@njit(cache=True)
def _all_finite(x: np.ndarray) -> bool:
    for v in x.flat:
        if not np.isfinite(v):
            return False
    return True


@njit(cache=True, inline="always")
def add_columns(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                i: int, dim: int, d0: float, d1: float, d2: float, u: np.ndarray) -> None:
    """``u += W[:, i dim:(i+1) dim] (d0, d1, d2)[:dim]``: contact ``i``'s columns (dense when
    ``WT`` has rows, :func:`_add_dense`, else its blocks, :func:`_add_blocks`). Inlined and
    indexed without views: a call or a view with arrays costs reference counting per
    contact."""
    if WT.shape[0] > 0:
        _add_dense(WT, i, dim, d0, d1, d2, u)
    else:
        _add_blocks(bptr, brow, bdata, i, dim, d0, d1, d2, u)


@njit(cache=True, inline="always")
def _add_dense(WT: np.ndarray, i: int, dim: int, d0: float, d1: float, d2: float,
               u: np.ndarray) -> None:
    """:func:`add_columns` of a dense ``W`` (contact ``i``'s columns are rows of ``WT``)."""
    b = i * dim
    n = u.shape[0]
    if dim == 3:
        for k in range(n):
            u[k] += WT[b, k] * d0 + WT[b + 1, k] * d1 + WT[b + 2, k] * d2
    elif dim == 2:
        for k in range(n):
            u[k] += WT[b, k] * d0 + WT[b + 1, k] * d1
    else:
        for k in range(n):
            u[k] += WT[b, k] * d0


@njit(cache=True, inline="always")
def _add_blocks(bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray, i: int, dim: int,
                d0: float, d1: float, d2: float, u: np.ndarray) -> None:
    """:func:`add_columns` of a ``W`` stored by block columns."""
    for p in range(bptr[i], bptr[i + 1]):
        j = brow[p] * dim
        if dim == 3:
            u[j] += bdata[p, 0, 0] * d0 + bdata[p, 0, 1] * d1 + bdata[p, 0, 2] * d2
            u[j + 1] += bdata[p, 1, 0] * d0 + bdata[p, 1, 1] * d1 + bdata[p, 1, 2] * d2
            u[j + 2] += bdata[p, 2, 0] * d0 + bdata[p, 2, 1] * d1 + bdata[p, 2, 2] * d2
        elif dim == 2:
            u[j] += bdata[p, 0, 0] * d0 + bdata[p, 0, 1] * d1
            u[j + 1] += bdata[p, 1, 0] * d0 + bdata[p, 1, 1] * d1
        else:
            u[j] += bdata[p, 0, 0] * d0


@njit(cache=True)
def column_product(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                   q: np.ndarray, r: np.ndarray, dim: int, u: np.ndarray) -> None:
    """``u = W r + q``, column block after column block (zero impulses skipped)."""
    for k in range(q.shape[0]):
        u[k] = q[k]
    for i in range(q.shape[0] // dim):
        b = i * dim
        d0 = r[b]
        d1 = r[b + 1] if dim > 1 else 0.0
        d2 = r[b + 2] if dim > 2 else 0.0
        if d0 != 0.0 or d1 != 0.0 or d2 != 0.0:
            add_columns(WT, bptr, brow, bdata, i, dim, d0, d1, d2, u)


@njit(cache=True)
def csc_to_blocks(colptr: np.ndarray, rowidx: np.ndarray, cdata: np.ndarray, n: int,
                  dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block columns ``(bptr, brow, bdata)`` of an ``(n, n)`` CSC matrix: every
    ``dim x dim`` block holding a stored entry, its other entries zero, duplicates summed."""
    m = n // dim
    marker = np.full(m, -1, np.int64)
    bptr = np.zeros(m + 1, np.int64)
    for i in range(m):
        count = 0
        for col in range(i * dim, (i + 1) * dim):
            for p in range(colptr[col], colptr[col + 1]):
                jb = rowidx[p] // dim
                if marker[jb] != i:
                    marker[jb] = i
                    count += 1
        bptr[i + 1] = bptr[i] + count
    brow = np.empty(bptr[m], np.int64)
    bdata = np.zeros((bptr[m], dim, dim))
    slot = np.empty(m, np.int64)
    marker[:] = -1
    for i in range(m):
        pos = bptr[i]
        for c in range(dim):
            col = i * dim + c
            for p in range(colptr[col], colptr[col + 1]):
                jb = rowidx[p] // dim
                if marker[jb] != i:
                    marker[jb] = i
                    slot[jb] = pos
                    brow[pos] = jb
                    pos += 1
                bdata[slot[jb], rowidx[p] - jb * dim, c] += cdata[p]
    return bptr, brow, bdata


@njit(cache=True)
def prepare_columns(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                    dim: int, blocks: np.ndarray, inverses: np.ndarray) -> tuple[int, int]:
    """What the solver needs of ``W`` once, written into ``blocks`` and ``inverses`` (both
    ``(m, dim, dim)``): the diagonal blocks and the inverses of spatial blocks (NaN first
    entry when a block is too close to singular for a unique stick impulse: the slip case
    then decides). Returns ``(code, terms)``: code :data:`W_NOT_FINITE`, or
    :data:`BAD_DIAGONAL` ``+ i`` for the first contact ``i`` whose normal diagonal entry is
    not positive, else 0; ``terms`` bounds the terms of one entry of ``W r + q`` (a row's
    stored entries plus one, for :func:`certify_columns`).
    """
    m = blocks.shape[0]
    n = m * dim
    if WT.shape[0] > 0:
        if not _all_finite(WT):
            return W_NOT_FINITE, 0
        for i in range(m):
            for k in range(dim):
                for col in range(dim):
                    blocks[i, k, col] = WT[i * dim + col, i * dim + k]
        terms = n + 1
    else:
        if not _all_finite(bdata):
            return W_NOT_FINITE, 0
        blocks[:] = 0.0
        per_row = np.zeros(m, np.int64)
        for i in range(m):
            for p in range(bptr[i], bptr[i + 1]):
                per_row[brow[p]] += 1
                if brow[p] == i:
                    blocks[i] += bdata[p]
        terms = dim * per_row.max() + 1 if m else 1
    inverses[:] = 0.0
    for i in range(m):
        if not (blocks[i, 0, 0] > 0.0):
            return BAD_DIAGONAL + i, terms
        if dim == 3:
            _inverse_3x3(blocks, inverses, i)
    return 0, terms


@njit(cache=True, inline="always")
def _inverse_3x3(blocks: np.ndarray, inverses: np.ndarray, i: int) -> None:
    """``inverses[i] = blocks[i]⁻¹`` by cofactors when the determinant exceeds
    ``1e3 eps trace³`` (a 3 x 3 LAPACK call costs more than the solve of a small problem);
    otherwise no unique stick impulse: a NaN first entry makes the stick test fail and the
    slip case decides. Cofactors of a block that far from singular lose at most about
    ``1e-3 / eps`` of relative accuracy in the worst case, and the stick impulse they give
    is checked by the whole problem's residual like every other."""
    a = blocks[i]
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    scale = a[0, 0] + a[1, 1] + a[2, 2]
    if not (det > 1e3 * _EPS * scale ** 3):
        inverses[i, 0, 0] = np.nan
        return
    inverses[i, 0, 0] = c00 / det
    inverses[i, 1, 0] = c01 / det
    inverses[i, 2, 0] = c02 / det
    inverses[i, 0, 1] = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det
    inverses[i, 1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det
    inverses[i, 2, 1] = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det
    inverses[i, 0, 2] = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det
    inverses[i, 1, 2] = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det
    inverses[i, 2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det


@njit(cache=True, inline="always")
def _local_update(blocks: np.ndarray, inverses: np.ndarray, i: int, dim: int, u: np.ndarray,
                  r: np.ndarray, mu: float, max_local_iter: int, qloc: np.ndarray,
                  rloc: np.ndarray) -> tuple[int, float, float, float]:
    """Contact ``i``'s exact local solve with the others' impulses frozen, on scalars: its
    local free velocity ``u_i - W_ii r_i``, then :func:`_local_1d_scalar`,
    :func:`_local_2d_scalars` or the quick cases of :func:`local_3d` (its slip case through
    the work arrays ``qloc`` and ``rloc`` of length 3). Returns ``(state, r_i)`` (the new
    impulse padded with zeros to three entries); ``r`` and ``u`` are not written."""
    b = i * dim
    if dim == 1:
        state, n0 = _local_1d_scalar(blocks[i, 0, 0], u[b] - blocks[i, 0, 0] * r[b])
        return state, n0, 0.0, 0.0
    if dim == 2:
        r0, r1 = r[b], r[b + 1]
        w00, w01 = blocks[i, 0, 0], blocks[i, 0, 1]
        w10, w11 = blocks[i, 1, 0], blocks[i, 1, 1]
        state, n0, n1 = _local_2d_scalars(w00, w01, w10, w11, u[b] - (w00 * r0 + w01 * r1),
                                          u[b + 1] - (w10 * r0 + w11 * r1), mu)
        return state, n0, n1, 0.0
    r0, r1, r2 = r[b], r[b + 1], r[b + 2]
    q0 = u[b] - (blocks[i, 0, 0] * r0 + blocks[i, 0, 1] * r1 + blocks[i, 0, 2] * r2)
    q1 = u[b + 1] - (blocks[i, 1, 0] * r0 + blocks[i, 1, 1] * r1 + blocks[i, 1, 2] * r2)
    q2 = u[b + 2] - (blocks[i, 2, 0] * r0 + blocks[i, 2, 1] * r1 + blocks[i, 2, 2] * r2)
    state, n0, n1, n2 = _quick_3d(inverses, i, q0, q1, q2, mu)
    if state == SLIP:
        return _slip_update(blocks, i, q0, q1, q2, r0, r1, r2, mu, n1, n2, max_local_iter,
                            qloc, rloc)
    return state, n0, n1, n2


@njit(cache=True)
def _slip_update(blocks: np.ndarray, i: int, q0: float, q1: float, q2: float, r0: float,
                 r1: float, r2: float, mu: float, rs1: float, rs2: float, max_local_iter: int,
                 qloc: np.ndarray, rloc: np.ndarray) -> tuple[int, float, float, float]:
    """The slip case of spatial contact ``i`` in a sweep (:func:`_slip_3d` from its local
    free velocity ``q`` and impulse ``r``, the stick guess's tangents ``rs``): ``(state,
    r_i)``. A call of its own: written into the sweep's loop, its arrays keep the compiler
    from optimising the column updates."""
    # the local fallback starts from r_i, and the slip direction's guess is r_i's
    qloc[0], qloc[1], qloc[2] = q0, q1, q2
    rloc[0], rloc[1], rloc[2] = r0, r1, r2
    state = _slip_3d(blocks[i], qloc, mu, rloc, rs1, rs2, max_local_iter)
    return state, rloc[0], rloc[1], rloc[2]


#: Largest number of sweeps between two checks of the error (:func:`_check_gap`).
MAX_CHECK_GAP = 32


@njit(cache=True, inline="always")
def _check_gap(err: float, last_err: float, sweeps: int, tol: float, done: int) -> int:
    """Sweeps until the next check of the error, from the last two checks and the ``done``
    sweeps so far: at most an eighth of ``done`` (at least 1, at most
    :data:`MAX_CHECK_GAP`), and while the error falls, at most half the sweeps the observed
    linear rate needs to reach ``tol``. A check costs about a third of a dense sweep; NSGS
    converges linearly once the contact states settle, so on a slow problem most checks
    only confirm the rate; before they settle the error can stall, then drop by decades in
    a few sweeps, which no rate foresees. The sweeps spent past the one that reached
    ``tol`` are therefore at most an eighth of those done (the answer is then more
    accurate, never less), and the checks at most about ``8 log(sweeps)``."""
    gap = min(max(1, done // 8), MAX_CHECK_GAP)
    if not (err < last_err and err > 0.0):
        return gap
    rate = np.log(err / last_err) / sweeps          # < 0: log of the error per sweep
    need = np.log(tol / err) / rate                 # > 0: sweeps to reach tol at that rate
    if not (need >= 2.0):
        return 1
    return int(min(0.5 * need, gap))


@njit(cache=True)
def nsgs_columns(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                 blocks: np.ndarray, inverses: np.ndarray, q: np.ndarray, mu: np.ndarray,
                 dim: int, r: np.ndarray, u: np.ndarray, states: np.ndarray, tol: float,
                 max_sweeps: int, max_local_iter: int, work: np.ndarray
                 ) -> tuple[int, int, float]:
    """Non-smooth Gauss–Seidel over contacts from the impulses in ``r``, exact local solves
    (:func:`local_1d`, :func:`local_2d`, :func:`local_3d`), ``u = W r + q`` kept up to date.

    Stops when the relative natural-map error of the whole problem (:func:`relative_error`,
    checked on the running ``u`` after the sweeps :func:`_check_gap` picks: every sweep
    for the first 16) is ``<= tol``, or after ``max_sweeps`` sweeps. ``u`` is
    recomputed exactly every :data:`REFRESH_SWEEPS` sweeps; the caller
    confirms the last on an exact product. Returns ``(code, sweeps, error)``: code
    :data:`CONVERGED` or :data:`SWEEP_LIMIT`. ``work``: at least 6 floats of scratch (a
    spatial contact's local slip solve), owned by the caller so that a solve allocates
    nothing.
    """
    # the sweeps specialised on W's storage and on dim (a constant in each body): with the
    # other kinds' code in its loop (the sparse update, another dim's local solve), the
    # compiler keeps a dense sweep's column update slow (a planar dense sweep measured 4x
    # slower, a spatial one up to 1.3x)
    if WT.shape[0] > 0:
        if dim == 3:
            return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 3, r, u,
                                states, tol, max_sweeps, max_local_iter, True, work)
        if dim == 2:
            return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 2, r, u,
                                states, tol, max_sweeps, max_local_iter, True, work)
        return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 1, r, u, states,
                            tol, max_sweeps, max_local_iter, True, work)
    if dim == 3:
        return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 3, r, u, states,
                            tol, max_sweeps, max_local_iter, False, work)
    if dim == 2:
        return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 2, r, u, states,
                            tol, max_sweeps, max_local_iter, False, work)
    return _nsgs_sweeps(WT, bptr, brow, bdata, blocks, inverses, q, mu, 1, r, u, states, tol,
                        max_sweeps, max_local_iter, False, work)


@njit(cache=True, inline="always")
def _nsgs_sweeps(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                 blocks: np.ndarray, inverses: np.ndarray, q: np.ndarray, mu: np.ndarray,
                 dim: int, r: np.ndarray, u: np.ndarray, states: np.ndarray, tol: float,
                 max_sweeps: int, max_local_iter: int, dense: bool, work: np.ndarray
                 ) -> tuple[int, int, float]:
    """The sweeps of :func:`nsgs_columns`, ``dense`` and ``dim`` constants at each call."""
    m = mu.shape[0]
    column_product(WT, bptr, brow, bdata, q, r, dim, u)
    q_norm = _norm(q)
    next_check, last_check, last_err = 1, 0, np.inf
    qloc = work[0:3]
    rloc = work[3:6]
    err = np.inf
    for sweep in range(1, max_sweeps + 1):
        for i in range(m):
            b = i * dim
            state, n0, n1, n2 = _local_update(blocks, inverses, i, dim, u, r, mu[i],
                                              max_local_iter, qloc, rloc)
            states[i] = state
            d0 = n0 - r[b]
            d1 = n1 - r[b + 1] if dim > 1 else 0.0
            d2 = n2 - r[b + 2] if dim > 2 else 0.0
            if d0 != 0.0 or d1 != 0.0 or d2 != 0.0:
                if dense:
                    _add_dense(WT, i, dim, d0, d1, d2, u)
                else:
                    _add_blocks(bptr, brow, bdata, i, dim, d0, d1, d2, u)
                r[b] = n0
                if dim > 1:
                    r[b + 1] = n1
                if dim > 2:
                    r[b + 2] = n2
        if sweep == next_check or sweep == max_sweeps:
            err = _relative_error(q_norm, r, u, mu, dim)
            if err <= tol:
                return CONVERGED, sweep, err
            next_check = sweep + _check_gap(err, last_err, sweep - last_check, tol, sweep)
            last_err, last_check = err, sweep
        if sweep % REFRESH_SWEEPS == 0:
            column_product(WT, bptr, brow, bdata, q, r, dim, u)
    return SWEEP_LIMIT, max_sweeps, err


@njit(cache=True)
def certify_columns(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                    terms: int, q: np.ndarray, r: np.ndarray, u: np.ndarray, mu: np.ndarray,
                    dim: int, tol: float, work: np.ndarray) -> tuple[float, float, bool]:
    """The acceptance test of every frictional-contact path: ``u = W r + q`` recomputed
    from ``r``, then ``(error, tolerance, certified)`` with the relative natural-map
    :func:`relative_error` and the tolerance ``tol`` plus the round-off bound of ``u``.

    One entry of ``u`` from ``k`` terms (a row's stored entries and ``q_i``; ``terms`` is
    the largest ``k``) is off by at most ``gamma_k (|W||r| + |q|)_i``; ``û`` adds
    ``μ |u_T|`` (at most ``1 + max μ`` times that), and the 2-norm over ``n`` entries at
    most ``sqrt(n)`` times the largest. With the factor
    :data:`~nscontrol.numerics._lcp_kernels.ROUNDOFF_FACTOR`: ``2 k eps (1 + max μ) sqrt(n)
    max_i (|W||r| + |q|)_i / max(|q|, |r|, |u|)``. As for the LCP, the tolerance is ``-inf``
    (nothing certified) when ``|W||r|`` exceeds the scale by
    :data:`~nscontrol.numerics._lcp_kernels.MAX_CANCELLATION`. ``work``: at least ``n``
    floats of scratch, owned by the caller.
    """
    n = q.shape[0]
    column_product(WT, bptr, brow, bdata, q, r, dim, u)
    a = work
    for k in range(n):
        a[k] = abs(q[k])
    if WT.shape[0] > 0:
        for c in range(n):
            rc = abs(r[c])
            for k in range(n):
                a[k] += abs(WT[c, k]) * rc
    for i in range(bptr.shape[0] - 1):    # no block column when W is dense
        for p in range(bptr[i], bptr[i + 1]):
            j = brow[p] * dim
            for k in range(dim):
                for c in range(dim):
                    a[j + k] += abs(bdata[p, k, c]) * abs(r[i * dim + c])
    big = 0.0
    for k in range(n):
        if not (a[k] <= big):     # also propagates NaN
            big = a[k]
    err = relative_error(q, r, u, mu, dim)
    scale = max(_norm(q), _norm(r), _norm(u))
    cancellation = big / scale if scale > 0.0 else 0.0   # scale 0: r = u = q = 0, exact
    if not (cancellation <= MAX_CANCELLATION):     # also NaN and inf
        return err, -np.inf, False
    mu_max = 0.0
    for i in range(mu.shape[0]):
        mu_max = max(mu_max, mu[i])
    tolerance = tol + ROUNDOFF_FACTOR * terms * _EPS * (1.0 + mu_max) * np.sqrt(n) * cancellation
    return err, tolerance, bool(err <= tolerance)


@njit(cache=True)
def work_size(n: int) -> int:
    """Floats of scratch :func:`solve_columns` needs for ``n`` unknowns (the sweeps' local
    slip solve: 6; the certification: ``n``; one after the other)."""
    return max(n, 6)


@njit(cache=True, inline="always")
def solve_columns(WT: np.ndarray, bptr: np.ndarray, brow: np.ndarray, bdata: np.ndarray,
                  blocks: np.ndarray, inverses: np.ndarray, terms: int, q: np.ndarray,
                  mu: np.ndarray, r: np.ndarray, u: np.ndarray, states: np.ndarray,
                  tol: float, max_sweeps: int, max_local_iter: int, work: np.ndarray
                  ) -> tuple[int, int, float, float, bool, int]:
    """One solve of :class:`~nscontrol.numerics.friction_contact.FrictionContactSolver`:
    ``W`` prepared first when ``terms`` is 0 (``μ`` checked, code :data:`MU_INVALID`, then
    :func:`prepare_columns`, whose codes it returns), ``q`` and the start ``r`` checked
    finite (code :data:`NOT_FINITE`), then :func:`nsgs_columns` and
    :func:`certify_columns`, sweeping on from the exact ``u`` when the running one passed
    ``tol`` and the exact one does not. ``work``: at least ``max(n, 6)`` floats of scratch
    (:func:`work_size`), owned by the caller. Returns ``(code, sweeps,
    error, tolerance, certified, terms)``."""
    dim = blocks.shape[1]
    if terms == 0:
        for i in range(mu.shape[0]):
            if not (mu[i] >= 0.0 and mu[i] < np.inf):
                return MU_INVALID, 0, np.nan, np.nan, False, 0
        code, terms = prepare_columns(WT, bptr, brow, bdata, dim, blocks, inverses)
        if code != 0:
            return code, 0, np.nan, np.nan, False, terms
    if not (_all_finite(q) and _all_finite(r)):
        return NOT_FINITE, 0, np.nan, np.nan, False, terms
    done = 0
    while True:
        code, sweeps, err = nsgs_columns(WT, bptr, brow, bdata, blocks, inverses, q, mu,
                                         dim, r, u, states, tol, max_sweeps - done,
                                         max_local_iter, work)
        done += sweeps
        err, tolerance, ok = certify_columns(WT, bptr, brow, bdata, terms, q, r, u, mu, dim,
                                             tol, work)
        if ok or code != CONVERGED or err <= tol or done >= max_sweeps:
            return code, done, err, tolerance, ok, terms


@njit(cache=True)
def dense_columns(W: np.ndarray) -> np.ndarray:
    """The dense ``WT`` the solver reads (see above): ``W`` itself when it is exactly
    symmetric (a Delassus matrix), else a C-contiguous copy of its transpose; either way
    contact ``i``'s columns are contiguous rows. NaN entries make it a copy (the copy's
    values are checked where ``W``'s are)."""
    n = W.shape[0]
    for k in range(n):
        for c in range(k):
            if W[k, c] != W[c, k]:
                return np.ascontiguousarray(W.T)
    return W


@njit(cache=True)
def solve_dense_once(W: np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray,
                     u: np.ndarray, states: np.ndarray, tol: float, max_sweeps: int,
                     max_local_iter: int) -> tuple[int, int, float, float, bool]:
    """:func:`solve_columns` on a dense ``W`` used once (``dim = len(q) / len(states)``),
    the blocks prepared in this call, all its scratch in one allocation. The one
    compiled call of :func:`~nscontrol.numerics.friction_contact.solve_friction_contact` on
    a small dense problem. Returns ``(code, sweeps, error, tolerance, certified)``."""
    n = q.shape[0]
    m = states.shape[0]
    dim = n // m
    k = m * dim * dim
    buf = np.empty(2 * k + work_size(n))
    bptr = np.zeros(1, np.int64)        # no block column: W is dense
    code, sweeps, err, tolerance, ok, _ = solve_columns(
        dense_columns(W), bptr, bptr[:0], buf[:0].reshape((0, 1, 1)),
        buf[:k].reshape((m, dim, dim)), buf[k:2 * k].reshape((m, dim, dim)), 0, q, mu, r, u,
        states, tol, max_sweeps, max_local_iter, buf[2 * k:])
    return code, sweeps, err, tolerance, ok


_F64_1D = types.Array(types.float64, 1, "C")
_I32_1D = types.Array(types.int32, 1, "C")
#: The one signature of :func:`solve_dense_once` on the short path of
#: :func:`~nscontrol.numerics.friction_contact.solve_friction_contact`.
SOLVE_DENSE_ONCE_SIGNATURE = (types.Array(types.float64, 2, "C"), _F64_1D, _F64_1D, _F64_1D,
                              _F64_1D, types.Array(types.int64, 1, "C"), types.float64,
                              types.int64, types.int64)
#: The one signature of :func:`solve_sparse_once` there (scipy's int32 indices).
SOLVE_SPARSE_ONCE_SIGNATURE = (_I32_1D, _I32_1D, _F64_1D, types.boolean, _F64_1D, _F64_1D,
                               _F64_1D, _F64_1D, types.Array(types.int64, 1, "C"),
                               types.float64, types.int64, types.int64)


@njit(cache=True)
def solve_sparse_once(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, csr: bool,
                      q: np.ndarray, mu: np.ndarray, r: np.ndarray, u: np.ndarray,
                      states: np.ndarray, tol: float, max_sweeps: int, max_local_iter: int
                      ) -> tuple[int, int, float, float, bool]:
    """:func:`solve_dense_once` for a sparse ``W`` given by its CSR (``csr``) or CSC arrays:
    its block columns (:func:`csr_to_blocks`, :func:`csc_to_blocks`) built in this call."""
    m = states.shape[0]
    n = q.shape[0]
    dim = n // m
    if csr:
        bptr, brow, bdata = csr_to_blocks(indptr, indices, data, n, dim)
    else:
        bptr, brow, bdata = csc_to_blocks(indptr, indices, data, n, dim)
    k = m * dim * dim
    buf = np.empty(2 * k + work_size(n))
    code, sweeps, err, tolerance, ok, _ = solve_columns(
        np.zeros((0, 0)), bptr, brow, bdata, buf[:k].reshape((m, dim, dim)),
        buf[k:2 * k].reshape((m, dim, dim)), 0, q, mu, r, u, states, tol, max_sweeps,
        max_local_iter, buf[2 * k:])
    return code, sweeps, err, tolerance, ok


@njit(cache=True)
def csr_to_csc(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, n: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The CSC arrays of an ``(n, n)`` CSR matrix."""
    nnz = indptr[n]
    colptr = np.zeros(n + 1, np.int64)
    for p in range(nnz):
        colptr[indices[p] + 1] += 1
    for j in range(n):
        colptr[j + 1] += colptr[j]
    fill = colptr[:n].copy()
    rowidx = np.empty(nnz, np.int64)
    cdata = np.empty(nnz)
    for i in range(n):
        for p in range(indptr[i], indptr[i + 1]):
            j = indices[p]
            rowidx[fill[j]] = i
            cdata[fill[j]] = data[p]
            fill[j] += 1
    return colptr, rowidx, cdata


@njit(cache=True)
def csr_to_blocks(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, n: int,
                  dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`csc_to_blocks` of an ``(n, n)`` CSR matrix."""
    colptr, rowidx, cdata = csr_to_csc(indptr, indices, data, n)
    return csc_to_blocks(colptr, rowidx, cdata, n, dim)


