"""Filippov systems for :mod:`nscontrol.simulate.switching`.

Each piece is integrated by DOP853 (``rtol``/``atol`` options) with one terminal event per
surface, armed in the direction that leaves the current side (so a piece that starts on a
surface never re-triggers it). At a hit of surface ``j`` with ``σ± = ∇h_jᵀF±``:

* ``σ⁻σ⁺ > 0``: crossing; saltation ``I + (F⁺ - F⁻)nᵀ/(nᵀF⁻)``;
* ``σ⁻ > 0 > σ⁺``: attracting sliding; the Filippov field
  ``F_s = (σ⁺F⁻ - σ⁻F⁺)/(σ⁺ - σ⁻)`` is integrated with exit events ``σ⁻ = 0`` (leave to the
  ``h < 0`` side) and ``σ⁺ = 0`` (leave to ``h > 0``); saltation at the start
  ``I + (F_s - F⁻)nᵀ/(nᵀF⁻)``, identity at a tangential exit;
* the arrival side's ``σ`` zero: grazing (recorded, the mode is kept);
* ``σ⁻ < 0 < σ⁺``: repelling sliding, refused (non-unique forward solutions).

Second-order sliding (relative degree two of the switching: ``∇h_jᵀ(F⁺ - F⁻) = 0`` on the
surface, as for the super-twisting controller whose sign acts on an integrator): the crossings
of ``h_j = 0`` accumulate in finite time at a point where ``h_j = σ_j = 0``. At a crossing where
``|σ|`` is below ``_TWO_SLIDING_SIGMA`` times its scale ``|∇h_j| |F|`` (or that follows the
previous crossing within ``1e-9 (1 + |t|)``), and the weight below lies in ``[0, 1]``, the motion
continues on ``h_j = σ̂_j = 0`` (event ``"two_sliding_start"``) with the field
``F₂ = F⁻ + α (F⁺ - F⁻)``, ``α = -(∂_t σ̂ + ∇σ̂ᵀF⁻) / ∇σ̂ᵀ(F⁺ - F⁻)`` (the equivalent control
that keeps ``σ̂`` at zero; ``σ̂`` is ``∇h_jᵀ(F⁺ + F⁻)/2`` evaluated at the point projected onto
the surface, so a non-smooth term that vanishes on the surface, such as ``|s|^{1/2}``, does not
enter its central differences). The entry state is projected onto ``h_j = 0``, then onto
``σ̂ = 0`` along ``F⁺ - F⁻`` (the only direction the switching moves the state in); the samples
onto ``h_j = 0``. The motion leaves (``"two_sliding_exit"``) when ``α`` reaches 0
or 1, to the side towards which ``σ̂`` then moves. Not available with ``sensitivity=True``.

A tangential touch without a sign change of ``h_k`` is caught by a non-terminal event on
``σ_k = ∇h_kᵀF`` of the current field, armed in the direction of an extremum of ``h_k`` towards
the surface: at a root where ``|h_k| <= 100 (atol + rtol |x|) |∇h_k|`` a ``grazing`` event is
recorded (the mode is kept).

While sliding on ``h_j = 0`` the samples and the state at the end of every sliding piece are
projected back onto the surface (Newton along ``∇h_j``), so the integration error of the
Filippov field does not accumulate off a curved surface.

With ``sensitivity=True`` the variational equation ``Φ' = J Φ`` (``J`` from
``system.jacobian`` or central differences; for ``F_s`` always by differences) is integrated
with the state.

A smooth :class:`~nscontrol.systems.nonlinear.NonlinearSystem` is the case of no surface
(:func:`run_smooth`): one DOP853 piece over the whole span, the variational equation with it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ModelError, SolverError
from ..numerics.differences import central_difference_jacobian
from .switching import saltation_matrix

_GRAZE_FACTOR = 100.0
#: Onset of second-order sliding at a crossing: |σ| below this times |∇h| |F|. In the
#: homogeneous (super-twisting) approximation the time still to go to the accumulation point
#: is proportional to |σ|, so this bounds the error of the reaching time by about 1e-7 times
#: the field's time scale.
_TWO_SLIDING_SIGMA = 1e-7
#: Central-difference step (relative) for the derivatives of σ̂: about eps^(1/3), balancing
#: the O(δ²) truncation against the O(eps/δ) rounding.
_FD_STEP = 6e-6


class _Fields:
    def __init__(self, system: Any) -> None:
        self.s = system
        self.J = system.n_surfaces

    def side(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int, side: int
             ) -> FloatArray:
        sg = list(signs)
        sg[j] = side
        return np.asarray(self.s.field(t, x, tuple(sg)), float)

    def sigmas(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int
               ) -> tuple[float, float, FloatArray, FloatArray, FloatArray]:
        n = self.s.gradient(j, x)
        fm, fp = self.side(t, x, signs, j, -1), self.side(t, x, signs, j, 1)
        return float(n @ fm), float(n @ fp), fm, fp, n

    def sliding(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int) -> FloatArray:
        sm, sp, fm, fp, _ = self.sigmas(t, x, signs, j)
        return (sp * fm - sm * fp) / (sp - sm)

    def sigma_hat(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int) -> float:
        """``∇h_jᵀ(F⁺ + F⁻)/2`` at ``x`` projected onto ``h_j = 0``."""
        sm, sp, _, _, _ = self.sigmas(t, _on_surface(self.s, j, x), signs, j)
        return 0.5 * (sm + sp)

    def two_sliding_terms(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int
                          ) -> tuple[float, float, FloatArray, FloatArray]:
        """``(a0, a1, F⁻, F⁺)``: ``dσ̂/dt = a0 + α a1`` along ``F⁻ + α (F⁺ - F⁻)``, all at
        ``x`` projected onto ``h_j = 0`` (a term like ``|h|^{1/2}`` would otherwise turn the
        integrator's O(1e-14) departures from the surface into O(1e-7) jumps of the field)."""
        x = _on_surface(self.s, j, x)
        fm, fp = self.side(t, x, signs, j, -1), self.side(t, x, signs, j, 1)
        scale = 1.0 + float(np.linalg.norm(x)) + abs(t)

        def along(dt: float, v: FloatArray) -> float:
            eps = _FD_STEP * scale / max(1.0, float(np.linalg.norm(v)), abs(dt))
            return (self.sigma_hat(t + eps * dt, x + eps * v, signs, j)
                    - self.sigma_hat(t - eps * dt, x - eps * v, signs, j)) / (2.0 * eps)

        return along(1.0, fm), along(0.0, fp - fm), fm, fp

    def two_sliding_weight(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int
                           ) -> float:
        """The weight ``α`` of ``F⁺`` that keeps ``σ̂`` at zero (NaN when none does)."""
        a0, a1 = self.two_sliding_terms(t, x, signs, j)[:2]
        return -a0 / a1 if a1 != 0.0 else float("nan")

    def two_sliding(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int
                    ) -> FloatArray:
        """The second-order sliding field ``F⁻ + α (F⁺ - F⁻)``."""
        a0, a1, fm, fp = self.two_sliding_terms(t, x, signs, j)
        return fm + (-a0 / a1) * (fp - fm)

    def rhs(self, signs: tuple[int, ...], sliding: int) -> Any:
        if sliding < 0:
            return lambda t, x: np.asarray(self.s.field(t, x, signs), float)
        return lambda t, x: self.sliding(t, x, signs, sliding)

    def jac(self, signs: tuple[int, ...], sliding: int) -> Any:
        if sliding < 0:
            return lambda t, x: self.s.jac(t, x, signs)
        f = self.rhs(signs, sliding)
        return lambda t, x: central_difference_jacobian(lambda xx: f(t, xx), x)


class _NoSurfaces:
    """A smooth system seen as a Filippov system with no switching surface, its input bound:
    the one field ``f(t, x, u(t))`` on the (only) side ``signs = ()``."""

    surfaces: tuple[Any, ...] = ()
    n_surfaces = 0

    def __init__(self, system: Any, u: Any) -> None:
        self.system = system
        self.n_states = system.n_states
        self.state_names = system.state_names
        self.u_of = system.input_function(u)

    def field(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return self.system.rhs(t, x, self.u_of(t))

    def jac(self, t: float, x: FloatArray, signs: tuple[int, ...]) -> FloatArray:
        return self.system.jac(t, x, self.u_of(t))

    def h(self, x: FloatArray) -> FloatArray:
        return np.zeros(0)


def run_smooth(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]
               ) -> dict[str, Any]:
    """Integrate a smooth :class:`~nscontrol.systems.nonlinear.NonlinearSystem` (input from
    ``options["u"]`` or the system's) by the Filippov path with no surface."""
    extra = run_filippov(_NoSurfaces(system, options.get("u")), x0, run, options)
    del extra["final_mode"]      # a single mode: nothing to report
    return extra


def _mode_code(signs: tuple[int, ...], sliding: int) -> int:
    code = sum(1 << j for j, s in enumerate(signs) if s > 0)
    return code + (sliding + 1) * (1 << len(signs)) if sliding >= 0 else code


def _tiny(a: float, b: FloatArray, c: FloatArray) -> float:
    return 1e-10 * float(np.linalg.norm(b) * np.linalg.norm(c)) + 1e-300


def _robust_sigmas(fields: _Fields, t: float, x: FloatArray, signs: tuple[int, ...], j: int
                   ) -> tuple[float, float, FloatArray, FloatArray, FloatArray]:
    """``σ⁻, σ⁺`` at a hit; a side whose ``σ`` vanishes (tangent field) is decided by the sign
    ``σ`` takes a moment later along that side's field."""
    sm, sp, fm, fp, n = fields.sigmas(t, x, signs, j)
    dt = 1e-7 * (1.0 + abs(t))
    if abs(sm) <= _tiny(sm, n, fm):
        sm = fields.sigmas(t + dt, x + dt * fm, signs, j)[0]
    if abs(sp) <= _tiny(sp, n, fp):
        sp = fields.sigmas(t + dt, x + dt * fp, signs, j)[1]
    return sm, sp, fm, fp, n


def _initial_mode(fields: _Fields, t: float, x: FloatArray) -> tuple[tuple[int, ...], int]:
    h = fields.s.h(x)
    signs = [1 if v > 0 else -1 for v in h]
    sliding = -1
    for j in np.flatnonzero(np.abs(h) <= 1e-12 * (1.0 + np.linalg.norm(x))):
        sm, sp, fm, fp, n = _robust_sigmas(fields, t, x, tuple(signs), int(j))
        if sm < 0 < sp:
            raise ModelError(f"x0: starts on surface {j} where both sides push away "
                             f"(repelling sliding, σ⁻ = {sm:.3g} < 0 < σ⁺ = {sp:.3g}): "
                             f"forward solutions are not unique; move x0 off the surface")
        if sm > 0 > sp and sliding < 0:
            sliding = int(j)
        elif sm < 0 and sp < 0:
            signs[j] = -1
        else:
            signs[j] = 1
    return tuple(signs), sliding


def run_filippov(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]
                 ) -> dict[str, Any]:
    from scipy.integrate import solve_ivp

    fields = _Fields(system)
    n = system.n_states
    t, x = run.t0, x0.copy()
    signs, sliding = _initial_mode(fields, t, x)
    second = -1                      # the surface of second-order sliding, -1 when none
    if sliding >= 0 and _two_sliding_onset(fields, t, x, signs, sliding, -np.inf):
        second, sliding = sliding, -1    # starts on s = s' = 0: no first-order sliding field
        x = _enter_two_sliding(fields, run, t, x, signs, second)
    run.rec.sample(t, x, force=True)
    if sliding >= 0:
        run.event(t, "sliding_start", sliding, x, x, _mode_code(signs, -1),
                  _mode_code(signs, sliding), np.eye(n))
    pieces = 0
    last_graze: dict[int, float] = {}
    last_cross: dict[int, float] = {}
    while t < run.tf:
        if second >= 0:
            f, (events, kinds) = _two_sliding_piece(system, fields, signs, second)
        else:
            f = fields.rhs(signs, sliding)
            events, kinds = _events(system, fields, signs, sliding)
        if run.sensitivity:
            rhs, y0 = _with_variational(f, fields.jac(signs, sliding), n), \
                np.concatenate([x, np.eye(n).ravel()])
        else:
            rhs, y0 = f, x
        sol = solve_ivp(rhs, (t, run.tf), y0, method="DOP853", rtol=run.rtol, atol=run.atol,
                        events=events, dense_output=True)
        t_end = float(sol.t[-1])
        ts = run.samples(t, t_end, last=sol.status == 0)
        if ts.size and sol.sol is not None:
            X = sol.sol(ts)[:n].T
            if max(sliding, second) >= 0:
                X = np.array([_project(system, max(sliding, second), xs) for xs in X])
            run.rec.extend(ts, X)
        if sol.status < 0:
            raise SolverError(f"switching: DOP853 failed at t = {t_end:.6g} "
                              f"({sol.message}); the field may be singular or blow up there. "
                              f"The trajectory up to that time is in err.trajectory",
                              status="dop853")
        _record_grazings(system, run, sol, kinds, signs, sliding, t_end, last_graze)
        if run.sensitivity:
            run.Phi = sol.y[n:, -1].reshape(n, n) @ run.Phi
        run.stuck = 0 if t_end > t else run.stuck
        if t_end <= t:
            run.zero_length(t_end)
        pieces += 1
        t, x = t_end, sol.y[:n, -1].copy()
        if max(sliding, second) >= 0:
            x = _project(system, max(sliding, second), x)
        run.bar.update(t)
        if sol.status != 1:
            break
        which = next(i for i, te in enumerate(sol.t_events)
                     if te.size and kinds[i][0] != "graze")
        kind, k = kinds[which]
        if kind == "exit2":
            signs = _leave_two_sliding(fields, run, t, x, signs, second, k)
            second = -1
            continue
        if kind == "exit":
            old = _mode_code(signs, sliding)
            new_signs = list(signs)
            new_signs[sliding] = k
            j, sliding, signs = sliding, -1, tuple(new_signs)
            run.event(t, "sliding_exit", j, x, x, old, _mode_code(signs, -1), np.eye(n))
            run.rec.sample(t, x, force=True)
            last_graze[j] = t   # a tangential exit: the σ root at its start is not a graze
            continue
        if sliding < 0 and second < 0 and _two_sliding_onset(fields, t, x, signs, k,
                                                              last_cross.get(k, -np.inf)):
            x = _enter_two_sliding(fields, run, t, x, signs, k)
            second = k
            continue
        last_cross[k] = t
        signs, sliding = _hit_surface(fields, run, t, x, signs, sliding, k)
        last = run.rec.events[-1] if run.rec.events else None
        if last is not None and last.kind == "grazing" and last.index == k:
            last_graze[k] = t   # a σ root right after this touch is the same grazing
        run.rec.sample(t, x, force=True)
    if run.rec.last_time < run.tf:
        run.rec.sample(run.tf, x, force=True)
    final = _two_sliding_code(signs, second) if second >= 0 else _mode_code(signs, sliding)
    return {"pieces": pieces, "final_mode": final,
            "propagation": "dop853"}


