"""Chapter 7, checks 1 and 2: the set-valued Stribeck law of the one-link robot and its
implicit-Euler step with the exact stick and slip branches."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.laws import Coulomb, Stribeck
from nscontrol.systems import OneLinkRobot
from nscontrol.systems.feedback import StaticLaw
from nscontrol.testing.check import check_system

J = 0.05
EPS = np.finfo(float).eps


def reference_friction():
    """The reference example's friction (ours: the paper's numbers were not available)."""
    return Stribeck(0.4, 0.2, 0.05, 2.0, 0.02)


# -- check 1: the friction law ---------------------------------------------------------------
def test_friction_at_rest_is_the_whole_static_interval():
    F = reference_friction()
    for v in (-0.4, 0.0, 0.4):       # every point of [-T_s, T_s] is in F(0)
        assert F.graph_residual([0.0], [v]) == 0.0
    assert F.graph_residual([0.0], [0.45]) == pytest.approx(0.05, rel=1e-12)
    # f continuous at 0+: f(s) - T_s = O(s) (viscous) + O(s^2) (Stribeck), both < 1e-9 here
    assert abs(float(F.magnitude(1e-9)[0]) - 0.4) < 1e-9


def test_slope_constants_match_the_delta_2_closed_forms():
    F = reference_friction()
    drop = (0.4 - 0.2) / 0.05
    tan_closed = math.sqrt(2.0 / math.e) * drop - 0.02
    # sup (1 - exp(-x^2))/x found independently by a bounded scalar search (xatol 1e-12:
    # the maximum is flat, so the value is exact to ~1e-24 relative, far below 1e-6)
    res = minimize_scalar(lambda x: math.expm1(-x * x) / x, bounds=(0.5, 2.0),
                          method="bounded", options={"xatol": 1e-12})
    sec_closed = -res.fun * drop - 0.02
    assert float(F.sigma_tan[0]) == pytest.approx(tan_closed, rel=1e-6)
    assert float(F.sigma_sec[0]) == pytest.approx(sec_closed, rel=1e-6)
    # the reference example's figures (to the 6 digits they are given with)
    assert float(F.sigma_tan[0]) == pytest.approx(3.41106, abs=5e-6)
    assert float(F.sigma_sec[0]) == pytest.approx(2.53269, abs=5e-6)
    assert F.sigma_sec[0] <= F.sigma_tan[0]


def test_slope_constants_for_other_exponents():
    one = Stribeck(1.0, 0.0, 1.0, delta=1.0)        # shape exp(-x): both constants are 1
    assert float(one.sigma_tan[0]) == 1.0 and float(one.sigma_sec[0]) == 1.0
    steep = Stribeck(1.0, 0.0, 1.0, delta=0.5)
    assert math.isinf(float(steep.sigma_tan[0]))
    with pytest.raises(ModelError, match=r"^friction: its curve falls infinitely steeply"):
        OneLinkRobot(J, steep)


def test_the_law_and_its_monotone_part_keep_the_law_contract():
    F = reference_friction()
    check_system(F)
    check_system(F.loop_transformation().monotone_part)
    check_system(OneLinkRobot(J, F).lure_system())


# -- check 2: the plant step -------------------------------------------------------------
class Torque(StaticLaw):
    """A constant torque ``u``, held over the step."""

    n_outputs, period = 1, None

    def __init__(self, u):
        self.u = u

    def output(self, t, xc, m):
        return np.array([self.u])


def one_step(robot, omega, u, h=1e-4):
    """One implicit-Euler step of the plant from (0, omega) under the torque u."""
    tr = nsc.simulate(nsc.closed_loop(robot.lure_system(), Torque(u)), [0.0, omega], (0.0, h),
                      method="implicit_euler", h=h, progress=False)
    v = tr.x[-1, 1]
    return v, float(robot.friction_torque(v, tr.signal("w")[-1, 0])), tr


@pytest.mark.parametrize("omega,u", [(0.0, 0.39), (1e-4, -0.3), (-5e-4, 0.1)])
def test_stick_branch(omega, u):
    robot, h = OneLinkRobot(J, reference_friction()), 1e-4
    assert abs(omega + h * u / J) <= h * 0.4 / J          # inside the stick band
    v, tf, _ = one_step(robot, omega, u, h)
    assert v == 0.0
    assert abs(tf) <= 0.4 * (1.0 + 4 * EPS)               # in [-T_s, T_s] up to rounding


@pytest.mark.parametrize("omega,u", [(0.3, 0.0), (-2.0, 1.0), (0.02, 0.5), (1e-3, -3.0)])
def test_slip_branch_residual(omega, u):
    F = reference_friction()
    robot, h = OneLinkRobot(J, F), 1e-4
    v, tf, _ = one_step(robot, omega, u, h)
    free = omega + h * u / J
    s = math.copysign(1.0, free)
    assert v != 0.0 and math.copysign(1.0, v) == s and abs(v) <= abs(free)
    residual = J * v + h * s * float(F.magnitude(abs(v))[0]) - J * free
    assert abs(residual) < 1e-12
    assert tf == pytest.approx(s * float(F.magnitude(abs(v))[0]), abs=1e-12)


@pytest.mark.parametrize("law", [Coulomb(0.2), Stribeck(0.2, 0.2, 0.05, 2.0, 0.0)],
                         ids=["relay", "flat-stribeck"])
def test_coulomb_slip_matches_the_closed_form(law):
    robot, h, omega, u = OneLinkRobot(J, law), 1e-4, 0.7, -0.5
    v, _, _ = one_step(robot, omega, u, h)
    free = omega + h * u / J
    closed = free - h * 0.2 / J
    # the same three operations in another order: a few ulps of the largest term
    assert abs(v - closed) <= 4 * EPS * (abs(omega) + abs(h * u / J) + h * 0.2 / J)


def test_a_step_beyond_the_uniqueness_bound_is_refused_with_the_bound():
    robot = OneLinkRobot(J, reference_friction())
    bound = J / 3.4110555398428275
    assert robot.max_step() == pytest.approx(bound, rel=1e-12)
    robot.check_step(0.99 * bound)
    with pytest.raises(ModelError, match=r"^h: the implicit friction step needs h \* "
                                         r"sigma_tan < J.*h < J / sigma_tan = 0\.01465"):
        robot.check_step(bound)
