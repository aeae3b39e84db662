"""The normalised buck converter: validation, physical entry, exact propagation."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nscontrol.errors import ModelError
from nscontrol.systems import BuckConverter, SwitchedAffineSystem

U = np.finfo(float).eps


@pytest.mark.parametrize("kwargs, name", [
    ({"delta": -0.35}, "delta"), ({"delta": float("nan")}, "delta"),
    ({"delta": "0.35"}, "delta"), ({"delta": 0.35, "u_levels": (1.0, -1.0)}, "u_levels"),
    ({"delta": 0.35, "u_levels": (0.0,)}, "u_levels"),
    ({"delta": 0.35, "u_levels": (0.0, float("inf"))}, "u_levels"),
    ({"delta": 0.35, "time_scale": 0.0}, "time_scale")])
def test_bad_parameters_are_refused_naming_the_argument(kwargs, name):
    with pytest.raises(ModelError, match=f"^{name}"):
        BuckConverter(**kwargs)


@pytest.mark.parametrize("arg", ["R", "L", "C", "E"])
def test_from_physical_refuses_a_non_positive_component(arg):
    values = {"R": 20.0, "L": 2e-3, "C": 40e-6, "E": 40.0}
    values[arg] = -1.0
    with pytest.raises(ModelError, match=f"^{arg}"):
        BuckConverter.from_physical(**values)


def test_from_physical_gives_the_normalised_damping_and_time_scale():
    buck = BuckConverter.from_physical(R=20.0, L=2e-3, C=40e-6, E=40.0)
    # δ = (1/R)√(L/C) and √(LC): each a handful of roundings, so 10 u relative
    assert abs(buck.delta - np.sqrt(2e-3 / 40e-6) / 20.0) <= 10 * U * buck.delta
    assert abs(buck.time_scale - np.sqrt(2e-3 * 40e-6)) <= 10 * U * buck.time_scale
    assert buck.u_levels == (0.0, 1.0) and buck.voltage_scale == 40.0
    # 20 kHz: T = 1/(f_s √(LC)) ≈ 0.177
    assert abs(buck.normalized_period(20e3) - 1 / (20e3 * np.sqrt(8e-8))) <= 10 * U


def test_propagation_matches_an_ode_solver_and_the_equilibrium_is_u_bar():
    buck = BuckConverter.normalized(0.35, (0.0, 1.0))
    x0 = np.array([0.3, -0.2])
    sol = solve_ivp(lambda t, x: buck.field(1.0, x), (0.0, 2.0), x0, rtol=1e-12, atol=1e-14)
    # DOP45 at rtol 1e-12 over 2 time units of a contracting flow: error ≲ 1e-10
    assert np.max(np.abs(buck.propagate(1.0, x0, 2.0) - sol.y[:, -1])) <= 1e-10
    assert np.allclose(buck.field(0.7, [0.7, 0.0]), 0.0, atol=0.0)


def test_switched_form_is_a_switched_affine_system_with_centred_pwm():
    buck = BuckConverter.normalized(0.35)
    sw = buck.switched(0.18, lambda t, x: 0.09)
    assert isinstance(sw, SwitchedAffineSystem)
    assert sw.controller.pattern == "centered" and sw.controller.period == 0.18
    assert np.array_equal(sw.modes[0][1], [0.0, -1.0]) and np.array_equal(sw.modes[1][1],
                                                                          [0.0, 1.0])