def _two_sliding_code(signs: tuple[int, ...], j: int) -> int:
    """Mode number of second-order sliding on surface ``j``: after those of first order."""
    return _mode_code(signs, j) + (len(signs) + 1) * (1 << len(signs))


def _two_sliding_onset(fields: _Fields, t: float, x: FloatArray, signs: tuple[int, ...],
                       k: int, previous: float) -> bool:
    """Whether a crossing of surface ``k`` at ``(t, x)`` is the accumulation point of a
    second-order sliding motion (see the module's notes)."""
    sm, sp, fm, fp, nrm = fields.sigmas(t, x, signs, k)
    scale = float(np.linalg.norm(nrm)) * max(float(np.linalg.norm(fm)),
                                             float(np.linalg.norm(fp))) + 1e-300
    if abs(sp - sm) > 1e-10 * scale:        # the switching acts on h' itself: first order
        return False
    near = abs(sm) <= _TWO_SLIDING_SIGMA * scale or t - previous <= 1e-9 * (1.0 + abs(t))
    return near and 0.0 <= fields.two_sliding_weight(t, x, signs, k) <= 1.0


def _enter_two_sliding(fields: _Fields, run: Any, t: float, x: FloatArray,
                       signs: tuple[int, ...], k: int) -> FloatArray:
    """Project ``x`` onto ``h_k = 0``, then onto ``σ̂_k = 0`` by one Newton step along
    ``F⁺ - F⁻`` (the only direction the switching moves the state in, tangent to the surface;
    a state the switching does not act on, such as an exosystem's, is left alone); record
    ``"two_sliding_start"`` and return the projected state."""
    if run.sensitivity:
        raise ModelError(f"sensitivity: not available through second-order sliding (reached "
                         f"on surface {k} at t = {t:.12g}); run with sensitivity=False")
    system = fields.s
    y = _project(system, k, x)
    _, a1, fm, fp = fields.two_sliding_terms(t, y, signs, k)
    if a1 != 0.0:
        y = y - fields.sigma_hat(t, y, signs, k) / a1 * (fp - fm)
    run.event(t, "two_sliding_start", k, x, y, _mode_code(signs, -1),
              _two_sliding_code(signs, k))
    run.rec.sample(t, y, force=True)
    return y


