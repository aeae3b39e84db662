"""The one-step inclusion ``w ∈ -φ(a + D_h w)`` solved in Python (the initial multiplier, and
the steps of laws with no compiled form: curved graphs, shared-argument super-twisting),
each solution verified by the law's graph residual."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import InadmissibleStateError, SolverError
from ._law_data import law_parts, lcp_step_data

__all__ = ["GRAPH_TOL", "initial_multiplier", "solve_inclusion_python",
           "shared_argument_weights"]

#: Acceptance of a per-step inclusion solution on the Python path (graph residual, relative
#: to ``1 + |a| + |w|``).
GRAPH_TOL = 1e-9


def initial_multiplier(system: Any, x0: FloatArray, t0: float) -> tuple[FloatArray, FloatArray]:
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
               f"domain of {part!r}" for sl, part in law_parts(system.law)
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
    z, w, _ = solve_inclusion_python(system.law, a, system.D)
    return z, w


def solve_inclusion_python(law: Any, a: FloatArray, Dh: FloatArray
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
    from ...laws.inclusion import solve_inclusion

    if shared_argument_weights(law, Dh) is not None:
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


def shared_argument_weights(law: Any, Dh: FloatArray) -> FloatArray | None:
    """``d`` when ``D_h = 1 dᵀ`` (identical rows, ``d > 0``, at least two components) and
    every part of ``law`` is a scalar super-twisting law or relay; else ``None``."""
    from ...laws.relay import Relay
    from ...laws.super_twisting import SuperTwistingLaw

    if Dh.ndim != 2 or Dh.shape[0] < 2:
        return None
    d = Dh[0]
    if np.any(d <= 0.0) or np.max(np.abs(Dh - d[None, :])) > 1e-14 * float(np.max(d)):
        return None
    if not all(isinstance(p, (Relay, SuperTwistingLaw)) and p.dim == 1
               for _, p in law_parts(law)):
        return None
    return d.copy()


def _shared_argument_step(law: Any, a: FloatArray, Dh: FloatArray
                          ) -> tuple[FloatArray, FloatArray]:
    """Solve ``w ∈ -φ(a + D_h w)`` with ``D_h = 1 dᵀ``: the common argument ``s`` solves
    ``s + Σ_j d_j φ_j(s) ∋ a_0`` (each ``φ_j = k1_j |·|^{1/2} sign + k2_j Sign``, a relay having
    ``k1 = 0``), in closed form; at ``s = 0`` the set-valued parts share ``a_0`` in proportion
    to their bounds."""
    from ...laws.relay import Relay
    from ...laws.super_twisting import super_twisting_resolvent

    d = Dh[0]
    k1 = np.array([0.0 if isinstance(p, Relay) else float(p.k1[0]) for _, p in law_parts(law)])
    k2 = np.array([float(p.bound[0]) if isinstance(p, Relay) else float(p.k2[0])
                   for _, p in law_parts(law)])
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

