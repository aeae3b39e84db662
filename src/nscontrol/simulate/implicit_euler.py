"""Implicit Euler / θ-method time-stepping for Lur'e systems (``method="implicit_euler"``).

Integrates :class:`~nscontrol.systems.lure.LureSystem` (``x' = Ax + Gw + Bu``,
``z = Hx + Dw + g``, ``w ∈ -φ(z)``). The smooth part is a θ-method, the multiplier is always
implicit, so every step is the one-step inclusion

::

    x_{k+1} = Φ x_k + Γ ū_k + G_h w,        ū_k = (1-θ) u(t_k) + θ u(t_{k+1})
    z_{k+1} = a_k + D_h w,   w ∈ -φ(z_{k+1}),   a_k = H(Φ x_k + Γ ū_k) + g(t_{k+1})

with ``W = I - hθA``, ``Φ = W⁻¹(I + h(1-θ)A)``, ``Γ = hW⁻¹B``, ``G_h = hW⁻¹G``,
``D_h = H G_h + D``. It is solved exactly at every step:

* componentwise laws (relay, Coulomb, normal cones of intervals, complementarity, the
  monotone set-valued Stribeck law -- its slip branch by safeguarded Newton -- and their
  products) with a diagonal ``D_h``, or one that a permutation makes lower triangular (a plant
  and its observer): closed-form resolvents ``z_i = (1 + d_ii φ_i)⁻¹(a_i + Σ_j d_ij w_j)``
  component after component, in a compiled loop;
* laws with a complementarity form (``law.complementarity_form()``: relay, friction, normal
  cones, products) and a full ``D_h``: one LCP per step (or per diagonal block, see below) by
  the shared Lemke kernel of :mod:`nscontrol.numerics._lcp_kernels`, in the same compiled loop,
  each solution verified by its natural residual;
* any other monotone law (curved graphs): its own resolvent when the (block of) ``D_h`` is
  diagonal, else forward–backward splitting on ``0 ∈ D_h⁻¹(z - a) + φ(z)``, in Python, each
  solution verified by the law's graph residual.

Multipliers that read one argument (the super-twisting controller ``u = -k1|s|^{1/2}sign(s) +
ν``, ``ν' = -k2 Sign(s)``: two laws of the same ``s``, entering different states): ``D_h`` then
has identical rows ``1 dᵀ`` and is singular, but the step is the scalar inclusion
``s + Σ_j d_j φ_j(s) ∋ a``. When every part of the ``Product`` law is a scalar
:class:`~nscontrol.laws.super_twisting.SuperTwistingLaw` or :class:`~nscontrol.laws.relay.Relay`,
``d > 0`` and ``D = 0``, it is solved in closed form (the quadratic in ``|s|^{1/2}`` of
:func:`~nscontrol.laws.super_twisting.super_twisting_resolvent`), in Python.

Block structure: when the law is a ``Product`` whose parts are coupled one way only through
``D_h`` (a plant and its observer: the observer sees the plant, not the reverse), ``D_h`` is
block triangular up to a permutation of the parts. Each diagonal block is then solved after the
blocks it depends on, and only the diagonal blocks need a positive definite symmetric part (the
whole ``D_h`` need not). Couplings below ``1e-14 max|D_h|`` count as structural zeros.

Inputs: an :class:`~nscontrol.numerics.lti.Exosystem` input enters through its exact mean over
each step, ``ū_k = (1/h) ∫ u`` (so ``x' = -sign(x) + d(t)`` is integrated exactly before
reaching, and the reaching time is found within one step); any other input through the
θ-combination ``ū_k = (1-θ) u(t_k) + θ u(t_{k+1})`` of its samples (first-order accurate).

Because the multiplier is implicit, a sliding motion is reached in finitely many steps and then
held with ``z`` exactly zero (no chattering).

Options
-------
h : float
    Step (the span is cut into ``N = ceil((tf - t0)/h)`` equal steps).
theta : float in [1/2, 1]
    θ of the smooth part (1: backward Euler, 1/2: trapezoidal).
record_every : int
    Keep every k-th step (the final state is always kept).
signals : iterable of str, optional
    Subset of ``("z", "w", "y")`` to record (other names raise ``ModelError``).
progress : bool, optional
    Progress bar on stderr (default: shown after 2 s).
u : Exosystem or callable or array_like, optional
    External input overriding the system's ``u`` (what a periodically forced analysis passes).
controller : callable ``(t, x) -> u``, optional
    Feedback evaluated at the start of every step and held over it (zero-order hold); it
    replaces ``u``. What :func:`nscontrol.closed_loop` passes for controllers and observers
    written as Python code around a Lur'e plant (a digital controller with a friction
    compensation, chapter 7). The steps then run one at a time in Python.
compiled_blocks : object, optional
    Passed by :func:`nscontrol.closed_loop` with ``controller=`` when every block of the
    loop has a compiled form (:class:`~nscontrol.systems.feedback.CompiledBlock`): with the
    closed-form solver the blocks and the steps then run in one compiled loop
    (``stats["controller"] = "compiled"``); otherwise ``controller=`` runs
    (``"python"``).
sensitivity : bool
    Also compute ``stats["state_transition"]``, the exact Jacobian ``∂x_N/∂x_0`` of the
    *discrete* map (the product of the steps' Jacobians ``Φ + G_h (∂w/∂a) HΦ``, each from
    the implicit function theorem on the step's inclusion at its solution, see
    :mod:`nscontrol.simulate._lure_sensitivity`), with ``stats["degenerate_steps"]`` (steps
    whose solution sits at a corner of the law's graph, where the map is not differentiable;
    the first one's time in ``stats["first_degenerate_time"]``, and a warning).

A failed step raises :class:`~nscontrol.errors.SolverError` with the partial trajectory
(``simulate(..., on_failure="return")`` returns it with ``status = -1``). A step fails when
its one-step problem has no verified solution: Lemke's status, or a natural residual above
``1e-10`` (LCP), or a graph residual above ``1e-9 (1 + |a| + |w|)`` (Python path).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._progress import TimeProgress
from .._validation import (
    FloatArray,
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
)
from ..errors import InadmissibleStateError, ModelError, SolverError
from .trajectory import (
    ChunkProgress,
    Recorder,
    Trajectory,
    _signal_names,
    evaluable_prefix,
)

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ..systems.lure import LureSystem

__all__ = ["integrate", "ImplicitEulerOptions", "StepMatrices", "step_matrices",
           "componentwise_spec", "lcp_step_data"]

_CHUNK = 1 << 16
_SIGNALS = ("z", "w", "y")
#: Couplings of ``D_h`` below this fraction of ``max|D_h|`` are structural zeros.
_STRUCTURAL_ZERO = 1e-14
#: Acceptance of a per-step LCP solution (natural residual, relative to ``1 + max|q|``).
LCP_TOL = 1e-10
#: Acceptance of a per-step inclusion solution on the Python path (graph residual, relative
#: to ``1 + |a| + |w|``).
GRAPH_TOL = 1e-9


class StepMatrices:
    """The constant matrices of one θ-method step.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system.
    h : float
        Step.
    theta : float
        θ of the smooth part, in ``[1/2, 1]``.

    Attributes
    ----------
    Phi, Gam, Gh : ndarray
        ``Φ = W⁻¹(I + h(1-θ)A)``, ``Γ = hW⁻¹B``, ``G_h = hW⁻¹G`` with ``W = I - hθA``.
    HPhi, HGam : ndarray
        ``HΦ`` and ``HΓ``.
    Dh : ndarray
        The one-step matrix ``D_h = H G_h + D``.

    Notes
    -----
    Entries of ``Φ``, ``Γ``, ``G_h`` below ``1e-14`` times the largest are set to exact zeros:
    the round-off of the solve must not couple blocks that are uncoupled (a plant does not see
    its observer).

    Raises
    ------
    ModelError
        ``I - hθA`` is singular (condition number above ``1e14``).
    """

    def __init__(self, system: Any, h: float, theta: float) -> None:
        A, G, H = system.A, system.G, system.H
        n = A.shape[0]
        W = np.eye(n) - h * theta * A
        cond = np.linalg.cond(W)
        if not np.isfinite(cond) or cond > 1e14:
            raise ModelError(f"h: I - h·θ·A is singular for h = {h:g}, θ = {theta:g} "
                             f"(condition number {cond:.3g}); change the step h")
        B = system.B if system.B is not None else np.zeros((n, 0))
        self.Phi = _structural(np.linalg.solve(W, np.eye(n) + h * (1.0 - theta) * A), False)
        self.Gam = _structural(np.linalg.solve(W, h * B), False)
        self.Gh = _structural(np.linalg.solve(W, h * G), False)
        self.HPhi = H @ self.Phi
        self.HGam = H @ self.Gam
        self.Dh = H @ self.Gh + system.D
        self.h, self.theta = h, theta


def step_matrices(system: Any, h: float, theta: float = 1.0) -> StepMatrices:
    """The step matrices of the θ-method for ``system`` and step ``h``.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system.
    h : float
        Step, ``> 0``.
    theta : float, optional
        θ in ``[1/2, 1]`` (default 1, backward Euler).

    Returns
    -------
    StepMatrices
        ``Φ, Γ, G_h, HΦ, HΓ, D_h`` (see the module docstring).

    Examples
    --------
    >>> from nscontrol.laws.relay import Relay
    >>> from nscontrol.systems.lure import LureSystem
    >>> m = step_matrices(LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0)), 0.1)
    >>> float(m.Phi[0, 0]), float(m.Dh[0, 0])
    (1.0, 0.1)
    """
    h = check_positive("h", h)
    theta = check_in_interval("theta", theta, 0.5, 1.0)
    return StepMatrices(system, h, theta)


def componentwise_spec(law: Any) -> tuple[np.ndarray, FloatArray, FloatArray] | None:
    """The compiled description of a law that acts componentwise with a known resolvent.

    Parameters
    ----------
    law : SetValuedLaw
        A relay, Coulomb, interval/box normal cone, complementarity law or a product of them.

    Returns
    -------
    (kind, p1, p2) or None
        Per component: ``kind[i] = 0`` for ``c Sign`` with ``c = p1[i]`` (relay, Coulomb),
        ``kind[i] = 1`` for the normal cone of ``[p1[i], p2[i]]`` (complementarity:
        ``[0, inf)``), ``kind[i] = 2`` for a monotone set-valued Stribeck law (its parameters
        in :func:`curve_parameters`). ``None`` for any other law.

    Examples
    --------
    >>> from nscontrol.laws.normal_cone import Complementarity
    >>> from nscontrol.laws.product import Product
    >>> from nscontrol.laws.relay import Relay
    >>> kind, p1, p2 = componentwise_spec(Product(Relay(2.0), Complementarity(1)))
    >>> kind.tolist(), p1.tolist(), p2.tolist()
    ([0, 1], [2.0, 0.0], [0.0, inf])
    """
    from ..laws.friction import Stribeck
    from ..laws.normal_cone import NormalConeBox
    from ..laws.product import Product
    from ..laws.relay import Relay

    if isinstance(law, Product):
        specs = [componentwise_spec(p) for p in law.parts]
        parts = [p for p in specs if p is not None]
        if len(parts) < len(specs):
            return None
        kinds, p1, p2 = (np.concatenate([p[i] for p in parts]) for i in range(3))
        return kinds, p1, p2
    m = int(law.dim)
    if isinstance(law, Relay):  # Coulomb is a Relay of bound mu·N
        return np.zeros(m, np.int64), _per_component(law.bound, m), np.zeros(m)
    if isinstance(law, NormalConeBox):
        return (np.ones(m, np.int64), _per_component(law.lower, m),
                _per_component(law.upper, m))
    if isinstance(law, Stribeck) and law.monotone:   # parameters in curve_parameters(law)
        return np.full(m, 2, np.int64), np.zeros(m), np.zeros(m)
    return None


def curve_parameters(law: Any) -> FloatArray:
    """Per component ``(T_s, T_c, omega_s, delta, b)`` of the monotone Stribeck components of
    ``law`` (``componentwise_spec`` kind 2), zeros for the other components; shape ``(m, 5)``.
    """
    from ..laws.friction import Stribeck
    from ..laws.product import Product

    parts = law.parts if isinstance(law, Product) else [law]
    rows = []
    for part in parts:
        if isinstance(part, Stribeck):
            rows.append(np.column_stack([part.static, part.coulomb, part.stribeck_velocity,
                                         part.delta, part.viscous]))
        else:
            rows.append(np.zeros((int(part.dim), 5)))
    return np.ascontiguousarray(np.vstack(rows), dtype=np.float64)


def _per_component(value: Any, m: int) -> FloatArray:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, float), (m,)), dtype=float)


def lcp_step_data(law: Any, Dh: FloatArray) -> tuple[FloatArray, ...] | None:
    """The per-step LCP of the inclusion ``w ∈ -φ(a + D_h w)``, from the law's complementarity
    form.

    Parameters
    ----------
    law : SetValuedLaw
        The law ``φ``.
    Dh : (m, m) ndarray
        The one-step matrix.

    Returns
    -------
    (M, Qa, q0, T, s) or None
        The LCP ``0 <= ξ ⟂ Mξ + Qa·a + q0 >= 0`` and the multiplier ``w = Tξ + s``; ``None``
        when the law has no complementarity form (curved graphs).

    Notes
    -----
    With the form ``w = w0 + Eξ``, ``η = Nz z + Nξ ξ + r``: ``M = Nz D_h E + Nξ``, ``Qa = Nz``,
    ``q0 = Nz D_h w0 + r``, ``T = E``, ``s = w0``; ``M`` is monotone when ``D_h`` is.

    Examples
    --------
    >>> from nscontrol.laws.normal_cone import Complementarity
    >>> M, Qa, q0, T, s = lcp_step_data(Complementarity(1), np.array([[2.0]]))
    >>> M.tolist(), Qa.tolist(), T.tolist()
    ([[2.0]], [[1.0]], [[1.0]])
    """
    try:
        form = law.complementarity_form()
    except ModelError:
        return None
    M = form.Nz @ Dh @ form.E + form.Nxi
    q0 = form.Nz @ Dh @ form.w0 + form.r
    return (np.ascontiguousarray(M), np.ascontiguousarray(form.Nz), q0,
            np.ascontiguousarray(form.E), np.asarray(form.w0, float).copy())


# -- structure of the one-step matrix -----------------------------------------------------
def _structural(M: FloatArray, keep_diagonal: bool = True) -> FloatArray:
    """``M`` with entries below ``1e-14 max|M|`` set to exact zeros (diagonal kept)."""
    D = np.array(M, dtype=float)
    tol = _STRUCTURAL_ZERO * float(np.max(np.abs(D), initial=0.0))
    off = np.abs(D) <= tol
    if keep_diagonal and D.ndim == 2 and D.shape[0] == D.shape[1]:
        np.fill_diagonal(off, False)
    D[off] = 0.0
    return D


def _acyclic_order(D: FloatArray) -> np.ndarray | None:
    """An order of the components in which each depends only on earlier ones (``D[i, j] != 0``
    for ``j`` before ``i``): ``D`` is lower triangular after this permutation. ``None`` if the
    coupling graph has a cycle (Kahn's algorithm)."""
    m = D.shape[0]
    dep = D != 0.0
    np.fill_diagonal(dep, False)
    remaining = dep.sum(axis=1)
    order = [int(i) for i in np.flatnonzero(remaining == 0)]
    done = np.zeros(m, bool)
    done[order] = True
    head = 0
    while head < len(order):
        j = order[head]
        head += 1
        for i in np.flatnonzero(dep[:, j]):
            remaining[i] -= 1
            if remaining[i] == 0 and not done[i]:
                done[i] = True
                order.append(int(i))
    return np.array(order, np.int64) if len(order) == m else None


@dataclass(frozen=True, eq=False)
class _Block:
    """One diagonal block of ``D_h``: the law components ``idx`` of the parts ``parts``."""

    idx: np.ndarray
    parts: tuple[int, ...]
    law: Any
    D: FloatArray


def _law_parts(law: Any) -> list[tuple[slice, Any]]:
    from ..laws.product import Product

    if isinstance(law, Product):
        return list(zip(law._slices, law.parts, strict=True))
    return [(slice(0, int(law.dim)), law)]


def _blocks(law: Any, D: FloatArray) -> list[_Block]:
    """The strongly connected groups of the law's parts under the coupling of ``D``, in an
    order where each group depends only on earlier ones (block lower triangular)."""
    from ..laws.product import Product

    parts = _law_parts(law)
    k = len(parts)
    reach = np.zeros((k, k), bool)
    for a, (sa, _) in enumerate(parts):
        for b, (sb, _) in enumerate(parts):
            reach[a, b] = a == b or bool(np.any(D[sa, sb] != 0.0))
    for c in range(k):  # transitive closure (Warshall)
        reach |= reach[:, c:c + 1] & reach[c:c + 1, :]
    groups: list[list[int]] = []
    seen: set[int] = set()
    for a in range(k):
        if a not in seen:
            g = [b for b in range(k) if reach[a, b] and reach[b, a]]
            seen.update(g)
            groups.append(g)
    # a group depending on another reaches strictly more parts: sort by that count
    groups.sort(key=lambda g: int(reach[g[0]].sum()))
    out = []
    for g in groups:
        idx = np.concatenate([np.arange(parts[a][0].start, parts[a][0].stop) for a in g])
        sub = parts[g[0]][1] if len(g) == 1 else Product(*(parts[a][1] for a in g))
        out.append(_Block(idx.astype(np.int64), tuple(g), sub, D[np.ix_(idx, idx)].copy()))
    return out


def _single_state_rows(system: Any) -> np.ndarray:
    """``ucol[i] = j`` when ``z_i = H[i, j] x_j + g_i`` (one state, no feedthrough), else -1:
    the closed form then imposes an active constraint exactly on ``x_j``."""
    H, D = system.H, system.D
    ucol = np.full(H.shape[0], -1, np.int64)
    for i in range(H.shape[0]):
        nz = np.flatnonzero(H[i])
        if nz.size == 1 and not np.any(D[i]):
            ucol[i] = nz[0]
    return ucol


def _min_sym_eig(M: FloatArray) -> float:
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[0]) if M.size else 1.0