def _leave_two_sliding(fields: _Fields, run: Any, t: float, x: FloatArray,
                       signs: tuple[int, ...], k: int, bound: int) -> tuple[int, ...]:
    """Leave second-order sliding on surface ``k`` (``α`` reached ``bound`` 0 or 1) to the side
    ``σ̂`` moves to: beyond the bound both fields move it the same way, with the sign of
    ``a1`` (bound 0) or of ``-a1`` (bound 1)."""
    a1 = fields.two_sliding_terms(t, x, signs, k)[1]
    side = (1 if a1 > 0 else -1) * (1 if bound == 0 else -1)
    new = list(signs)
    new[k] = side
    out = tuple(new)
    run.event(t, "two_sliding_exit", k, x, x, _two_sliding_code(signs, k), _mode_code(out, -1))
    run.rec.sample(t, x, force=True)
    return out


def _two_sliding_piece(system: Any, fields: _Fields, signs: tuple[int, ...], j: int
                       ) -> tuple[Any, tuple[list[Any], list[tuple[str, int]]]]:
    """Field and events of a piece in second-order sliding on surface ``j``: the other
    surfaces' events as in first order, and the exits ``α = 0`` (falling) and ``α = 1``
    (rising), both terminal."""
    events, kinds = _events(system, fields, signs, -1)
    keep = [i for i, (_, k) in enumerate(kinds) if k != j]
    events, kinds = [events[i] for i in keep], [kinds[i] for i in keep]
    n = system.n_states

    def exit_event(bound: int) -> Any:
        def ev(t: float, y: FloatArray) -> float:
            return fields.two_sliding_weight(t, y[:n], signs, j) - bound
        ev.terminal, ev.direction = True, -1.0 if bound == 0 else 1.0  # type: ignore[attr-defined]  # solve_ivp reads these
        return ev

    for bound in (0, 1):
        events.append(exit_event(bound))
        kinds.append(("exit2", bound))
    return (lambda t, x: fields.two_sliding(t, x, signs, j)), (events, kinds)


