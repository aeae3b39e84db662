"""Numerical blow-up is a result, not a success: a run whose state becomes infinite or NaN
stops at the first non-finite sample with NonFiniteStateError (or status -1 under
on_failure), keeps every sample before it, and names the model's function that returned the
non-finite value when it is one."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import NonFiniteStateError
from nscontrol.laws.relay import Relay
from nscontrol.systems.hybrid import LinearHybridSystem
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.systems.lure import LureSystem


def _unstable_lure():
    return LureSystem([[50.0]], [[1.0]], [[1.0]], Relay(1.0), state_names=("x",))


def test_an_unstable_lure_system_is_cut_at_its_first_non_finite_sample():
    with pytest.raises(NonFiniteStateError, match=r"^implicit_euler: state x became inf "
                                                   r"between t = ") as info:
        nsc.simulate(_unstable_lure(), [1.0], (0.0, 100.0), h=1e-2)
    partial = info.value.trajectory
    # implicit Euler's growth (1 - 50 h)^{-k} = 2^k at h = 1e-2 overflows after ~1024 steps:
    # every kept sample is finite, the next one is not
    assert np.all(np.isfinite(partial.x)) and partial.status == -1
    assert info.value.time > partial.t[-1] and info.value.state == "x"
    assert "unstable" in str(info.value)
    returned = nsc.simulate(_unstable_lure(), [1.0], (0.0, 100.0), h=1e-2, on_failure="return")
    np.testing.assert_array_equal(returned.t, partial.t)
    with pytest.warns(nsc.errors.NscontrolWarning, match="became inf"):
        warned = nsc.simulate(_unstable_lure(), [1.0], (0.0, 100.0), h=1e-2,
                              on_failure="warn")
    assert warned.status == -1


@pytest.mark.parametrize("method, opts", [("event_driven", {}), ("moreau_jean", {"h": 1e-3})])
def test_negative_stiffness_blows_up_as_an_error_in_both_mechanics_methods(method, opts):
    spring = LagrangianSystem([[1.0]], stiffness=[[-400.0]], gap_matrix=[[1.0]],
                              gap_offset=[10.0])          # e^{20 t}: overflows near t = 35
    with pytest.raises(NonFiniteStateError) as info:
        nsc.simulate(spring, [0.1, 0.0], (0.0, 100.0), method=method, **opts)
    assert np.all(np.isfinite(info.value.trajectory.x))


def test_an_unstable_linear_hybrid_system_is_an_error():
    grow = LinearHybridSystem(np.diag([50.0, 50.0]), [[1.0, 0.0]], [1e300], np.eye(2))
    with pytest.raises(NonFiniteStateError, match="^event_driven: state x"):
        nsc.simulate(grow, [1.0, 0.0], (0.0, 20.0))


def test_a_nan_input_is_named_as_the_cause_not_the_step():
    def u(t):
        t = np.atleast_1d(np.asarray(t, float))
        return np.where(t[:, None] > 0.5, np.nan, 0.0)

    plant = LureSystem([[0.0, 1.0], [-1.0, 0.0]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                       B=[[0.0], [1.0]], u=u)
    with pytest.raises(NonFiniteStateError, match=r"the input u\(t\) of the model returns a "
                                                   r"non-finite value at t = 0\.51") as info:
        nsc.simulate(plant, [1.0, 0.0], (0.0, 1.0), h=1e-2)
    assert "smaller h" not in str(info.value)
    assert info.value.trajectory.t[-1] == pytest.approx(0.5)


def test_a_nan_force_on_the_moreau_jean_python_path_names_the_force():
    def force(t, q, v):
        return np.array([np.nan if t > 0.2 else 0.0])

    ball = LagrangianSystem([[1.0]], constant_force=[-9.81], force=force, gap_matrix=[[1.0]],
                            gap_offset=[0.0])
    with pytest.raises(nsc.ModelError, match="force") as info:
        nsc.simulate(ball, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3)
    assert info.value.trajectory.t[-1] >= 0.2 - 1e-3
