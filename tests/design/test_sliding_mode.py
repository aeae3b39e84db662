"""Sampled sliding-mode blocks: the known answers for the explicit and implicit
discretizations (reaching, exact zero, chattering orders) and Levant's differentiator."""

import math

import numpy as np
import pytest

from nscontrol.analysis import chattering_amplitude, fitted_order, reaching_time
from nscontrol.design import (
    FirstOrderSMC,
    LevantDifferentiator,
    SuperTwistingController,
    differentiate,
    run_sampled,
    super_twisting_gains,
)
from nscontrol.errors import ModelError
from nscontrol.numerics.lti import Exosystem, discretize
from nscontrol.systems import SlidingModePlant
from nscontrol.systems.feedback import Measurement

EPS = np.finfo(float).eps
K1, K2 = super_twisting_gains(1.5)
# A fitted order is exact only as h -> 0; the next term of the error expansion changes the
# slope between neighbouring steps by O(h / h_ref). Over a factor-4 range of h below 1e-3
# that is below 0.15 for these problems (time scales ~ 1): the tolerance on orders.
ORDER_TOL = 0.15


def _plants():
    return (SlidingModePlant.double_integrator(),
            SlidingModePlant.double_integrator(disturbance=Exosystem.sinusoid(0.3, omega=5.0)))


def test_gain_rule_is_levants():
    assert super_twisting_gains(1.5) == (1.5 * math.sqrt(1.5), 1.1 * 1.5)


def test_bad_discretization_refused():
    with pytest.raises(ModelError, match="^discretization: expected 'implicit' or"):
        FirstOrderSMC(_plants()[0], 1.0, 1e-3, discretization="midpoint")


# -- first-order SMC -------------------------------------------------------------------------
def test_implicit_first_order_reaches_in_closed_form_and_stays_exactly():
    plant, h, alpha = _plants()[0], 1e-3, 1.0
    ctrl = FirstOrderSMC(plant, alpha, h)
    tr = run_sampled(plant, ctrl, [1.0, 0.0], (0.0, 10.0))
    s = tr.signal("s")
    # s_{k+1} = s_k - alpha cG while |s_k| > alpha cG: zero after ceil(s0 / (alpha cG))
    # samples (cG = h + h^2/2 for the double integrator); the continuous-time time is
    # s0 / alpha = 1, reached within one sample
    k_reach = math.ceil(1.0 / (alpha * ctrl.cG))
    scale = np.abs(tr.x).max(axis=1) + 1.0
    # after reaching s_k = c x_k is one rounded linear combination: below 4 eps |c||x|
    assert np.all(np.abs(s[k_reach:]) <= 4 * EPS * scale[k_reach:])
    assert np.all(np.abs(s[:k_reach - 1]) > 4 * EPS)
    assert abs(tr.t[k_reach] - 1.0) <= h
    # u equals the discrete equivalent control -(cG)^-1 c (Phi - I) x_k: the projection is
    # inactive and the switching part -s_k / cG is at rounding level (4 eps |x| / cG)
    u = tr.signal("u")[:, 0]
    ueq = np.array([ctrl.equivalent_control(x) for x in tr.x])
    tail = slice(k_reach + 1, -1)
    assert np.all(np.abs(u[tail] - ueq[tail]) <= 8 * EPS * scale[tail] / ctrl.cG)


def test_explicit_first_order_chatters_with_amplitude_of_order_h():
    plant = _plants()[0]
    hs = np.array([2e-3, 1e-3, 5e-4, 2.5e-4])
    amp = [chattering_amplitude(*_ts(run_sampled(plant, FirstOrderSMC(plant, 1.0, h,
                                                                      "explicit"),
                                                 [1.0, 0.0], (0.0, 4.0))), after=2.0)
           for h in hs]
    # explicit: s_{k+1} = s_k - alpha cG sign(s_k), so |s_k| <= alpha cG once reached
    assert all(a <= 1.0 * (h + h * h / 2) * (1 + 4 * EPS) for a, h in zip(amp, hs, strict=True))
    assert abs(fitted_order(hs, amp).order - 1.0) <= ORDER_TOL


def _ts(tr):
    return tr.t, tr.signal("s")


# -- super-twisting --------------------------------------------------------------------------
def test_implicit_super_twisting_is_exactly_zero_without_disturbance():
    plant = _plants()[0]
    tr = run_sampled(plant, SuperTwistingController(plant, K1, K2, 1e-2), [0.5, 0.0],
                     (0.0, 6.0))
    s = tr.signal("s")
    # s_k = c x_k with x_k from one ZOH step of an exact prediction: rounding only, below
    # 8 eps (|x| + 1) once the prediction is zero
    tol = 8 * EPS * (np.abs(tr.x).max() + 1.0)
    t_reach = reaching_time(tr.t, s, tol)
    # reached, and well before the end (the continuous-time loop reaches near t = 2.1)
    assert t_reach <= 4.0
    assert np.all(np.abs(s[tr.t >= t_reach]) <= tol)


@pytest.mark.parametrize("estimate, order", [(True, 2.0), (False, 1.0)])
def test_implicit_super_twisting_accuracy_with_disturbance(estimate, order):
    plant = _plants()[1]
    hs = np.array([2e-3, 1e-3, 5e-4, 2.5e-4])
    amp = [chattering_amplitude(*_ts(run_sampled(
        plant, SuperTwistingController(plant, K1, K2, h, estimate_disturbance=estimate),
        [0.5, 0.0], (0.0, 6.0))), after=4.0) for h in hs]
    # with the one-step disturbance estimate |s_k| = cG |mean d over step k - over step k-1|
    # = O(h^2); without it |s_k| = cG |mean d| = O(h) (cG = h + h^2/2, |d| <= 0.3)
    assert abs(fitted_order(hs, amp).order - order) <= ORDER_TOL
    if not estimate:
        assert max(a / (h + h * h / 2) for a, h in zip(amp, hs, strict=True)) <= 0.3 * (1 + 1e-9)


