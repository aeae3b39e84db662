"""How every step's inclusion is solved, chosen once per system and step: the structure of
the one-step matrix ``D_h`` (diagonal, triangular up to a permutation, block triangular, full
or shared-argument), the solver (closed form, LCP or Python), and the checks that make the
inclusion uniquely solvable; :class:`Setup` keeps all of it beside the system."""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError
from ._inclusion import shared_argument_weights
from ._law_data import componentwise_spec, curve_parameters, law_parts, lcp_step_data
from ._matrices import StepMatrices, structural

__all__ = ["Plan", "Setup"]


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


def _blocks(law: Any, D: FloatArray) -> list[_Block]:
    """The strongly connected groups of the law's parts under the coupling of ``D``, in an
    order where each group depends only on earlier ones (block lower triangular)."""
    from ...laws.product import Product

    parts = law_parts(law)
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
class Plan:
    """How every step's inclusion is solved (chosen once per run)."""

    solver: str                # "closed_form", "lcp" or "python"
    structure: str             # "diagonal", "triangular", "block_triangular" or "full"
    D: FloatArray              # D_h with structural zeros
    order: np.ndarray | None   # closed form: component order
    blocks: tuple[_Block, ...]
    lcp: tuple[Any, ...] | None = None   # padded per-block LCP data for the compiled loop


def _plan(system: Any, Dh: FloatArray, h: float) -> Plan:
    """Choose the solver and check that the one-step inclusion is uniquely solvable."""
    D = structural(Dh)
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
            return Plan("closed_form", structure, D, order, ())
    blocks = _blocks(system.law, D)
    if len(blocks) == 1:
        lam = _min_sym_eig(D)
        if lam <= 0.0 and shared_argument_weights(system.law, D) is not None \
                and not np.any(system.D):
            return Plan("python", "shared_argument", D, None, tuple(blocks))
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
        return Plan("lcp", structure, D, None, tuple(blocks), _pad_lcp(blocks, data))
    return Plan("python", structure, D, None, tuple(blocks))


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


@dataclass(frozen=True, eq=False)
class Setup:
    """What a run computes once from the model and the step, before its first step: the step
    matrices, the solver plan and the compiled closed form's law data. Shared by the runs of
    one system and step (a sweep, a period map): :meth:`of` keeps it beside the system."""

    mats: StepMatrices
    plan: Plan
    spec: tuple[np.ndarray, FloatArray, FloatArray] | None
    curve: FloatArray | None
    ucol: np.ndarray | None

    @classmethod
    def of(cls, system: Any, h: float, theta: float) -> Setup:
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
    def build(cls, system: Any, h: float, theta: float) -> Setup:
        mats = StepMatrices(system, h, theta)
        plan = _plan(system, mats.Dh, h)
        if plan.solver != "closed_form":
            return cls(mats, plan, None, None, None)
        spec = componentwise_spec(system.law)
        if spec is None:   # _plan chooses the closed form only for such laws
            raise ModelError("law: the closed-form step needs a componentwise law")
        return cls(mats, plan, spec, curve_parameters(system.law), _single_state_rows(system))


#: The setups of the systems in use (a LureSystem is frozen: its matrices do not change).
_SETUPS: weakref.WeakKeyDictionary[Any, dict[tuple[float, float], Setup]] = \
    weakref.WeakKeyDictionary()

