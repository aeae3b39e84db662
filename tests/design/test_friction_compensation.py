"""Chapter 7: the friction-compensating PD with a reduced-order observer, closed around the
one-link robot by ``nscontrol.closed_loop`` and run by implicit Euler (checks 3-9, 11).

Every 10 s run at h = 1e-4 takes 1e5 Python-driven steps; the checks over 12 random starts
and the step-halving check are marked slow, with a one-start version in the default suite.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from nscontrol.analysis.friction_equilibria import (
    equilibrium_halfwidth,
    limit_cycle_summary,
    observer_error_bound,
    stick_equilibria,
    stick_margin,
)
from nscontrol.design.friction_compensation import (
    FrictionCompensatingPD,
    PDLaw,
    ReducedOrderVelocityObserver,
    SetPoint,
    Sinusoid,
    compensation_model,
    one_link_gains,
    simulate_friction_loop,
)
from nscontrol.errors import ModelError, NscontrolWarning
from nscontrol.laws import Stribeck
from nscontrol.systems import OneLinkRobot

# the reference example (our choice: the paper's numbers were not available)
J, KP, KD, L, H, T_S = 0.05, 2.0, 0.3, 150.0, 1e-4, 0.4
F = Stribeck(T_S, 0.2, 0.05, 2.0, 0.02)
ROBOT = OneLinkRobot(J, F)
SIGMA_TAN = float(F.sigma_tan[0])


def set_point_run(kappa, *, l=L, theta0=0.0, ref=1.0, omega0=0.0, omega_hat0=0.0, T=10.0):
    return simulate_friction_loop(ROBOT, PDLaw(KP, KD, J, SetPoint(ref)), l=l, kappa=kappa,
                                  h=H, T=T, theta0=theta0, omega0=omega0,
                                  omega_hat0=omega_hat0)


def random_starts(n, seed=7):
    rng = np.random.default_rng(seed)
    return [dict(theta0=rng.uniform(-2, 2), ref=rng.uniform(-2, 2), omega0=rng.uniform(-3, 3),
                 omega_hat0=rng.uniform(-3, 3)) for _ in range(n)]


# -- the digital loop is exactly the recursion of the method ------------------------------
def test_the_closed_loop_is_the_sampled_recursion_step_for_step():
    """200 ticks of the loop against a hand-written recursion (plant step by a bracketed
    root, observer by backward Euler on the new sample): the same arithmetic up to the root
    solvers' tolerances, so 1e-12 (root tolerance 1e-15 times the derivative bound
    (1 + h sigma_tan / J) ~ 1, accumulated over 200 contracting steps)."""
    pd = PDLaw(KP, KD, J, SetPoint(1.0))
    run = simulate_friction_loop(ROBOT, pd, l=L, kappa=1.0, h=H, T=200 * H, omega0=0.5,
                                 omega_hat0=-0.2)
    ctrl = FrictionCompensatingPD(pd, F, H)
    theta, omega, xi = 0.0, 0.5, -0.2 - L * 0.0
    for k in range(200):
        w_hat = xi + L * theta
        assert run.omega_hat[k] == pytest.approx(w_hat, abs=1e-12)
        upd = pd.torque(k * H, theta, w_hat)
        u = upd + ctrl.friction_estimate(w_hat)
        free = omega + H * u / J
        if abs(free) <= H * T_S / J:
            omega = 0.0
        else:
            s, a = math.copysign(1.0, free), abs(free)
            v = brentq(lambda v, a=a: J * v + H * float(F.magnitude(v)[0]) - J * a, 0.0, a,
                       xtol=1e-15, rtol=4 * np.finfo(float).eps)
            omega = s * v
        theta += H * omega
        xi = (xi + H * (-L * L * theta + upd / J)) / (1.0 + H * L)
        assert run.theta[k + 1] == pytest.approx(theta, abs=1e-12)
        assert run.omega[k + 1] == pytest.approx(omega, abs=1e-12)


# -- checks 3, 4, 5: exact and no compensation from random starts ------------------------
def exact_and_none(n):
    out = []
    for start in random_starts(n):
        out.append((start, set_point_run(1.0, **start), set_point_run(0.0, **start)))
    return out


def check_exact_none(n):
    worst_exact = worst_none = 0.0
    worst_excess = -np.inf
    for start, exact, none in exact_and_none(n):
        m = exact.window(8.0)
        err = np.max(np.abs(exact.error[m]))
        # check 3: converged (it does not stick: |omega| tiny too)
        assert err < 1e-6 and np.max(np.abs(exact.omega[m])) < 1e-6, start
        worst_exact = max(worst_exact, err)
        # check 4: |e(t_k)| <= |e0| exp(-(l - sigma_tan/J) t_k) + 4 h T_s / J
        e = np.abs(exact.estimation_error)
        bound = observer_error_bound(exact.t, e[0], J, L, F, h=H)
        worst_excess = max(worst_excess, float(np.max(e - bound)))
        assert np.all(e <= bound), (start, float(np.max(e - bound)))
        # check 5: without compensation the link sticks inside the predicted set
        m2 = none.window(8.0)
        assert np.all(none.omega[m2] == 0.0), start
        x1 = none.error[-1]
        assert abs(KP * x1) * J * L / (J * L + KD) <= T_S, (start, x1)
        worst_none = max(worst_none, float(np.max(np.abs(none.error[m2]))))
    assert worst_none >= 100.0 * worst_exact
    return worst_exact, worst_none, worst_excess


def test_exact_compensation_converges_and_none_sticks_one_start():
    check_exact_none(1)


@pytest.mark.slow
def test_exact_compensation_converges_and_none_sticks_twelve_starts():
    worst_exact, worst_none, worst_excess = check_exact_none(12)
    print(f"check 3-5: worst exact error {worst_exact:.3g}, worst none {worst_none:.3g}, "
          f"worst observer-bound excess {worst_excess:.3g}")


# -- check 6: undercompensation ends in the predicted equilibrium set ------------------------
@pytest.mark.parametrize("kappa", [0.5, 0.8])
def test_undercompensation_stops_inside_the_equilibrium_set(kappa):
    run = set_point_run(kappa)
    m = run.window(8.0)
    assert np.all(run.omega[m] == 0.0)
    x1 = run.error[-1]
    c_max = equilibrium_halfwidth(J, KP, KD, L, F, compensation_model(F, kappa))
    assert abs(x1) <= c_max
    # the stuck estimate is biased exactly as predicted: omega_hat* = -k_p x1 / (J l + k_d);
    # the observer's error decays like (1 + h l)^-k, below 1e-12 after 2 s of rest
    assert abs(run.omega_hat[-1] + KP * x1 / (J * L + KD)) < 1e-6


# -- check 7: overcompensation oscillates ------------------------------------------------
def test_overcompensation_ends_on_a_symmetric_limit_cycle_growing_with_kappa():
    amplitude = {}
    for kappa in (1.1, 1.3):
        run = set_point_run(kappa)
        cyc = limit_cycle_summary(run.t, run.error, run.omega, window=5.0)
        assert cyc["max_speed"] > 0.05
        # a symmetric cycle seen at the samples: each extreme is off by at most
        # max|omega| h, so |max + min| / span <= 2 max|omega| h / span (measured: 4e-8)
        span = 2.0 * cyc["amplitude"]
        assert cyc["asymmetry"] <= 2.0 * cyc["max_speed"] * H / span
        amplitude[kappa] = cyc["amplitude"]
    assert amplitude[1.3] > amplitude[1.1]


# -- check 8: a slow observer stalls the link even with exact compensation ------------------
def test_a_slow_observer_stalls_the_link_where_proposition_b_says():
    run = set_point_run(1.0, l=10.0)
    m = run.window(8.0)
    assert np.all(run.omega[m] == 0.0)
    x1 = run.error[-1]
    assert abs(x1) > 1e-3
    assert stick_margin(x1, J, KP, KD, 10.0, F, F)[0] >= 0.0
    ranges = stick_equilibria(J, KP, KD, 10.0, F, F)
    assert any(lo <= abs(x1) <= hi for lo, hi in ranges)
    assert stick_equilibria(J, KP, KD, L, F, F) == []


# -- check 9: tracking sin t ---------------------------------------------------------------
def tracking_error(kappa, h, T=10.0):
    run = simulate_friction_loop(ROBOT, PDLaw(KP, KD, J, Sinusoid(1.0, 1.0)), l=L,
                                 kappa=kappa, h=h, T=T)
    m = run.window(T - 2.0 * np.pi)
    return float(np.max(np.abs(run.error[m])))


@pytest.mark.slow
def test_tracking_error_is_first_order_in_h_and_small_only_with_compensation():
    e1, e2 = tracking_error(1.0, H), tracking_error(1.0, H / 2)
    print(f"check 9: max error {e1:.3g} (h), {e2:.3g} (h/2), ratio {e2 / e1:.3f}")
    assert e1 <= 5 * H
    assert 0.4 <= e2 / e1 <= 0.6          # halves within 20 % (first-order scheme)
    assert tracking_error(0.0, H) >= 0.05


# -- check 11: the regularised model agrees with time stepping -------------------------------
@pytest.mark.slow
def test_regularised_model_agrees_at_two_seconds():
    """Friction f(|omega|) tanh(omega/eps), eps = 1e-5 rad/s, continuous controller and
    observer, Radau: at t = 2 s the angle agrees with the time-stepping run to 1e-3 rad
    (both are first-order close: the ZOH and the backward Euler each err by O(h) = 1e-4)."""
    pd = PDLaw(KP, KD, J, SetPoint(1.0))
    ctrl = FrictionCompensatingPD(pd, F, H)
    eps = 1e-5

    def rhs(t, y):
        th, om, xi = y
        w_hat = xi + L * th
        upd = pd.torque(t, th, w_hat)
        u = upd + ctrl.friction_estimate(w_hat)
        fr = float(F.magnitude(abs(om))[0]) * math.tanh(om / eps)
        return [om, (u - fr) / J, -L * xi - L * L * th + upd / J]

    sol = solve_ivp(rhs, (0.0, 2.0), [0.0, 0.0, 0.0], method="Radau", rtol=1e-9, atol=1e-11)
    run = set_point_run(1.0, T=2.0)
    assert sol.status == 0
    assert abs(sol.y[0, -1] - run.theta[-1]) < 1e-3


# -- bad input and the gain helper -----------------------------------------------------------
def test_bad_input_is_refused():
    pd = PDLaw(KP, KD, J)
    with pytest.raises(ModelError, match=r"^kappa"):
        compensation_model(F, -0.1)
    with pytest.raises(ModelError, match=r"^l: the observer gain must be > 0"):
        ReducedOrderVelocityObserver(-5.0, pd, H)
    with pytest.raises(ModelError, match=r"^h: the implicit friction step needs h \* sigma_tan"):
        simulate_friction_loop(ROBOT, pd, l=L, kappa=1.0, h=J / SIGMA_TAN, T=1.0)


def test_gain_helper_follows_the_rule_and_warns():
    g = one_link_gains(J, F, math.sqrt(40.0), 0.47)
    assert g.kp == pytest.approx(2.0, rel=1e-12)
    assert g.l == pytest.approx(2 * SIGMA_TAN / J, rel=1e-12)
    assert g.l_necessary == pytest.approx(float(F.sigma_sec[0]) / J, rel=1e-12)
    with pytest.warns(NscontrolWarning, match="l \\* control_period"):
        one_link_gains(J, F, math.sqrt(40.0), 0.47, control_period=0.01)


def test_measured_velocity_never_compensates_static_friction_at_rest():
    """Without observer the compensation reads the measured velocity, 0 at rest: the link
    stops where the spring-like PD torque is below T_s, |k_p x1| <= T_s, whatever T_hat."""
    run = simulate_friction_loop(ROBOT, PDLaw(KP, KD, J, SetPoint(1.0)), l=None, kappa=1.0,
                                 h=H, T=4.0)
    m = run.window(3.0)
    assert np.all(run.omega[m] == 0.0)
    assert abs(KP * run.error[-1]) <= T_S
    assert abs(run.error[-1]) > 1e-3          # stuck short of the set-point


def test_block_parameters_are_named_records():
    """The compiled blocks' flat parameters are the named records of the kernels module,
    read back field by field (no hand-counted offsets)."""
    from nscontrol.design._friction_compensation_kernels import PARAMETERS

    pd = PDLaw(KP, KD, J, Sinusoid(0.5, 3.0), feedforward=False)
    ctrl = FrictionCompensatingPD(pd, compensation_model(F, 1.3), H, value_at_zero=0.1,
                                  smooth_eps=1e-3)
    c = ctrl.compiled().params.view(PARAMETERS)[0]
    assert (c["kind"], c["a"], c["w"], c["kp"], c["kd"], c["J"], c["feedforward"]) == (
        1.0, 0.5, 3.0, KP, KD, J, 0.0)
    assert (c["has_compensation"], c["T_s"], c["T_c"], c["b"]) == (
        1.0, 1.3 * T_S, 1.3 * 0.2, 1.3 * 0.02)
    assert (c["value_at_zero"], c["has_eps"], c["eps"]) == (0.1, 1.0, 1e-3)
    o = ReducedOrderVelocityObserver(L, pd, H).compiled().params.view(PARAMETERS)[0]
    assert (o["T"], o["l"], o["kp"], o["has_compensation"]) == (H, L, KP, 0.0)


def test_python_methods_follow_the_closed_forms():
    """The methods (now calling the compiled functions) against the formulas written here:
    a few roundings of O(1) numbers, so 8 ulps relative."""
    pd = PDLaw(KP, KD, J, Sinusoid(0.5, 3.0))
    t, th, wh = 0.7, 0.2, -0.4
    r, dr, ddr = 0.5 * math.sin(2.1), 1.5 * math.cos(2.1), -4.5 * math.sin(2.1)
    assert pd.reference(t) == pytest.approx((r, dr, ddr), rel=8 * np.finfo(float).eps)
    assert pd.torque(t, th, wh) == pytest.approx(
        J * ddr - KP * (th - r) - KD * (wh - dr), rel=8 * np.finfo(float).eps)
    ctrl = FrictionCompensatingPD(pd, F, H, value_at_zero=0.05)
    mag = 0.2 + 0.2 * math.exp(-(0.4 / 0.05) ** 2) + 0.02 * 0.4
    assert ctrl.friction_estimate(wh) == pytest.approx(-mag, rel=8 * np.finfo(float).eps)
    assert ctrl.friction_estimate(0.0) == 0.05
    obs = ReducedOrderVelocityObserver(L, pd, H)
    xi = (0.3 + H * (-L * L * th + 0.1 / J)) / (1.0 + H * L)
    assert obs.estimate(np.array([0.3, 0.1, 0.0]), th) == pytest.approx(
        xi + L * th, rel=8 * np.finfo(float).eps)


def test_the_default_path_is_compiled_and_an_arbitrary_reference_falls_back_to_python():
    """Compiled by default; a reference with no compiled form runs the Python methods (the
    same functions, so the same numbers bit for bit), and ``stats`` says which path ran."""
    fast = simulate_friction_loop(ROBOT, PDLaw(KP, KD, J, SetPoint(1.0)), l=L, kappa=1.0,
                                  h=H, T=300 * H, omega0=0.5)
    slow = simulate_friction_loop(ROBOT, PDLaw(KP, KD, J, lambda t: (1.0, 0.0, 0.0)), l=L,
                                  kappa=1.0, h=H, T=300 * H, omega0=0.5)
    assert fast.trajectory.stats["controller"] == "compiled"
    assert slow.trajectory.stats["controller"] == "python"
    for name in ("theta", "omega", "omega_hat", "u", "friction", "reference"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name), err_msg=name)
