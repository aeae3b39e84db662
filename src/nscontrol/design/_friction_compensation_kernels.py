"""Chapter 7's blocks (:mod:`nscontrol.design.friction_compensation`), written once.

Every formula of the PD law, the friction estimate and the reduced-order observer lives here
as a compiled function; the Python methods of the blocks call these same functions (with the
reference values of their Python reference callable), and the compiled blocks
(``BLOCK_SIGNATURE``) call them with the reference computed by :func:`reference`. So the two
paths run the same machine code.

Parameters are one named record, :data:`PARAMETERS` (a numpy structured dtype of
``float64`` fields, built by :func:`nscontrol._validation.named_record`), passed as its flat
``float64`` view (the compiled loops' signature, and a cheap argument from Python); each
function reads it back by name (``p.view(PARAMETERS)[0].kp``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE

_F = np.float64
#: The parameters of chapter 7's blocks, one record for the PD law, the controller and the
#: observer (a block leaves the fields it does not read at 0): the reference ``kind`` (0
#: set-point ``a``, 1 ``a sin(w t)``), the PD gains, the inertia and the feedforward switch
#: (1.0 on); the friction model ``T_hat`` (``has_compensation`` 0.0 for none; ``T_s, T_c,
#: omega_s, delta, b``), ``T_hat(0)`` and the optional smoothing of the sign; the observer's
#: sampling period ``T`` and gain ``l``.
PARAMETERS = np.dtype([
    ("kind", _F), ("a", _F), ("w", _F), ("kp", _F), ("kd", _F), ("J", _F), ("feedforward", _F),
    ("has_compensation", _F), ("T_s", _F), ("T_c", _F), ("omega_s", _F), ("delta", _F),
    ("b", _F), ("value_at_zero", _F), ("has_eps", _F), ("eps", _F), ("T", _F), ("l", _F)])


@njit(cache=True)
def sinusoid(t, a, w):
    """``(r, r', r'')`` of ``r(t) = a sin(w t)``."""
    s, c = math.sin(w * t), math.cos(w * t)
    return a * s, a * w * c, -a * w * w * s


@njit(cache=True)
def reference(t, p):
    """``(r, r', r'')`` of the reference (a set-point or a sinusoid)."""
    c = p.view(PARAMETERS)[0]
    if c.kind == 0.0:
        return c.a, 0.0, 0.0
    return sinusoid(t, c.a, c.w)


@njit(cache=True)
def pd_torque(r, dr, ddr, theta, omega_hat, p):
    """``u_pd = J r'' - k_p (theta - r) - k_d (omega_hat - r')`` (feedforward optional)."""
    c = p.view(PARAMETERS)[0]
    ff = c.J * ddr if c.feedforward != 0.0 else 0.0
    return ff - c.kp * (theta - r) - c.kd * (omega_hat - dr)


@njit(cache=True)
def friction_estimate(v, p):
    """``T_hat(v) = sign(v) f_hat(|v|)`` (``value_at_zero`` at 0, or the smoothed sign)."""
    c = p.view(PARAMETERS)[0]
    if c.has_compensation == 0.0:
        return 0.0
    s = abs(v)
    mag = c.T_c + (c.T_s - c.T_c) * math.exp(-(s / c.omega_s) ** c.delta) + c.b * s
    if c.has_eps != 0.0:
        return max(-1.0, min(1.0, v / c.eps)) * mag
    if v == 0.0:
        return c.value_at_zero
    return math.copysign(mag, v)


@njit(cache=True)
def control(r, dr, ddr, theta, v, p):
    """The controller's torque ``u = u_pd + T_hat(v)`` (``v`` the velocity it reads)."""
    return pd_torque(r, dr, ddr, theta, v, p) + friction_estimate(v, p)


@njit(cache=True)
def observer_xi(xi, u_pd, theta, p):
    """Backward Euler on ``xi' = -l xi - l^2 theta + u_pd / J`` over one period ``T``, from
    the carried ``xi`` and ``u_pd`` with the new angle sample ``theta``."""
    c = p.view(PARAMETERS)[0]
    T, l = c.T, c.l
    return (xi + T * (-l * l * theta + u_pd / c.J)) / (1.0 + T * l)


@njit(cache=True)
def observer_estimate(xi, u_pd, theta, p):
    """``omega_hat = xi_new + l theta`` at a tick (carried ``xi``, ``u_pd``; sample ``theta``)."""
    return observer_xi(xi, u_pd, theta, p) + p.view(PARAMETERS)[0].l * theta


@njit(cache=True)
def observer_step(r, dr, ddr, xi, u_pd, theta, p):
    """The state ``(xi_new, u_pd_new, omega_hat)`` carried into the next tick."""
    xi_new = observer_xi(xi, u_pd, theta, p)
    omega_hat = xi_new + p.view(PARAMETERS)[0].l * theta
    return xi_new, pd_torque(r, dr, ddr, theta, omega_hat, p), omega_hat


@njit(cache=True)
def observer_estimates(xo, theta, p):
    """:func:`observer_estimate` at many ticks (rows of ``xo``, entries of ``theta``)."""
    out = np.empty(theta.size)
    for k in range(theta.size):
        out[k] = observer_estimate(xo[k, 0], xo[k, 1], theta[k], p)
    return out


@njit(cache=True)
def references(t, p):
    """``r`` of the reference on the times ``t``."""
    out = np.empty(t.size)
    for k in range(t.size):
        out[k] = reference(t[k], p)[0]
    return out


# -- the compiled blocks (CompiledBlock's signature) --------------------------------------------
@njit(BLOCK_SIGNATURE, cache=True)
def controller_output(t, xb, y, x, xhat, lam, p):
    """``[u_pd + T_hat(omega_hat)]``; ``omega_hat`` the estimate, else the measured velocity."""
    r, dr, ddr = reference(t, p)
    v = xhat[0] if xhat.size > 0 else x[1]
    out = np.empty(1)
    out[0] = control(r, dr, ddr, y[0], v, p)
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def observer_output(t, xb, y, x, xhat, lam, p):
    """``[omega_hat]`` at a tick."""
    out = np.empty(1)
    out[0] = observer_estimate(xb[0], xb[1], y[0], p)
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def observer_update(t, xb, y, x, xhat, lam, p):
    """``[xi, u_pd, omega_hat]`` carried into the next tick."""
    r, dr, ddr = reference(t, p)
    out = np.empty(3)
    out[0], out[1], out[2] = observer_step(r, dr, ddr, xb[0], xb[1], y[0], p)
    return out