@dataclass(frozen=True, eq=False)
class _Plan:
    """How every step's inclusion is solved (chosen once per run)."""

    solver: str                # "closed_form", "lcp" or "python"
    structure: str             # "diagonal", "triangular", "block_triangular" or "full"
    D: FloatArray              # D_h with structural zeros
    order: np.ndarray | None   # closed form: component order
    blocks: tuple[_Block, ...]
    lcp: tuple[Any, ...] | None = None   # padded per-block LCP data for the compiled loop


def _plan(system: Any, Dh: FloatArray, h: float) -> _Plan:
    """Choose the solver and check that the one-step inclusion is uniquely solvable."""
    D = _structural(Dh)
    spec = componentwise_spec(system.law)
    if spec is not None:
        order = _acyclic_order(D)
        if order is not None:
            d = np.diag(D)
            bad = np.flatnonzero(d <= 0.0)
            if bad.size:
                i = int(bad[0])
                raise ModelError(
                    f"h: the one-step matrix D_h = h·H(I - hθA)⁻¹G + D is not positive "
                    f"definite on law component {i} for h = {h:g}: D_h[{i}, {i}] = {d[i]:.3g} "
                    f"(D_h is triangular up to a permutation, so its diagonal entries must be "
                    f"positive); the one-step inclusion may have no or several solutions. "
                    f"Check the sign of (H·G)[{i}, {i}] (it must be positive, relative degree "
                    f"one) or add a positive feedthrough D")
            off = D - np.diag(d)
            structure = "diagonal" if not np.any(off) else "triangular"
            return _Plan("closed_form", structure, D, order, ())
    blocks = _blocks(system.law, D)
    if len(blocks) == 1:
        lam = _min_sym_eig(D)
        if lam <= 0.0 and _shared_argument_weights(system.law, D) is not None \
                and not np.any(system.D):
            return _Plan("python", "shared_argument", D, None, tuple(blocks))
        if lam <= 0.0:
            raise ModelError(
                f"h: the one-step matrix D_h = h·H(I - hθA)⁻¹G + D is not positive definite for "
                f"h = {h:g} (smallest eigenvalue of its symmetric part {lam:.3g}), and it has no "
                f"block-triangular structure (one-way coupled parts of a Product law, as a "
                f"plant and its observer) that would let smaller blocks be solved one after "
                f"the other; the one-step inclusion may have no or several solutions. Check "
                f"the sign of H·G (it must be positive, relative degree one) or add a positive "
                f"feedthrough D")
        structure = "full"
    else:
        for b, blk in enumerate(blocks):
            lam = _min_sym_eig(blk.D)
            if lam <= 0.0:
                raise ModelError(
                    f"h: diagonal block {b} of the one-step matrix D_h = h·H(I - hθA)⁻¹G + D "
                    f"(law components {blk.idx.tolist()}, part(s) {list(blk.parts)} of the "
                    f"Product law) is not positive definite for h = {h:g}: smallest "
                    f"eigenvalue of its symmetric part {lam:.3g}. D_h is block triangular "
                    f"(solved block by block), so each diagonal block must be positive "
                    f"definite; check the sign of H·G on these components (relative degree "
                    f"one), add a positive feedthrough D there, or change h")
        structure = "block_triangular"
    data = [lcp_step_data(b.law, b.D) for b in blocks]
    if all(d is not None for d in data):
        return _Plan("lcp", structure, D, None, tuple(blocks), _pad_lcp(blocks, data))
    return _Plan("python", structure, D, None, tuple(blocks))


