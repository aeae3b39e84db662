"""One closed-loop composition: linear blocks stacked into one exact model, Python blocks
stepped beside a Moreau–Jean plant, named signals, clear refusals."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import DimensionError, ModelError
from nscontrol.simulate.lowering import stacked_model
from nscontrol.systems.feedback import (
    Controller,
    LinearController,
    LinearObserver,
    Measurement,
    StateFeedback,
)
from nscontrol.systems.lagrangian import LagrangianSystem

EPS = np.finfo(float).eps


def _mass_on_wall(**kw):
    """A unit mass above a floor at q = 0, pushed down by a unit force."""
    return LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
                            constant_force=[-1.0], **kw)


def test_state_feedback_on_a_linear_mechanical_plant_stays_exact_and_compiled():
    plant = _mass_on_wall(restitution=0.5)
    K = np.array([[-4.0, -1.0]])
    loop = nsc.closed_loop(plant, StateFeedback(K, k=[5.0]))
    assert isinstance(stacked_model(loop), LagrangianSystem) and stacked_model(loop).is_linear
    folded = nsc.simulate(loop, [0.2, 0.0], (0.0, 10.0))
    # the same law written into the plant by hand (u = K x + 5: stiffness 4, damping 1, the
    # offset plus the unit weight a constant force 4): both are exact flows, so they agree to
    # roundoff x number of samples
    by_hand = LagrangianSystem([[1.0]], stiffness=[[4.0]], damping=[[1.0]], gap_matrix=[[1.0]],
                               gap_offset=[0.0], constant_force=[4.0], restitution=0.5)
    legacy = nsc.simulate(by_hand, [0.2, 0.0], (0.0, 10.0))
    np.testing.assert_allclose(folded.x, legacy.x, rtol=0, atol=1e3 * len(folded.t) * EPS)
    np.testing.assert_allclose(folded.signal("u")[:, 0], folded.x @ K[0] + 5.0, atol=1e-15)
    mj = nsc.simulate(loop, [0.2, 0.0], (0.0, 10.0), method="moreau_jean", h=1e-3)
    assert mj.stats["path"] in ("tridiagonal", "dense")          # compiled, not "python"
    # energy is the plant's (not the folded model's): ½ v² + q (unit force down)
    np.testing.assert_allclose(mj.signal("energy"), 0.5 * mj.x[:, 1] ** 2 + mj.x[:, 0],
                               atol=10 * EPS)


class SampledPD:
    """A user-written sampled controller: PD on the position error, held over ``period``."""

    n_states, n_outputs = 0, 1

    def __init__(self, kp, kd, ref, period):
        self.kp, self.kd, self.ref, self.period = kp, kd, ref, period

    def output(self, t, xc, m):
        return np.array([self.kp * (self.ref - m.x[0]) - self.kd * m.x[1]])

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return xc


def test_a_user_sampled_controller_on_moreau_jean_matches_the_exact_discrete_loop():
    """Free flight (the floor far below): Moreau–Jean with theta = 1/2 is exact at its steps
    for a force constant over each step, so the loop equals x_{k+1} = Phi x_k + Gamma u_k at
    the sampling instants, to roundoff."""
    plant = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[100.0],
                             actuation=[[1.0]])
    T, h = 0.05, 0.005
    ctrl = SampledPD(kp=4.0, kd=2.0, ref=1.0, period=T)
    assert isinstance(ctrl, Controller)
    loop = nsc.closed_loop(plant, ctrl)
    assert stacked_model(loop) is None and loop.default_method == "moreau_jean"
    tr = nsc.simulate(loop, [0.0, 0.0], (0.0, 2.0), h=h, theta=0.5)
    Phi = np.array([[1.0, T], [0.0, 1.0]])
    Gam = np.array([T * T / 2, T])
    x = np.zeros(2)
    ref = [x]
    for _ in range(40):
        x = Phi @ x + Gam * (4.0 * (1.0 - x[0]) - 2.0 * x[1])
        ref.append(x)
    idx = [int(np.argmin(np.abs(tr.t - k * T))) for k in range(41)]
    # 400 steps of a contracting loop: roundoff grows at most linearly, 1e3 ulps is generous
    np.testing.assert_allclose(tr.x[idx], np.array(ref), rtol=0, atol=1e3 * EPS)
    u = tr.signal("u")[:, 0]
    k5 = idx[5]
    assert u[k5 + 1] == u[k5 + 9]                 # held between samples (zero-order hold)


class ImpactCounter:
    """An 'observer' whose state counts the plant's impacts (reset) and integrates y."""

    n_states, n_outputs, period = 2, 2, None

    def output(self, t, xc, m):
        return xc

    def update(self, t, xc, m):
        return np.array([0.0, m.y[0]])

    def reset(self, t, xc, jump):
        return xc + np.array([1.0, 0.0])


def test_python_blocks_are_reset_at_every_impact():
    ball = LagrangianSystem.bouncing_ball(restitution=0.8)
    loop = nsc.closed_loop(ball, observer=ImpactCounter(), output_matrix=[[1.0, 0.0]])
    tr = nsc.simulate(loop, [1.0, 0.0], (0.0, 3.0), h=1e-3)
    n_impacts = len(tr.events_of("impact"))
    assert n_impacts >= 5
    assert tr.signal("xhat")[-1, 0] == n_impacts
    # the second state integrates q by explicit Euler: within O(h) of the trapezoid sum
    trapezoid = np.sum(np.diff(tr.t) * 0.5 * (tr.x[1:, 0] + tr.x[:-1, 0]))
    assert abs(tr.signal("xhat")[-1, 1] - trapezoid) < 1e-3 * 3.0 * 1.0 * 2   # h * T * max|q'|