def _on_surface(system: Any, j: int, x: FloatArray) -> FloatArray:
    """``x`` projected onto ``h_j = 0``, then nudged (Newton steps on one coordinate, down to
    one ulp) until ``h_j`` is exactly zero in floating point when such a nudge exists: a term
    like ``|h|^{1/2}`` of the field turns a rounding-level ``h`` of 1e-16 into a 1e-8 jump,
    which central differences and the integrator's error control would amplify."""
    y = _project(system, j, x)
    g = system.gradient(j, y)
    hv = float(system.surfaces[j](y))
    for i in np.argsort(-np.abs(g))[:2]:
        for _ in range(4):
            if hv == 0.0 or g[i] == 0.0:
                return y
            cand = y.copy()
            step = cand[i] - hv / g[i]
            cand[i] = step if step != cand[i] else np.nextafter(
                cand[i], -np.inf if hv * g[i] > 0 else np.inf)
            hc = float(system.surfaces[j](cand))
            if not abs(hc) < abs(hv):
                break
            y, hv = cand, hc
    return y


def _project(system: Any, j: int, x: FloatArray) -> FloatArray:
    """``x`` moved back onto ``h_j = 0`` by Newton steps along ``∇h_j`` (at most 4)."""
    best = x
    hb = abs(float(system.surfaces[j](x)))
    for _ in range(4):
        if hb == 0.0:
            break
        g = system.gradient(j, best)
        gg = float(g @ g)
        if gg == 0.0:
            break
        cand = best - float(system.surfaces[j](best)) / gg * g
        hc = abs(float(system.surfaces[j](cand)))
        if not hc < hb:
            break
        best, hb = cand, hc
    return best


