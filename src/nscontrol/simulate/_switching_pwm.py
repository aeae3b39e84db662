"""PWM-switched affine systems for :mod:`nscontrol.simulate.switching`.

At each sampling instant ``t_k = t0 + kT`` (computed from ``k``, never accumulated) the
controller reads ``x(t_k)`` and its schedule gives the switching instants ``t_k + o_j`` of the
period in closed form. The state is carried from instant to instant over the differences of
these exact instants, each piece propagated exactly by the mode's
:class:`~nscontrol.numerics.lti.LTIFlow` on the augmented state ``[x; 1]``
(:meth:`SwitchedAffineSystem.flow`, shared across runs). So neither the instants nor the times
at which the duty is evaluated drift over long runs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ModelError


def run_pwm(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]) -> dict[str, Any]:
    ctrl = system.controller
    if ctrl is None:
        raise ModelError("system.controller: a SwitchedAffineSystem needs its PWMController to "
                         "be simulated, and the controller is part of the model (not a "
                         "simulate option): build SwitchedAffineSystem(modes, "
                         "controller=PWMController(period, duty))")
    if run.sensitivity:
        raise ModelError("sensitivity: not available for PWM systems (the switching instants "
                         "depend on the sampled state); use the stroboscopic-map analysis")
    n = system.n_states
    flows: dict[int, Any] = {}

    def flow(mode: int) -> Any:
        if mode not in flows:
            flows[mode] = system.flow(mode)
        return flows[mode]

    T, t0, tf = ctrl.period, run.t0, run.tf
    n_periods = math.ceil((tf - t0) / T - 1e-12)
    xi = np.r_[x0, 1.0]
    t = t0
    run.rec.sample(t, x0, force=True)
    duties, mode_prev = [], -1
    k = 0
    while k < n_periods:
        t_k = t0 + k * T                      # exact instants, not accumulated
        t_next = t0 + (k + 1) * T
        if not t_next > t_k:
            raise ModelError(f"period: T = {T:g} is below the floating-point resolution of the "
                             f"time near t_k = {t_k:.17g}: the run cannot advance; shift t_span "
                             f"towards 0 or use a longer period")
        d = ctrl.duty_at(t_k, xi[:n])
        duties.append(d)
        offs = ctrl.offsets(d)
        starts = [t_k + o for o, _ in offs]
        ends = starts[1:] + [t_next]
        for (_, mode), a, b in zip(offs, starts, ends, strict=True):
            if a >= tf:
                break
            b = min(b, tf)
            if mode_prev >= 0 and mode != mode_prev:  # a switching instant, exact
                x = xi[:n]
                run.event(a, "switch", -1, x, x, mode_prev, mode)
                run.rec.sample(a, x, force=True)
            mode_prev = mode
            if b <= a:
                continue
            fl = flow(mode)
            ts = run.samples(a, b, last=False)
            if ts.size:
                run.rec.extend(ts, np.atleast_2d(fl.propagate(xi, ts - a))[:, :n])
            xi = fl.state_at(xi, b - a)
            xi[n] = 1.0
            t = b
        k += 1
        run.bar.update(t)
    if run.rec.last_time < tf:
        run.rec.sample(tf, xi[:n], force=True)
    return {"periods": k, "duty": np.array(duties), "final_mode": mode_prev}
