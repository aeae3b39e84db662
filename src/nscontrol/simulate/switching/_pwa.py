"""Piecewise-affine systems for :mod:`nscontrol.simulate.switching`.

With no input or an :class:`~nscontrol.numerics.lti.Exosystem` input each region's flow is
linear in the augmented state ``ξ = [x; ω; 1]`` (``ω' = Sω``, ``u = C_u ω``)::

    ξ' = [[A_i, E C_u, b_i], [0, S, 0], [0, 0, 0]] ξ

so a piece is propagated exactly by the region's matrix exponential and the exit through a
facet ``H_ir x = h_ir`` is the first root of ``h_ir - H_ir x(t)``, located by the exact event
search of :func:`~nscontrol.numerics.lti.first_event` (grazing flagged). The pieces and the
plain crossings run in one compiled loop (:mod:`._pwa_kernels`), which hands every other event
(grazing, the domain's facets, no region to enter) to the Python code here. Any other input
function uses DOP853 with one terminal, direction-aware event per facet, and a non-terminal
event on the derivative of each facet's slack, so that a tangential touch without a sign
change is reported as ``grazing`` there too. In both cases the sensitivity of a piece is
``expm(A_i τ)`` (the input does not change it) and a crossing multiplies it by the saltation
matrix ``I + (F⁺ - F⁻)nᵀ/(nᵀF⁻)`` (the identity for a continuous field).

With a ``domain``: ``x0`` outside it raises ``InadmissibleStateError``; its facets are guards
as well, and a trajectory that leaves it stops there with a ``domain_exit`` event (index: the
domain row, ``mode_to = -1``) and ``status = 1``.
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..._validation import FloatArray
from ...errors import InadmissibleStateError, ModelError, SlidingError, ZenoError
from ..event_driven._flight import projection_stats
from ._run import SwitchingStepper, saltation_matrix


def _exosystem(system: Any, u: Any) -> Any:
    """The input (``u``, or the system's when ``None``) as an Exosystem, ``None`` for no input,
    or ``"function"`` otherwise."""
    u = system.u if u is None else u
    if u is None or system.E is None:
        return None
    if all(hasattr(u, a) for a in ("S", "Cu", "w0")):
        return u
    return "function"


class _Modes:
    """The regions' augmented matrices ``M_i`` for one input, and the arrays the compiled loop
    (:mod:`._pwa_kernels`) reads: facets, and per region its flow and guard data, prepared
    when the region is first visited. Cached per model and input (:meth:`of`): a period map
    or a sweep simulates the same model many times."""

    def __init__(self, system: Any, S: FloatArray, Bu: FloatArray) -> None:
        from ...numerics.lti import TAYLOR_DEGREE

        n, r, R = system.n_states, S.shape[0], system.n_regions
        m = n + r + 1
        self.n, self.r, self.m, self.R = n, r, m, R
        self.aug = np.zeros((R, m, m))
        for k, (A, b) in enumerate(zip(system.A, system.b, strict=True)):
            self.aug[k, :n, :n], self.aug[k, :n, n:n + r], self.aug[k, :n, -1] = A, Bu, b
            self.aug[k, n:n + r, n:n + r] = S
        nf = np.array([H.shape[0] for H, _ in system.regions], dtype=np.int64)
        dom = system.domain
        nd = 0 if dom is None else dom[0].shape[0]
        self.nf, self.nd = nf, nd
        pf = int(nf.max(initial=0))
        self.H = np.zeros((R, max(pf, 1), n))
        self.h = np.zeros((R, max(pf, 1)))
        for k, (H, h) in enumerate(system.regions):
            self.H[k, :nf[k]], self.h[k, :nf[k]] = H, h
        # guards of region k: its facets, then the domain's, then padding (g = 1, no root)
        p = max(pf + nd, 1)
        self.guards: list[tuple[FloatArray, FloatArray]] = []
        for H, h in system.regions:
            Hk = H if dom is None else np.vstack([H, dom[0]])
            hk = h if dom is None else np.concatenate([h, dom[1]])
            G = np.zeros((Hk.shape[0], m))
            G[:, :n] = -Hk
            self.guards.append((G, np.asarray(hk, float)))
        K1 = TAYLOR_DEGREE + 1
        self.kinds = np.zeros(R, dtype=np.int64)
        self.lams = np.zeros((R, m), dtype=complex)
        self.Vs = np.zeros((R, m, m), dtype=complex)
        self.Vinvs = np.zeros((R, m, m), dtype=complex)
        self.phis = np.zeros((R, m, m))
        self.taylors = np.zeros((R, K1, m, m))
        self.ds = np.ones((R, m))
        self.hs = np.ones(R)
        self.kappas = np.ones(R)
        self.Ws = np.zeros((R, K1, p, m))
        self.g0s = np.ones((R, p))
        self.row_norms = np.ones((R, p))
        self.ready = np.zeros(R, dtype=np.bool_)
        self.bern = np.zeros((K1, K1, K1))   # the search's Bernstein tables, from a context

    @classmethod
    def of(cls, system: Any, exo: Any) -> _Modes:
        """The modes of ``system`` under the exosystem ``exo`` (``None``: no input), shared
        by the runs of an equal model and input (the most recent 32 are kept). The same
        model object with the same input object finds its modes without hashing them."""
        per_system = _MODES_OF.get(system)
        if per_system is None:
            per_system = _MODES_OF[system] = {}
        known = per_system.get(id(exo))
        if known is not None and known[0] is exo:   # the entry holds exo: its id is unique
            return known[1]
        modes = cls._shared(system, exo)
        if len(per_system) >= 8:
            per_system.pop(next(iter(per_system)))
        per_system[id(exo)] = (exo, modes)
        return modes

    @classmethod
    def _shared(cls, system: Any, exo: Any) -> _Modes:
        """The modes of an equal model and input, found by their matrices' bytes."""
        n = system.n_states
        if exo is None:
            S, Bu = np.zeros((0, 0)), np.zeros((n, 0))
        else:
            S = np.atleast_2d(np.asarray(exo.S, float))
            Bu = system.E @ np.atleast_2d(np.asarray(exo.Cu, float))
        parts = [S, Bu, *system.A, *system.b, *(a for reg in system.regions for a in reg)]
        if system.domain is not None:
            parts += list(system.domain)
        key = tuple((a.shape, a.tobytes()) for a in (np.asarray(v, float) for v in parts))
        modes = _MODES.pop(key, None)
        if modes is None:
            modes = cls(system, S, Bu)
            if len(_MODES) >= 32:
                _MODES.pop(next(iter(_MODES)))
        _MODES[key] = modes  # most recently used last
        return modes

    def prepare(self, k: int) -> None:
        """Build region ``k``'s flow and guard data for the compiled loop."""
        from ...numerics.lti import LTIFlow

        flow = LTIFlow.shared(self.aug[k])
        ctx = flow.guard_context()
        G, g0 = self.guards[k]
        W, norms = ctx.guard_data(G)
        p = G.shape[0]
        self.kinds[k] = ctx.kind
        if flow.method == "eig":
            self.lams[k], self.Vs[k], self.Vinvs[k] = ctx.lam, ctx.V, ctx.Vinv
        self.phis[k], self.taylors[k], self.ds[k], self.hs[k] = ctx.phi, ctx.taylor, ctx.d, ctx.h
        self.kappas[k] = ctx.kappa
        self.Ws[k, :, :p], self.g0s[k, :p], self.row_norms[k, :p] = W, g0, norms
        self.bern = ctx.bern
        self.ready[k] = True

    def field(self, i: int, xi: FloatArray) -> FloatArray:
        """``x'`` of region ``i`` at ``ξ``."""
        return self.aug[i, :self.n] @ xi

    def derivatives(self, i: int, xi: FloatArray, k: int) -> list[FloatArray]:
        """``x', x'', ...`` (``k`` of them) of the flow of region ``i`` at ``ξ``."""
        out, v = [], xi
        for _ in range(k):
            v = self.aug[i] @ v
            out.append(v[:self.n])
        return out

    def choose(self, xi: FloatArray, exclude: int = -1) -> int:
        """The region whose flow from ``ξ`` enters it (:func:`._pwa_kernels.choose_region`)."""
        from ._pwa_kernels import choose_region

        return int(choose_region(self.H, self.h, self.nf, self.aug, xi, self.n, exclude))

    def entering(self, j: int, xi: FloatArray, tol: float) -> bool:
        from ._pwa_kernels import entering

        return bool(entering(self.H, self.h, self.nf, self.aug, j, xi, self.n, tol))


_MODES: dict[Any, _Modes] = {}
#: Per model object (a PiecewiseAffineSystem is frozen), per input object: its modes.
_MODES_OF: weakref.WeakKeyDictionary[Any, dict[int, tuple[Any, _Modes]]] = \
    weakref.WeakKeyDictionary()


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


class _Buffers:
    """What one call of the compiled loop writes: samples (one row per requested time),
    the crossings it settles, and the guards of the event it hands back."""

    EVENTS = 256

    def __init__(self, modes: _Modes, n_samples: int) -> None:
        n, p, cap = modes.n, modes.g0s.shape[1], self.EVENTS
        self.s_x = np.empty((n_samples, n))
        self.e_t, self.e_ptr = np.empty(cap), np.empty(cap, dtype=np.int64)
        self.e_row = np.empty(cap, dtype=np.int64)
        self.e_from, self.e_to = np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64)
        self.e_x, self.e_S = np.empty((cap, n)), np.empty((cap, n, n))
        self.hit, self.graze = np.zeros(p, dtype=np.int8), np.zeros(p, dtype=np.int8)