def _pad_lcp(blocks: list[_Block], data: list[Any]) -> tuple[Any, ...]:
    """Per-block LCP data stacked in zero-padded arrays for the compiled loop."""
    nb = len(blocks)
    P = max(1, max(d[0].shape[0] for d in data))
    Pm = max(1, max(b.idx.size for b in blocks))
    M3, Qa3, q03 = np.zeros((nb, P, P)), np.zeros((nb, P, Pm)), np.zeros((nb, P))
    T3, s3 = np.zeros((nb, Pm, P)), np.zeros((nb, Pm))
    comp = np.zeros((nb, Pm), np.int64)
    nv, mg = np.zeros(nb, np.int64), np.zeros(nb, np.int64)
    for g, (blk, (M, Qa, q0, T, s)) in enumerate(zip(blocks, data, strict=True)):
        v, k = M.shape[0], blk.idx.size
        nv[g], mg[g] = v, k
        comp[g, :k] = blk.idx
        M3[g, :v, :v], Qa3[g, :v, :k], q03[g, :v] = M, Qa, q0
        T3[g, :k, :v], s3[g, :k] = T, s
    return M3, Qa3, q03, T3, s3, comp, nv, mg


# -- the initial multiplier and the Python one-step solve ----------------------------------
def _initial_multiplier(system: Any, x0: FloatArray, t0: float) -> tuple[FloatArray, FloatArray]:
    """``(z0, w0)`` at the initial time (the minimal-norm selection when ``D = 0``).

    Raises
    ------
    InadmissibleStateError
        ``D = 0`` and ``H x0 + g(t0)`` lies outside the domain of the law.
    """
    a = system.H @ x0
    if system.has_shift:
        a += system.shift_at(t0)[0]
    m = a.shape[0]
    if not system.D.any():
        bad = [f"z[{sl.start}:{sl.stop}] = {np.array2string(a[sl], precision=6)} outside the "
               f"domain of {part!r}" for sl, part in _law_parts(system.law)
               if not part.in_domain(a[sl], 1e-12 * (1.0 + float(np.abs(a[sl]).max())))]
        if bad:
            raise InadmissibleStateError(
                f"x0: the initial state violates the law's constraint: z0 = H x0 + g(t0) must "
                f"lie in dom φ (with D = 0 the multiplier cannot enforce it), got "
                f"{'; '.join(bad)} for x0 = {np.array2string(x0, precision=6)}. Start from an "
                f"admissible state (e.g. z0 >= 0 for complementarity)")
        try:
            return a, -np.asarray(system.law.select(a), float).reshape(m)
        except InadmissibleStateError as exc:  # a boundary point within the tolerance
            raise InadmissibleStateError(f"x0: z0 = H x0 + g(t0) = {a} is outside dom φ: "
                                         f"{exc}") from None
    z, w, _ = _solve_inclusion_python(system.law, a, system.D)
    return z, w