def test_a_linear_controller_and_observer_stack_into_one_lure_system():
    """A Lur'e plant with a dynamic (integral) controller: the stacked model is one
    LureSystem integrated by implicit Euler; the integral action removes the offset."""
    from nscontrol.laws.relay import Relay
    from nscontrol.systems.lure import LureSystem

    A = np.array([[0.0, 1.0], [-2.0, -3.0]])
    plant = LureSystem(A, [[0.0], [0.5]], [[0.0, 1.0]], Relay(0.2), B=[[0.0], [1.0]],
                       C=[[1.0, 0.0]], u=lambda t: np.ones((np.size(t), 1)))
    integral = LinearController([[0.0]], [[-1.0]], [[1.0]], [[0.0]])   # u = -∫ y
    loop = nsc.closed_loop(plant, integral)
    assert isinstance(stacked_model(loop), LureSystem) and stacked_model(loop).n_states == 3
    tr = nsc.simulate(loop, np.zeros(3), (0.0, 60.0), h=1e-2)
    assert abs(tr.x[-1, 0]) < 1e-3        # integral action: y -> 0 (decay rate >= 0.2)
    np.testing.assert_allclose(tr.signal("u")[:, 0], tr.x[:, 2], atol=0)


def test_composition_refuses_what_no_integrator_runs():
    ball = LagrangianSystem.bouncing_ball()
    with pytest.raises(ModelError, match=r"^controller: expected a block with n_states"):
        nsc.closed_loop(ball, controller=lambda t, x: 0.0)
    with pytest.raises(ModelError, match=r"^observer: a StateFeedback/LinearController "):
        nsc.closed_loop(ball, observer=StateFeedback([[1.0, 0.0]]))
    loop = nsc.closed_loop(ball, observer=ImpactCounter())
    with pytest.raises(ModelError, match=r"^event_driven: runs a closed loop whose controller "
                                         r"is a continuous law without state"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), method="event_driven")
    from nscontrol.testing.setvalued_problems import relay_feedback

    # Python blocks around a Lur'e plant run by implicit Euler only
    lure_loop = nsc.closed_loop(relay_feedback().system, SampledPD(1, 1, 0, 0.1))
    assert stacked_model(lure_loop) is None and lure_loop.default_method == "implicit_euler"
    with pytest.raises(ModelError, match=r"^moreau_jean: this loop's blocks run as Python code "
                                         r"stepped with a LureSystem"):
        nsc.simulate(lure_loop, np.zeros(lure_loop.n_states), (0.0, 1.0),
                     method="moreau_jean", h=1e-2)
    with pytest.raises(DimensionError, match=r"^controller: K must have shape \(1, 2\)"):
        nsc.closed_loop(_mass_on_wall(), StateFeedback([[1.0, 2.0, 3.0]]))


def test_a_controller_error_mid_run_keeps_the_partial_loop():
    class Failing(SampledPD):
        def output(self, t, xc, m):
            if t > 0.2:
                return np.array([np.nan])
            return super().output(t, xc, m)

    plant = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[100.0],
                             actuation=[[1.0]])
    loop = nsc.closed_loop(plant, Failing(1.0, 1.0, 1.0, 0.05))
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value") as info:
        nsc.simulate(loop, [0.0, 0.0], (0.0, 1.0), h=0.01)
    assert 0.19 < info.value.trajectory.t[-1] <= 0.26


def test_measurement_and_blocks_validate_their_matrices():
    with pytest.raises(DimensionError, match="^B: "):
        LinearController([[0.0]], [[1.0, 2.0], [3.0, 4.0]], [[1.0]], [[0.0]])
    with pytest.raises(ModelError, match="^law: G, H, K, D describe a Lur'e observer"):
        LinearObserver(np.eye(2), np.ones((2, 1)), G=np.ones((2, 1)))
    m = Measurement(0.0, y=np.zeros(1), x=np.array([1.0, 2.0]))
    with pytest.raises(ModelError, match="needs an observer|has no observer"):
        StateFeedback([[1.0, 1.0]], on="estimate").output(0.0, np.zeros(0), m)


def test_a_pwa_plant_with_its_observer_is_one_pwa_system_on_the_product_of_regions():
    """Chapter 11's observer (a copy of the plant with output injection) composed with the
    one-sided oscillator: 2 x 2 regions, the error x - x̂ decays at the certified rate."""
    from nscontrol.design.convergent_pwa import design_observer
    from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    from nscontrol.systems.feedback import PiecewiseObserver

    plant = one_sided_oscillator(0.1)
    obs = design_observer(plant, sigma=1.0)
    loop = nsc.closed_loop(plant, observer=PiecewiseObserver(obs.L, obs.C))
    assert stacked_model(loop).n_regions == 4 and stacked_model(loop).n_states == 4
    tr = nsc.simulate(loop, [0.5, 0.0, -0.5, 0.3], (0.0, 10.0))
    err = np.linalg.norm(tr.signal("error"), axis=1)
    np.testing.assert_allclose(tr.signal("error"), tr.x[:, :2] - tr.x[:, 2:], atol=0)
    # |e(t)| <= sqrt(cond P) e^{-sigma t} |e(0)| with sigma = 1 (the design's certificate)
    bound = np.sqrt(np.linalg.cond(obs.P)) * np.exp(-1.0 * tr.t) * err[0]
    assert np.all(err <= bound * (1 + 1e-9) + 1e-12)