def _record_grazings(system: Any, run: Any, sol: Any, kinds: list[tuple[str, int]],
                     signs: tuple[int, ...], sliding: int, t_end: float,
                     last_graze: dict[int, float]) -> None:
    """Grazing events from the roots of ``σ_k`` found in the piece (before its end)."""
    n = system.n_states
    found = []
    for i, (kind, k) in enumerate(kinds):
        if kind != "graze":
            continue
        for tr in sol.t_events[i]:
            tr = float(tr)
            if tr >= t_end and sol.status == 1:
                continue
            xr = sol.sol(tr)[:n]
            g = system.gradient(k, xr)
            tol = _GRAZE_FACTOR * (run.atol + run.rtol * float(np.max(np.abs(xr)))) * \
                float(np.linalg.norm(g))
            if abs(float(system.surfaces[k](xr))) > tol:
                continue
            if abs(tr - last_graze.get(k, -np.inf)) <= 1e-9 * (1.0 + abs(tr)):
                continue
            found.append((tr, k, xr))
    code = _mode_code(signs, sliding)
    for tr, k, xr in sorted(found, key=lambda e: e[0]):
        last_graze[k] = tr
        run.event(tr, "grazing", k, xr, xr, code, code)
        run.rec.sample(tr, xr, force=True)