def _replay(run: Any, buf: _Buffers, ptr0: int, ptr: int, n_e: int, label: Any) -> None:
    """Record the samples and settled events of one call of the compiled loop, in time
    order (the samples up to an event's time come before it); ``label(row, i, j)`` gives the
    kind, index and mode numbers of the event from region ``i`` to ``j`` through ``row``."""
    te = run.t_eval
    for k in range(n_e):
        p = int(buf.e_ptr[k])
        if p > ptr0:
            run.rec.extend(te[ptr0:p], buf.s_x[ptr0:p])
        ptr0 = p
        x = buf.e_x[k].copy()
        kind, index, mode_from, mode_to = label(int(buf.e_row[k]), int(buf.e_from[k]),
                                                int(buf.e_to[k]))
        run.event(float(buf.e_t[k]), kind, index, x, x, mode_from, mode_to)
        if run.sensitivity:   # already multiplied into Φ by the loop
            run.saltations.append(buf.e_S[k].copy())
        run.rec.sample(float(buf.e_t[k]), x, force=True)
    if ptr > ptr0:
        run.rec.extend(te[ptr0:ptr], buf.s_x[ptr0:ptr])


def pwa_stepper(system: Any, x0: FloatArray, run: Any) -> SwitchingStepper:
    """The stepper of a PWA run: exact pieces (no input or an exosystem), or DOP853 pieces
    (an input given as a function of time)."""
    _check_x0(system, x0)
    exo = _exosystem(system, run.opts.u)
    if exo == "function":
        return _PwaOdeStepper(system, x0, run)
    modes = _Modes.of(system, exo)
    w_t0 = np.zeros(0) if exo is None else np.asarray(exo.w0, float).reshape(-1)
    if exo is not None and run.t0 != 0.0:   # the exosystem's state at t0
        w_t0 = expm(np.atleast_2d(np.asarray(exo.S, float)) * run.t0) @ w_t0
    xi = np.concatenate([x0, w_t0, [1.0]])
    i = modes.choose(xi)
    if i < 0:
        raise InadmissibleStateError(f"x0: {x0} lies in no region of the partition")
    return CompiledPiecesStepper(system, run, modes, xi, i)


