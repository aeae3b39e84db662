"""PWM-switched affine systems for :mod:`nscontrol.simulate.switching`.

At each sampling instant the controller's schedule gives the switching instants of the period in
closed form; each sub-interval is propagated exactly with the exponential of the augmented
matrix ``[[A_σ, b_σ], [0, 0]]`` (cached per mode and duration, so a periodic schedule costs a
few exponentials in total).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import expm

from .._validation import FloatArray
from ..errors import ModelError


def run_pwm(system: Any, x0: FloatArray, run: Any, options: dict[str, Any]) -> dict[str, Any]:
    ctrl = system.controller
    if ctrl is None:
        raise ModelError("system.controller: a SwitchedAffineSystem needs a PWMController to be "
                         "simulated; pass controller=PWMController(period, duty)")
    if run.sensitivity:
        raise ModelError("sensitivity: not available for PWM systems (the switching instants "
                         "depend on the sampled state); use the stroboscopic-map analysis")
    n = system.n_states
    aug = []
    for A, b in system.modes:
        M = np.zeros((n + 1, n + 1))
        M[:n, :n], M[:n, n] = A, b
        aug.append(M)
    cache: dict[tuple[int, float], FloatArray] = {}

    def step(mode: int, x: FloatArray, tau: float) -> FloatArray:
        key = (mode, tau)
        E = cache.get(key)
        if E is None:
            E = expm(aug[mode] * tau)
            if len(cache) < 4096:
                cache[key] = E
        return E[:n, :n] @ x + E[:n, n]

    T = ctrl.period
    t, x = run.t0, x0.copy()
    run.rec.sample(t, x, force=True)
    duties, mode_prev = [], -1
    k = 0
    while t < run.tf - 1e-12 * T:
        t_k = run.t0 + k * T
        d, pieces = ctrl.schedule(t_k, x)
        duties.append(d)
        for tau, mode in pieces:
            if mode_prev >= 0 and mode != mode_prev:  # a switching instant, exact
                run.event(t, "switch", -1, x, x, mode_prev, mode)
                run.rec.sample(t, x, force=True)
            t_end = min(t + tau, run.tf)
            ts = run.samples(t, t_end, last=False)
            if ts.size:
                run.rec.extend(ts, np.array([step(mode, x, s - t) for s in ts]))
            x = step(mode, x, t_end - t)
            t, mode_prev = t_end, mode
            if t >= run.tf:
                break
        k += 1
        run.bar.update(t)
    if run.rec.last_time < run.tf:
        run.rec.sample(run.tf, x, force=True)
    return {"periods": k, "duty": np.array(duties), "final_mode": mode_prev}
