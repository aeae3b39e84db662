"""Piecewise-affine systems for :mod:`nscontrol.simulate.switching`.

With no input or an :class:`~nscontrol.numerics.lti.Exosystem` input each region's flow is
linear in the augmented state ``ξ = [x; ω; 1]`` (``ω' = Sω``, ``u = C_u ω``)::

    ξ' = [[A_i, E C_u, b_i], [0, S, 0], [0, 0, 0]] ξ

so a piece is propagated exactly by :class:`~nscontrol.numerics.lti.LTIFlow` and the exit
through a facet ``H_ir x = h_ir`` is the first root of ``h_ir - H_ir x(t)``, located by
:func:`~nscontrol.numerics.lti.first_event` (grazing flagged). Any other input function uses
DOP853 with one terminal, direction-aware event per facet. In both cases the sensitivity of a
piece is ``expm(A_i τ)`` (the input does not change it) and a crossing multiplies it by the
saltation matrix ``I + (F⁺ - F⁻)nᵀ/(nᵀF⁻)`` (the identity for a continuous field).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import expm

from .._validation import FloatArray
from ..errors import ModelError
from .switching import saltation_matrix


def _exosystem(system: Any, options: dict[str, Any]) -> Any:
    """The input as an Exosystem, ``None`` for no input, or ``"function"`` otherwise."""
    u = options.get("u", system.u)
    if u is None or system.E is None:
        return None
    if all(hasattr(u, a) for a in ("S", "Cu", "w0")):
        return u
    return "function"


class _Modes:
    """Augmented matrices and cached flows of the regions for one input."""

    def __init__(self, system: Any, exo: Any, t0: float) -> None:
        from ..numerics.lti import LTIFlow

        n = system.n_states
        self.n = n
        if exo is None:
            S = np.zeros((0, 0))
            Bu = np.zeros((n, 0))
            w0 = np.zeros(0)
        else:
            S = np.atleast_2d(np.asarray(exo.S, float))
            Cu = np.atleast_2d(np.asarray(exo.Cu, float))
            Bu = system.E @ Cu
            w0 = expm(S * t0) @ np.asarray(exo.w0, float) if S.size else np.zeros(0)
        r = S.shape[0]
        self.r = r
        self.w_t0 = w0
        self.aug = []
        for A, b in zip(system.A, system.b, strict=True):
            M = np.zeros((n + r + 1, n + r + 1))
            M[:n, :n], M[:n, n:n + r], M[:n, -1] = A, Bu, b
            M[n:n + r, n:n + r] = S
            self.aug.append(M)
        self._flows: dict[int, Any] = {}
        self._LTIFlow = LTIFlow

    def flow(self, i: int) -> Any:
        if i not in self._flows:
            self._flows[i] = self._LTIFlow(self.aug[i])
        return self._flows[i]

    def derivatives(self, i: int, xi: FloatArray, k: int) -> list[FloatArray]:
        """``x', x'', ...`` (``k`` of them) of the flow of region ``i`` at ``ξ``."""
        out, v = [], xi
        for _ in range(k):
            v = self.aug[i] @ v
            out.append(v[:self.n])
        return out


def _entering(system: Any, modes: _Modes, j: int, xi: FloatArray, tol: float) -> bool:
    """Whether the flow of region ``j`` from ``ξ`` (on its boundary) moves into region ``j``."""
    H, h = system.regions[j]
    x = xi[:modes.n]
    slack = h - H @ x
    scale = 1.0 + np.abs(h) + np.abs(H) @ np.abs(x)
    if np.any(slack < -tol * scale):
        return False
    active = np.abs(slack) <= tol * scale
    if not np.any(active):
        return True
    ders = modes.derivatives(j, xi, 3)
    for r in np.flatnonzero(active):
        for d in ders:  # the first nonzero derivative of h_r - H_r x decides
            v = -float(H[r] @ d)
            if abs(v) > 1e-12 * (np.abs(H[r]) @ np.abs(d) + 1e-300):
                if v < 0:
                    return False
                break
    return True


def _choose_region(system: Any, modes: _Modes, xi: FloatArray, exclude: int = -1) -> int:
    for tol in (1e-12, 1e-9):
        for j in range(system.n_regions):
            if j != exclude and _entering(system, modes, j, xi, tol):
                return j
    return -1