def _events(system: Any, fields: _Fields, signs: tuple[int, ...], sliding: int
            ) -> tuple[list[Any], list[tuple[str, int]]]:
    """Events of a piece: each surface armed in the direction leaving the current side
    (terminal), the extrema of each surface function towards it (``σ_k = 0``, non-terminal:
    grazing candidates), and while sliding the exits ``σ⁻ = 0`` (falling) and ``σ⁺ = 0``
    (rising, terminal)."""
    n = system.n_states
    events: list[Any] = []
    kinds: list[tuple[str, int]] = []

    def surface(k: int) -> Any:
        def ev(t: float, y: FloatArray) -> float:
            return float(system.surfaces[k](y[:n]))
        ev.terminal, ev.direction = True, -float(signs[k])  # type: ignore[attr-defined]  # solve_ivp reads these
        return ev

    def exit_event(side: int) -> Any:
        def ev(t: float, y: FloatArray) -> float:
            return float(fields.sigmas(t, y[:n], signs, sliding)[0 if side < 0 else 1])
        ev.terminal, ev.direction = True, float(side)  # type: ignore[attr-defined]  # solve_ivp reads these
        return ev

    def graze(k: int) -> Any:
        def ev(t: float, y: FloatArray) -> float:
            x = y[:n]
            return float(system.gradient(k, x) @ fields.rhs(signs, sliding)(t, x))
        ev.terminal, ev.direction = False, float(signs[k])  # type: ignore[attr-defined]  # solve_ivp reads these
        return ev

    for k in range(len(signs)):
        if k != sliding:
            events.append(surface(k))
            kinds.append(("surface", k))
            events.append(graze(k))
            kinds.append(("graze", k))
    if sliding >= 0:
        for side in (-1, 1):
            events.append(exit_event(side))
            kinds.append(("exit", side))
    return events, kinds


