"""Event-driven integration with one planar frictional contact held closed: stick, slip and
slip reversal located exactly, against the closed forms of the pushed block, the inclined
block and the spring-block (stick-slip oscillator), and against Moreau–Jean with friction."""

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import LagrangianSystem, brick_stack, inclined_block
from nscontrol.systems.feedback import StateFeedback, StaticLaw

EPS = np.finfo(float).eps
G = 9.81
MU = 0.4
# Event times are roots of guards computed from e^{At} z (a handful of N-term products,
# N <= 5 here, each with relative error ~ N eps) divided by the guard's slope, then refined
# to a few ulps: the located time and the state there carry ~ 10 N eps relative error. We
# allow 1000 eps relative (a factor 20 above that estimate for the accumulation over the
# 3 successive flights of the oscillator).
REL = 1000 * EPS


def _ed(system, x0, tf, **kw):
    return nsc.simulate(system, x0, (0.0, tf), method="event_driven", progress=False, **kw)


def _spring_block(k=50.0, m=1.0, mu=MU):
    """A block on the ground tied to a wall by a spring: ``m x'' = -k x + λ_T``."""
    return LagrangianSystem([m, m], stiffness=np.diag([k, 0.0]), constant_force=[0.0, -m * G],
                            gap_matrix=[[0.0, 1.0]], friction=mu, tangent_matrix=[[1.0, 0.0]],
                            names=("x", "y"))


def test_pushed_block_stops_at_the_closed_form_time_and_distance():
    v0 = 2.0
    traj = _ed(inclined_block(MU, 0.0), [0.0, 0.0, v0, 0.0], 1.0)
    t_stop, d_stop = v0 / (MU * G), v0 ** 2 / (2 * MU * G)
    (ev,) = traj.events
    assert ev.kind == "stick" and (ev.mode_from, ev.mode_to) == (1, 0)
    assert abs(ev.time - t_stop) <= REL * t_stop
    assert abs(ev.post[0] - d_stop) <= REL * d_stop
    assert abs(traj.x[-1, 0] - d_stop) <= REL * d_stop
    assert abs(traj.x[-1, 2]) <= REL * v0
    slipping = traj.t < ev.time
    # slipping: the friction force is -μ m g exactly (to the rounding of μ g, a few ulps)
    np.testing.assert_allclose(traj.signals["friction"][slipping], -MU * G, rtol=8 * EPS)
    assert set(traj.signals["contact_state"][slipping]) == {2.0}
    # stuck on flat ground: no friction needed (rounding of g · 0 terms: exact zero)
    assert np.all(traj.signals["friction"][traj.t > ev.time] == 0.0)
    assert set(traj.signals["contact_state"][traj.t > ev.time]) == {1.0}


@pytest.mark.parametrize("angle", [0.2, np.arctan(MU)])
def test_inclined_block_sticks_when_tan_theta_is_at_most_mu(angle):
    traj = _ed(inclined_block(MU, angle), [0.0, 0.0, 0.0, 0.0], 2.0)
    assert traj.events == ()
    # the stick acceleration is the rounding of m g sin α - λ_T: a few ulps of g, over 2 s
    assert np.max(np.abs(traj.x[:, 2])) <= 8 * EPS * G * 2.0
    assert np.max(np.abs(traj.x[:, 0])) <= 8 * EPS * G * 2.0 ** 2
    # the friction holds the weight's component along the slope (a few ulps of m g)
    np.testing.assert_allclose(traj.signals["friction"], -G * np.sin(angle), rtol=8 * EPS)
    np.testing.assert_allclose(traj.signals["normal_force"], G * np.cos(angle), rtol=8 * EPS)


def test_inclined_block_slides_with_the_coulomb_acceleration():
    angle = 0.6  # tan 0.6 = 0.68 > μ
    traj = _ed(inclined_block(MU, angle), [0.0, 0.0, 0.0, 0.0], 2.0, dt=0.1)
    a = G * (np.sin(angle) - MU * np.cos(angle))
    assert traj.events == ()
    assert set(traj.signals["contact_state"]) == {2.0}
    # x = a t²/2 from the matrix exponential of a nilpotent flow: relative error ~ N eps
    np.testing.assert_allclose(traj.x[1:, 0], 0.5 * a * traj.t[1:] ** 2, rtol=REL)
    np.testing.assert_allclose(traj.x[1:, 2], a * traj.t[1:], rtol=REL)


def test_spring_block_stops_each_half_period_and_sticks_in_the_dead_zone():
    k, m = 50.0, 1.0
    w, xc = np.sqrt(k / m), MU * m * G / k  # dead zone |x| <= μ m g / k
    x0 = 6.5 * xc
    traj = _ed(_spring_block(k, m), [x0, 0.0, 0.0, 0.0], 3.0)
    # each half period about the centre ±xc the amplitude loses 2 xc: stops at -4.5 xc,
    # 2.5 xc (outside the dead zone: the slip reverses), then -0.5 xc (inside: sticks)
    kinds = [e.kind for e in traj.events]
    assert kinds == ["slip_reversal", "slip_reversal", "stick"]
    for i, (ev, x_stop) in enumerate(zip(traj.events, [-4.5, 2.5, -0.5], strict=True)):
        t_stop = (i + 1) * np.pi / w
        assert abs(ev.time - t_stop) <= REL * t_stop
        assert abs(ev.post[0] - x_stop * xc) <= REL * x0
    stuck = traj.t > traj.events[-1].time
    np.testing.assert_allclose(traj.x[stuck, 0], traj.events[-1].post[0], rtol=REL)
    np.testing.assert_allclose(traj.signals["friction"][stuck], -0.5 * xc * k, rtol=REL)


