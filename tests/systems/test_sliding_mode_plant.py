"""The sliding-mode plant and its continuous-time closed loops (Filippov path), including
second-order sliding after an accumulation of crossings."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import nscontrol as nsc
from nscontrol.errors import DimensionError, ModelError
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import SlidingModePlant, differentiator_loop

L = 1.5
K1, K2 = 1.5 * np.sqrt(L), 1.1 * L
REF_RTOL = 1e-12


def _disturbed() -> SlidingModePlant:
    return SlidingModePlant.double_integrator(disturbance=Exosystem.sinusoid(0.3, omega=5.0))


def test_relative_degree_two_refused():
    with pytest.raises(ModelError, match="^c: c B = 0"):
        SlidingModePlant([[0, 1], [0, 0]], [0, 1], [1, 0])


def test_wrong_input_shape_refused():
    with pytest.raises(DimensionError, match="^B: expected one input column"):
        SlidingModePlant([[0, 1], [0, 0]], [[0, 1], [1, 0]], [1, 1])


def test_disturbance_must_be_an_exosystem():
    with pytest.raises(ModelError, match="^disturbance: expected a one-output Exosystem"):
        SlidingModePlant.double_integrator(disturbance=lambda t: 0.0)


def _reference_reaching_time() -> float:
    """Event-driven reference, independent of nscontrol's Filippov path: smooth phases of
    the super-twisting loop with a fixed sign, integrated by solve_ivp (rtol 1e-12) from one
    crossing of s = 0 to the next, until the crossings are less than 1e-10 apart."""
    def field(t, y, sg):
        x, v, nu = y
        s = x + v
        u = -K1 * np.sqrt(abs(s)) * sg + nu
        return [v, u + 0.3 * np.sin(5.0 * t), -K2 * sg]

    t, y, sg, last = 0.0, np.array([0.5, 0.0, 0.0]), 1.0, -1.0
    for _ in range(200):
        def hit(t, y, sg):
            return y[0] + y[1]
        hit.terminal, hit.direction = True, -sg
        sol = solve_ivp(field, (t, 6.0), y, args=(sg,), events=hit, method="DOP853",
                        rtol=REF_RTOL, atol=1e-14)
        t, y, sg = float(sol.t_events[0][0]), sol.y_events[0][0], -sg
        if t - last < 1e-10:
            return t
        last = t
    raise AssertionError("the reference found no accumulation of crossings")


@pytest.fixture(scope="module")
def super_twisting_run():
    loop = _disturbed().super_twisting_loop(K1, K2)
    return nsc.simulate(loop, [0.5, 0.0, 0.0], (0.0, 6.0), progress=False)


def test_super_twisting_reaches_second_order_sliding_at_the_reference_time(
        super_twisting_run):
    tr = super_twisting_run
    t_reach = float(tr.event_times("two_sliding_start")[0])
    t_ref = _reference_reaching_time()
    # the reference's accumulation point is within a few crossing gaps (< 1e-10) of its
    # last crossing; ours enters at |s'| <= 1e-7 x field scale, i.e. about 1e-7 time units
    # early (homogeneous approximation); the acceptance band is 1e-4
    assert abs(t_reach - t_ref) <= 1e-4
    assert abs(t_reach - 2.13636) <= 1e-4 + 2e-5      # the stated reference value +- 2e-5


def test_super_twisting_holds_s_zero_and_follows_the_closed_form(super_twisting_run):
    tr = super_twisting_run
    t_reach = float(tr.event_times("two_sliding_start")[0])
    after = tr.t > t_reach
    s = tr.x[after, 0] + tr.x[after, 1]
    assert np.max(np.abs(s)) <= 1e-12               # the acceptance bound: samples on s = 0
    # on s = 0: x' = -x, so x(t) = x(t_r) e^{-(t - t_r)}. The 2-sliding field keeps s' = 0
    # with an equivalent control from central differences (relative error ~ 1e-10) and
    # DOP853 at rtol 1e-11: the deviation stays below 1e-8 x |x(t_r)| over 4 time units.
    x_r = tr.x[np.searchsorted(tr.t, t_reach, side="right") - 1, 0]
    x_cf = x_r * np.exp(-(tr.t[after] - t_reach))
    assert np.max(np.abs(tr.x[after, 0] - x_cf)) <= 1e-8 * abs(x_r)


def test_first_order_loop_reaches_at_the_closed_form_time():
    plant = SlidingModePlant.double_integrator()
    tr = nsc.simulate(plant.first_order_loop(alpha=2.0), [1.0, 0.0], (0.0, 2.0),
                      progress=False)
    # s' = -alpha sign(s) with the equivalent control: t_r = |s0| / (alpha |cB|) = 0.5.
    # Event location by DOP853 at rtol 1e-11 on a linear s(t): error ~ 1e-11 x t_r; 1e-9
    # leaves a factor 100.
    assert tr.events[0].kind == "sliding_start"
    assert abs(tr.events[0].time - 0.5) <= 1e-9


def test_differentiator_is_exact_after_finite_time():
    k1, k2 = 1.5, 1.1                               # L = 1 >= |f''| for f = sin t
    tr = nsc.simulate(differentiator_loop(Exosystem.sinusoid(1.0, omega=1.0), k1, k2),
                      [0.0, 0.0, 0.0, 1.0], (0.0, 8.0), progress=False)
    t_conv = float(tr.event_times("two_sliding_start")[0])
    assert t_conv < 8.0
    after = tr.t > t_conv
    # exact differentiation in continuous time: the remaining error is the integrator's
    # (rtol 1e-11 over |f| <= 1, ~ 1e-10 accumulated over 6 time units) and the
    # central-difference equivalent control's (~1e-10 relative)
    assert np.max(np.abs(tr.x[after, 0] - np.sin(tr.t[after]))) <= 1e-9
    assert np.max(np.abs(tr.x[after, 1] - np.cos(tr.t[after]))) <= 1e-9


def test_implicit_euler_accepts_the_super_twisting_inclusion():
    from nscontrol.laws import Product, Relay, SuperTwistingLaw
    from nscontrol.systems import LureSystem

    # the super-twisting loop as a Lur'e system: two multipliers read the same s = x + x'
    # (w1 in -k1|s|^1/2 sign s into x'', w2 in -k2 Sign s into nu'), so D_h has rank one and
    # the step is the scalar inclusion solved in closed form
    lure = LureSystem([[0, 1, 0], [0, 0, 1], [0, 0, 0]], [[0, 0], [1, 0], [0, 1]],
                      [[1, 1, 0], [1, 1, 0]], Product(SuperTwistingLaw(K1, 0.0), Relay(K2)),
                      B=[[0], [1], [0]], u=Exosystem.sinusoid(0.3, omega=5.0))
    errors = []
    for h in (1e-2, 1e-3):
        tr = nsc.simulate(lure, [0.5, 0.0, 0.0], (0.0, 6.0), method="implicit_euler", h=h,
                          progress=False)
        assert tr.stats["structure"] == "shared_argument"
        z = tr.signal("z")[:, 0]
        k = int(np.flatnonzero(z != 0.0)[-1]) + 1
        # after reaching, s is exactly zero: the disturbance's exact mean over each step is
        # in the one-step problem, whose solution is s = 0 once |a| <= the sign's weight;
        # x1 + x2 recomputed from the state rounds to a few eps x |x| (|x| <= 1)
        assert np.max(np.abs(tr.x[k:, 0] + tr.x[k:, 1])) <= 4 * np.finfo(float).eps
        errors.append(abs(tr.t[k] - 2.1363530))
    # implicit Euler is first order: the reaching-time error shrinks by about 10 with h
    # (the next term, O(h^2), changes the ratio by a factor 1 +- 0.3 at h = 1e-2)
    assert 10 ** 0.85 <= errors[0] / errors[1] <= 10 ** 1.15


def test_second_order_sliding_is_left_where_the_equivalent_sign_leaves_its_bounds():
    # differentiating f = 1.5 sin t with k2 = 1.1 < sup|f''| = 1.5: on z0 = f, z1 = f' the
    # sign's equivalent value is f''/k2-like, |1.5 sin t| / 1.1, which reaches 1 at
    # t = arcsin(1.1 / 1.5): the motion must leave there
    tr = nsc.simulate(differentiator_loop(Exosystem.sinusoid(1.5, omega=1.0), 3.0, 1.1),
                      [0.1, 1.5, 0.0, 1.0], (0.0, 1.0), progress=False)
    assert [e.kind for e in tr.events if e.kind.startswith("two_")] == \
        ["two_sliding_start", "two_sliding_exit"]
    # the exit is located by DOP853 on the weight alpha(t), itself from central differences
    # with relative error ~1e-10 and slope ~1: 1e-8 leaves a factor 100
    assert abs(tr.event_times("two_sliding_exit")[0] - np.arcsin(1.1 / 1.5)) <= 1e-8


def test_a_start_on_the_second_order_sliding_set_stays_there():
    # x0 on s = 0 with s' = x2 + nu + d(0) = 0: no first-order sliding field exists there
    # (both sides give the same s'), the motion starts in second-order sliding
    tr = nsc.simulate(_disturbed().super_twisting_loop(K1, K2), [0.1, -0.1, 0.1], (0.0, 1.0),
                      progress=False)
    assert [e.kind for e in tr.events] == ["two_sliding_start"]
    assert np.max(np.abs(tr.x[:, 0] + tr.x[:, 1])) <= 1e-12


def _ulps(value, k):
    """``value`` moved by ``k`` units in the last place."""
    v = float(value)
    for _ in range(abs(k)):
        v = float(np.nextafter(v, np.inf if k > 0 else -np.inf))
    return v


_X0 = [0.1, 1.5, 0.0, 1.0]


@pytest.mark.parametrize("amplitude, k1, k2, x0", [
    (1.5, 3.0, 1.1, _X0),                              # the case that hung on another machine
    (1.5, 3.0, 1.1 * (1 - 1e-3), _X0),
    (1.5, 3.0, 1.1 * (1 + 1e-3), _X0),
    (1.5 * (1 + 1e-3), 3.0, 1.1, _X0),
    (1.5, 2.9, 1.1, _X0),
    (1.5, 3.1, 1.1, _X0),
    *[(1.5, 3.0, 1.1, [_ulps(_X0[0], k), _ulps(_X0[1], -k), _X0[2], _ulps(_X0[3], k)])
      for k in (1, -1, 3, -3)],                        # the start moved by a few ulps
])
def test_second_order_sliding_exit_does_not_depend_on_rounding(amplitude, k1, k2, x0):
    # The second-order sliding piece integrates the fields restricted to s = 0 (the odd
    # |s|^{1/2} term cancelled between two points at ±1e-6 from the surface), so its field is
    # Lipschitz and DOP853's steps do not shrink on rounding: every perturbation of the
    # start or of the gains finishes, and leaves where |A sin t| = k2 (as in the test above).
    # Step budget: DOP853 (order 8, rtol 1e-11) takes about rtol^(-1/8) = 24 steps per unit
    # of time on a smooth piece; each restart after an event grows its first step by at most
    # 10 per step from ~1e-6, 7 steps; the reaching phase's crossings of the non-Lipschitz
    # |s|^{1/2} field cost more (each is approached with steps shrinking like |s|), bounded
    # here by 20 per piece plus 1000: a field that loses its smoothness on rounding costs
    # 1e5 steps and more (the hang never left t = 0.2686).
    loop = differentiator_loop(Exosystem.sinusoid(amplitude, omega=1.0), k1, k2)
    tr = nsc.simulate(loop, x0, (0.0, 1.0), progress=False, max_steps=20_000)
    assert [e.kind for e in tr.events if e.kind.startswith("two_")] == \
        ["two_sliding_start", "two_sliding_exit"]
    assert tr.stats["steps"] <= 1000 + 20 * tr.stats["pieces"]
    # the exit as above: alpha from five-point differences (relative error ~1e-10), slope ~1
    assert abs(tr.event_times("two_sliding_exit")[0] - np.arcsin(k2 / amplitude)) <= 1e-8
