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
   (:func:`~nscontrol.numerics.scaling.balance`) and the horizon is cut into cells of width
   ``h = 1/||Ab||_2``. Cell start states are ``y_{k+1} = Φ y_k`` with ``Φ = e^{Ab h}``
   (computed once per flow and cached). The whole search (steps 2-6) is one numba kernel
   (:func:`nscontrol.numerics._lti_kernels.search`), which integrators also call from their
   own compiled event loops; a far event costs about a microsecond per cell.
2. *Taylor polynomial per cell.* On a cell starting at ``t_k``, ``g(t_k + σh) = Σ_j a_j σ^j``
   with ``a_j = G D (Ab h)^j y_k / j!``, ``j <= K = 18``; since ``||Ab h|| = 1`` the truncation
   error is below ``e/19! ≈ 2e-17`` relative, i.e. the polynomial *is* ``g`` to rounding. The
   matrices ``G D (Ab h)^j / j!`` are cached per flow and guard matrix.
3. *Certificate.* The Bernstein coefficients of each polynomial on ``[0, 1]`` enclose its
   range. A cell whose smallest Bernstein coefficient exceeds the touch tolerance is
   certified root-free for that guard. No grid step needs tuning: the enclosure is
   rigorous, so a double root or a near-grazing pair between grid points cannot slip through.
4. *Exact analysis of the remaining cells, in time order.* When the Bernstein coefficients
   of ``g'`` have one sign, ``g`` is monotone on the cell. Otherwise the critical points of
   ``g`` (real roots of the polynomial ``g'``) are isolated by subdivision of the Bernstein
   form of ``g'`` (de Casteljau halving, left half first; no sign variation -> no root, one
   -> exactly one, refined by safeguarded Newton) and split the cell into monotone pieces.
   Walking
   them left to right: the first piece whose right end has ``g <= 0`` holds the first root,
   a unique one, refined by a safeguarded Newton iteration (bisection whenever the Newton
   step leaves the bracket); a local minimum with ``|g| <= tol`` is a tangential touch
   (``grazing=True``), reported at the minimum. Two roots closer than the grid appear as a
   negative local minimum and the first of them is returned.
5. *Machine precision.* The cell start state is recomputed from ``x0`` by the exact flow
   (the eigen-decomposition, or ``Φ^k`` by binary powering: ``log2 k`` products instead of
   ``k``) and the root re-polished by Newton on that polynomial.
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
from functools import cache, cached_property
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg

from .._validation import (
    FloatArray,
    as_finite_scalar,
    as_matrix,
    as_square,
    as_vector,
    check_positive,
)
from ..errors import DimensionError, InadmissibleStateError, ModelError
from .scaling import balance
from .statespace import state_matrix

__all__ = ["Exosystem", "augment", "LTIFlow", "discretize", "Discretization", "GuardEvent",
           "first_event", "project_restart"]