def test_spring_block_released_inside_the_dead_zone_never_moves():
    k = 50.0
    traj = _ed(_spring_block(k), [0.9 * MU * G / k, 0.0, 0.0, 0.0], 1.0)
    assert traj.events == ()
    # held by friction: the stick acceleration is rounding, a few ulps of k x0 / m, over 1 s
    assert np.max(np.abs(traj.x[:, 2])) <= 8 * EPS * MU * G


def test_agrees_with_moreau_jean_to_first_order():
    k, m = 50.0, 1.0
    xc = MU * m * G / k
    system, x0, tf = _spring_block(k, m), [6.5 * xc, 0.0, 0.0, 0.0], 1.6
    ed = _ed(system, x0, tf, dt=1e-2)
    errors = []
    for h in (1e-3, 1e-4):
        mj = nsc.simulate(system, x0, (0.0, tf), method="moreau_jean", h=h, progress=False)
        errors.append(np.max(np.abs(np.interp(ed.t, mj.t, mj.x[:, 2]) - ed.x[:, 2])))
        # an event inside a step leaves a velocity error of at most h |Δa|, |Δa| <= 2 μ g (a
        # reversal); three events
        assert errors[-1] <= 3 * h * 2 * MU * G
    # first order: the ratio is 10, within a factor 2 (where events fall inside the steps)
    assert 5.0 <= errors[0] / errors[1] <= 20.0


def test_refuses_what_it_cannot_locate_exactly():
    block = inclined_block(MU, 0.0)
    with pytest.raises(ModelError, match="x0.*moreau_jean"):  # an impact with friction
        _ed(block, [0.0, 0.1, 1.0, 0.0], 1.0)
    with pytest.raises(ModelError, match="one planar contact.*moreau_jean"):
        _ed(brick_stack(1, MU), np.array([0.0, 0.05, 0.0, 0.0, 0.0, 0.0]), 1.0)
    with pytest.raises(ModelError, match="sensitivity"):
        _ed(block, [0.0, 0.0, 1.0, 0.0], 1.0, sensitivity=True)
    with pytest.raises(ModelError, match="^controller: .*StateFeedback.*moreau_jean"):
        _ed(nsc.closed_loop(block, _Zero()), [0.0, 0.0, 1.0, 0.0], 1.0)


class _Zero(StaticLaw):
    """A law written in Python (no force): refused with friction, which needs a linear flow."""

    n_outputs, period = 2, None

    def output(self, t, xc, m):
        return np.zeros(2)


def test_a_state_feedback_is_folded_into_the_frictional_flow():
    # u = K [q; v] with K = -[50, 0, 0, 0] on the x force is the spring of _spring_block:
    # the same flow, folded into the model, so the same exact events and states
    spring = _spring_block()
    free = LagrangianSystem([1.0, 1.0], constant_force=[0.0, -G], gap_matrix=[[0.0, 1.0]],
                            friction=MU, tangent_matrix=[[1.0, 0.0]], names=("x", "y"))
    loop = nsc.closed_loop(free, StateFeedback([[-50.0, 0.0, 0.0, 0.0],
                                                [0.0, 0.0, 0.0, 0.0]]))
    x0 = [0.1, 0.0, 0.0, 0.0]
    a, b = _ed(loop, x0, 2.0), _ed(spring, x0, 2.0)
    assert [e.kind for e in a.events] == [e.kind for e in b.events] == ["stick"]
    # the same model: every number equal (the fold builds the stiffness 0 - 1·(-50) = 50)
    np.testing.assert_array_equal(a.event_times(), b.event_times())
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.signals["u"][:, 0], -50.0 * a.x[:, 0])


def test_lift_off_is_refused_with_the_run_so_far():
    # a vertical pull 2 m g sin(t): the normal force m g (1 - 2 sin t) reaches zero at π/6
    pull = Exosystem.sinusoid([0.0, 2.0 * G], 1.0)
    with pytest.raises(ModelError, match="normal force reaches zero.*moreau_jean") as err:
        _ed(inclined_block(MU, 0.0), [0.0, 0.0, 1.0, 0.0], 1.0, u=pull)
    traj = err.value.trajectory
    assert abs(traj.t[-1] - np.pi / 6) <= REL * np.pi


def test_block_under_a_ramp_force_slips_when_the_force_reaches_mu_m_g():
    # a horizontal push c t: stuck until c t* = μ m g, then m x'' = c (t - t*), so
    # x = c (t - t*)³ / 6 (m = 1)
    c = 2.0
    push = Exosystem.polynomial([[0.0, 0.0], [c, 0.0]])
    traj = _ed(inclined_block(MU, 0.0), [0.0, 0.0, 0.0, 0.0], 3.0, u=push, dt=0.1)
    t_star = MU * G / c
    (ev,) = traj.events
    assert ev.kind == "slip" and (ev.mode_from, ev.mode_to) == (0, 1)
    assert abs(ev.time - t_star) <= REL * t_star
    after = traj.t > ev.time
    # an error δ <= REL t* in the slip's start shifts x by c (t - t*)² δ / 2 at most
    shift = c * 3.0 ** 2 / 2 * REL * t_star
    np.testing.assert_allclose(traj.x[after, 0], c * (traj.t[after] - t_star) ** 3 / 6,
                               rtol=REL, atol=shift)
    # stuck before: the friction balances the push exactly (a few ulps of c t)
    before = traj.t < ev.time
    np.testing.assert_allclose(traj.signals["friction"][before], -c * traj.t[before],
                               rtol=8 * EPS, atol=8 * EPS * c * t_star)
