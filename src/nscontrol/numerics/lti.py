"""Exact numerics for linear time-invariant flows: exosystem inputs, propagation, ZOH
discretisation and the location of guard events on the exact solution.

Between events, every model of nscontrol whose flow is linear (plant, observer, exosystem
generating the input) is one autonomous system ``X' = A X``: :func:`augment` stacks a plant
``x' = A x + B u`` with an :class:`Exosystem` (``u = Cu w``, ``w' = S w``). Its solution is
``X(t) = e^{At} X(0)``, computed by :class:`LTIFlow`.

Propagation (:class:`LTIFlow`)
------------------------------
``LTIFlow(A)`` decomposes ``A`` once. When ``A`` is diagonalisable with a well-conditioned
eigenvector matrix (``cond(V) <= 1e5``), ``e^{At} = V diag(e^{λt}) V^{-1}``: any number of
times then costs one exponential per eigenvalue and a matrix product, with a relative error
about ``cond(V)·eps``. Otherwise (defective ``A``, e.g. a free mass ``q'' = 0`` or a
polynomial exosystem, both Jordan blocks) every time goes through ``scipy.linalg.expm``
(Padé with scaling and squaring), batched over an array of times.

Event location (:func:`first_event`)
------------------------------------
A guard is ``g_i(t) = G_i e^{At} x0 + g0_i``. The search never samples ``g`` alone: it works
on a certified local representation of ``g`` and of ``g'``.

1. *Balance and grid.* ``A`` is balanced by a diagonal similarity ``A = D Ab D^{-1}``
   (``scipy.linalg.matrix_balance``) and the horizon is cut into cells of width
   ``h = 1/||Ab||_2``. Cell start states are ``y_{k+1} = Φ y_k`` with ``Φ = e^{Ab h}``
   (computed once per flow and cached); the scan over cells runs in a numba kernel
   (:mod:`nscontrol.numerics._lti_kernels`), so a far event costs microseconds per cell.
2. *Taylor polynomial per cell.* On a cell starting at ``t_k``, ``g(t_k + σh) = Σ_j a_j σ^j``
   with ``a_j = G D (Ab h)^j y_k / j!``, ``j <= K = 18``; since ``||Ab h|| = 1`` the truncation
   error is below ``e/19! ≈ 2e-17`` relative, i.e. the polynomial *is* ``g`` to rounding. The
   matrices ``G D (Ab h)^j / j!`` are cached per flow and guard matrix.
3. *Certificate.* The Bernstein coefficients of each polynomial on ``[0, 1]`` enclose its
   range. A cell whose smallest Bernstein coefficient exceeds the touch tolerance is
   certified root-free for that guard. No grid step needs tuning: the enclosure is
   rigorous, so a double root or a near-grazing pair between grid points cannot slip through.
4. *Exact analysis of the remaining cells, in time order.* When the Bernstein coefficients
   of ``g'`` have one sign, ``g`` is monotone on the cell and the kernel finds its root
   directly. Otherwise (in Python) the critical points of ``g`` (real roots of the polynomial
   ``g'``) split the cell into monotone pieces. Walking
   them left to right: the first piece whose right end has ``g <= 0`` holds the first root,
   a unique one, refined by a safeguarded Newton iteration (bisection whenever the Newton
   step leaves the bracket); a local minimum with ``|g| <= tol`` is a tangential touch
   (``grazing=True``), reported at the minimum. Two roots closer than the grid appear as a
   negative local minimum and the first of them is returned.
5. *Machine precision.* The cell start state is recomputed from ``x0`` by the exact flow
   (no accumulated powers of ``Φ``) and the root re-polished by Newton on that polynomial.
6. *Simultaneous guards.* Every guard whose first event lies within ``simultaneous_tol``
   (relative to ``max(t, h)``) of the earliest one is reported in ``indices``.

Guards at zero at ``t = 0`` (just after an impact) are classified by the sign of their first
non-negligible derivative there: positive -> the root at 0 is ignored; negative -> an event
at ``t = 0`` is returned; a guard identically zero (sliding along the surface) never fires.
A guard negative at 0 beyond tolerance is an inadmissible state.

References
----------
D5.3 chapter 2, section 5 (exact event-driven simulation of impacting LTI systems).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg

from .._validation import FloatArray, as_matrix, as_square, as_vector, check_positive
from ..errors import DimensionError, InadmissibleStateError, ModelError

__all__ = ["Exosystem", "augment", "LTIFlow", "discretize", "Discretization", "GuardEvent",
           "first_event"]

#: Largest eigenvector condition number for which the eigendecomposition path is used.
EIG_COND_LIMIT = 1e5
#: Taylor degree per cell; with ||Ab h|| = 1 the remainder is below e/(K+1)! ≈ 2e-17.
TAYLOR_DEGREE = 18
_REMAINDER = math.e / math.factorial(TAYLOR_DEGREE + 1)


# --------------------------------------------------------------------------- exosystem
@dataclass(frozen=True, eq=False)
class Exosystem:
    """A linear signal generator: ``w' = S w``, ``w(0) = w0``, ``u(t) = Cu w(t)``.

    Parameters
    ----------
    S : (q, q) array_like
        Generator matrix.
    Cu : (m, q) array_like
        Output map from the generator state to the input ``u``.
    w0 : (q,) array_like
        Initial generator state.

    Notes
    -----
    Constants, polynomials and sinusoids are built by the class methods; ``exo1 + exo2``
    adds two inputs of the same size (block-diagonal ``S``).

    Examples
    --------
    >>> exo = Exosystem.sinusoid(2.0, omega=3.0, offset=1.0)
    >>> bool(abs(exo.u(0.5)[0] - (1.0 + 2.0 * np.sin(1.5))) < 1e-14)
    True
    """

    S: FloatArray
    Cu: FloatArray
    w0: FloatArray

    def __post_init__(self) -> None:
        S = as_square("S", self.S)
        q = S.shape[0]
        object.__setattr__(self, "S", S)
        object.__setattr__(self, "Cu", as_matrix("Cu", self.Cu, cols=q))
        object.__setattr__(self, "w0", as_vector("w0", self.w0, q))

    @property
    def n_states(self) -> int:
        """Dimension ``q`` of the generator state."""
        return self.S.shape[0]

    @property
    def n_inputs(self) -> int:
        """Dimension ``m`` of the generated input."""
        return self.Cu.shape[0]

    @classmethod
    def constant(cls, value: Any) -> Exosystem:
        """A constant input ``u(t) = value`` (scalar or vector)."""
        v = as_vector("value", value)
        m = v.shape[0]
        return cls(np.zeros((m, m)), np.eye(m), v)

    @classmethod
    def polynomial(cls, coeffs: Any) -> Exosystem:
        """A polynomial input ``u(t) = Σ_k coeffs[k] t^k``.

        ``coeffs`` has shape ``(d + 1,)`` (scalar input) or ``(d + 1, m)``. The generator is a
        chain ``w_k = t^k / k!`` (a nilpotent ``S``), shared by all components of ``u``.
        """
        c = _poly_coeffs("coeffs", coeffs)
        d1 = c.shape[0]
        S = np.diag(np.ones(d1 - 1), -1)
        fact = np.array([math.factorial(k) for k in range(d1)], dtype=float)
        Cu = (c * fact[:, None]).T
        w0 = np.zeros(d1)
        w0[0] = 1.0
        return cls(S, Cu, w0)

    @classmethod
    def sinusoid(cls, amplitude: Any, omega: float, phase: float = 0.0,
                 offset: Any = 0.0) -> Exosystem:
        """``u(t) = offset + amplitude · sin(omega t + phase)`` (amplitude/offset may be vectors).

        The generator state is ``(sin(ωt + φ), cos(ωt + φ))``, plus a constant state when an
        offset is non-zero.
        """
        amp = as_vector("amplitude", amplitude)
        off = as_vector("offset", offset)
        if off.shape[0] not in (1, amp.shape[0]) and amp.shape[0] != 1:
            raise DimensionError(f"offset: expected length 1 or {amp.shape[0]} (amplitude's), "
                                 f"got length {off.shape[0]}")
        m = max(amp.shape[0], off.shape[0])
        amp, off = np.broadcast_to(amp, (m,)), np.broadcast_to(off, (m,))
        w = check_positive("omega", omega, allow_zero=True)
        ph = float(phase)
        if not np.isfinite(ph):
            raise ModelError(f"phase: expected a finite number, got {phase!r}")
        S = np.array([[0.0, w], [-w, 0.0]])
        Cu = np.column_stack([amp, np.zeros(m)])
        w0 = np.array([np.sin(ph), np.cos(ph)])
        if np.any(off != 0.0):
            S = scipy.linalg.block_diag(S, 0.0)
            Cu = np.column_stack([Cu, off])
            w0 = np.append(w0, 1.0)
        return cls(S, Cu, w0)

    def __add__(self, other: Exosystem) -> Exosystem:
        if not isinstance(other, Exosystem):
            return NotImplemented
        if other.n_inputs != self.n_inputs:
            raise DimensionError(f"other: expected an exosystem with {self.n_inputs} inputs, "
                                 f"got {other.n_inputs}")
        return Exosystem(scipy.linalg.block_diag(self.S, other.S),
                         np.hstack([self.Cu, other.Cu]), np.concatenate([self.w0, other.w0]))

    @cached_property
    def _flow(self) -> LTIFlow:
        return LTIFlow(self.S)

    def w(self, t: Any) -> FloatArray:
        """Generator state at ``t`` (scalar -> ``(q,)``, array -> ``(len(t), q)``)."""
        return self._flow.propagate(self.w0, t)

    def u(self, t: Any) -> FloatArray:
        """Input at ``t`` (scalar -> ``(m,)``, array of times -> ``(len(t), m)``)."""
        return self.w(t) @ self.Cu.T


def _poly_coeffs(name: str, value: Any) -> FloatArray:
    """Polynomial coefficients as a finite ``(d + 1, m)`` array."""
    arr = as_vector(name, value) if np.ndim(value) <= 1 else as_matrix(name, value)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.shape[0] == 0:
        raise DimensionError(f"{name}: expected at least one coefficient, got none")
    return arr


def augment(A: Any, B: Any, exo: Exosystem) -> FloatArray:
    """The matrix of the autonomous system ``[x; w]' = A_aug [x; w]``.

    ``A_aug = [[A, B Cu], [0, S]]`` for ``x' = A x + B u``, ``u = Cu w``, ``w' = S w``.
    The initial state is ``np.concatenate([x0, exo.w0])``.
    """
    A = as_square("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, rows=n)
    if B.shape[1] != exo.n_inputs:
        raise DimensionError(f"B: expected {exo.n_inputs} columns (the exosystem's inputs), "
                             f"got shape {B.shape}")
    q = exo.n_states
    return np.block([[A, B @ exo.Cu], [np.zeros((q, n)), exo.S]])


# --------------------------------------------------------------------------- flow
class LTIFlow:
    """The flow ``t -> e^{At}`` of ``x' = A x``, with its decomposition cached.

    Parameters
    ----------
    A : (n, n) array_like
        System matrix (finite).

    Attributes
    ----------
    A : ndarray
        The validated matrix.
    method : {"eig", "expm"}
        ``"eig"`` when ``A`` is diagonalisable with ``cond(V) <= EIG_COND_LIMIT``,
        ``"expm"`` (scipy's Padé, batched) otherwise.
    """

    def __init__(self, A: Any) -> None:
        self.A = as_square("A", A)
        self.A.setflags(write=False)
        self.n = self.A.shape[0]
        self.method = "expm"
        if self.n:
            lam, V = np.linalg.eig(self.A)
            if np.linalg.cond(V) <= EIG_COND_LIMIT:
                self.method = "eig"
                self._lam, self._V, self._Vinv = lam, V, np.linalg.inv(V)
        self._guard: _GuardContext | None = None

    def __repr__(self) -> str:
        return f"LTIFlow(n={self.n}, method={self.method!r})"

    def expm(self, t: Any) -> FloatArray:
        """``e^{At}``: ``(n, n)`` for a scalar ``t``, ``(len(t), n, n)`` for an array."""
        ts, scalar = _times(t)
        if self.method == "eig":
            E = np.exp(np.multiply.outer(ts, self._lam))
            out = np.einsum("ij,tj,jk->tik", self._V, E, self._Vinv).real
        else:
            out = scipy.linalg.expm(ts[:, None, None] * self.A)
        return out[0] if scalar else out

    def propagate(self, x0: Any, t: Any) -> FloatArray:
        """``e^{At} x0``: ``(n,)`` for a scalar ``t``, time-major ``(len(t), n)`` otherwise."""
        x0 = as_vector("x0", x0, self.n)
        ts, scalar = _times(t)
        if self.method == "eig":
            c = self._Vinv @ x0
            out = (np.exp(np.multiply.outer(ts, self._lam)) * c) @ self._V.T
            out = out.real
        else:
            out = scipy.linalg.expm(ts[:, None, None] * self.A) @ x0
        return out[0] if scalar else out

    def state_at(self, x0: FloatArray, t: float) -> FloatArray:
        """``e^{At} x0`` for a validated ``x0`` and one time (no checks: internal hot path)."""
        if self.method == "eig":
            return (self._V @ (np.exp(self._lam * t) * (self._Vinv @ x0))).real
        return scipy.linalg.expm(self.A * t) @ x0

    def guard_context(self) -> _GuardContext:
        """Balanced matrix, cell width and cached powers used by :func:`first_event`."""
        if self._guard is None:
            self._guard = _GuardContext(self.A)
        return self._guard


def _times(t: Any) -> tuple[FloatArray, bool]:
    ts = np.asarray(t, dtype=float)
    scalar = ts.ndim == 0
    ts = np.atleast_1d(ts)
    if ts.ndim != 1:
        raise DimensionError(f"t: expected a scalar or a 1-d array of times, got shape {ts.shape}")
    if not np.all(np.isfinite(ts)):
        raise ModelError("t: expected finite times, got NaN or infinite value(s)")
    return ts, scalar


class Discretization(NamedTuple):
    """Zero-order-hold discretisation ``x_{k+1} = Ad x_k + Bd u_k``."""

    Ad: FloatArray
    Bd: FloatArray


def discretize(A: Any, B: Any, h: float) -> Discretization:
    """Exact zero-order-hold discretisation of ``x' = A x + B u`` with step ``h``.

    Computed from one exponential of the augmented matrix:
    ``expm([[A, B], [0, 0]] h) = [[Ad, Bd], [0, I]]``, so ``Bd = ∫_0^h e^{As} ds B`` holds
    also for singular ``A``.

    Returns
    -------
    Discretization
        Named pair ``(Ad, Bd)``.
    """
    A = as_square("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, rows=n)
    h = check_positive("h", h)
    m = B.shape[1]
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = scipy.linalg.expm(M * h)
    return Discretization(E[:n, :n], E[:n, n:])


# --------------------------------------------------------------------------- events
@dataclass(frozen=True)
class GuardEvent:
    """The first zero of a set of guards.

    Attributes
    ----------
    t : float
        Time of the event, relative to the start of the search.
    indices : tuple of int
        Guards at zero at ``t`` (all those simultaneous within the tolerance), ascending.
    grazing : bool
        True when every reported guard touches zero tangentially (a local minimum at zero)
        instead of crossing it.
    """

    t: float
    indices: tuple[int, ...]
    grazing: bool


def _bernstein_matrix(K: int) -> FloatArray:
    """``b = M a``: Bernstein coefficients on [0, 1] of ``Σ_j a_j σ^j`` (degree K)."""
    M = np.zeros((K + 1, K + 1))
    for k in range(K + 1):
        for j in range(k + 1):
            M[k, j] = math.comb(k, j) / math.comb(K, j)
    return M


class _GuardContext:
    """Per-flow cache for the event search (balancing, cell width, powers of Φ)."""

    def __init__(self, A: FloatArray) -> None:
        n = A.shape[0]
        Ab, (scale, _) = scipy.linalg.matrix_balance(A, permute=False, separate=True)
        self.d = scale.astype(float)
        norm = float(np.linalg.norm(Ab, 2)) if n else 0.0
        self.h = 1.0 / norm if norm > 0.0 else 1.0
        self.Ab = Ab
        self.Abh = Ab * self.h
        self.phi = scipy.linalg.expm(self.Abh) if n else np.eye(0)
        K = TAYLOR_DEGREE
        self.bern = _bernstein_matrix(K)
        self.bern_d = _bernstein_matrix(K - 1)
        self._taylor: FloatArray | None = None
        self._guards: dict[Any, tuple[FloatArray, ...]] = {}

    def guard_data(self, G: FloatArray, h_cell: float) -> tuple[FloatArray, ...]:
        """``(G D, row norms, W)`` with ``W[j] = G D (Ab h)^j / j!``: the guard Taylor
        coefficients are ``W @ (cell start states)``. Cached for the grid step (an
        integrator calls first_event with the same G at every event)."""
        key = (G.shape, G.tobytes())
        if h_cell == self.h and key in self._guards:
            return self._guards[key]
        GD = G * self.d
        W = np.einsum("pn,knl->kpl", GD, self.taylor_matrices(h_cell))
        data = (GD, np.linalg.norm(GD, axis=1), np.ascontiguousarray(W))
        if h_cell == self.h:
            if len(self._guards) >= 16:
                self._guards.pop(next(iter(self._guards)))
            self._guards[key] = data
        return data

    def taylor_matrices(self, h_cell: float) -> FloatArray:
        """``[(Ab h)^j / j!]_{j=0..K}`` as a ``(K + 1, n, n)`` array (cached for the grid h)."""
        if h_cell == self.h and self._taylor is not None:
            return self._taylor
        M = self.Ab * h_cell
        T = [np.eye(M.shape[0])]
        for j in range(1, TAYLOR_DEGREE + 1):
            T.append((M @ T[-1]) / j)
        T = np.asarray(T)
        if h_cell == self.h:
            self._taylor = T
        return T


def first_event(flow_or_A: LTIFlow | Any, x0: Any, G: Any, g0: Any, t_max: float, *,
                graze_tol: float = 1e-12, simultaneous_tol: float = 1e-12
                ) -> GuardEvent | None:
    """First time in ``(0, t_max]`` at which a guard ``g_i(t) = G_i e^{At} x0 + g0_i`` is zero.

    Parameters
    ----------
    flow_or_A : LTIFlow or (n, n) array_like
        The flow (reuse one :class:`LTIFlow` across calls: its caches make repeated searches
        fast) or the matrix ``A``.
    x0 : (n,) array_like
        State at the start of the search (``t = 0``).
    G : (p, n) array_like
        One row per guard.
    g0 : (p,) array_like
        Guard offsets.
    t_max : float
        Search horizon, ``> 0``.
    graze_tol : float, optional
        Relative tolerance (to ``|G_i D| |y| + |g0_i|``) below which a local minimum of a
        guard counts as a tangential touch and a guard value counts as zero at ``t = 0``.
    simultaneous_tol : float, optional
        Guards whose first events are within ``simultaneous_tol · max(t, h)`` of the first one
        are reported together (``h`` is the internal cell width, about ``1/||A||``).

    Returns
    -------
    GuardEvent or None
        ``None`` when no guard reaches zero in ``(0, t_max]``.

    Raises
    ------
    DimensionError
        Shapes of ``x0``, ``G``, ``g0`` disagree with ``A``.
    ModelError
        NaN/inf entries, ``t_max <= 0``.
    InadmissibleStateError
        A guard is negative at ``t = 0`` (beyond the tolerance).

    Notes
    -----
    The bracketing strategy (Bernstein-certified Taylor cells, then an exact walk over the
    monotone pieces between critical points) is described in the module docstring; it does
    not miss tangential touches or pairs of roots closer than the grid.

    Examples
    --------
    >>> A = np.array([[0.0, 1.0], [-1.0, 0.0]])          # x = (cos t, -sin t)
    >>> ev = first_event(A, [1.0, 0.0], [[1.0, 0.0]], [0.0], 10.0)
    >>> bool(abs(ev.t - np.pi / 2) < 1e-14), ev.indices, ev.grazing
    (True, (0,), False)
    """
    flow = flow_or_A if isinstance(flow_or_A, LTIFlow) else LTIFlow(flow_or_A)
    n = flow.n
    x0 = x0 if _clean(x0, (n,)) else as_vector("x0", x0, n)
    G = G if _clean(G, (None, n)) else as_matrix("G", G, cols=n)
    p = G.shape[0]
    g0 = g0 if _clean(g0, (p,)) else as_vector("g0", g0, p)
    t_max = check_positive("t_max", t_max)
    graze_tol = check_positive("graze_tol", graze_tol)
    simultaneous_tol = check_positive("simultaneous_tol", simultaneous_tol, allow_zero=True)
    ctx = flow.guard_context()
    return _Search(flow, ctx, x0, G, g0, t_max, graze_tol, simultaneous_tol).run()


def _shallow_dip(a: FloatArray, tol: float) -> bool:
    """Whether ``a0 + a1 s + a2 s^2`` (a1 < 0 < a2) dips no deeper than ``-tol``: a guard
    restarted at a grazing point located to ~sqrt(eps) has a tiny negative slope there but
    leaves the surface; that is not a new event."""
    return bool(a[2] > 0.0 and a[0] - a[1] ** 2 / (4.0 * a[2]) >= -tol)


def _clean(a: Any, shape: tuple[int | None, ...]) -> bool:
    """Fast path: already a finite float64 array of this shape (else the checks of
    ``nscontrol._validation`` run and raise their specific errors)."""
    return (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == len(shape)
            and all(s is None or s == d for s, d in zip(shape, a.shape, strict=True))
            and bool(np.isfinite(a).all()))


class _Search:
    """One call of :func:`first_event` (state of the chunked scan)."""

    def __init__(self, flow: LTIFlow, ctx: _GuardContext, x0: FloatArray, G: FloatArray,
                 g0: FloatArray, t_max: float, graze_tol: float, sim_tol: float) -> None:
        self.flow, self.ctx, self.x0 = flow, ctx, x0
        self.g0, self.t_max = g0, t_max
        self.graze_tol, self.sim_tol = graze_tol, sim_tol
        self.y0 = x0 / ctx.d
        self.h = min(ctx.h, t_max)
        self.GD, self.row_norm, self.W = ctx.guard_data(G, self.h)
        self.active = np.ones(len(g0), dtype=bool)
        self.skip_start = np.zeros(len(g0), dtype=bool)

    def run(self) -> GuardEvent | None:
        from ._lti_kernels import HITS, NO_EVENT, scan_cells

        early = self._classify_start()
        if early is not None:
            return early
        if not self.active.any():
            return None
        ctx, p = self.ctx, len(self.g0)
        n_cells = max(1, math.ceil(self.t_max / self.h))
        y, k = self.y0.copy(), 0
        sigma, hit = np.zeros(p), np.zeros(p, dtype=np.int8)
        while k < n_cells:
            code, k = scan_cells(self.W, self.g0, self.row_norm, self.graze_tol, _REMAINDER,
                                 ctx.phi, ctx.bern, ctx.bern_d, y, k, n_cells, self.h,
                                 self.t_max, self.active, self.skip_start, sigma, hit)
            if code == NO_EVENT:
                return None
            a = self.W @ y
            a[0] += self.g0
            if code == HITS:
                hits = {int(i): (float(sigma[i]), False) for i in np.flatnonzero(hit)}
                return self._finish(k, k * self.h, a, hits)
            event = self._walk_cell(k, a, y)
            if event is not None:
                return event
            y = ctx.phi @ y
            k += 1
        return None

    def _walk_cell(self, k: int, a: FloatArray, y: FloatArray) -> GuardEvent | None:
        """Exact analysis (critical points of g) of cell ``k``, Taylor coefficients ``a``."""
        scale = self.row_norm * math.sqrt(y @ y) + np.abs(self.g0)
        tol = self.graze_tol * scale
        bern_min = (self.ctx.bern @ a).min(axis=0)
        flagged = (bern_min <= tol + _REMAINDER * scale) & self.active
        sigma_end = min(1.0, (self.t_max - k * self.h) / self.h)
        hits = {}
        for i in np.flatnonzero(flagged):
            hit = _walk(a[:, i], sigma_end, tol[i], bool(self.skip_start[i] and k == 0),
                        self.ctx)
            if hit is not None:
                hits[int(i)] = hit
        return self._finish(k, k * self.h, a, hits) if hits else None

    def _classify_start(self) -> GuardEvent | None:
        """Handle guards at zero at t = 0; reject negative ones."""
        g_start = self.GD @ self.y0 + self.g0
        tol = self.graze_tol * (self.row_norm * math.sqrt(self.y0 @ self.y0) + np.abs(self.g0))
        if (g_start > tol).all():
            return None  # the common case: every guard strictly positive
        a = self.W @ self.y0  # (K+1, p): scaled derivatives at 0
        a[0] += self.g0
        negative = a[0] < -tol
        if negative.any():
            i = int(np.flatnonzero(negative)[0])
            raise InadmissibleStateError(
                f"x0: guard {i} is negative at t = 0 (g = {a[0, i]:.3g} < 0); the search "
                "needs every guard >= 0 at its start — check the state or the guard signs")
        starts_zero = np.abs(a[0]) <= tol
        falling = []
        for i in np.flatnonzero(starts_zero):
            nz = np.flatnonzero(np.abs(a[1:, i]) > tol[i])
            if nz.size == 0:
                self.active[i] = False  # identically zero: moves along the surface
            elif a[1 + nz[0], i] < 0.0 and not _shallow_dip(a[:3, i], tol[i]):
                falling.append(int(i))
            else:
                self.skip_start[i] = True
        if falling:
            return GuardEvent(0.0, tuple(falling), False)
        return None

    def _finish(self, k_glob: int, t_k: float, a: FloatArray,
                hits: dict[int, tuple[float, bool]]) -> GuardEvent:
        """Re-polish on the exact start state, gather simultaneous guards."""
        from ._lti_kernels import polish

        if k_glob > 0:
            y = self.flow.state_at(self.x0, t_k) / self.ctx.d
            a = self.W @ y
            a[0] += self.g0
            hits = {i: (polish(np.ascontiguousarray(a[:, i]), s, g), g)
                    for i, (s, g) in hits.items()}
        s_first = min(s for s, _ in hits.values())
        t_first = t_k + s_first * self.h
        delta = self.sim_tol * max(t_first, self.h) / self.h
        chosen = {i: g for i, (s, g) in hits.items() if s <= s_first + delta}
        if len(chosen) < len(self.g0):
            for i in np.flatnonzero(self.active & ~(self.skip_start & (k_glob == 0))):
                if int(i) not in chosen and _horner(a[::-1, i].tolist(),
                                                    s_first + delta) <= 0.0:
                    chosen[int(i)] = False
        t_event = min(t_first, self.t_max)
        return GuardEvent(float(t_event), tuple(sorted(chosen)), all(chosen.values()))


def _trim(a: FloatArray) -> FloatArray:
    """Drop negligible high-order coefficients (keeps np.roots well conditioned)."""
    mags = np.abs(a)
    big = np.flatnonzero(mags > 1e-17 * mags.sum())
    return a[: int(big[-1]) + 1] if big.size else a[:1]


def _horner(c_desc: list[float], x: float) -> float:
    """Value at ``x`` of the polynomial with descending coefficients ``c_desc``."""
    r = 0.0
    for c in c_desc:
        r = r * x + c
    return r


def _horner2(c_desc: list[float], x: float) -> tuple[float, float]:
    """Value and derivative at ``x`` (one Horner sweep)."""
    r, d = 0.0, 0.0
    for c in c_desc:
        d = d * x + r
        r = r * x + c
    return r, d


def _derivative(a: FloatArray) -> FloatArray:
    """Ascending coefficients of ``P'`` from those of ``P``."""
    return a[1:] * np.arange(1, len(a))


def _critical_points(a: FloatArray, sigma_end: float, ctx: _GuardContext) -> list[float]:
    """Real roots of ``P'`` in ``(0, sigma_end)``, polished (``P = Σ a_j σ^j``)."""
    if len(a) < 3:
        return []
    da = _derivative(a)
    if len(a) == TAYLOR_DEGREE + 1:
        bd = ctx.bern_d @ da
        if bd.min() > 0.0 or bd.max() < 0.0:
            return []  # g' has one sign on the whole cell: g is monotone
    da = _trim(da)
    if len(da) < 2:
        return []
    roots = np.roots(da[::-1])
    near_real = roots[np.abs(roots.imag) <= 1e-6].real
    d1, d2 = da[::-1].tolist(), _derivative(da)[::-1].tolist()
    out = []
    for r in near_real.tolist():
        if -1e-9 <= r <= sigma_end + 1e-9:
            for _ in range(3):
                curv = _horner(d2, r)
                if curv == 0.0:
                    break
                r -= _horner(d1, r) / curv
            if 0.0 < r < sigma_end:
                out.append(r)
    return sorted(out)


def _walk(a: FloatArray, sigma_end: float, tol: float, skip_start: bool,
          ctx: _GuardContext) -> tuple[float, bool] | None:
    """First zero of ``P(σ) = Σ a_j σ^j`` on ``[0, sigma_end]``: ``(σ, grazing)`` or None."""
    crit = _critical_points(a, sigma_end, ctx)
    a = _trim(a)
    p = a[::-1].tolist()
    if skip_start:  # flat start of a guard leaving zero: not a touch
        while crit and _horner(p, crit[0]) <= tol:
            crit.pop(0)
    pts = [0.0, *crit, sigma_end]
    vals = [_horner(p, x) for x in pts]
    if not skip_start and vals[0] <= 0.0:
        return 0.0, False
    last = len(pts) - 1
    for j in range(1, len(pts)):
        if j < last and abs(vals[j]) <= tol:
            return pts[j], True  # a local minimum at zero: tangential touch
        if vals[j] <= 0.0:
            return _bracketed_root(a, pts[j - 1], pts[j], vals[j - 1], vals[j]), False
    return None


_EPS = float(np.finfo(float).eps)


def _bracketed_root(a: FloatArray, lo: float, hi: float, f_lo: float, f_hi: float) -> float:
    """Root of the monotone ``P`` on ``[lo, hi]`` with ``P(lo) > 0 >= P(hi)``: safeguarded
    Newton from the secant point (a bisection step whenever Newton leaves the bracket)."""
    p = a[::-1].tolist()
    x = lo + (hi - lo) * f_lo / (f_lo - f_hi) if f_lo > f_hi else 0.5 * (lo + hi)
    for _ in range(200):
        fx, d = _horner2(p, x)
        if fx == 0.0:
            return x
        if fx > 0.0:
            lo = x
        else:
            hi = x
        x_new = x - fx / d if d != 0.0 else 0.5 * (lo + hi)
        if not lo < x_new < hi:
            x_new = 0.5 * (lo + hi)
        if abs(x_new - x) <= 2.0 * _EPS * abs(x) or hi - lo <= 4.0 * _EPS * abs(hi):
            return x_new
        x = x_new
    return x
