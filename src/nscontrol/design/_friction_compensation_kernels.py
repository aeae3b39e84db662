"""Compiled forms of chapter 7's blocks (:mod:`nscontrol.design.friction_compensation`).

They repeat the Python methods' arithmetic operation for operation (same order, same
``exp``/``pow``), so the compiled loop reproduces the Python one. Parameter layout:

* PD law ``pd = [kind, a, w, kp, kd, J, feedforward]``: ``kind`` 0 for a set-point ``a``,
  1 for ``a sin(w t)``;
* controller ``pd + [has_compensation, T_s, T_c, omega_s, delta, b, value_at_zero,
  has_eps, eps]``;
* observer ``pd + [T, l]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE

PD_SIZE = 7


@njit(cache=True)
def pd_torque(t, theta, omega_hat, p):
    """``u_pd = J r'' - k_p (theta - r) - k_d (omega_hat - r')`` (``PDLaw.torque``)."""
    if p[0] == 0.0:
        r, dr, ddr = p[1], 0.0, 0.0
    else:
        a, w = p[1], p[2]
        s, c = math.sin(w * t), math.cos(w * t)
        r, dr, ddr = a * s, a * w * c, -a * w * w * s
    kp, kd, J = p[3], p[4], p[5]
    ff = J * ddr if p[6] != 0.0 else 0.0
    return ff - kp * (theta - r) - kd * (omega_hat - dr)


@njit(cache=True)
def friction_estimate(v, p):
    """``T_hat(v)`` (``FrictionCompensatingPD.friction_estimate``), parameters from
    ``p[PD_SIZE]``."""
    o = PD_SIZE
    if p[o] == 0.0:
        return 0.0
    ts, tc, ws, dl, b = p[o + 1], p[o + 2], p[o + 3], p[o + 4], p[o + 5]
    s = abs(v)
    mag = tc + (ts - tc) * math.exp(-(s / ws) ** dl) + b * s
    if p[o + 7] != 0.0:
        return max(-1.0, min(1.0, v / p[o + 8])) * mag
    if v == 0.0:
        return p[o + 6]
    return math.copysign(mag, v)


@njit(BLOCK_SIGNATURE, cache=True)
def controller_output(t, xb, y, x, xhat, lam, p):
    """``[u_pd + T_hat(omega_hat)]``; ``omega_hat`` the estimate, else the measured velocity."""
    v = xhat[0] if xhat.size > 0 else x[1]
    out = np.empty(1)
    out[0] = pd_torque(t, y[0], v, p) + friction_estimate(v, p)
    return out


@njit(cache=True)
def _xi(xo, theta, p):
    T, l, J = p[PD_SIZE], p[PD_SIZE + 1], p[5]
    return (xo[0] + T * (-l * l * theta + xo[1] / J)) / (1.0 + T * l)


@njit(BLOCK_SIGNATURE, cache=True)
def observer_output(t, xb, y, x, xhat, lam, p):
    """``[omega_hat]`` at a tick (``ReducedOrderVelocityObserver.output``)."""
    out = np.empty(1)
    out[0] = _xi(xb, y[0], p) + p[PD_SIZE + 1] * y[0]
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def observer_update(t, xb, y, x, xhat, lam, p):
    """``[xi, u_pd, omega_hat]`` carried into the next tick."""
    theta = y[0]
    xi = _xi(xb, theta, p)
    omega_hat = xi + p[PD_SIZE + 1] * theta
    out = np.empty(3)
    out[0] = xi
    out[1] = pd_torque(t, theta, omega_hat, p)
    out[2] = omega_hat
    return out