def _with_variational(f: Any, jf: Any, n: int) -> Any:
    """The right-hand side of ``[x; vec Φ]`` with ``Φ' = J(x) Φ``."""
    def rhs(t: float, y: FloatArray) -> FloatArray:
        Phi = y[n:].reshape(n, n)
        return np.concatenate([f(t, y[:n]), (jf(t, y[:n]) @ Phi).ravel()])
    return rhs


def _hit_surface(fields: _Fields, run: Any, t: float, x: FloatArray, signs: tuple[int, ...],
                 sliding: int, k: int) -> tuple[tuple[int, ...], int]:
    """Classify a hit of surface ``k`` and record the event; returns the new mode."""
    sm0, sp0, _, _, _ = fields.sigmas(t, x, signs, k)
    sm, sp, fm, fp, nrm = _robust_sigmas(fields, t, x, signs, k)
    came = signs[k]
    arrival_sigma = sm0 if came < 0 else sp0
    old = _mode_code(signs, sliding)
    flipped = list(signs)
    flipped[k] = -came
    flipped_t = tuple(flipped)
    f_before = fields.rhs(signs, sliding)(t, x)
    if abs(arrival_sigma) <= _tiny(arrival_sigma, nrm, fm if came < 0 else fp):
        run.event(t, "grazing", k, x, x, old, old)
        return signs, sliding
    if sm * sp > 0:  # crossing (also while sliding on another surface)
        slide_after = sliding
        if sliding >= 0:  # does the sliding on `sliding` survive with the new fields?
            jm, jp = fields.sigmas(t, x, flipped_t, sliding)[:2]
            if not jm > 0 > jp:
                slide_after = -1
                flipped[sliding] = -1 if jm <= 0 else 1
                flipped_t = tuple(flipped)
        f_after = fields.rhs(flipped_t, slide_after)(t, x)
        S = saltation_matrix(f_before, f_after, nrm) if run.sensitivity else None
        run.event(t, "crossing", k, x, x, old, _mode_code(flipped_t, slide_after), S)
        if slide_after < 0 <= sliding:  # the crossing's saltation already maps F_s to F⁺
            run.event(t, "sliding_exit", sliding, x, x, _mode_code(flipped_t, sliding),
                      _mode_code(flipped_t, -1), np.eye(x.shape[0]))
        return flipped_t, slide_after
    if sm > 0 > sp:  # attracting sliding
        if sliding >= 0:
            raise ModelError(f"switching: at t = {t:.12g} the motion slides on surfaces "
                             f"{sliding} and {k} at once (codimension-2 sliding), which is "
                             f"not supported")
        f_s = (sp * fm - sm * fp) / (sp - sm)
        S = saltation_matrix(f_before, f_s, nrm) if run.sensitivity else None
        run.event(t, "sliding_start", k, x, x, old, _mode_code(signs, k), S)
        return signs, k
    raise ModelError(f"switching: repelling sliding on surface {k} at t = {t:.12g}, x = {x} "
                     f"(σ⁻ = {sm:.3g} < 0 < σ⁺ = {sp:.3g}): forward solutions are not "
                     f"unique; change the model or the initial state")
