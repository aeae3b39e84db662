"""PWM-switched affine systems for :mod:`nscontrol.simulate.switching`.

At each sampling instant ``t_k = t0 + kT`` (computed from ``k``, never accumulated) the
controller reads ``x(t_k)`` and its schedule gives the switching instants ``t_k + o_j`` of the
period in closed form. The state is carried from instant to instant over the differences of
these exact instants, each piece propagated exactly by the mode's
:class:`~nscontrol.numerics.lti.LTIFlow` on the augmented state ``[x; 1]``
(:meth:`SwitchedAffineSystem.flow`, shared across runs). So neither the instants nor the times
at which the duty is evaluated drift over long runs.

Sensitivity (``sensitivity=True``). Over the period from ``t_k`` the transition starts at
``I``; each piece multiplies it by its mode's ``e^{A_σ Δ}``; at each switching instant
``s_j = t_k + o_j(d(x_k))`` whose offset moves with the duty, the term
``(f_before - f_after)(x(s_j)) ∂s_j/∂x_k`` is added
(:func:`nscontrol.numerics.saltation.time_shift_term`), with
``∂s_j/∂x_k = (∂o_j/∂d) ∇d(x_k)``: the duty reads the **sampled** state, so the instants
depend on ``x_k`` and on nothing later (the instantaneous state's saltation is the identity,
and ``stats["saltation_matrices"]`` is empty). ``∂o_j/∂d`` is ``±1/2`` for the two edges of
a centred pulse, ``1`` for the falling edge of a leading one, ``-1`` for the rising edge of a
trailing one. ``∇d`` is a central difference of the unclipped duty law (exact up to rounding
for an affine law; step ``1e-7(1 + |x_i|)``, error ``O(1e-9)`` relative otherwise). A
saturated period (the unclipped duty outside ``[0, T]``) has no switching-time dependence;
a duty exactly at ``0`` or ``T`` is a corner of the clipped law (one-sided derivatives
differ): such periods are counted in ``stats["degenerate_periods"]`` and the saturated side
is used.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError
from ...numerics.differences import central_difference_gradient
from ...numerics.saltation import time_shift_term
from ._run import SwitchingStepper

#: ``∂o_j/∂d`` of the pieces' offsets, in the order of ``PWMController.offsets(d)`` for
#: ``0 < d < T`` (every piece nonempty): centred ``(0, d/2, T - d/2)``, leading ``(0, d)``,
#: trailing ``(0, T - d)``.
_OFFSET_RATES = {"centered": (0.0, 0.5, -0.5), "leading": (0.0, 1.0), "trailing": (0.0, -1.0)}


class PwmStepper(SwitchingStepper):
    """A PWM run, one controller period per :meth:`piece`."""

    def __init__(self, system: Any, x0: FloatArray, run: Any) -> None:
        super().__init__(run)
        ctrl = system.controller
        if ctrl is None:
            raise ModelError("system.controller: a SwitchedAffineSystem needs its PWMController "
                             "to be simulated, and the controller is part of the model (not a "
                             "simulate option): build SwitchedAffineSystem(modes, "
                             "controller=PWMController(period, duty))")
        self.system, self.ctrl, self.n = system, ctrl, system.n_states
        self.flows: dict[int, Any] = {}
        self.n_periods = math.ceil((run.tf - run.t0) / ctrl.period - 1e-12)
        self.xi = np.r_[x0, 1.0]
        run.rec.sample(run.t0, x0, force=True)
        self.duties: list[float] = []
        self.mode_prev = -1
        self.degenerate = 0
        self.k = 0
        self.done = self.n_periods <= 0

    def flow(self, mode: int) -> Any:
        if mode not in self.flows:
            self.flows[mode] = self.system.flow(mode)
        return self.flows[mode]

    def state(self) -> FloatArray:
        return self.xi[:self.n]

    def piece(self) -> float:
        """Period ``k``: the duty read at the exact ``t_k = t0 + kT``, the sub-intervals
        propagated exactly."""
        run, ctrl, n = self.run, self.ctrl, self.n
        T, k = ctrl.period, self.k
        t_k = run.t0 + k * T                      # exact instants, not accumulated
        t_next = run.t0 + (k + 1) * T
        _check_advance(T, t_k, t_next)
        run.step(t_k)                             # one period: one step of the budget
        d = ctrl.duty_at(t_k, self.xi[:n])
        self.duties.append(d)
        offs = ctrl.offsets(d)
        starts = [t_k + o for o, _ in offs]
        rates = None
        if run.sensitivity:
            rates, corner = _instant_gradients(ctrl, t_k, self.xi[:n], len(offs))
            self.degenerate += corner
        Phi = self._pieces(offs, starts, starts[1:] + [t_next], rates)
        if run.sensitivity:
            run.Phi = Phi @ run.Phi
        self.k = k + 1
        self.done = self.k >= self.n_periods
        return self.t

    def _pieces(self, offs: Any, starts: list[float], ends: list[float], rates: Any
                ) -> FloatArray:
        """Propagate over the period's sub-intervals, recording the switches; the period's
        transition (with sensitivity)."""
        run, system, n, tf = self.run, self.system, self.n, self.run.tf
        Phi = np.eye(n)
        xi = self.xi
        for j, ((_, mode), a, b) in enumerate(zip(offs, starts, ends, strict=True)):
            if a >= tf:
                break
            b = min(b, tf)
            if self.mode_prev >= 0 and mode != self.mode_prev:  # a switching instant, exact
                x = xi[:n]
                run.event(a, "switch", -1, x, x, self.mode_prev, mode)
                run.rec.sample(a, x, force=True)
                if rates is not None and rates[j] is not None:
                    Phi += time_shift_term(system.field(self.mode_prev, x),
                                           system.field(mode, x), rates[j])
            self.mode_prev = mode
            if b <= a:
                continue
            fl = self.flow(mode)
            ts = run.samples(a, b, last=False)
            if ts.size:
                run.rec.extend(ts, np.atleast_2d(fl.propagate(xi, ts - a))[:, :n])
            if run.sensitivity:
                Phi = np.asarray(fl.expm(b - a))[:n, :n] @ Phi
            xi = fl.state_at(xi, b - a)
            xi[n] = 1.0
            self.xi = xi
            self.t = b
        return Phi

    def extra(self) -> dict[str, Any]:
        return _pwm_stats(self.k, self.duties, self.mode_prev,
                          self.degenerate if self.run.sensitivity else None)


def _check_advance(T: float, t_k: float, t_next: float) -> None:
    if not t_next > t_k:
        raise ModelError(f"period: T = {T:g} is below the floating-point resolution of the "
                         f"time near t_k = {t_k:.17g}: the run cannot advance; shift t_span "
                         f"towards 0 or use a longer period")


def _pwm_stats(periods: int, duties: list[float], final_mode: int,
               degenerate: int | None) -> dict[str, Any]:
    """The run's statistics; ``degenerate`` (with sensitivity): the periods whose duty sat on
    a corner of the clipped duty law (warned about)."""
    out: dict[str, Any] = {"periods": periods, "duty": np.array(duties),
                           "final_mode": final_mode}
    if degenerate is not None:
        out["degenerate_periods"] = degenerate
        if degenerate:
            import warnings

            from ...errors import NscontrolWarning

            warnings.warn(f"switching: the duty sat exactly on 0 or the period in {degenerate} "
                          f"period(s), a corner of the clipped duty law where the map is not "
                          f"differentiable; stats['state_transition'] uses the saturated side",
                          NscontrolWarning, stacklevel=5)
    return out


def _instant_gradients(ctrl: Any, t_k: float, x_k: FloatArray, n_pieces: int
                       ) -> tuple[list[FloatArray | None], int]:
    """``∂s_j/∂x_k`` for each piece's start (``None`` where it does not move with ``x_k``) and
    whether the duty sits exactly on a clipping bound (a corner: 1, else 0)."""
    raw = float(ctrl.duty(t_k, x_k))
    if not 0.0 < raw < ctrl.period:   # saturated: the instants do not move
        on_bound = raw in (0.0, ctrl.period) and bool(np.any(_duty_gradient(ctrl, t_k, x_k)))
        return [None] * n_pieces, int(on_bound)
    rates = _OFFSET_RATES[ctrl.pattern]
    if len(rates) != n_pieces:   # pragma: no cover - 0 < d < T gives every piece
        raise ModelError(f"controller.pattern: {ctrl.pattern!r} gave {n_pieces} pieces for "
                         f"the duty {raw:.6g} in (0, T), expected {len(rates)}")
    grad = _duty_gradient(ctrl, t_k, x_k)
    return [None if r == 0.0 else r * grad for r in rates], 0


def _duty_gradient(ctrl: Any, t_k: float, x_k: FloatArray) -> FloatArray:
    """``∇d(x_k)`` of the unclipped duty law, by central differences."""
    return central_difference_gradient(lambda x: float(ctrl.duty(t_k, x)), np.array(x_k))