class CompiledPiecesStepper(SwitchingStepper):
    """Exact pieces: one call of the compiled loop (:mod:`._pwa_kernels`) per
    :meth:`piece` from region ``i`` at the augmented state ``xi``, the events it settles
    recorded as :meth:`label` names them, and the event it hands back settled by
    :meth:`handoff` (a PWA's here; a Filippov system's in :mod:`._affine_filippov`)."""

    def __init__(self, system: Any, run: Any, modes: _Modes, xi: FloatArray, i: int,
                 first_sample: bool = True) -> None:
        super().__init__(run)
        self.system, self.modes, self.xi, self.i = system, modes, xi, i
        if not modes.ready[i]:
            modes.prepare(i)
        self.buf = _Buffers(modes, run.t_eval.shape[0])
        # t0 itself: the forced sample
        self.ptr = int(np.searchsorted(run.t_eval, run.t0, side="right"))
        if first_sample:
            run.rec.sample(run.t0, xi[:modes.n].copy(), force=True)
        self.segments = 0
        self.restart = False   # the first piece starts from the user's x0
        self.proj = np.zeros(5)   # round-off projections (_lti_kernels.project_restart)
        self.clock = np.array([np.nan, 0.0])   # the loop's time label and its rounding

    def state(self) -> FloatArray:
        return self.xi[:self.modes.n]

    def label(self, row: int, i: int, j: int) -> tuple[str, int, int, int]:
        """Kind, index, ``mode_from``, ``mode_to`` of a settled event (a PWA crossing)."""
        return "crossing", row, i, j

    def piece(self) -> float:
        from ...numerics.lti import TAYLOR_REMAINDER
        from ._pwa_kernels import (
            DONE,
            HANDOFF,
            INADMISSIBLE,
            MAX_STUCK,
            NEED_FLOW,
            STUCK,
            run_pieces,
        )

        run, modes, buf = self.run, self.modes, self.buf
        ptr0 = self.ptr
        user = not self.restart
        code, self.t, i, self.ptr, n_e, run.stuck, pieces, index = run_pieces(
            modes.kinds, modes.lams, modes.Vs, modes.Vinvs, modes.phis, modes.taylors,
            modes.ds, modes.hs, modes.kappas, modes.ready, modes.Ws, modes.g0s,
            modes.row_norms, modes.bern, TAYLOR_REMAINDER, 1e-12, 1e-12, modes.H, modes.h,
            modes.nf, modes.aug, self.xi, float(self.t), float(run.tf), int(self.i), run.Phi,
            run.sensitivity, run.t_eval, self.ptr, buf.s_x, buf.e_t, buf.e_row, buf.e_from,
            buf.e_to, buf.e_x, buf.e_S, buf.e_ptr, run.max_events - run.n_events + 1,
            buf.hit, buf.graze, run.stuck, self.restart, self.proj, self.clock)
        self.i = i
        self.restart = self.restart or code != NEED_FLOW or pieces > 0
        self.segments += pieces
        _replay(run, buf, ptr0, self.ptr, n_e, self.label)
        t = self.t
        if code == DONE:
            self.done = True
        elif code == NEED_FLOW:
            modes.prepare(i)
        elif code == STUCK:
            raise ZenoError(f"switching: {MAX_STUCK} consecutive events at t = {t:.12g} "
                            f"without progress (Zeno point or an undecidable mode)", time=t)
        elif code == INADMISSIBLE:
            self.inadmissible(t, i, index, user)
        elif code == HANDOFF:
            self.handoff(t, i, [int(r) for r in np.flatnonzero(buf.hit)])
        return t

    def inadmissible(self, t: float, i: int, index: int, user: bool) -> None:
        """A piece starts with guard ``index`` of region ``i`` violated: raise."""
        raise _inadmissible(self.modes, i, index, self.xi, t, self.proj, user)

    def handoff(self, t: float, i: int, hits: list[int]) -> None:
        """Settle the event the loop hands back at ``t`` in region ``i`` (guards ``hits``)."""
        grazing = bool(self.buf.graze[hits].all())
        self.done, self.i = _settle(self.system, self.modes, self.run, t, i, self.xi, hits,
                                    grazing)

    def extra(self) -> dict[str, Any]:
        return {"segments": self.segments, "final_mode": self.i, "propagation": "exact",
                **projection_stats(self.proj)}