def _solve_inclusion_python(law: Any, a: FloatArray, Dh: FloatArray
                            ) -> tuple[FloatArray, FloatArray, float]:
    """Solve ``w ∈ -φ(a + D_h w)`` for a general monotone law (outside the compiled loops):
    the shared :func:`nscontrol.laws.inclusion.solve_inclusion` (closed form or LCP), and for
    curved laws with a full ``D_h`` forward–backward splitting. Returns ``(z, w, residual)``
    with the law's graph residual of ``(z, -w)``.

    Raises
    ------
    SolverError
        No convergence, or a graph residual above ``GRAPH_TOL (1 + |a| + |w|)``.
    """
    from ..laws.inclusion import solve_inclusion

    if _shared_argument_weights(law, Dh) is not None:
        z, w = _shared_argument_step(law, a, Dh)
        return z, w, law.graph_residual(z, -w)
    if _is_diagonal(Dh) or lcp_step_data(law, Dh) is not None:
        sol = solve_inclusion(law, Dh, a)
        z, w, res = sol.z, sol.w, float(sol.residual)
    else:
        z, w = _forward_backward(law, a, Dh)
        res = law.graph_residual(z, -w)
    scale = 1.0 + float(np.max(np.abs(a), initial=0.0)) + float(np.max(np.abs(w), initial=0.0))
    if not res <= GRAPH_TOL * scale:
        raise SolverError(f"implicit_euler: the one-step inclusion was not solved to tolerance "
                          f"(graph residual {res:.3g} > {GRAPH_TOL:g}·{scale:.3g}); the step "
                          f"matrix is badly conditioned (reduce h)", status="residual")
    return z, w, res


def _shared_argument_weights(law: Any, Dh: FloatArray) -> FloatArray | None:
    """``d`` when ``D_h = 1 dᵀ`` (identical rows, ``d > 0``, at least two components) and
    every part of ``law`` is a scalar super-twisting law or relay; else ``None``."""
    from ..laws.relay import Relay
    from ..laws.super_twisting import SuperTwistingLaw

    if Dh.ndim != 2 or Dh.shape[0] < 2:
        return None
    d = Dh[0]
    if np.any(d <= 0.0) or np.max(np.abs(Dh - d[None, :])) > 1e-14 * float(np.max(d)):
        return None
    if not all(isinstance(p, (Relay, SuperTwistingLaw)) and p.dim == 1
               for _, p in _law_parts(law)):
        return None
    return d.copy()


