"""Piecewise-affine systems for :mod:`nscontrol.simulate.switching`.

With no input or an :class:`~nscontrol.numerics.lti.Exosystem` input each region's flow is
linear in the augmented state ``ξ = [x; ω; 1]`` (``ω' = Sω``, ``u = C_u ω``)::

    ξ' = [[A_i, E C_u, b_i], [0, S, 0], [0, 0, 0]] ξ

so a piece is propagated exactly by :class:`~nscontrol.numerics.lti.LTIFlow` and the exit
through a facet ``H_ir x = h_ir`` is the first root of ``h_ir - H_ir x(t)``, located by
:func:`~nscontrol.numerics.lti.first_event` (grazing flagged). Any other input function uses
DOP853 with one terminal, direction-aware event per facet, and a non-terminal event on the
derivative of each facet's slack, so that a tangential touch without a sign change is reported
as ``grazing`` there too. In both cases the sensitivity of a piece is ``expm(A_i τ)`` (the
input does not change it) and a crossing multiplies it by the saltation matrix
``I + (F⁺ - F⁻)nᵀ/(nᵀF⁻)`` (the identity for a continuous field).

With a ``domain``: ``x0`` outside it raises ``InadmissibleStateError``; its facets are guards
as well, and a trajectory that leaves it stops there with a ``domain_exit`` event (index: the
domain row, ``mode_to = -1``) and ``status = 1``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import expm

from .._validation import FloatArray
from ..errors import InadmissibleStateError, ModelError, SlidingError, SolverError
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
        if i not in self._flows:   # shared: a sweep or a period map reuses the decompositions
            self._flows[i] = self._LTIFlow.shared(self.aug[i])
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


def _check_x0(system: Any, x0: FloatArray) -> None:
    """Refuse an initial state outside the declared domain."""
    if system.in_domain(x0):
        return
    Hd, hd = system.domain
    viol = Hd @ x0 - hd
    r = int(np.argmax(viol))
    raise InadmissibleStateError(
        f"x0: {np.array2string(x0, precision=6)} lies outside the domain H_d x <= h_d of the "
        f"system (row {r}: H_d[{r}]·x0 - h_d[{r}] = {viol[r]:.3g} > 0); the model is not "
        f"defined there. Start inside the domain")


def _leaving_domain(system: Any, modes: _Modes, i: int, xi: FloatArray, rows: list[int]
                    ) -> int:
    """The first domain row (among ``rows``, all at zero) that the flow of region ``i``
    crosses outwards at ``ξ`` (first nonzero derivative of ``h_d - H_d x`` negative), or -1."""
    Hd, _ = system.domain
    ders = modes.derivatives(i, xi, 3)
    for r in rows:
        for d in ders:
            v = -float(Hd[r] @ d)
            if abs(v) > 1e-12 * (np.abs(Hd[r]) @ np.abs(d) + 1e-300):
                if v < 0:
                    return r
                break
    return -1


def _domain_exit(run: Any, t: float, r: int, x: FloatArray, i: int) -> None:
    """Record the exit through domain row ``r`` and stop the run (status 1)."""
    run.event(t, "domain_exit", r, x, x, i, -1)
    run.rec.sample(t, x, force=True)
    run.status = 1
    run.message = (f"the trajectory left the domain H_d x <= h_d through row {r} at t = "
                   f"{t:.12g}, x = {np.array2string(x, precision=9)} (region {i}); the model is "
                   f"not defined beyond it")


def run_pwa(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]) -> dict[str, Any]:
    _check_x0(system, x0)
    exo = _exosystem(system, options)
    if exo == "function":
        return _run_pwa_ode(system, x0, run, options)
    from ..numerics.lti import first_event

    n = system.n_states
    modes = _Modes(system, exo, run.t0)
    xi = np.concatenate([x0, modes.w_t0, [1.0]])
    i = _choose_region(system, modes, xi)
    if i < 0:
        raise InadmissibleStateError(f"x0: {x0} lies in no region of the partition")
    dom = system.domain
    t = run.t0
    run.rec.sample(t, x0, force=True)
    segments = 0
    while t < run.tf:
        H, h = system.regions[i]
        nr = H.shape[0]
        if dom is not None:   # the domain's facets are guards too: leaving it stops the run
            H, h = np.vstack([H, dom[0]]), np.concatenate([h, dom[1]])
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
        hits = [int(r) for r in np.atleast_1d(ev.indices)]
        dom_rows = [r - nr for r in hits if r >= nr]
        hits = [r for r in hits if r < nr]
        if dom_rows and not ev.grazing:
            r = _leaving_domain(system, modes, i, xi, dom_rows)
            if r >= 0:
                _domain_exit(run, t, r, x_e, i)
                break
        if not hits:   # touched the domain boundary from inside and stays in: go on
            continue
        row = hits[0]
        j = _choose_region(system, modes, xi, exclude=i)
        if ev.grazing or j < 0:
            if j < 0 and not ev.grazing and not _entering(system, modes, i, xi, 1e-9):
                raise SlidingError(
                    f"switching: at t = {t:.12g} the flow leaves region {i} through facet "
                    f"{row} but no region's field points inward at x = {x_e}: a sliding motion "
                    f"on a facet of a discontinuous PWA system. Simulate "
                    f"FilippovSystem.from_pwa(system) instead", time=t, state=x_e.copy())
            run.event(t, "grazing", row, x_e, x_e, i, i)
            continue
        fm = modes.derivatives(i, xi, 1)[0]
        fp = modes.derivatives(j, xi, 1)[0]
        normal = system.regions[i][0][row]
        S = saltation_matrix(fm, fp, normal) if run.sensitivity else None
        run.event(t, "crossing", row, x_e, x_e, i, j, S)
        run.rec.sample(t, x_e, force=True)
        i = j
    if run.rec.last_time < run.tf and run.status == 0:
        run.rec.sample(run.tf, xi[:n], force=True)
    return {"segments": segments, "final_mode": i, "propagation": "exact"}


def _run_pwa_ode(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]
                 ) -> dict[str, Any]:
    """Pieces by DOP853 for inputs given as arbitrary functions of time: one terminal event
    per facet (leaving the region) and per domain facet, and one non-terminal event per facet
    on the slack's derivative (grazing candidates: a minimum of the slack at zero)."""
    from scipy.integrate import solve_ivp

    u = options.get("u", system.u)
    from ..systems.lure import as_input_function

    ufn = as_input_function("u", u, system.E.shape[1])
    if ufn is None:   # this path is taken only for inputs given as functions of time
        raise ModelError("u: expected an input function of time for the DOP853 path, got None")

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
        raise InadmissibleStateError(f"x0: {x0} lies in no region of the partition")
    run.rec.sample(t, x0, force=True)
    segments = 0
    last_graze: dict[int, float] = {}
    while t < run.tf:
        H, h = system.regions[i]
        events: list[Any] = []
        kinds: list[tuple[str, int]] = []
        for r in range(H.shape[0]):
            events.append(_facet_event(H[r], float(h[r])))
            kinds.append(("facet", r))
            events.append(_slack_extremum(H[r], lambda tt, xx, i=i: field(i, tt, xx)))
            kinds.append(("graze", r))
        if system.domain is not None:
            for r in range(system.domain[0].shape[0]):
                events.append(_facet_event(system.domain[0][r], float(system.domain[1][r])))
                kinds.append(("domain", r))
        sol = solve_ivp(lambda tt, xx, i=i: field(i, tt, xx), (t, run.tf), x, method="DOP853",
                        rtol=run.rtol, atol=run.atol, events=events, dense_output=True)
        t_end = float(sol.t[-1])
        ts = run.samples(t, t_end, last=sol.status == 0)
        if ts.size and sol.sol is not None:
            run.rec.extend(ts, sol.sol(ts).T)
        if sol.status < 0:
            raise SolverError(f"switching: DOP853 failed at t = {t_end:.6g} ({sol.message}) in "
                              f"region {i}; check the input function for NaN or infinite "
                              f"values. The trajectory up to that time is in err.trajectory",
                              status="dop853")
        for k, (kind, r) in enumerate(kinds):   # grazing: slack minimum at zero
            if kind != "graze":
                continue
            for tr in sol.t_events[k]:
                tr = float(tr)
                if tr >= t_end and sol.status == 1:
                    continue
                xr = sol.sol(tr)
                tol = 100.0 * (run.atol + run.rtol * float(np.max(np.abs(xr)))) * \
                    float(np.linalg.norm(H[r]))
                if abs(float(h[r] - H[r] @ xr)) <= tol and \
                        abs(tr - last_graze.get(r, -np.inf)) > 1e-9 * (1.0 + abs(tr)):
                    last_graze[r] = tr
                    run.event(tr, "grazing", r, xr, xr, i, i)
                    run.rec.sample(tr, xr, force=True)
        if run.sensitivity:
            run.Phi = expm(system.A[i] * (t_end - t)) @ run.Phi
        segments += 1
        t, x = t_end, sol.y[:, -1].copy()
        run.bar.update(t)
        if sol.status != 1:
            break
        hit = [k for k, te in enumerate(sol.t_events) if te.size and kinds[k][0] != "graze"
               and float(te[-1]) >= t_end]
        dom = [kinds[k][1] for k in hit if kinds[k][0] == "domain"]
        if not dom and system.domain is not None:   # a facet on the domain's boundary
            Hd, hd = system.domain                   # fired first: is the flow leaving?
            on = np.abs(hd - Hd @ x) <= 1e-9 * (1.0 + np.abs(hd) + np.abs(Hd) @ np.abs(x))
            dom = [int(r) for r in np.flatnonzero(on & (Hd @ field(i, t, x) > 0.0))]
        if dom:
            _domain_exit(run, t, dom[0], x, i)
            break
        row = kinds[hit[0]][1]
        j = mode_at(x, t, exclude=i)
        if j < 0:
            raise SlidingError(f"switching: at t = {t:.12g} no region's field points inward "
                               f"at x = {x} (sliding on a discontinuous PWA facet); simulate "
                               f"FilippovSystem.from_pwa(system) instead", time=t,
                               state=x.copy())
        S = (saltation_matrix(field(i, t, x), field(j, t, x), H[row])
             if run.sensitivity else None)
        run.event(t, "crossing", row, x, x, i, j, S)
        run.rec.sample(t, x, force=True)
        last_graze.clear()
        i = j
    if run.rec.last_time < run.tf and run.status == 0:
        run.rec.sample(run.tf, x, force=True)
    return {"segments": segments, "final_mode": i, "propagation": "dop853"}


def _facet_event(row: FloatArray, offset: float) -> Any:
    """Terminal event ``offset - row·x`` falling through zero (leaving the region)."""
    def g(t: float, x: FloatArray) -> float:
        return float(offset - row @ x)
    g.terminal, g.direction = True, -1.0  # type: ignore[attr-defined]  # solve_ivp reads these
    return g


def _slack_extremum(row: FloatArray, f: Any) -> Any:
    """Non-terminal event on ``d/dt (offset - row·x) = -row·f`` rising through zero: a
    minimum of the slack (a grazing when the slack is zero there)."""
    def g(t: float, x: FloatArray) -> float:
        return -float(row @ f(t, x))
    g.terminal, g.direction = False, 1.0  # type: ignore[attr-defined]  # solve_ivp reads these
    return g