def _inadmissible(modes: _Modes, i: int, index: int, xi: FloatArray, t: float,
                  proj: FloatArray, user: bool) -> InadmissibleStateError:
    """The error of a piece that starts with a facet of its region ``i`` violated."""
    if not user and proj[4] > 0.0:
        return InadmissibleStateError(
            f"switching: facet slack {index} of region {i} is negative at t = {t:.12g} "
            f"(g = {proj[3]:.3g}), beyond the integrator's round-off tolerance "
            f"{proj[4]:.3g} at a state it computed; the trajectory left its region. Check "
            f"that the partition's facets match between neighbouring regions")
    G, g0 = modes.guards[i]
    return InadmissibleStateError(
        f"x0: guard {index} of region {i} is negative at t = {t:.12g} (g = "
        f"{float(G[index] @ xi + g0[index]):.3g} < 0); start from a state inside its region "
        f"(every facet slack >= 0)")


def _settle(system: Any, modes: _Modes, run: Any, t: float, i: int, xi: FloatArray,
            hits: list[int], grazing: bool) -> tuple[bool, int]:
    """Python's handling of an event the compiled loop hands back (domain facets, grazing,
    no region to enter, a zero ``nᵀF⁻``): ``(whether the run stops, the region to go on
    in)``."""
    n = modes.n
    nr = int(modes.nf[i])
    x_e = xi[:n].copy()
    dom_rows = [r - nr for r in hits if r >= nr]
    hits = [r for r in hits if r < nr]
    if dom_rows and not grazing:
        r = _leaving_domain(system, modes, i, xi, dom_rows)
        if r >= 0:
            _domain_exit(run, t, r, x_e, i)
            return True, i
    if not hits:   # touched the domain boundary from inside and stays in: go on
        return False, i
    row = hits[0]
    j = modes.choose(xi, exclude=i)
    if grazing or j < 0:
        if j < 0 and not grazing and not modes.entering(i, xi, 1e-9):
            raise SlidingError(
                f"switching: at t = {t:.12g} the flow leaves region {i} through facet "
                f"{row} but no region's field points inward at x = {x_e}: a sliding motion "
                f"on a facet of a discontinuous PWA system. Simulate "
                f"FilippovSystem.from_pwa(system) instead", time=t, state=x_e)
        run.event(t, "grazing", row, x_e, x_e, i, i)
        return False, i
    normal = system.regions[i][0][row]
    S = saltation_matrix(modes.field(i, xi), modes.field(j, xi), normal) \
        if run.sensitivity else None
    run.event(t, "crossing", row, x_e, x_e, i, j, S)
    run.rec.sample(t, x_e, force=True)
    return False, j