def _shared_argument_step(law: Any, a: FloatArray, Dh: FloatArray
                          ) -> tuple[FloatArray, FloatArray]:
    """Solve ``w ∈ -φ(a + D_h w)`` with ``D_h = 1 dᵀ``: the common argument ``s`` solves
    ``s + Σ_j d_j φ_j(s) ∋ a_0`` (each ``φ_j = k1_j |·|^{1/2} sign + k2_j Sign``, a relay having
    ``k1 = 0``), in closed form; at ``s = 0`` the set-valued parts share ``a_0`` in proportion
    to their bounds."""
    from ..laws.relay import Relay
    from ..laws.super_twisting import super_twisting_resolvent

    d = Dh[0]
    k1 = np.array([0.0 if isinstance(p, Relay) else float(p.k1[0]) for _, p in _law_parts(law)])
    k2 = np.array([float(p.bound[0]) if isinstance(p, Relay) else float(p.k2[0])
                   for _, p in _law_parts(law)])
    a0 = float(a[0])
    s = float(super_twisting_resolvent(a0, float(d @ k1), float(d @ k2)))
    if s != 0.0:
        w = -(k1 * math.sqrt(abs(s)) + k2) * math.copysign(1.0, s)
    else:
        w = -k2 * (a0 / float(d @ k2))
    return np.full(a.shape[0], s), w


