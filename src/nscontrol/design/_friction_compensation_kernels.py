"""Chapter 7's blocks (:mod:`nscontrol.design.friction_compensation`), written once.

Every formula of the PD law, the friction estimate and the reduced-order observer lives here
as a compiled function; the Python methods of the blocks call these same functions (with the
reference values of their Python reference callable), and the compiled blocks
(``BLOCK_SIGNATURE``) call them with the reference computed by :func:`reference`. So the two
paths run the same machine code.

Parameters are named records (numpy structured dtypes of ``float64`` fields,
:func:`nscontrol._validation.named_record`): :data:`PD` for the PD law, :data:`CONTROLLER`
and :data:`OBSERVER` for the blocks (the PD fields first). The compiled loops pass a block's
record as its flat ``float64`` view; the block kernels read it back by name
(``p.view(CONTROLLER)[0]``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..systems._feedback_kernels import BLOCK_SIGNATURE

_F = np.float64
#: The PD law: reference ``kind`` (0 set-point ``a``, 1 ``a sin(w t)``), gains, inertia and
#: whether the feedforward ``J r''`` is on (1.0) or off (0.0).
PD = np.dtype([("kind", _F), ("a", _F), ("w", _F), ("kp", _F), ("kd", _F), ("J", _F),
               ("feedforward", _F)])
#: The controller: the PD fields, then the friction model ``T_hat`` (``has_compensation``
#: 0.0 for none; ``T_s, T_c, omega_s, delta, b``), ``T_hat(0)`` and the optional smoothing.
CONTROLLER = np.dtype(PD.descr + [("has_compensation", _F), ("T_s", _F), ("T_c", _F),
                                  ("omega_s", _F), ("delta", _F), ("b", _F),
                                  ("value_at_zero", _F), ("has_eps", _F), ("eps", _F)])
#: The observer: the PD fields, then the sampling period ``T`` and the gain ``l``.
OBSERVER = np.dtype(PD.descr + [("T", _F), ("l", _F)])


@njit(cache=True)
def sinusoid(t, a, w):
    """``(r, r', r'')`` of ``r(t) = a sin(w t)``."""
    s, c = math.sin(w * t), math.cos(w * t)
    return a * s, a * w * c, -a * w * w * s


@njit(cache=True)
def reference(t, c):
    """``(r, r', r'')`` of the record's reference (a set-point or a sinusoid)."""
    if c.kind == 0.0:
        return c.a, 0.0, 0.0
    return sinusoid(t, c.a, c.w)


@njit(cache=True)
def pd_torque(r, dr, ddr, theta, omega_hat, c):
    """``u_pd = J r'' - k_p (theta - r) - k_d (omega_hat - r')`` (feedforward optional)."""
    ff = c.J * ddr if c.feedforward != 0.0 else 0.0
    return ff - c.kp * (theta - r) - c.kd * (omega_hat - dr)


@njit(cache=True)
def friction_estimate(v, c):
    """``T_hat(v) = sign(v) f_hat(|v|)`` (``value_at_zero`` at 0, or the smoothed sign)."""
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
def control(r, dr, ddr, theta, v, c):
    """The controller's torque ``u = u_pd + T_hat(v)`` (``v`` the velocity it reads)."""
    return pd_torque(r, dr, ddr, theta, v, c) + friction_estimate(v, c)


@njit(cache=True)
def observer_xi(xi, u_pd, theta, c):
    """Backward Euler on ``xi' = -l xi - l^2 theta + u_pd / J`` over one period ``T``, from
    the carried ``xi`` and ``u_pd`` with the new angle sample ``theta``."""
    T, l = c.T, c.l
    return (xi + T * (-l * l * theta + u_pd / c.J)) / (1.0 + T * l)


@njit(cache=True)
def observer_estimate(xi, u_pd, theta, c):
    """``omega_hat = xi_new + l theta`` at a tick (carried ``xi``, ``u_pd``; sample ``theta``)."""
    return observer_xi(xi, u_pd, theta, c) + c.l * theta


@njit(cache=True)
def observer_step(r, dr, ddr, xi, u_pd, theta, c):
    """The state ``(xi_new, u_pd_new, omega_hat)`` carried into the next tick."""
    xi_new = observer_xi(xi, u_pd, theta, c)
    omega_hat = xi_new + c.l * theta
    return xi_new, pd_torque(r, dr, ddr, theta, omega_hat, c), omega_hat


@njit(cache=True)
def observer_estimates(xo, theta, c):
    """:func:`observer_estimate` at many ticks (rows of ``xo``, entries of ``theta``)."""
    out = np.empty(theta.size)
    for k in range(theta.size):
        out[k] = observer_estimate(xo[k, 0], xo[k, 1], theta[k], c)
    return out


@njit(cache=True)
def references(t, c):
    """``r`` of the record's reference on the times ``t``."""
    out = np.empty(t.size)
    for k in range(t.size):
        out[k] = reference(t[k], c)[0]
    return out


# -- the compiled blocks (CompiledBlock's signature) --------------------------------------------
@njit(BLOCK_SIGNATURE, cache=True)
def controller_output(t, xb, y, x, xhat, lam, p):
    """``[u_pd + T_hat(omega_hat)]``; ``omega_hat`` the estimate, else the measured velocity."""
    c = p.view(CONTROLLER)[0]
    r, dr, ddr = reference(t, c)
    v = xhat[0] if xhat.size > 0 else x[1]
    out = np.empty(1)
    out[0] = control(r, dr, ddr, y[0], v, c)
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def observer_output(t, xb, y, x, xhat, lam, p):
    """``[omega_hat]`` at a tick."""
    out = np.empty(1)
    out[0] = observer_estimate(xb[0], xb[1], y[0], p.view(OBSERVER)[0])
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def observer_update(t, xb, y, x, xhat, lam, p):
    """``[xi, u_pd, omega_hat]`` carried into the next tick."""
    c = p.view(OBSERVER)[0]
    r, dr, ddr = reference(t, c)
    out = np.empty(3)
    out[0], out[1], out[2] = observer_step(r, dr, ddr, xb[0], xb[1], y[0], c)
    return out