class _PwaOdeStepper(SwitchingStepper):
    """Pieces by DOP853 for inputs given as arbitrary functions of time: one terminal event
    per facet (leaving the region) and per domain facet, and one non-terminal event per
    facet on the slack's derivative (grazing candidates: a minimum of the slack at zero);
    one piece and its event per :meth:`piece`."""

    def __init__(self, system: Any, x0: FloatArray, run: Any) -> None:
        from ...systems.lure import as_input_function

        super().__init__(run)
        u = system.u if run.opts.u is None else run.opts.u
        ufn = as_input_function("u", u, system.E.shape[1])
        if ufn is None:   # this path is taken only for inputs given as functions of time
            raise ModelError("u: expected an input function of time for the DOP853 path, "
                             "got None")
        self.ufn = ufn
        self.system, self.x = system, x0.copy()
        self.i = self.mode_at(self.x, self.t)
        if self.i < 0:
            raise InadmissibleStateError(f"x0: {x0} lies in no region of the partition")
        run.rec.sample(self.t, x0, force=True)
        self.segments = 0
        self.last_graze: dict[int, float] = {}

    def field(self, i: int, t: float, x: FloatArray) -> FloatArray:
        s = self.system
        return s.A[i] @ x + s.b[i] + s.E @ self.ufn(t)[0]

    def mode_at(self, x: FloatArray, t: float, exclude: int = -1) -> int:
        return _inward_region(self.system, self.field, x, t, exclude)

    def state(self) -> FloatArray:
        return self.x

    def piece(self) -> float:
        run, system, i, t = self.run, self.system, self.i, self.t
        events, kinds = _region_events(system, i, self.field)
        sol = run.dop853(lambda tt, xx, i=i: self.field(i, tt, xx), t, self.x, events)
        t_end = float(sol.t[-1])
        ts = run.samples(t, t_end, last=sol.status == 0)
        if ts.size and sol.sol is not None:
            run.rec.extend(ts, sol.sol(ts).T)
        if sol.status < 0:
            raise run.piece_failure(sol, t_end, f"in region {i}; check the input function for "
                                                f"NaN or infinite values")
        _record_ode_grazings(run, sol, kinds, system.regions[i], i, t_end, self.last_graze)
        if run.sensitivity:
            run.Phi = expm(system.A[i] * (t_end - t)) @ run.Phi
        self.segments += 1
        self.t, self.x = t_end, sol.y[:, -1].copy()
        if sol.status != 1:
            self.done = True
        else:
            self._event(sol, kinds)
        return self.t

    def _event(self, sol: Any, kinds: list[tuple[str, int]]) -> None:
        """The event that ended the piece: leaving the domain, or a crossing."""
        run, system, i, t, x = self.run, self.system, self.i, self.t, self.x
        hit = [k for k, te in enumerate(sol.t_events) if te.size and kinds[k][0] != "graze"
               and float(te[-1]) >= t]
        dom = [kinds[k][1] for k in hit if kinds[k][0] == "domain"]
        if not dom and system.domain is not None:   # a facet on the domain's boundary
            Hd, hd = system.domain                   # fired first: is the flow leaving?
            on = np.abs(hd - Hd @ x) <= 1e-9 * (1.0 + np.abs(hd) + np.abs(Hd) @ np.abs(x))
            dom = [int(r) for r in np.flatnonzero(on & (Hd @ self.field(i, t, x) > 0.0))]
        if dom:
            _domain_exit(run, t, dom[0], x, i)
            self.done = True
            return
        row = kinds[hit[0]][1]
        j = self.mode_at(x, t, exclude=i)
        if j < 0:
            raise SlidingError(f"switching: at t = {t:.12g} no region's field points inward "
                               f"at x = {x} (sliding on a discontinuous PWA facet); simulate "
                               f"FilippovSystem.from_pwa(system) instead", time=t,
                               state=x.copy())
        S = (saltation_matrix(self.field(i, t, x), self.field(j, t, x),
                              system.regions[i][0][row]) if run.sensitivity else None)
        run.event(t, "crossing", row, x, x, i, j, S)
        run.rec.sample(t, x, force=True)
        self.last_graze.clear()
        self.i = j

    def extra(self) -> dict[str, Any]:
        return {"segments": self.segments, "final_mode": self.i, "propagation": "dop853"}