def _forward_backward(law: Any, a: FloatArray, Dh: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Forward–backward splitting on ``0 ∈ D_h⁻¹(z - a) + φ(z)``: the first operator is
    strongly monotone and Lipschitz when ``D_h`` is positive definite (ch08 §3.1)."""
    Dinv = np.linalg.inv(Dh)
    mu = float(np.linalg.eigvalsh(0.5 * (Dinv + Dinv.T))[0])
    gamma = mu / float(np.linalg.norm(Dinv, 2)) ** 2
    z = a.copy()
    for _ in range(100_000):
        z_new = np.asarray(law.resolvent(z - gamma * (Dinv @ (z - a)), gamma=gamma), float)
        if np.linalg.norm(z_new - z) <= 1e-13 * max(1.0, float(np.linalg.norm(z))):
            return z_new, Dinv @ (z_new - a)
        z = z_new
    raise SolverError("implicit_euler: forward-backward iteration for the one-step inclusion "
                      "did not converge in 100000 iterations; the step matrix is badly "
                      "conditioned (reduce h)", status="max_iter")


def _is_diagonal(M: FloatArray) -> bool:
    off = M - np.diag(np.diag(M))
    return bool(np.max(np.abs(off), initial=0.0) <= 1e-14 * max(1.0, np.max(np.abs(M))))


# -- the options ----------------------------------------------------------------------------
@dataclass(frozen=True)
class ImplicitEulerOptions:
    """The options of ``method="implicit_euler"``, validated once (their meaning: the module
    docstring). Build it with :meth:`parse` from the keyword options of ``simulate``."""

    h: float
    theta: float = 1.0
    u: Any = None
    record_every: int = 1
    signals: frozenset[str] | None = None
    progress: bool | None = None
    sensitivity: bool = False
    controller: Callable[[float, FloatArray], Any] | None = None
    compiled_blocks: Any = None     # used only with a controller (see the module docstring)

    @classmethod
    def parse(cls, options: Mapping[str, Any]) -> ImplicitEulerOptions:
        """The checked options: unknown names and bad values raise ``ModelError``.

        Parameters
        ----------
        options : mapping
            The method's options as given to :func:`nscontrol.simulate` (``h`` required).

        Returns
        -------
        ImplicitEulerOptions
            The validated record.
        """
        unknown = set(options) - _OPTIONS
        if unknown:
            raise ModelError(f"implicit_euler: unknown option(s) {sorted(unknown)}; "
                             f"accepted: {sorted(_OPTIONS)}")
        if "h" not in options:
            raise ModelError("h: implicit_euler needs a step, e.g. simulate(sys, x0, t_span, "
                             "method='implicit_euler', h=1e-3)")
        get = options.get
        controller = _check_controller(get("controller"), get("u"))
        sensitivity = check_bool("sensitivity", get("sensitivity", False))
        if sensitivity and controller is not None:
            raise ModelError("sensitivity: not available with a controller= (the Jacobian of "
                             "the discrete map would miss the feedback's derivative)")
        signals = get("signals")
        return cls(h=check_positive("h", options["h"]),
                   theta=check_in_interval("theta", get("theta", 1.0), 0.5, 1.0),
                   u=get("u"), record_every=check_integer("record_every",
                                                          get("record_every", 1), minimum=1),
                   signals=None if signals is None else frozenset(
                       _signal_names(signals, _SIGNALS)),
                   progress=check_bool("progress", get("progress"), allow_none=True),
                   sensitivity=sensitivity, controller=controller,
                   compiled_blocks=get("compiled_blocks") if controller is not None else None)


_OPTIONS = frozenset(ImplicitEulerOptions.__dataclass_fields__)


def _check_controller(controller: Any, u: Any) -> Any:
    """The ``controller`` option (``None`` when absent): a callable, not given with ``u``."""
    if controller is None:
        return None
    if not callable(controller):
        raise ModelError(f"controller: expected a callable (t, x) -> u, got "
                         f"{type(controller).__name__}")
    if u is not None:
        raise ModelError("controller, u: give one of them (the controller's output is the "
                         "input u)")
    return controller


# -- the integrator -----------------------------------------------------------------------
def integrate(system: LureSystem, x0: ArrayLike, t_span: tuple[float, float],
              **options: Any) -> Trajectory:
    """Integrate a :class:`~nscontrol.systems.lure.LureSystem` by the θ-method.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system (a plant with its observer is one stacked system).
    x0 : array_like, shape (n,)
        Initial state; with ``D = 0``, ``H x0 + g(t0)`` must lie in the law's domain.
    t_span : (float, float)
        Start and end times.
    **options
        ``h`` (required), ``theta`` (default 1), ``u``, ``sensitivity``, ``record_every``,
        ``signals``, ``progress``, ``controller``, ``compiled_blocks`` -- see the module
        docstring; checked once into an :class:`ImplicitEulerOptions`.

    Returns
    -------
    Trajectory
        States at the step times and signals ``z`` (law argument), ``w`` (multiplier) and
        ``y = C x``; ``stats`` has ``steps``, ``h``, ``theta``, ``solver`` (``closed_form``,
        ``lcp`` or ``python``), ``structure`` of ``D_h`` (``diagonal``, ``triangular``,
        ``block_triangular``, ``full`` or ``shared_argument``), ``blocks``, ``input``
        (``exact_mean``, ``samples`` or ``none``) and, for the LCP and Python paths,
        ``max_residual`` (the largest accepted per-step residual); with
        ``sensitivity=True`` also ``state_transition``, ``degenerate_steps`` and
        ``first_degenerate_time``.

    Raises
    ------
    ModelError
        Not a LureSystem, bad options, ``I - hθA`` singular, or ``D_h`` (or one of its
        diagonal blocks, when block triangular) not positive definite.
    InadmissibleStateError
        ``D = 0`` and ``H x0 + g(t0)`` outside the law's domain.
    SolverError
        A one-step problem failed or its solution did not pass the residual check;
        ``err.trajectory`` holds the steps before it.

    Examples
    --------
    An ideal diode clamping a capacitor voltage (complementarity, exact ``z·w = 0``):

    >>> from nscontrol import simulate
    >>> from nscontrol.testing.setvalued_problems import diode_circuit
    >>> p = diode_circuit()
    >>> tr = simulate(p.system, p.x0, p.t_span, h=1e-3)
    >>> tr.stats["solver"], bool(np.all(tr.signal("z") * tr.signal("w") == 0.0))
    ('closed_form', True)
    """
    opts = ImplicitEulerOptions.parse(options)
    _check_system(system, opts)
    t0, tf = t_span
    n_steps = max(1, math.ceil((tf - t0) / opts.h - 1e-9))
    h = (tf - t0) / n_steps
    setup = _Setup.of(system, h, opts.theta)   # before the input: it does not depend on it
    system = _with_input(system, opts.u)
    run = _Run(system, setup, opts, n_steps)
    x0 = as_vector("x0", x0, system.n_states)
    return run.steps(x0, t0)


def _check_system(system: Any, opts: ImplicitEulerOptions) -> None:
    """A Lur'e system, with an input matrix when the options feed it an input."""
    from ..systems.lure import LureSystem

    if not isinstance(system, LureSystem):
        raise ModelError(f"implicit_euler: expected a LureSystem, got {type(system).__name__}; "
                         f"for PWA/Filippov/switched systems use method='switching'")
    if opts.controller is not None and system.B is None:
        raise ModelError("controller: this LureSystem has no input matrix B, so it takes no "
                         "input; build it with B= to close a loop around it")


def _with_input(system: Any, u: Any) -> Any:
    """``system`` with its input replaced by ``u`` (``None``: unchanged)."""
    if u is None:
        return system
    if system.B is None:
        raise ModelError("u: this LureSystem has no input matrix B, so it takes no input; "
                         "build it with B= to force it")
    from dataclasses import replace

    return replace(system, u=u)


@dataclass(frozen=True, eq=False)
class _Setup:
    """What a run computes once from the model and the step, before its first step: the step
    matrices, the solver plan and the compiled closed form's law data. Shared by the runs of
    one system and step (a sweep, a period map): :meth:`of` keeps it beside the system."""

    mats: StepMatrices
    plan: _Plan
    spec: tuple[np.ndarray, FloatArray, FloatArray] | None
    curve: FloatArray | None
    ucol: np.ndarray | None

    @classmethod
    def of(cls, system: Any, h: float, theta: float) -> _Setup:
        per_system = _SETUPS.get(system)
        if per_system is None:
            per_system = _SETUPS[system] = {}
        setup = per_system.get((h, theta))
        if setup is None:
            if len(per_system) >= 8:     # a study of many steps: keep the latest few
                per_system.pop(next(iter(per_system)))
            setup = per_system[(h, theta)] = cls.build(system, h, theta)
        return setup

    @classmethod
    def build(cls, system: Any, h: float, theta: float) -> _Setup:
        mats = StepMatrices(system, h, theta)
        plan = _plan(system, mats.Dh, h)
        if plan.solver != "closed_form":
            return cls(mats, plan, None, None, None)
        spec = componentwise_spec(system.law)
        if spec is None:   # _plan chooses the closed form only for such laws
            raise ModelError("law: the closed-form step needs a componentwise law")
        return cls(mats, plan, spec, curve_parameters(system.law), _single_state_rows(system))


#: The setups of the systems in use (a LureSystem is frozen: its matrices do not change).
_SETUPS: weakref.WeakKeyDictionary[Any, dict[tuple[float, float], _Setup]] = \
    weakref.WeakKeyDictionary()


class _Run:
    """One run: the recorder, the stepper, the optional sensitivity, the chunked loop."""

    def __init__(self, system: Any, setup: _Setup, opts: ImplicitEulerOptions,
                 n_steps: int) -> None:
        self.system, self.opts, self.n_steps = system, opts, n_steps
        self.plan = setup.plan
        self.h = setup.mats.h
        self.rec = Recorder(system.n_states, every=opts.record_every, signals=opts.signals,
                            offered=_SIGNALS,
                            capacity=Recorder.capacity_for(n_steps + 2, opts.record_every))
        self.stepper = _Stepper(system, setup)
        self.controller = opts.controller
        # the LCP and Python solvers step one at a time in Python: no compiled blocks there
        self.blocks = opts.compiled_blocks if self.plan.solver == "closed_form" else None
        self.jac = None
        if opts.sensitivity:
            from ._lure_sensitivity import StepJacobians

            self.jac = StepJacobians(system, setup.mats, self.plan.D, _law_parts(system.law))

    def steps(self, x0: FloatArray, t0: float) -> Trajectory:
        """Record the initial state, run every step in chunks, freeze the record."""
        system, rec, n_steps = self.system, self.rec, self.n_steps
        z0, w0 = _initial_multiplier(system, x0, t0)
        rec.sample(t0, x0, force=True, z=z0, w=w0, y=system.C @ x0)
        x, done = x0, 0
        tf = t0 + self.h * n_steps
        with TimeProgress(t0, tf, desc="implicit_euler", enable=self.opts.progress) as bar:
            while done < n_steps:
                k1 = min(n_steps, done + _CHUNK)
                times = np.asarray(t0 + self.h * np.arange(done, k1 + 1), dtype=float)
                with rec.chunk(partial(_record_finished, rec=rec, system=system, times=times)
                               ) as self.stepper.progress:
                    X, Z, W = self.chunk(x, times, done)
                _record_block(rec, system, times[1:], X, Z, W, last=k1 == n_steps)
                if self.jac is not None:
                    self.jac.extend(times[1:], Z, W, self.stepper.worst)
                x, done = X[-1], k1
                bar.update(times[-1])
        if self.jac is not None and self.jac.degenerate_steps:
            _warn_degenerate(self.jac)
        return rec.finish(status=0, message=None, method="implicit_euler",
                          stats=self.stats(n_steps), state_names=system.state_names)

    def chunk(self, x: FloatArray, times: FloatArray, done: int) -> tuple[FloatArray, ...]:
        """The steps over ``times`` by the path chosen for the run (a solver failure ends
        the run with its verified steps recorded)."""
        stepper, blocks, controller = self.stepper, self.blocks, self.controller
        try:
            if blocks is not None:
                return stepper.run_with_blocks(x, times, blocks)
            return stepper.run(x, times) if controller is None else \
                stepper.run_with_controller(x, times, controller)
        except SolverError as exc:
            X, Z, W = exc.partial  # type: ignore[attr-defined]  # partial run, added at raise
            _record_block(self.rec, self.system, times[1:1 + X.shape[0]], X, Z, W, last=True)
            if self.jac is not None:   # the transition up to the last verified step
                self.jac.extend(times[1:1 + X.shape[0]], Z, W, stepper.worst)
            traj = self.rec.finish(status=-1, message=str(exc), method="implicit_euler",
                                   stats=self.stats(done + X.shape[0]),
                                   state_names=self.system.state_names)
            raise SolverError(str(exc), status=exc.status, trajectory=traj) from None

    def stats(self, steps: int) -> dict[str, Any]:
        plan, controller, jac = self.plan, self.controller, self.jac
        out = {"steps": int(steps), "h": float(self.h), "theta": float(self.opts.theta),
               "solver": plan.solver, "structure": plan.structure,
               "blocks": max(1, len(plan.blocks)),
               "input": "controller" if controller is not None else self.stepper.input_mode}
        if controller is not None:
            out["controller"] = "compiled" if self.blocks is not None else "python"
        if plan.solver != "closed_form":
            out["max_residual"] = self.stepper.worst
        if jac is not None:
            out["state_transition"] = jac.transition.copy()
            out["degenerate_steps"] = jac.degenerate_steps
            out["first_degenerate_time"] = jac.first_degenerate_time
        return out


def _warn_degenerate(jac: Any) -> None:
    import warnings

    from ..errors import NscontrolWarning

    warnings.warn(f"implicit_euler: {jac.degenerate_steps} step(s) ended at a corner of the "
                  f"law's graph (first at t = {jac.first_degenerate_time:.6g}), where the "
                  f"discrete map is not differentiable; stats['state_transition'] uses the "
                  f"constraint-active one-sided derivative there", NscontrolWarning,
                  stacklevel=3)


def _record_finished(progress: ChunkProgress, *, rec: Recorder, system: Any,
                     times: FloatArray) -> None:
    """Record the steps a failed chunk finished (see :meth:`Recorder.chunk`)."""
    X, Z, W = progress.written()
    _record_block(rec, system, times[1:1 + progress.done], X, Z, W, last=True)


def _record_block(rec: Recorder, system: Any, t: FloatArray, X: FloatArray, Z: FloatArray,
                  W: FloatArray, *, last: bool) -> None:
    if X.shape[0] == 0:
        return
    sig = {}
    if rec.wants("z"):
        sig["z"] = Z
    if rec.wants("w"):
        sig["w"] = W
    if rec.wants("y"):
        sig["y"] = X @ system.C.T
    if last and X.shape[0] > 1:
        rec.extend(t[:-1], X[:-1], **{k: v[:-1] for k, v in sig.items()})
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    elif last:
        rec.sample(t[-1], X[-1], force=True, **{k: v[-1] for k, v in sig.items()})
    else:
        rec.extend(t, X, **sig)


def _exosystem_mean(exo: Any, h: float) -> FloatArray:
    """``Ψ/h`` with ``Ψ = ∫_0^h e^{Sτ} dτ``: the mean of ``ω`` over a step is ``(Ψ/h) ω(t_k)``
    (top-right block of the exponential of ``[[S, I], [0, 0]] h``)."""
    from scipy.linalg import expm

    S = np.atleast_2d(np.asarray(exo.S, float))
    r = S.shape[0]
    M = np.zeros((2 * r, 2 * r))
    M[:r, :r], M[:r, r:] = S, np.eye(r)
    return expm(M * h)[:r, r:] / h


class _Stepper:
    """Runs blocks of steps with the solver chosen once for the whole run."""

    def __init__(self, system: Any, setup: _Setup) -> None:
        mats = setup.mats
        self.system, self.m, self.plan = system, mats, setup.plan
        self.worst = 0.0   # largest accepted per-step residual (LCP / Python paths)
        self.progress = ChunkProgress()   # the chunk in progress (see Recorder.chunk)
        u = system.u
        self.exo = None
        if system.has_input and all(hasattr(u, a) for a in ("S", "Cu", "w0", "w")):
            self.exo = u
            self.mean = _exosystem_mean(u, mats.h).T @ np.atleast_2d(np.asarray(u.Cu, float)).T
        self.input_mode = ("exact_mean" if self.exo is not None else
                           "samples" if system.has_input else "none")
        if setup.spec is not None:   # the closed form's law data
            self.spec, self.curve, self.ucol = setup.spec, setup.curve, setup.ucol

    def _inputs(self, times: FloatArray) -> tuple[FloatArray, FloatArray]:
        sys_, th = self.system, self.m.theta
        if self.exo is not None:   # exact mean of the input over each step
            ubar = np.atleast_2d(self.exo.w(times[:-1])).reshape(times.size - 1, -1) @ self.mean
        elif sys_.has_input:
            U = sys_.input_at(times)
            ubar = (1.0 - th) * U[:-1] + th * U[1:]
        else:
            ubar = np.zeros((times.size - 1, max(sys_.n_inputs, 0)))
        gnext = sys_.shift_at(times[1:]) if sys_.has_shift else \
            np.zeros((times.size - 1, sys_.n_multipliers))
        return np.ascontiguousarray(ubar), np.ascontiguousarray(gnext)

    def run_with_controller(self, x: FloatArray, times: FloatArray,
                            controller: Any) -> tuple[FloatArray, ...]:
        """Steps over ``times`` one at a time, the input ``controller(t_k, x_k)`` held over
        each (zero-order hold)."""
        k, q = times.size - 1, self.system.n_inputs
        n, mm = self.system.n_states, self.system.n_multipliers
        X, Z, W = np.empty((k, n)), np.empty((k, mm)), np.empty((k, mm))
        self.progress.rows = (X, Z, W)
        fast = self._compiled_step()
        ubar, gnext = np.zeros((1, q)), np.zeros((1, mm))
        for j in range(k):
            u = np.asarray(controller(float(times[j]), x.copy()), dtype=float).reshape(-1)
            if u.size != q or not all(map(math.isfinite, u.tolist())):
                raise ModelError(f"controller: expected a finite input of length {q} at t = "
                                 f"{times[j]:.6g}, got {u!r}")
            if fast is not None:         # the compiled step, straight into the outputs
                ubar[0] = u
                if self.system.has_shift:
                    gnext[0] = self.system.shift_at(times[j + 1:j + 2])[0]
                fast(x, ubar, gnext, X[j:j + 1], Z[j:j + 1], W[j:j + 1])
                x = X[j]
                self.progress.done = j + 1
                continue
            try:
                Xj, Zj, Wj = self.run(x, times[j:j + 2], ubar=u[None, :])
            except SolverError as exc:
                exc.partial = (X[:j], Z[:j], W[:j])  # type: ignore[attr-defined]  # partial run, added at raise
                raise
            x = X[j] = Xj[0]
            Z[j], W[j] = Zj[0], Wj[0]
            self.progress.rows, self.progress.done = (X, Z, W), j + 1
        return X, Z, W

    def run_with_blocks(self, x: FloatArray, times: FloatArray,
                        blocks: Any) -> tuple[FloatArray, ...]:
        """Steps over ``times`` in one compiled loop with the compiled blocks of a closed loop
        (``blocks``, from :func:`nscontrol.closed_loop`): the same operations, in the same
        order, as :meth:`run_with_controller` with the blocks' Python methods."""
        from ..systems._feedback_kernels import calling_blocks
        from ._lure_kernels import controlled_steps

        k = times.size - 1
        n, mm = self.system.n_states, self.system.n_multipliers
        X, Z, W = np.empty((k, n)), np.empty((k, mm)), np.empty((k, mm))
        gnext = self.system.shift_at(times[1:]) if self.system.has_shift else \
            np.zeros((k, mm))
        XO, XC, U = blocks.log_arrays(k)
        m, plan, (kind, p1, p2) = self.m, self.plan, self.spec
        with calling_blocks():      # a block's error raised from the call
            done, status = controlled_steps(  # type: ignore[call-arg]  # numba's stub: 1 tuple
                m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, plan.order,
                plan.structure != "diagonal", kind, p1, p2, self.curve, self.system.H,
                self.ucol, blocks.Cy, times, np.ascontiguousarray(x, dtype=float),
                np.ascontiguousarray(gnext, dtype=float), X, Z, W, *blocks.kernel_state(),
                XO, XC, U)
        blocks.log(times[:done], XO[:done], XC[:done], U[:done])
        if status != 0:
            blocks.raise_status(int(status), float(times[done]))
        return X, Z, W

    def _compiled_step(self) -> Any:
        """``step(x, ubar, gnext, X, Z, W)``: one compiled closed-form step, or ``None``."""
        if self.plan.solver != "closed_form":
            return None
        from ._lure_kernels import triangular_steps

        m, plan, (kind, p1, p2) = self.m, self.plan, self.spec
        coupled = plan.structure != "diagonal"

        def step(x: FloatArray, ubar: FloatArray, gnext: FloatArray, X: FloatArray,
                 Z: FloatArray, W: FloatArray) -> None:
            triangular_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, plan.order, coupled,
                             kind, p1, p2, self.curve, self.system.H, self.ucol, x, ubar,
                             gnext, X, Z, W)
        return step

    def run(self, x: FloatArray, times: FloatArray,
            ubar: FloatArray | None = None) -> tuple[FloatArray, ...]:
        if ubar is None:
            try:
                ubar, gnext = self._inputs(times)
            except Exception:
                self._run_until_input_fails(x, times)
                raise
        else:
            gnext = self.system.shift_at(times[1:]) if self.system.has_shift else \
                np.zeros((times.size - 1, self.system.n_multipliers))
        k = times.size - 1
        n, mm = self.system.n_states, self.system.n_multipliers
        X, Z, W = np.empty((k, n)), np.empty((k, mm)), np.empty((k, mm))
        m, plan = self.m, self.plan
        if plan.solver == "closed_form":
            from ._lure_kernels import triangular_steps

            kind, p1, p2 = self.spec
            triangular_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, plan.order,
                             plan.structure != "diagonal", kind, p1, p2, self.curve,
                             self.system.H,
                             self.ucol, x, ubar, gnext, X, Z, W)
            return X, Z, W
        if plan.solver == "lcp":
            from ._lure_lcp_kernels import lcp_steps

            if plan.lcp is None:   # _plan sets the LCP data whenever it chooses "lcp"
                raise ModelError("law: the LCP step was planned without its LCP data")
            M3, Qa3, q03, T3, s3, comp, nv, mg = plan.lcp
            done, status, res = lcp_steps(m.Phi, m.Gam, m.Gh, m.HPhi, m.HGam, plan.D, M3, Qa3,
                                          q03, T3, s3, comp, nv, mg, x, ubar, gnext, X, Z, W,
                                          LCP_TOL)
            if status == 0:
                self.worst = max(self.worst, float(res))
            else:
                name = _LEMKE_STATUS.get(int(status), str(status))
                why = (f"Lemke stopped with status {name!r}" if status != _RESIDUAL_FAILURE
                       else f"its natural residual {res:.3g} is above {LCP_TOL:g}")
                err = SolverError(f"implicit_euler: the one-step LCP at t = "
                                  f"{times[done + 1]:.6g} has no verified solution: {why}; the "
                                  f"step matrix may be badly conditioned (reduce h)",
                                  status=name)
                err.partial = (X[:done], Z[:done], W[:done])  # type: ignore[attr-defined]  # partial run, added at raise
                raise err
            return X, Z, W
        H, D = self.system.H, plan.D
        for j in range(k):
            q = m.Phi @ x + m.Gam @ ubar[j]
            a = H @ q + gnext[j]
            w = np.zeros(mm)
            z = np.empty(mm)
            try:
                for blk in plan.blocks:   # in dependency order: earlier blocks are solved
                    ag = a[blk.idx] + D[blk.idx] @ w   # w of this and later blocks is 0
                    zg, wg, res = _solve_inclusion_python(blk.law, ag, blk.D)
                    w[blk.idx], z[blk.idx] = wg, zg
                    self.worst = max(self.worst, res)
            except SolverError as exc:
                exc.partial = (X[:j], Z[:j], W[:j])  # type: ignore[attr-defined]  # partial run, added at raise
                raise
            x = q + m.Gh @ w
            X[j], Z[j], W[j] = x, z, w
            self.progress.rows, self.progress.done = (X, Z, W), j + 1
        return X, Z, W

    def _run_until_input_fails(self, x: FloatArray, times: FloatArray) -> None:
        """The steps of a chunk whose input cannot be evaluated over it whole (``u``
        raised): those before the first time it fails at (found by bisection on prefixes of
        ``times``) are run into :attr:`progress`, kept when the caller's error goes on
        (``times[:k]`` gives the inputs of the ``k - 1`` steps it spans)."""
        ok = evaluable_prefix(lambda k: self._inputs(times[:k]), times.size)
        if ok >= 2:
            self.progress.rows = self.run(x, times[:ok])
            self.progress.done = ok - 1


_RESIDUAL_FAILURE = 3  # NUMERICAL_FAILURE of the LCP kernels: residual check failed
_LEMKE_STATUS = {1: "ray_termination", 2: "max_iter", 3: "residual"}
