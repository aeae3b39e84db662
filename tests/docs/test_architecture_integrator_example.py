"""The "integrator of your own" worked example of docs/architecture.md runs and does what it
says: a registered user method, called by name through ``simulate``, of second order."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.simulate import METHODS


@pytest.fixture
def scope(doc_block):
    names = set(METHODS)
    scope, _ = doc_block("### Worked example: an integrator of your own")
    yield scope
    METHODS._paths.pop("heun", None)           # leave the registry as the suite found it
    METHODS._classes.pop("heun", None)
    assert set(METHODS) == names


def test_the_user_integrator_is_second_order(scope):
    e1, e2 = scope["errors"]
    # Heun's global error is C h^2 + O(h^3): halving h divides it by 4 (1 + O(h)); at
    # h = 0.1 the O(h) correction is below 10 %, far above the rounding (1e-16 x 20 steps)
    assert 3.6 < e1 / e2 < 4.4
    # and its size: a step's error is h^3/6 x (exact), so at t = 1 the global error is
    # t e^{-t} h^2 / 6 = 6.1e-4 at h = 0.1 (to O(h^3)); below twice that
    assert e1 < 2 * np.exp(-1.0) * 0.1**2 / 6


def test_the_driver_serves_the_user_integrator(scope):
    decay = scope["decay"]
    traj = nsc.simulate(decay, [1.0], (0.0, 1.0), method="heun", h=0.25, record_every=2)
    # the driver's own options reach it: every 2nd sample and the last, t counted exactly
    np.testing.assert_array_equal(traj.t, [0.0, 0.5, 1.0])
    assert traj.method == "heun"
    with pytest.raises(ModelError, match="unknown option"):
        nsc.simulate(decay, [1.0], (0.0, 1.0), method="heun", h=0.1, rtol=1e-6)


def test_a_failing_user_integrator_keeps_its_samples(scope):
    # the loop holds the stepper's record: an error of the model mid-run leaves with every
    # step computed before it (h = 0.01: a step evaluates f at t_k and t_k + h; f raises past
    # t = 0.5, so the step from 0.5 fails and the samples t = 0, 0.01, ..., 0.5 are kept)
    def rhs(t, x):
        if t > 0.5 + 1e-9:
            raise ArithmeticError("model failed")
        return -x

    failing = nsc.systems.NonlinearSystem(1, rhs)
    with pytest.raises(ArithmeticError) as info:
        nsc.simulate(failing, [1.0], (0.0, 1.0), method="heun", h=0.01)
    traj = info.value.trajectory
    assert traj.status == -1 and traj.method == "heun"
    np.testing.assert_allclose(traj.t, 0.01 * np.arange(51), rtol=0, atol=1e-15)