def _inward_region(system: Any, field: Any, x: FloatArray, t: float, exclude: int) -> int:
    """A region (not ``exclude``) holding ``x`` whose field ``field(j, t, x)`` does not point
    out through a facet ``x`` lies on; -1 when none."""
    for j in range(system.n_regions):
        if j == exclude or not system.contains(j, x, 1e-9):
            continue
        H, hh = system.regions[j]
        act = np.abs(hh - H @ x) <= 1e-9 * (1 + np.abs(hh) + np.abs(H) @ np.abs(x))
        if not np.any(act) or np.all(H[act] @ field(j, t, x) <= 0.0):
            return j
    return -1


def _region_events(system: Any, i: int, field: Any) -> tuple[list[Any], list[tuple[str, int]]]:
    """The DOP853 events of a piece in region ``i``: per facet a terminal one (leaving) and a
    grazing candidate (the slack's minimum), and per domain facet a terminal one."""
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
    return events, kinds


def _record_ode_grazings(run: Any, sol: Any, kinds: list[tuple[str, int]],
                         region: tuple[FloatArray, FloatArray], i: int, t_end: float,
                         last_graze: dict[int, float]) -> None:
    """Record the grazings of a DOP853 piece in region ``i``: a slack minimum at zero (to
    100 times the solver's tolerance), once per touch."""
    H, h = region
    for k, (kind, r) in enumerate(kinds):
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