#: Largest eigenvector condition number for which the eigendecomposition path is used.
EIG_COND_LIMIT = 1e5
#: Taylor degree per cell; with ||Ab h|| = 1 the remainder is below e/(K+1)! ≈ 2e-17.
TAYLOR_DEGREE = 18
#: Bound ``e/(K+1)!`` of the Taylor remainder on one cell (``||Ab h|| = 1``), passed to the
#: compiled search by every caller.
TAYLOR_REMAINDER = math.e / math.factorial(TAYLOR_DEGREE + 1)
#: Condition of the cell path's propagation ``Φ^k y`` (binary powering: at most ``2·53``
#: rounded products for any ``k < 2^53``), in the restart tolerance.
CELL_KAPPA = 2.0 * 53


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
        ph = as_finite_scalar("phase", phase)
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

    Parameters
    ----------
    A : (n, n) array_like
        State matrix of the plant.
    B : (n, q) array_like
        Its input matrix.
    exo : Exosystem
        The signal generator ``w' = S w``, ``u = Cu w``.
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
    A : (n, n) array_like or StateSpace
        System matrix (finite), or a state-space model (python-control's ``StateSpace``)
        whose ``A`` is used.

    Attributes
    ----------
    A : ndarray
        The validated matrix.
    method : {"eig", "expm"}
        ``"eig"`` when ``A`` is diagonalisable with ``cond(V) <= EIG_COND_LIMIT``,
        ``"expm"`` (scipy's Padé, batched) otherwise.
    """

    def __init__(self, A: Any) -> None:
        self.A = as_square("A", state_matrix("A", A))
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

    @classmethod
    def shared(cls, A: Any) -> LTIFlow:
        """The flow of ``A``, reused across calls with an equal matrix.

        Integrators build the flow of every mode they visit; a sweep or a benchmark that
        simulates the same model again would redo the decomposition, the balancing and the
        event-search tables each time. Flows are immutable, so one instance can serve all
        (the most recent ``_SHARED_FLOWS_MAX`` matrices are kept).
        """
        A = as_square("A", state_matrix("A", A))
        key = (A.shape, A.tobytes())
        flow = _SHARED_FLOWS.pop(key, None)
        if flow is None:
            flow = cls(A)
            if len(_SHARED_FLOWS) >= _SHARED_FLOWS_MAX:
                _SHARED_FLOWS.pop(next(iter(_SHARED_FLOWS)))
        _SHARED_FLOWS[key] = flow  # most recently used last
        return flow

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
            self._guard = _GuardContext(self)
        return self._guard


_SHARED_FLOWS: dict[Any, LTIFlow] = {}
_SHARED_FLOWS_MAX = 64


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
    """Zero-order-hold discretisation ``x_{k+1} = Ad x_k + Bd u_k``.

    Parameters
    ----------
    Ad : (n, n) ndarray
        ``e^{Ah}``.
    Bd : (n, q) ndarray
        ``∫_0^h e^{As} ds B``.
    """

    Ad: FloatArray
    Bd: FloatArray


def discretize(A: Any, B: Any, h: float) -> Discretization:
    """Exact zero-order-hold discretisation of ``x' = A x + B u`` with step ``h``.

    Computed from one exponential of the augmented matrix:
    ``expm([[A, B], [0, 0]] h) = [[Ad, Bd], [0, I]]``, so ``Bd = ∫_0^h e^{As} ds B`` holds
    also for singular ``A``.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix.
    B : (n, q) array_like
        Input matrix.
    h : float
        Sampling period (> 0).

    Returns
    -------
    Discretization
        Named pair ``(Ad, Bd)``.
    """
    A = as_square("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, rows=n)
    h = check_positive("h", h)
    key = (A.shape, B.shape, A.tobytes(), B.tobytes(), h)
    pair = _DISCRETIZATIONS.get(key)
    if pair is None:
        m = B.shape[1]
        M = np.zeros((n + m, n + m))
        M[:n, :n], M[:n, n:] = A, B
        E = scipy.linalg.expm(M * h)
        pair = (E[:n, :n].copy(), E[:n, n:].copy())
        if len(_DISCRETIZATIONS) >= _DISCRETIZATIONS_KEPT:
            try:                         # the oldest entry (another thread may be at it)
                _DISCRETIZATIONS.pop(next(iter(_DISCRETIZATIONS)), None)
            except (StopIteration, RuntimeError):   # pragma: no cover - a race
                pass
        _DISCRETIZATIONS[key] = pair
    return Discretization(pair[0].copy(), pair[1].copy())


#: The last discretisations, by the bytes of ``A``, ``B`` and ``h``: a model simulated or
#: designed again (a sweep, a controller's every run) reuses its exponential, which costs
#: milliseconds against microseconds for the key.
_DISCRETIZATIONS: dict[tuple[Any, ...], tuple[FloatArray, FloatArray]] = {}
_DISCRETIZATIONS_KEPT = 64


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


@cache
def _bernstein_matrices(K: int) -> FloatArray:
    """``B[d]`` for ``d = 0..K``: ``b = B[d][:d+1, :d+1] a`` are the Bernstein coefficients
    on [0, 1] of ``Σ_{j<=d} a_j σ^j`` (degree ``d``); constants, computed once (read-only)."""
    B = np.zeros((K + 1, K + 1, K + 1))
    for d in range(K + 1):
        for k in range(d + 1):
            for j in range(k + 1):
                B[d, k, j] = math.comb(k, j) / math.comb(d, j)
    B.setflags(write=False)
    return B


class _GuardContext:
    """Per-flow data of the compiled event search (balancing, cell width, ``Φ``, the Taylor
    matrices, Bernstein matrices and the flow's propagation data), with the guard matrices
    cached (an integrator searches with the same ``G`` at every event)."""

    def __init__(self, flow: LTIFlow) -> None:
        from ._lti_kernels import KIND_CELLS, KIND_EIG, taylor_tables

        A = flow.A
        n = A.shape[0]
        d, omega = balance([A])
        Ab = A / d[:, None] * d[None, :]
        self.d = np.ascontiguousarray(d, dtype=float)
        self.h = 1.0 / omega
        self.Ab = Ab
        K = TAYLOR_DEGREE
        self.bern = _bernstein_matrices(K)
        # (Ab h)^j / j!, j = 0..K, and Φ = e^{Ab h} as their sum (||Ab h|| = 1: the Taylor
        # remainder is below TAYLOR_REMAINDER, i.e. rounding)
        self.taylor = np.empty((K + 1, n, n))
        self.phi = np.empty((n, n))
        if n:
            taylor_tables(np.ascontiguousarray(Ab * self.h), self.taylor, self.phi)
        # the propagation's condition, for the round-off tolerance of a restart
        # (_lti_kernels.restart_tolerance): cond(V) of the eigen-decomposition, or the at
        # most 2·53 rounded products of binary powering on the cell path
        self.kappa = float(np.linalg.cond(flow._V)) if flow.method == "eig" else CELL_KAPPA
        if flow.method == "eig":
            self.kind = KIND_EIG
            self.lam = np.ascontiguousarray(flow._lam, dtype=complex)
            self.V = np.ascontiguousarray(flow._V, dtype=complex)
            self.Vinv = np.ascontiguousarray(flow._Vinv, dtype=complex)
        else:
            self.kind = KIND_CELLS
            self.lam = np.zeros(1, dtype=complex)
            self.V = self.Vinv = np.zeros((1, 1), dtype=complex)
        self._guards: dict[Any, tuple[FloatArray, FloatArray]] = {}

    def guard_data(self, G: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``(W, row norms of G D)`` with ``W[j] = G D (Ab h)^j / j!``: the guard Taylor
        coefficients on a cell are ``W @ (cell start state)``."""
        key = (G.shape, G.tobytes())
        data = self._guards.get(key)
        if data is None:
            GD = G * self.d
            W = np.ascontiguousarray(np.einsum("pn,knl->kpl", GD, self.taylor))
            data = (W, np.linalg.norm(GD, axis=1))
            if len(self._guards) >= 16:
                self._guards.pop(next(iter(self._guards)))
            self._guards[key] = data
        return data

    def flow_args(self) -> tuple[Any, ...]:
        """Propagation data in the order of :func:`._lti_kernels.propagate`."""
        return (self.kind, self.lam, self.V, self.Vinv, self.phi, self.taylor, self.d, self.h)


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
    return _search(ctx, x0, G, g0, t_max, graze_tol, simultaneous_tol)


def project_restart(flow: LTIFlow, x: FloatArray, G: FloatArray, g0: FloatArray, t: float,
                    proj: FloatArray, *, n_free: int | None = None) -> FloatArray:
    """A state the integrator computed itself, with its guards negative at round-off level
    projected onto ``{G x + g0 >= 0}`` (the compiled loops call the same kernel,
    :func:`nscontrol.numerics._lti_kernels.project_restart`; see its tolerance there).

    Parameters
    ----------
    flow : LTIFlow
        The flow the next search runs on (its balancing and condition set the tolerance).
    x : (n,) ndarray
        The restart state (not changed).
    G, g0 : ndarray
        The guards ``G x + g0 >= 0`` of the next search.
    t : float
        The restart's time label (its rounding enters the tolerance).
    proj : (5,) ndarray
        The run's projection record, updated: count, largest ``|g|`` projected, largest
        ``|g|/tol``, and the value and tolerance of a violation beyond it.
    n_free : int, optional
        Only the first ``n_free`` entries may move (default all): the others are the
        constant or input generator of an augmented state.

    Returns
    -------
    ndarray
        The projected state (``x`` itself when nothing was projected).

    Raises
    ------
    InadmissibleStateError
        A guard negative beyond the round-off tolerance: not the integrator's rounding.
    """
    from ._lti_kernels import project_restart as kernel

    ctx = flow.guard_context()
    W, _ = ctx.guard_data(G)
    y = x / ctx.d
    done = proj[0]
    i = kernel(W, np.asarray(g0, dtype=float), ctx.kappa, ctx.h, float(t),
               flow.n if n_free is None else n_free, y, np.empty(W.shape[0]), proj)
    if i >= 0:
        raise InadmissibleStateError(
            f"guard {i} is negative at t = {t:.12g} (g = {proj[3]:.3g}), beyond the "
            f"integrator's round-off tolerance {proj[4]:.3g} at a state it computed: the "
            f"state left the admissible set; check the model's modes and guards")
    return y * ctx.d if proj[0] > done else x


def _search(ctx: _GuardContext, x0: FloatArray, G: FloatArray, g0: FloatArray, t_max: float,
            graze_tol: float, simultaneous_tol: float) -> GuardEvent | None:
    """Run the compiled search on validated arguments."""
    from ._lti_kernels import EVENT, NEGATIVE, search

    W, row_norm = ctx.guard_data(G)
    p = G.shape[0]
    hit, graze = np.zeros(p, dtype=np.int8), np.zeros(p, dtype=np.int8)
    code, t, index = search(W, g0, row_norm, graze_tol, simultaneous_tol, TAYLOR_REMAINDER, ctx.phi,
                            ctx.bern, x0 / ctx.d, ctx.h, t_max, ctx.kind, ctx.lam,
                            ctx.V, ctx.Vinv, ctx.taylor, ctx.d, hit, graze)
    if code == NEGATIVE:
        value = float(G[index] @ x0 + g0[index])
        raise InadmissibleStateError(
            f"x0: guard {index} is negative at t = 0 (g = {value:.3g} < 0); the search "
            "needs every guard >= 0 at its start — check the state or the guard signs")
    if code != EVENT:
        return None
    indices = tuple(int(i) for i in np.flatnonzero(hit))
    return GuardEvent(float(t), indices, bool(graze[list(indices)].all()))


def _clean(a: Any, shape: tuple[int | None, ...]) -> bool:
    """Fast path: already a finite float64 array of this shape (else the checks of
    ``nscontrol._validation`` run and raise their specific errors)."""
    return (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == len(shape)
            and all(s is None or s == d for s, d in zip(shape, a.shape, strict=True))
            and bool(np.isfinite(a).all()))