def run_pwa(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]) -> dict[str, Any]:
    exo = _exosystem(system, options)
    if exo == "function":
        return _run_pwa_ode(system, x0, run, options)
    from ..numerics.lti import first_event

    n = system.n_states
    modes = _Modes(system, exo, run.t0)
    xi = np.concatenate([x0, modes.w_t0, [1.0]])
    i = _choose_region(system, modes, xi)
    if i < 0:
        raise ModelError(f"x0: {x0} lies in no region of the partition")
    t = run.t0
    run.rec.sample(t, x0, force=True)
    segments = 0
    while t < run.tf:
        H, h = system.regions[i]
        G = np.zeros((H.shape[0], xi.shape[0]))
        G[:, :n] = -H
        flow = modes.flow(i)
        ev = first_event(flow, xi, G, h, run.tf - t)
        t_end = run.tf if ev is None else min(t + float(ev.t), run.tf)
        tau = t_end - t
        ts = run.samples(t, t_end, last=ev is None)
        if ts.size:
            X = np.atleast_2d(flow.propagate(xi, ts - t))
            run.rec.extend(ts, X[:, :n])
        xi_end = np.asarray(flow.propagate(xi, tau), float).reshape(-1)
        if run.sensitivity:  # the x-block of the augmented exponential is expm(A_i τ)
            run.Phi = np.asarray(flow.expm(tau))[:n, :n] @ run.Phi
        segments += 1
        run.bar.update(t_end)
        if tau <= 0.0:
            run.zero_length(t_end)
        else:
            run.stuck = 0
        xi, t = xi_end, t_end
        if ev is None or t >= run.tf:
            break
        x_e = xi[:n]
        row = int(np.atleast_1d(ev.indices)[0])
        j = _choose_region(system, modes, xi, exclude=i)
        if ev.grazing or j < 0:
            if j < 0 and not ev.grazing and not _entering(system, modes, i, xi, 1e-9):
                raise ModelError(
                    f"switching: at t = {t:.12g} the flow leaves region {i} through facet "
                    f"{row} but no region's field points inward at x = {x_e}: a sliding motion "
                    f"on a facet of a discontinuous PWA system. Simulate "
                    f"FilippovSystem.from_pwa(system) instead")
            run.event(t, "grazing", row, x_e, x_e, i, i)
            continue
        fm = modes.derivatives(i, xi, 1)[0]
        fp = modes.derivatives(j, xi, 1)[0]
        normal = H[row]
        S = saltation_matrix(fm, fp, normal) if run.sensitivity else None
        run.event(t, "crossing", row, x_e, x_e, i, j, S)
        run.rec.sample(t, x_e, force=True)
        i = j
    if run.rec.last_time < run.tf:
        run.rec.sample(run.tf, xi[:n], force=True)
    return {"segments": segments, "final_mode": i, "propagation": "exact"}


def _run_pwa_ode(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]
                 ) -> dict[str, Any]:
    """Pieces by DOP853 for inputs given as arbitrary functions of time."""
    from scipy.integrate import solve_ivp

    u = options.get("u", system.u)
    from ..systems.lure import _input_function

    ufn = _input_function("u", u, system.E.shape[1])

    def field(i: int, t: float, x: FloatArray) -> FloatArray:
        return system.A[i] @ x + system.b[i] + system.E @ ufn(t)[0]

    def mode_at(x: FloatArray, t: float, exclude: int = -1) -> int:
        for j in range(system.n_regions):
            if j == exclude or not system.contains(j, x, 1e-9):
                continue
            H, hh = system.regions[j]
            act = np.abs(hh - H @ x) <= 1e-9 * (1 + np.abs(hh) + np.abs(H) @ np.abs(x))
            if not np.any(act) or np.all(H[act] @ field(j, t, x) <= 0.0):
                return j
        return -1

    t, x = run.t0, x0.copy()
    i = mode_at(x, t)
    if i < 0:
        raise ModelError(f"x0: {x0} lies in no region of the partition")
    run.rec.sample(t, x0, force=True)
    segments = 0
    while t < run.tf:
        H, h = system.regions[i]
        events = [_facet_event(H[r], float(h[r])) for r in range(H.shape[0])]
        sol = solve_ivp(lambda tt, xx, i=i: field(i, tt, xx), (t, run.tf), x, method="DOP853",
                        rtol=run.rtol, atol=run.atol, events=events, dense_output=True)
        t_end = float(sol.t[-1])
        ts = run.samples(t, t_end, last=sol.status == 0)
        if ts.size:
            run.rec.extend(ts, sol.sol(ts).T)
        if run.sensitivity:
            run.Phi = expm(system.A[i] * (t_end - t)) @ run.Phi
        segments += 1
        t, x = t_end, sol.y[:, -1].copy()
        run.bar.update(t)
        if sol.status != 1:
            break
        row = next(r for r, te in enumerate(sol.t_events) if te.size)
        j = mode_at(x, t, exclude=i)
        if j < 0:
            raise ModelError(f"switching: at t = {t:.12g} no region's field points inward at "
                             f"x = {x} (sliding on a discontinuous PWA facet); simulate "
                             f"FilippovSystem.from_pwa(system) instead")
        S = (saltation_matrix(field(i, t, x), field(j, t, x), H[row])
             if run.sensitivity else None)
        run.event(t, "crossing", row, x, x, i, j, S)
        run.rec.sample(t, x, force=True)
        i = j
    if run.rec.last_time < run.tf:
        run.rec.sample(run.tf, x, force=True)
    return {"segments": segments, "final_mode": i, "propagation": "dop853"}


def _facet_event(row: FloatArray, offset: float) -> Any:
    """Terminal event ``offset - row·x`` falling through zero (leaving the region)."""
    def g(t: float, x: FloatArray) -> float:
        return float(offset - row @ x)
    g.terminal, g.direction = True, -1.0  # type: ignore[attr-defined]
    return g