def test_explicit_super_twisting_chatters_with_amplitude_of_order_h2():
    plant = _plants()[1]
    hs = np.array([1e-3, 5e-4, 2.5e-4])
    amp = [chattering_amplitude(*_ts(run_sampled(
        plant, SuperTwistingController(plant, K1, K2, h, "explicit"), [0.5, 0.0],
        (0.0, 12.0))), after=8.0) for h in hs]
    assert abs(fitted_order(hs, amp).order - 2.0) <= ORDER_TOL


def test_python_block_matches_the_compiled_loop():
    plant, h = _plants()[1], 1e-2
    for disc in ("implicit", "explicit"):
        ctrl = SuperTwistingController(plant, K1, K2, h, disc)
        tr = run_sampled(plant, ctrl, [0.5, 0.0], (0.0, 3.0))
        # the block's output/update on the same samples, plant propagated by the same ZOH
        A_aug, B_aug, _ = plant.augmented()
        Phi, Gam = discretize(A_aug, B_aug, h)
        X = np.concatenate([[0.5, 0.0], plant.disturbance.w(0.0)])
        xc = ctrl.x0
        for k in range(tr.t.shape[0] - 1):
            m = Measurement(tr.t[k], y=X[:2], x=X[:2])
            u = ctrl.output(tr.t[k], xc, m)
            xc = ctrl.update(tr.t[k], xc, m)
            X = Phi @ X + Gam[:, 0] * u[0]
        # same operations in another order (matrix products vs loops): rounding differences
        # grow at most linearly over 300 steps of a contracting loop
        assert np.allclose(X[:2], tr.x[-1], rtol=0.0, atol=300 * 8 * EPS)


def test_gain_rule_claim_on_the_known_answer_problem():
    # Levant's rule promises finite-time convergence for |d'| <= L: here |d'| = 1.5 = L.
    # The implicit loop at h = 1e-4 must be within its O(h^2) band well before T = 6.
    plant = _plants()[1]
    tr = run_sampled(plant, SuperTwistingController(plant, K1, K2, 1e-4), [0.5, 0.0],
                     (0.0, 6.0))
    # the band: cG |d'| h <= (h + h^2/2) 1.5 h, doubled for the worst phase
    assert chattering_amplitude(tr.t, tr.signal("s"), after=3.0) <= 2 * 1.5 * 1e-4 * 1.0001e-4


# -- Levant's differentiator -----------------------------------------------------------------
@pytest.mark.parametrize("disc", ["implicit", "explicit"])
def test_differentiator_orders(disc):
    k1, k2 = super_twisting_gains(1.0)                # |f''| <= 1 for f = sin t
    hs = np.array([2e-3, 1e-3, 5e-4])
    e0, e1 = [], []
    for h in hs:
        t = np.arange(0.0, 10.0, h)
        est = differentiate(LevantDifferentiator(k1, k2, h, disc), np.sin(t))
        keep = t >= 6.0
        e0.append(np.max(np.abs(est[keep, 0] - np.sin(t[keep]))))
        e1.append(np.max(np.abs(est[keep, 1] - np.cos(t[keep]))))
    if disc == "implicit":
        # the implicit estimate of f is the sample itself once in the band (z0 = f_k + 0)
        assert max(e0) == 0.0
    else:
        assert abs(fitted_order(hs, e0).order - 2.0) <= ORDER_TOL
    assert abs(fitted_order(hs, e1).order - 1.0) <= ORDER_TOL


# -- the blocks as Controllers of nscontrol.closed_loop -----------------------------------------
def test_blocks_regulate_a_lure_plant_with_coulomb_friction_in_closed_loop():
    import nscontrol as nsc
    from nscontrol.laws import Relay
    from nscontrol.systems import LureSystem

    # x'' = u - mu Sign(x'): the friction is a matched disturbance the controllers do not
    # know; the plant runs by implicit Euler, the blocks sampled every step (ZOH)
    mu, h = 0.3, 1e-3
    lure = LureSystem([[0, 1], [0, 0]], [[0], [1]], [[0, 1]], Relay(mu), B=[[0], [1]])
    model = SlidingModePlant.double_integrator()
    fo = FirstOrderSMC(model, 1.0, h)
    tr = nsc.simulate(nsc.closed_loop(lure, fo), [1.0, 0.0], (0.0, 6.0),
                      method="implicit_euler", h=h, progress=False)
    s = tr.x[:, 0] + tr.x[:, 1]
    # implicit first order: s_{k+1} = cG x (friction over the step) plus the O(h^2) gap
    # between the plant's implicit Euler step and the controller's ZOH model (|u| <= 2)
    assert chattering_amplitude(tr.t, s, after=4.0) <= fo.cG * mu + 2 * h * h
    st = SuperTwistingController(model, *super_twisting_gains(1.0), h)
    tr = nsc.simulate(nsc.closed_loop(lure, st), [1.0, 0.0], (0.0, 6.0),
                      method="implicit_euler", h=h, progress=False)
    s = tr.x[:, 0] + tr.x[:, 1]
    # while sliding the friction is constant, so the one-step estimate cancels it and the
    # model gap alike up to their change over a step: O(h^2) with a constant below 1
    assert chattering_amplitude(tr.t, s, after=4.0) <= h * h
