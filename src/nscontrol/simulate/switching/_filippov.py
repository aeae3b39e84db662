"""Filippov systems for :mod:`nscontrol.simulate.switching`.

Each piece is integrated by DOP853 (``rtol``/``atol`` options; steps counted on the run's
``max_steps`` budget, none below ``min_rel_step`` of the span) with one terminal event per
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
that keeps ``σ̂`` at zero; ``σ̂ = ∇h_jᵀ(F⁺ + F⁻)/2``). Every field of this piece is the side's
field **restricted to the surface** (:meth:`_Fields.on_surface`): the mean of its values at
the two points ``±d`` along the normal, ``d = 1e-6 (1 + |x|)``. A smooth field is met to
``O(d²)``; a continuous term odd in ``h_j``, such as the super-twisting's ``|s|^{1/2} sign s``,
cancels. Evaluated on the surface itself, that term turns a rounding-level ``h_j`` of 1e-17
into a 1e-8 jump of the field, the central differences of ``σ̂`` into jumps of ``α`` of 1e-3,
and DOP853's steps into an endless shrinking (the hang of issue 29); restricted, the piece's
field is Lipschitz, ``α``'s five-point differences (step ``1e-3 (1 + |x|)``) carry a relative
error of about 1e-10, and the steps are those of a smooth problem. Hypothesis: the field's
non-smooth dependence on ``h_j`` near the surface is odd (an even term such as ``|h_j|^{1/2}``
would be met only to ``O(√d)``). The entry state is projected onto ``h_j = 0``, then onto
``σ̂ = 0`` along ``F⁺ - F⁻`` (the only direction the switching moves the state in); the
samples onto ``h_j = 0``. The motion leaves (``"two_sliding_exit"``) when ``α`` reaches 0 or
1, to the side towards which ``σ̂`` then moves. Not available with ``sensitivity=True``.

A piece that starts within rounding of a surface (at a crossing, at a tangential exit) starts
strictly on its side of it, moved by a few roundings (:func:`_onto_sides`): from the far side
its event could miss a return to the surface within the first step, from the surface itself
fire at once, again and again.

A tangential touch without a sign change of ``h_k`` is caught by a non-terminal event on
``σ_k = ∇h_kᵀF`` of the current field, armed in the direction of an extremum of ``h_k`` towards
the surface: at a root where ``|h_k| <= 100 (atol + rtol |x|) |∇h_k|`` a ``grazing`` event is
recorded (the mode is kept).

While sliding on ``h_j = 0`` the samples and the state at the end of every sliding piece are
projected back onto the surface (Newton along ``∇h_j``, a piece's samples in one call), so the
integration error of the Filippov field does not accumulate off a curved surface.

With ``sensitivity=True`` the variational equation ``Φ' = J Φ`` (``J`` from
``system.jacobian`` or central differences; for ``F_s`` always by differences) is integrated
with the state.

A smooth :class:`~nscontrol.systems.nonlinear.NonlinearSystem` is the case of no surface
(:func:`run_smooth`): one DOP853 piece over the whole span, the variational equation with it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError
from ...numerics.differences import central_difference_jacobian
from ._run import SwitchingStepper, saltation_matrix

_GRAZE_FACTOR = 100.0
#: Onset of second-order sliding at a crossing: |σ| below this times |∇h| |F|. In the
#: homogeneous (super-twisting) approximation the time still to go to the accumulation point
#: is proportional to |σ|, so this bounds the error of the reaching time by about 1e-7 times
#: the field's time scale.
_TWO_SLIDING_SIGMA = 1e-7
#: Five-point central-difference step (relative to 1 + |x|) for the derivatives of σ̂: about
#: eps^(1/5) = 7e-4, balancing the O(ε⁴) truncation against the O(eps/ε) rounding.
_FD_STEP = 1e-3
#: Normal distance (relative to 1 + |x|) of the two points whose mean is a field restricted to
#: a surface: a smooth field is met to O(d²) = 1e-12 relative; an odd |h|^{1/2} term cancels up
#: to its rounding k eps |x| / (2 √d), about 1e-13 k.
_NORMAL_OFFSET = 1e-6


class _Fields:
    def __init__(self, system: Any) -> None:
        self.s = system
        self.J = system.n_surfaces
        self._terms_key: tuple[Any, ...] | None = None
        self._terms: tuple[float, float, FloatArray, FloatArray] = (0.0, 0.0, np.zeros(0),
                                                                    np.zeros(0))

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
        """The Filippov field on surface ``j`` (:func:`._filippov_kernels.filippov_field`)."""
        from ._filippov_kernels import filippov_field

        fm, fp = self.side(t, x, signs, j, -1), self.side(t, x, signs, j, 1)
        return filippov_field(fm, fp, np.asarray(self.s.gradient(j, x), float))

    def on_surface(self, t: float, y: FloatArray, signs: tuple[int, ...], j: int, side: int
                   ) -> FloatArray:
        """The field of side ``side`` restricted to ``h_j = 0`` near ``y``: the mean of its
        values at the two points at distance ``±d`` along the unit normal from ``y``'s
        first-order projection, ``d = _NORMAL_OFFSET (1 + |y|)``.

        A field smooth across the surface is met to ``O(d²)``; a continuous term odd in
        ``h_j`` such as ``k |h_j|^{1/2} sign h_j`` (the super-twisting's) cancels, leaving
        ``k e / (2 √(d |∇h_j|))`` for a rounding ``e`` of ``h_j`` at the two points, so the
        result is Lipschitz in ``y`` where the field itself is not (its slope in ``h_j`` is
        unbounded at ``h_j = 0``, which no rounding-level evaluation on the surface avoids).
        """
        g = self.s.gradient(j, y)
        gn = float(np.linalg.norm(g))
        if gn == 0.0:
            return self.side(t, y, signs, j, side)
        base = y - float(self.s.surfaces[j](y)) / (gn * gn) * g
        off = (_NORMAL_OFFSET * (1.0 + float(np.linalg.norm(y))) / gn) * g
        return 0.5 * (self.side(t, base + off, signs, j, side)
                      + self.side(t, base - off, signs, j, side))

    def sigma_hat(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int) -> float:
        """``∇h_jᵀ(F⁺ + F⁻)/2`` of the fields restricted to ``h_j = 0``
        (:meth:`on_surface`), at ``x`` projected onto the surface."""
        y = _project(self.s, j, x)
        fm = self.on_surface(t, y, signs, j, -1)
        fp = self.on_surface(t, y, signs, j, 1)
        return 0.5 * float(self.s.gradient(j, y) @ (fm + fp))

    def two_sliding_terms(self, t: float, x: FloatArray, signs: tuple[int, ...], j: int
                          ) -> tuple[float, float, FloatArray, FloatArray]:
        """``(a0, a1, F⁻, F⁺)``: ``dσ̂/dt = a0 + α a1`` along ``F⁻ + α (F⁺ - F⁻)``, the
        fields restricted to ``h_j = 0`` at ``x`` projected onto the surface. The derivatives
        of ``σ̂`` are five-point central differences (truncation ``O(ε⁴)`` and rounding
        ``O(eps/ε)`` balance near ``ε = 1e-3``) of a function smooth along the surface, so
        ``α`` is smooth too and an adaptive step never shrinks on its noise."""
        key = (t, x.tobytes(), signs, j)
        if key == self._terms_key:   # the step's last stage, then its events, ask again
            return self._terms
        y = _project(self.s, j, x)
        fm = self.on_surface(t, y, signs, j, -1)
        fp = self.on_surface(t, y, signs, j, 1)
        scale = 1.0 + float(np.linalg.norm(y))

        def along(dt: float, v: FloatArray) -> float:
            eps = _FD_STEP * scale / max(1.0, float(np.linalg.norm(v)), abs(dt))

            def at(k: float) -> float:
                return self.sigma_hat(t + k * eps * dt, y + k * eps * v, signs, j)
            return (8.0 * (at(1.0) - at(-1.0)) - (at(2.0) - at(-2.0))) / (12.0 * eps)

        self._terms_key = key
        self._terms = (along(1.0, fm), along(0.0, fp - fm), fm, fp)
        return self._terms

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


def smooth_stepper(system: Any, x0: FloatArray, run: Any) -> SwitchingStepper:
    """The stepper of a smooth :class:`~nscontrol.systems.nonlinear.NonlinearSystem` (input
    from the ``u`` option or the system's): the Filippov path with no surface."""
    return FilippovStepper(_NoSurfaces(system, run.opts.u), x0, run, smooth=True)


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


def start_mode(fields: _Fields, run: Any, t: float, x: FloatArray
               ) -> tuple[FloatArray, tuple[int, ...], int, int]:
    """The mode a run starts in at ``(t, x)``, its first sample and (on a surface) its sliding
    start recorded: ``(x, signs, sliding, second)`` (``x`` projected when the motion starts
    in second-order sliding, ``-1`` for no sliding of either order)."""
    signs, sliding = _initial_mode(fields, t, x)
    second = -1
    if sliding >= 0 and _two_sliding_onset(fields, t, x, signs, sliding, -np.inf):
        second, sliding = sliding, -1  # starts on s = s' = 0: no first-order field
        x = _enter_two_sliding(fields, run, t, x, signs, second)
    run.rec.sample(t, x, force=True)
    if sliding >= 0:
        run.event(t, "sliding_start", sliding, x, x, _mode_code(signs, -1),
                  _mode_code(signs, sliding), np.eye(x.shape[0]))
    return x, signs, sliding, second


class FilippovStepper(SwitchingStepper):
    """A Filippov run: one DOP853 piece of the current mode and the event that ends it per
    :meth:`piece` (crossing, sliding start or exit, second-order sliding)."""

    def __init__(self, system: Any, x0: FloatArray, run: Any, smooth: bool = False,
                 mode: tuple[tuple[int, ...], int] | None = None) -> None:
        super().__init__(run)
        self.system, self.smooth = system, smooth
        self.fields = fields = _Fields(system)
        self.pieces = 0
        self.last_graze: dict[int, float] = {}
        self.last_cross: dict[int, float] = {}
        self.second = -1                 # the surface of second-order sliding, -1 when none
        if mode is not None:             # resumed at (run.t0, x0) in a known mode: see resume
            self.x, (self.signs, self.sliding) = x0.copy(), mode
            return
        self.x, self.signs, self.sliding, self.second = start_mode(fields, run, self.t,
                                                                   x0.copy())

    @classmethod
    def resume(cls, system: Any, run: Any, t: float, x: FloatArray,
               mode: tuple[tuple[int, ...], int]) -> FilippovStepper:
        """The Python stepper going on from ``(t, x)`` in ``mode = (signs, sliding)`` (the
        compiled path, :mod:`._affine_filippov`, hands it an event it does not settle),
        nothing recorded."""
        stepper = cls(system, x, run, mode=mode)
        stepper.t = t
        return stepper

    def state(self) -> FloatArray:
        return self.x

    def piece(self) -> float:
        sol, kinds, self.t, self.x = _piece(self.system, self.fields, self.run, self.t,
                                            self.x, self.signs, self.sliding, self.second,
                                            self.last_graze)
        self.pieces += 1
        if sol.status != 1:
            self.done = True
            return self.t
        which = next(i for i, te in enumerate(sol.t_events)
                     if te.size and kinds[i][0] != "graze")
        self.settle(*kinds[which])
        return self.t

    def settle(self, kind: str, k: int) -> None:
        """The event of kind ``kind`` on surface (or side) ``k`` that ended the piece."""
        fields, run, t, x, n = self.fields, self.run, self.t, self.x, self.system.n_states
        signs, sliding = self.signs, self.sliding
        if kind == "exit2":
            self.signs = _leave_two_sliding(fields, run, t, x, signs, self.second, k)
            self.second = -1
            return
        if kind == "exit":
            old = _mode_code(signs, sliding)
            new_signs = list(signs)
            new_signs[sliding] = k
            j, self.sliding, self.signs = sliding, -1, tuple(new_signs)
            run.event(t, "sliding_exit", j, x, x, old, _mode_code(self.signs, -1), np.eye(n))
            run.rec.sample(t, x, force=True)
            self.last_graze[j] = t  # a tangential exit: the σ root at its start is no graze
            return
        if sliding < 0 and self.second < 0 and _two_sliding_onset(
                fields, t, x, signs, k, self.last_cross.get(k, -np.inf)):
            self.x = _enter_two_sliding(fields, run, t, x, signs, k)
            self.second = k
            return
        self.last_cross[k] = t
        self.signs, self.sliding = _hit_surface(fields, run, t, x, signs, sliding, k)
        last = run.rec.events[-1] if run.rec.events else None
        if last is not None and last.kind == "grazing" and last.index == k:
            self.last_graze[k] = t   # a σ root right after this touch is the same grazing
        run.rec.sample(t, x, force=True)

    def extra(self) -> dict[str, Any]:
        if self.smooth:          # a single mode: nothing to report
            return {"pieces": self.pieces, "propagation": "dop853"}
        final = (_two_sliding_code(self.signs, self.second) if self.second >= 0
                 else _mode_code(self.signs, self.sliding))
        return {"pieces": self.pieces, "final_mode": final, "propagation": "dop853"}


def _piece(system: Any, fields: _Fields, run: Any, t: float, x: FloatArray,
           signs: tuple[int, ...], sliding: int, second: int, last_graze: dict[int, float]
           ) -> tuple[Any, list[Any], float, FloatArray]:
    """One DOP853 piece of the current mode from ``(t, x)`` to its first event (or ``tf``):
    its samples and grazings recorded, the sensitivity advanced. Returns the solution, the
    kinds of its events, and the end time and state (projected onto a sliding surface)."""
    n = system.n_states
    if second >= 0:
        f, (events, kinds) = _two_sliding_piece(system, fields, signs, second)
    else:
        f = fields.rhs(signs, sliding)
        events, kinds = _events(system, fields, signs, sliding)
    x = _onto_sides(system, signs, max(sliding, second), x)
    if run.sensitivity:
        rhs, y0 = _with_variational(f, fields.jac(signs, sliding), n), \
            np.concatenate([x, np.eye(n).ravel()])
    else:
        rhs, y0 = f, x
    sol = run.dop853(rhs, t, y0, events)
    t_end = float(sol.t[-1])
    ts = run.samples(t, t_end, last=sol.status == 0)
    if ts.size and sol.sol is not None:
        X = sol.sol(ts)[:n].T
        if max(sliding, second) >= 0:
            X = _project_rows(system, max(sliding, second), X)
        run.rec.extend(ts, X)
    if sol.status < 0:
        raise run.piece_failure(sol, t_end, "the field may be singular or blow up there")
    _record_grazings(system, run, sol, kinds, signs, sliding, t_end, last_graze)
    if run.sensitivity:
        run.Phi = sol.y[n:, -1].reshape(n, n) @ run.Phi
    run.stuck = 0 if t_end > t else run.stuck
    if t_end <= t:
        run.zero_length(t_end)
    x = sol.y[:n, -1].copy()
    if max(sliding, second) >= 0:
        x = _project(system, max(sliding, second), x)
    return sol, kinds, t_end, x


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


def _project(system: Any, j: int, x: FloatArray) -> FloatArray:
    """``x`` moved back onto ``h_j = 0`` (:func:`_project_rows` of the one state)."""
    return _project_rows(system, j, x[None, :])[0]


def _project_rows(system: Any, j: int, X: FloatArray) -> FloatArray:
    """Every row of ``X`` moved back onto ``h_j = 0`` by Newton steps along ``∇h_j`` (at
    most 4), a step kept while it lowers ``|h_j|``: the rows still moving step together, the
    surface and its gradient called once per row and step (a sliding piece's samples are
    projected in one call)."""
    h = system.surfaces[j]
    out = np.array(X, float)
    hb = np.array([float(h(x)) for x in out])
    rows = np.flatnonzero(hb != 0.0)
    for _ in range(4):
        if rows.size == 0:
            break
        G = np.array([system.gradient(j, out[i]) for i in rows]).reshape(rows.size, -1)
        gg = np.einsum("ij,ij->i", G, G)
        rows, G, gg = rows[gg != 0.0], G[gg != 0.0], gg[gg != 0.0]
        cand = out[rows] - (hb[rows] / gg)[:, None] * G
        hc = np.array([float(h(x)) for x in cand])
        better = np.abs(hc) < np.abs(hb[rows])
        rows, cand, hc = rows[better], cand[better], hc[better]
        out[rows], hb[rows] = cand, hc
        rows = rows[hc != 0.0]
    return out


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


def _onto_sides(system: Any, signs: tuple[int, ...], skip: int, x: FloatArray) -> FloatArray:
    """``x`` moved, by a few roundings of ``h_k`` along ``∇h_k``, strictly onto the side
    ``signs[k]`` of every surface ``k != skip`` it lies within rounding of (as the state located
    at a crossing or a tangential exit does). Left on the far side of the surface by a rounding,
    a piece's event would miss a return to the surface within its first step (``h_k`` starting
    beyond the level and coming back before the step's end); left at ``h_k = 0`` exactly, it
    would fire at the piece's very start, again and again. A state farther than 1000 roundings
    from the surface is left alone."""
    y = x
    for k, side in enumerate(signs):
        if k == skip:
            continue
        h = float(system.surfaces[k](y))
        g = system.gradient(k, y)
        gg = float(g @ g)
        ulp = np.finfo(float).eps * (abs(h) + float(np.sqrt(gg) * np.linalg.norm(y)))
        if side * h > 0.0 or gg == 0.0 or abs(h) > 1000.0 * ulp:
            continue
        step = ulp
        for _ in range(8):
            cand = y + (side * step - h) / gg * g
            if side * float(system.surfaces[k](cand)) > 0.0:
                y = cand
                break
            step *= 2.0
    return y


def _events(system: Any, fields: _Fields, signs: tuple[int, ...], sliding: int
            ) -> tuple[list[Any], list[tuple[str, int]]]:
    """Events of a piece: each surface armed in the direction leaving the current side
    (terminal; the piece starts strictly on that side, :func:`_onto_sides`), the extrema of
    each surface function towards it (``σ_k = 0``, non-terminal: grazing candidates), and
    while sliding the exits ``σ⁻ = 0`` (falling) and ``σ⁺ = 0`` (rising, terminal)."""
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
        from ._filippov_kernels import filippov_combination

        S = saltation_matrix(f_before, filippov_combination(sm, sp, fm, fp), nrm) \
            if run.sensitivity else None
        run.event(t, "sliding_start", k, x, x, old, _mode_code(signs, k), S)
        return signs, k
    raise ModelError(f"switching: repelling sliding on surface {k} at t = {t:.12g}, x = {x} "
                     f"(σ⁻ = {sm:.3g} < 0 < σ⁺ = {sp:.3g}): forward solutions are not "
                     f"unique; change the model or the initial state")
