"""A run that fails mid-way keeps every sample computed before the failure (issue 30).

Each run below fails at t = 0.5 of (0, 1) with h = 1e-3, inside a chunk of many steps. The
partial trajectory in ``err.trajectory`` must end at the last step before the failure and
equal, sample by sample, a run of the same system stopped there (which never reaches the
failing time), and the error must be the one raised.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.laws.monotone_function import MonotoneFunction
from nscontrol.laws.relay import Relay
from nscontrol.systems.lagrangian import LagrangianSystem, affine_compiled_model
from nscontrol.systems.lure import LureSystem

EPS = np.finfo(float).eps
H = 1e-3
T_FAIL = 0.5
A = np.array([[0.0, 1.0], [-2.0, -3.0]])


class SensorFault(RuntimeError):
    """The user's own exception type."""


def _oscillator(fault):
    """A unit mass on a cubic spring above a far floor: a nonlinear force, so Moreau–Jean
    runs its Python loop (chunks of thousands of steps)."""
    def force(t, q, v):
        if t >= T_FAIL - 0.5 * H:      # the step starting at 0.5 (step starts are k h)
            raise fault()
        return -q - q ** 3

    return LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[10.0], force=force)


def _input(value_after):
    """u(t) = sin t, then ``value_after(t)`` (raises, or NaN) from t = 0.5 on."""
    def u(t):
        t = np.atleast_1d(np.asarray(t, float))
        if np.any(t >= T_FAIL - 0.5 * H):
            return value_after(t)
        return np.sin(t)[:, None]

    return u


def _raise(t):
    raise SensorFault("u: sensor unplugged")


def _nan_after(t):
    out = np.sin(t)[:, None]
    out[t >= T_FAIL - 0.5 * H] = np.nan
    return out


class NaNController:
    """A Python block (no compiled form): u = -x_1, NaN from t = 0.5 on."""

    n_states, n_outputs, period = 0, 1, None

    def output(self, t, xc, m):
        return np.array([np.nan if t >= T_FAIL - 0.5 * H else -m.x[0]])

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return xc


def _lure(law, u=None):
    return LureSystem(A, [[0.0], [0.5]], [[0.0, 1.0]], law, B=[[0.0], [1.0]],
                      C=[[1.0, 0.0]], u=u)


def _curved():
    """A curved monotone law (no closed form, no LCP): the Python inclusion solver."""
    return MonotoneFunction(lambda z: z + z ** 3, dim=1)


def _compiled_linear_plant():
    """A spring-mass above a far floor run by Moreau–Jean's compiled-model loop."""
    plant = LagrangianSystem([[1.0]], stiffness=[[1.0]], gap_matrix=[[1.0]],
                             gap_offset=[10.0], actuation=[[1.0]])
    return replace(plant, compiled=affine_compiled_model(plant))


# (system, x0, simulate options, expected error)
CASES = {
    "moreau_jean force raises": (
        lambda: _oscillator(SensorFault), [1.0, 0.0], {"method": "moreau_jean"},
        SensorFault),
    "moreau_jean force KeyboardInterrupt": (
        lambda: _oscillator(KeyboardInterrupt), [1.0, 0.0], {"method": "moreau_jean"},
        KeyboardInterrupt),
    "moreau_jean u raises": (   # a linear plant: the compiled tridiagonal runner
        lambda: LagrangianSystem([[1.0]], stiffness=[[1.0]], gap_matrix=[[1.0]],
                                 gap_offset=[10.0], actuation=[[1.0]]),
        [1.0, 0.0], {"method": "moreau_jean", "u": _input(_raise)}, SensorFault),
    "moreau_jean compiled model, u raises": (
        lambda: _compiled_linear_plant(), [1.0, 0.0],
        {"method": "moreau_jean", "u": _input(_raise)}, SensorFault),
    "implicit_euler u raises": (
        lambda: _lure(Relay(0.2), _input(_raise)), [1.0, 0.0], {"method": "implicit_euler"},
        SensorFault),
    "curved law, NaN input": (
        lambda: _lure(_curved(), _input(_nan_after)), [1.0, 0.0],
        {"method": "implicit_euler"}, ModelError),
    "Python block NaN on a Lur'e plant": (
        lambda: nsc.closed_loop(_lure(Relay(0.2)), NaNController()), [1.0, 0.0], {},
        ModelError),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_failed_run_keeps_every_sample_before_the_failure(case):
    make, x0, options, error = CASES[case]
    with pytest.raises(error) as info:
        nsc.simulate(make(), x0, (0.0, 1.0), h=H, **options)
    assert type(info.value) is error           # the error raised, not a wrapper
    partial = info.value.trajectory
    assert partial.status == -1
    if "compiled" in case:
        assert reference_path(make, x0, options) == "compiled_model"
    # the failing callable is read at a step's start (a closed loop's block) or end (an
    # input, an implicit force): the run ends at the last step whose end is before the
    # failing time, or at it; within one step of it in either case (rounding of k h: 1e-12)
    assert T_FAIL - H - 1e-12 <= partial.t[-1] <= T_FAIL + 1e-12
    reference = nsc.simulate(make(), x0, (0.0, float(partial.t[-1])), h=H, **options)
    assert len(partial.t) == len(reference.t)
    # the same operations on the same grid; implicit Euler's grid step (t_f - t0)/n may
    # differ from H by an ulp, which moves t_k by <= k ulps: 500 steps x |x'| <= 10, x 10
    tol = 10 * 500 * 10 * EPS
    np.testing.assert_allclose(partial.t, reference.t, rtol=0, atol=tol)
    np.testing.assert_allclose(partial.x, reference.x, rtol=0, atol=tol)


def reference_path(make, x0, options):
    """The Moreau–Jean path a run of ``make()`` takes (on a span the input never fails on)."""
    return nsc.simulate(make(), x0, (0.0, 0.1), h=H, **options).stats["path"]

