"""Event-driven integration of mechanical and linear hybrid systems against closed forms."""

import numpy as np
import pytest

from nscontrol import closed_loop
from nscontrol.errors import BudgetExceededError, NscontrolWarning, ZenoError
from nscontrol.numerics.lti import Exosystem
from nscontrol.simulate import simulate
from nscontrol.systems.feedback import StateFeedback, StaticLaw
from nscontrol.systems.hybrid import LinearHybridSystem
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.testing.mechanics_problems import BouncingBall, NewtonsCradle


def test_bouncing_ball_impact_times_and_accumulation() -> None:
    ball = BouncingBall(restitution=0.9, height=1.0, g=9.81)
    traj = simulate(ball.system(), ball.x0, (0.0, 10.0), method="event_driven")
    impacts = traj.event_times("impact")
    assert np.max(np.abs(impacts[:20] - ball.impact_times(20))) < 1e-12
    acc = traj.events_of("accumulation")
    assert len(acc) == 1
    assert abs(acc[0].time - 8.57895) <= 5e-6    # the figure quoted to 6 digits: half a unit
    assert abs(acc[0].time - ball.accumulation_time) < 1e-9
    after = traj.t > acc[0].time
    assert np.all(np.abs(traj.x[after]) < 1e-12)  # at rest on the ground
    assert traj.events_of("contact_start")[-1].time == acc[0].time
    # energy only decreases, and each impact keeps e² of the kinetic energy
    assert np.all(np.diff(traj.signals["energy"]) <= 1e-12)
    for k, ev in enumerate(traj.events_of("impact")[:20]):
        assert ev.post[1] == pytest.approx(-0.9 * ev.pre[1], rel=1e-12)
        assert -ev.pre[1] == pytest.approx(ball.impact_velocity(k), rel=1e-11)


def test_plastic_impact_then_persistent_contact() -> None:
    ball = BouncingBall(restitution=0.0)
    traj = simulate(ball.system(), ball.x0, (0.0, 2.0))
    (impact,) = traj.events_of("impact")
    assert impact.time == pytest.approx(np.sqrt(2 / 9.81), rel=1e-14)
    assert [e.kind for e in traj.events] == ["impact", "contact_start"]
    assert np.all(np.abs(traj.x[traj.t > impact.time]) < 1e-12)


def test_contact_is_left_when_the_force_would_become_negative() -> None:
    # mass on a spring held against the wall q <= 0.5 by a decreasing push u = 2 - t: the
    # contact force is λ = u - k q = 1.5 - t, which vanishes at t = 1.5
    system = LagrangianSystem(np.array([[1.0]]), stiffness=[[1.0]], gap_matrix=[[-1.0]],
                              gap_offset=[0.5], restitution=0.0, actuation=[[1.0]])
    traj = simulate(system, [0.5, 0.0], (0.0, 3.0), u=Exosystem.polynomial([2.0, -1.0]))
    kinds = [(e.kind, e.time) for e in traj.events]
    assert kinds[0] == ("contact_start", 0.0)
    assert kinds[1][0] == "contact_end"
    assert kinds[1][1] == pytest.approx(1.5, abs=1e-12)
    during = traj.t < 1.5
    assert np.all(traj.x[during, 0] == pytest.approx(0.5, abs=1e-12))
    assert np.all(traj.x[traj.t > 1.6, 0] < 0.5)  # leaves the wall


def test_newtons_cradle_momentum_and_energy_per_impact() -> None:
    cradle = NewtonsCradle(n=6, spacing=0.01, velocity=1.0)
    traj = simulate(cradle.system(), cradle.x0, (0.0, 0.1))
    impacts = traj.events_of("impact")
    assert [e.index for e in impacts] == list(range(5))
    assert np.max(np.abs(traj.event_times("impact") - cradle.impact_times())) < 1e-12
    n = cradle.n
    for ev in impacts:
        for x in (ev.pre, ev.post):
            assert np.sum(x[n:]) == pytest.approx(1.0, abs=1e-12)
            assert 0.5 * np.sum(x[n:] ** 2) == pytest.approx(0.5, abs=1e-12)
        j = ev.index
        assert ev.post[n + j] == pytest.approx(0.0, abs=1e-12)  # velocity handed on
        assert ev.post[n + j + 1] == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(traj.x[-1, n:], np.eye(n)[-1], atol=1e-12)


def test_restitution_law_for_random_masses_and_velocities(rng: np.random.Generator) -> None:
    for _ in range(15):
        m = rng.uniform(0.1, 10.0, 2)
        e = rng.uniform(0.0, 1.0)
        v = np.sort(rng.normal(size=2))[::-1]  # v1 > v2: approaching
        chain = LagrangianSystem.chain(m, restitution=e)
        traj = simulate(chain, [0.0, 0.3, *v], (0.0, 0.3 / (v[0] - v[1]) + 1.0))
        (ev,) = traj.events_of("impact")
        pre, post = ev.pre[2:], ev.post[2:]
        assert post[1] - post[0] == pytest.approx(-e * (pre[1] - pre[0]), rel=1e-12)
        assert m @ post == pytest.approx(m @ pre, rel=1e-12, abs=1e-12)
        assert 0.5 * m @ post**2 <= 0.5 * m @ pre**2 * (1 + 1e-14)


def test_restitution_on_random_chains_with_several_contacts(rng: np.random.Generator) -> None:
    # 3 to 6 beads of random masses and coefficients, random velocities: at every impact
    # (single or simultaneous) momentum is kept, every contact that was closed and approaching
    # leaves with u+ >= -e u- (= where its impulse is positive), and energy never grows
    for _ in range(10):
        n = int(rng.integers(3, 7))
        m = rng.uniform(0.2, 5.0, n)
        e = rng.uniform(0.0, 1.0, n - 1)
        x0 = np.concatenate([np.cumsum(rng.uniform(0.05, 0.3, n)), rng.normal(size=n)])
        chain = LagrangianSystem.chain(m, restitution=e)
        traj = simulate(chain, x0, (0.0, 2.0), on_failure="warn", dt=2.0)
        impacts = traj.events_of("impact")
        assert impacts
        P = traj.stats["impulses"]
        for ev, p in zip(impacts, P, strict=True):
            vm, vp = ev.pre[n:], ev.post[n:]
            assert m @ vp == pytest.approx(m @ vm, rel=1e-12, abs=1e-12)
            assert 0.5 * m @ vp**2 <= 0.5 * m @ vm**2 * (1 + 1e-13) + 1e-15
            um, up = np.diff(vm), np.diff(vp)  # normal velocities of the n - 1 contacts
            assert np.all(p >= 0.0)
            hit = p > 1e-14
            assert up[hit] == pytest.approx(-e[hit] * um[hit], rel=1e-9, abs=1e-12)
            assert m * (vp - vm) == pytest.approx(
                np.concatenate([[0.0], p]) - np.concatenate([p, [0.0]]), abs=1e-12)


def _ch02_plant() -> ImpactingBodies:
    return ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 1.0, (0, 1): 1.0},
                                        {(0, 0): 1.0}, restitution=1.0)


def test_impacting_bodies_hybrid_matches_lagrangian_form() -> None:
    plant = _ch02_plant()
    u = Exosystem.sinusoid(2.0, 1.3)
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.3, 0.0])
    hyb = plant.hybrid(u)
    a = simulate(hyb, np.concatenate([x0, u.w0]), (0.0, 20.0))
    b = simulate(plant, x0, (0.0, 20.0), u=u)
    ta, tb = a.event_times("jump"), b.event_times("impact")
    assert len(ta) >= 3
    assert np.max(np.abs(ta - tb)) < 1e-10
    assert np.allclose(a.x[-1, :6], b.x[-1], atol=1e-9)
    assert np.allclose(a.signals["y"][:, 0], a.x[:, 0])
    # e = 1: momentum of the colliding pair kept, relative velocity reversed
    for ev in a.events_of("jump"):
        assert ev.post[3] + ev.post[5] == pytest.approx(ev.pre[3] + ev.pre[5], abs=1e-12)
        assert ev.post[5] - ev.post[3] == pytest.approx(-(ev.pre[5] - ev.pre[3]), abs=1e-12)


def test_unresolvable_accumulation_raises_zeno_with_partial_trajectory() -> None:
    # a bouncing ball written as a bare hybrid system has no persistent-contact mode
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -9.81], [0.0, 0.0, 0.0]])

    def jump(t, x, idx):
        return np.array([x[0], -0.9 * x[1], x[2]])

    ball = LinearHybridSystem(A, [[1.0, 0.0, 0.0]], [0.0], jump)
    with pytest.raises(ZenoError) as err:   # bounces closer than 1 ms, not geometric
        simulate(ball, [1.0, 0.0, 1.0], (0.0, 10.0), min_interval=1e-3)
    assert len(err.value.trajectory.events) > 30
    assert err.value.trajectory.status == -1
    assert err.value.time < BouncingBall().accumulation_time


def test_nonlinear_path_matches_closed_form() -> None:
    # the bouncing ball with a callable (constant) mass takes the DOP853 path
    ball = LagrangianSystem(lambda q: np.array([[1.0]]), constant_force=[-9.81],
                            gap=lambda q: q.copy(), jacobian=lambda q: np.eye(1),
                            restitution=0.9, names=("ball",))
    traj = simulate(ball, [1.0, 0.0], (0.0, 3.0))
    exact = BouncingBall().impact_times(10)
    exact = exact[exact < 3.0]
    assert exact.size == 4
    assert np.max(np.abs(traj.event_times("impact") - exact)) < 1e-8


def test_two_link_arm_falls_onto_the_ground() -> None:
    arm = LagrangianSystem.two_link_arm(restitution=0.5)
    x0 = [0.8, -1.2, 0.0, 0.0]
    traj = simulate(arm, x0, (0.0, 0.6))
    impacts = traj.events_of("impact")
    assert impacts, "the arm should hit the ground"
    ev = impacts[0]
    J = arm.gap_jacobian(ev.pre[:2])
    assert J @ ev.post[2:] == pytest.approx(-0.5 * (J @ ev.pre[2:]), rel=1e-9)
    assert arm.energy(ev.post) <= arm.energy(ev.pre)


def test_zeno_warning_option_keeps_the_run() -> None:
    from nscontrol.errors import ZenoWarning

    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -9.81], [0.0, 0.0, 0.0]])
    ball = LinearHybridSystem(A, [[1.0, 0.0, 0.0]], [0.0],
                              lambda t, x, idx: np.array([x[0], -0.9 * x[1], x[2]]))
    with pytest.warns(ZenoWarning, match="accumulation"):
        traj = simulate(ball, [1.0, 0.0, 1.0], (0.0, 10.0), min_interval=0.1,
                        on_failure="warn")
    assert len(traj.event_times("jump")) >= 10
    with pytest.warns(NscontrolWarning, match="max_events"):   # the event budget
        simulate(ball, [1.0, 0.0, 1.0], (0.0, 10.0), max_events=10, on_failure="warn")
    assert traj.status == -1
    assert np.max(np.abs(traj.event_times("jump")[:10] - BouncingBall().impact_times(10))) < 1e-12


@pytest.mark.parametrize("method", ["event_driven", "moreau_jean"])
def test_simultaneous_impacts_through_the_multi_contact_law(method: str) -> None:
    # two beads hit a resting middle bead at the same instant from both sides (e = 1): the
    # Delassus LCP gives equal impulses, the outer beads bounce back, the middle one stays
    chain = LagrangianSystem.chain([1.0, 1.0, 1.0], restitution=1.0)
    x0 = [-0.1, 0.0, 0.1, 1.0, 0.0, -1.0]
    opts = {"h": 1e-4} if method == "moreau_jean" else {}
    traj = simulate(chain, x0, (0.0, 0.2), method=method, **opts)
    impacts = traj.events_of("impact")
    assert sorted(e.index for e in impacts) == [0, 1]
    assert impacts[0].time == impacts[1].time
    if method == "event_driven":
        assert impacts[0].time == pytest.approx(0.1, abs=1e-14)
    assert np.allclose(traj.x[-1, 3:], [-1.0, 0.0, 1.0], atol=1e-12)


def _forced_oscillator_with_wall() -> tuple[LinearHybridSystem, np.ndarray]:
    """Mass on a spring, harmonically forced, hitting a wall at q = 0.3 (e = 0.8); the
    exosystem state is part of the hybrid state."""
    e, omega = 0.8, 1.7
    A = np.zeros((4, 4))
    A[0, 1], A[1, 0], A[1, 1], A[1, 2] = 1.0, -1.0, -0.05, 1.0
    A[2, 3], A[3, 2] = omega, -omega  # (u, u') generator: u = 0.9 sin(ωt)
    J = np.eye(4)
    J[1, 1] = -e
    x0 = np.array([0.0, 0.0, 0.0, 0.9])
    return LinearHybridSystem(A, [[-1.0, 0.0, 0.0, 0.0]], [0.3], J), x0


def test_compiled_impacts_agree_with_the_python_path() -> None:
    # the same system with its jump as a matrix (impacts settled in the compiled loop) and as
    # a callable (every event through the Python path) gives the same run
    fast, x0 = _forced_oscillator_with_wall()
    J = fast.jump_matrices[0]
    slow = LinearHybridSystem(fast.A, fast.G, fast.g0, lambda t, x, idx: J @ x)
    a = simulate(fast, x0, (0.0, 60.0), dt=0.05)
    b = simulate(slow, x0, (0.0, 60.0), dt=0.05)
    ta, tb = a.event_times("jump"), b.event_times("jump")
    assert ta.size >= 15
    assert np.array_equal(a.t, b.t)
    assert np.max(np.abs(ta - tb)) < 1e-13
    assert np.max(np.abs(a.x - b.x)) < 1e-11
    # and both agree with scipy's DOP853 with event location
    from scipy.integrate import solve_ivp

    t, x, ref = 0.0, x0.copy(), []
    gap = lambda _t, z: 0.3 - z[0]  # noqa: E731
    gap.terminal, gap.direction = True, -1.0
    while True:
        sol = solve_ivp(lambda _t, z: fast.A @ z, (t, 60.0), x, method="DOP853", rtol=1e-13,
                        atol=1e-13, events=gap)
        if sol.status != 1:
            break
        t, x = float(sol.t_events[0][0]), J @ sol.y_events[0][0]
        ref.append(t)
    assert len(ref) == ta.size
    assert np.max(np.abs(ta - np.array(ref))) < 1e-9


def test_listeners_see_every_impact_in_time_order() -> None:
    ball = BouncingBall(restitution=0.9)
    seen = []
    traj = simulate(ball.system(), ball.x0, (0.0, 10.0),
                    listeners=[lambda t, xm, xp, idx, p: seen.append((t, xm, xp, list(idx), p))])
    impacts = traj.events_of("impact")
    assert len(seen) == len(impacts) > 20
    assert [s[0] for s in seen] == [e.time for e in impacts]
    assert all(s[3] == [0] for s in seen)
    for (_t, xm, xp, _, _p), ev in zip(seen, impacts, strict=True):
        assert np.array_equal(xm, ev.pre) and np.array_equal(xp, ev.post)
    for _, xm, xp, _, p in seen[:-1]:  # the last one closes the accumulation plastically
        assert xp[1] == pytest.approx(-0.9 * xm[1], rel=1e-14)
        assert p[0] == pytest.approx(xp[1] - xm[1], rel=1e-14)  # unit mass: P = Δv
    assert seen[-1][2][1] == 0.0
    assert np.array_equal(traj.stats["impulses"], np.array([s[4] for s in seen]))


def test_samples_on_the_grid_are_exact() -> None:
    ball = BouncingBall(restitution=0.9)
    traj = simulate(ball.system(), ball.x0, (0.0, 1.2), dt=0.01)
    t1 = ball.impact_times(1)[0]
    flight = (traj.t > 0.0) & (traj.t < t1)
    tt = traj.t[flight]
    assert np.allclose(tt / 0.01, np.round(tt / 0.01), atol=1e-9)  # grid points
    assert np.max(np.abs(traj.x[flight, 0] - (1.0 - 0.5 * 9.81 * tt**2))) < 1e-15
    assert np.max(np.abs(traj.x[flight, 1] + 9.81 * tt)) < 1e-14


def test_record_every_and_selected_signals() -> None:
    from nscontrol.errors import ModelError

    ball = BouncingBall(restitution=0.9)
    full = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.01)
    thin = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=0.01, record_every=10,
                    signals=["gap"])
    assert set(thin.signals) == {"gap"}
    assert thin.t.size < full.t.size / 5
    assert thin.t[-1] == full.t[-1] == 10.0  # the final state is always kept
    assert np.array_equal(thin.x[-1], full.x[-1])
    assert len(thin.events) == len(full.events)  # events are never thinned
    assert np.isin(thin.t, full.t).all()
    bare = simulate(ball.system(), ball.x0, (0.0, 1.0), signals=[])
    assert bare.signals == {}
    with pytest.raises(ModelError, match=r"^signals: unknown name\(s\) \['gapp'\]"):
        simulate(ball.system(), ball.x0, (0.0, 1.0), signals=["gapp"])
    with pytest.raises(ModelError, match=r"^record_every: expected an integer >= 1"):
        simulate(ball.system(), ball.x0, (0.0, 1.0), record_every=0)


def test_accumulation_does_not_depend_on_the_time_span() -> None:
    ball = BouncingBall(restitution=0.9)
    short = simulate(ball.system(), ball.x0, (0.0, 10.0), dt=10.0)
    long = simulate(ball.system(), ball.x0, (0.0, 1000.0), dt=1000.0)
    ts, tl = short.event_times("impact"), long.event_times("impact")
    assert ts.size == tl.size > 50
    assert np.max(np.abs(ts - tl)) < 1e-12
    assert long.event_times("accumulation")[0] == pytest.approx(ball.accumulation_time,
                                                                abs=1e-9)
    assert np.max(np.abs(long.x[long.t > 9.0])) < 1e-12  # resting until t = 1000


def _ball_under_a_ball() -> LagrangianSystem:
    # ball 0 bounces on the ground (q0 >= 0), ball 1 falls onto it (q1 - q0 >= 0)
    return LagrangianSystem(np.eye(2), constant_force=[-9.81, -9.81],
                            gap_matrix=[[1.0, 0.0], [-1.0, 1.0]], restitution=[0.9, 0.5])


def test_an_early_accumulation_still_watches_the_other_contacts() -> None:
    # a huge horizon declares the accumulation of ball 0 at once; while it is held on the
    # ground up to t∞ the falling ball 1 must still hit it, not pass through
    traj = simulate(_ball_under_a_ball(), [1.0, 176.0, 0.0, 0.0], (0.0, 12.0), dt=0.01,
                    zeno_horizon=10.0)
    assert np.min(traj.signals["gap"]) >= -1e-9
    hits = [e for e in traj.events_of("impact") if e.index == 1]
    assert hits and hits[0].time == pytest.approx(np.sqrt(2 * 176.0 / 9.81), rel=1e-9)
    assert traj.events_of("accumulation") == ()  # interrupted before t∞


def test_a_contact_force_touching_zero_keeps_the_contact() -> None:
    # a unit mass pressed on the ground by u = -(1 - t)²: the contact force (1 - t)² only
    # touches zero at t = 1
    system = LagrangianSystem(np.eye(1), gap_matrix=[[1.0]], restitution=0.0,
                              actuation=[[1.0]])
    traj = simulate(system, [0.0, 0.0], (0.0, 2.0), u=Exosystem.polynomial([-1.0, 2.0, -1.0]))
    assert [e.kind for e in traj.events] == ["contact_start", "grazing"]
    assert traj.events_of("grazing")[0].time == pytest.approx(1.0, abs=1e-6)
    assert np.max(np.abs(traj.x)) < 1e-12


def test_input_runs_in_absolute_time_like_moreau_jean() -> None:
    from nscontrol.testing.mechanics_problems import impact_oscillator

    system = impact_oscillator(stiffness=1.0, damping=0.0, wall=0.3, restitution=0.8)
    u = Exosystem.sinusoid(0.9, 1.7)
    ed = simulate(system, [0.0, 0.0], (5.0, 30.0), u=u)
    mj = simulate(system, [0.0, 0.0], (5.0, 30.0), u=u, method="moreau_jean", h=1e-4)
    te, tm = ed.event_times("impact"), mj.event_times("impact")
    assert te.size == tm.size >= 2
    # Moreau-Jean h = 1e-4: each impact on the grid within h, plus the O(h) phase drift of
    # the flights over 25 s: 20 h (measured 1.9 h)
    assert np.max(np.abs(te - tm)) < 20 * 1e-4


def test_pre_and_post_impact_samples() -> None:
    ball = BouncingBall(restitution=0.9)
    traj = simulate(ball.system(), ball.x0, (0.0, 1.0))
    t1 = ball.impact_times(1)[0]
    at = np.flatnonzero(traj.t == t1)
    assert at.size == 2
    assert traj.x[at[0], 1] == pytest.approx(-ball.impact_velocity(0), rel=1e-12)
    assert traj.x[at[1], 1] == pytest.approx(0.9 * ball.impact_velocity(0), rel=1e-12)


def test_failed_runs_keep_their_part_in_the_callers_state_order() -> None:
    plant = _ch02_plant()
    u = Exosystem.sinusoid(2.0, 1.3)
    with pytest.raises(BudgetExceededError, match="^max_events") as err:
        simulate(plant, [0.0, 0.0, 0.0, 0.0, 0.3, 0.0], (0.0, 20.0), u=u, max_events=2)
    assert err.value.budget == "max_events" and err.value.limit == 2
    part = err.value.trajectory
    assert part.state_names == plant.state_names and part.status == -1
    assert len(part.events_of("impact")) == 2
    # an error raised inside the run (a closed loop's law that returns NaN) keeps the run too
    from nscontrol.errors import ModelError

    ball = BouncingBall()
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value") as err2:
        simulate(closed_loop(ball.system(), _NaNAfter()), ball.x0, (0.0, 2.0),
                 method="event_driven")
    assert err2.value.trajectory is not None and err2.value.trajectory.t[-1] > 0.4


class _NaNAfter(StaticLaw):
    """A law whose output turns NaN after ``t = 0.5``."""

    n_outputs, period = 1, None

    def output(self, t, xc, m):
        return np.array([np.nan if t > 0.5 else 0.0])


class _PD(StaticLaw):
    """``u = -4 q - 0.3 v`` written in Python: the flow is DOP853's."""

    n_outputs, period = 1, None

    def output(self, t, xc, m):
        return -4.0 * m.x[:1] - 0.3 * m.x[1:]


def test_linear_state_feedback_stays_exact() -> None:
    # u = K [q; v] = -[4, 0.3] [q; v] on a free mass is the spring-damper k = 4, c = 0.3:
    # the same impacts (the gain is folded into the model: the flow stays exact)
    free = LagrangianSystem(np.eye(1), gap_matrix=[[-1.0]], gap_offset=[0.5],
                            restitution=0.7, actuation=[[1.0]], constant_force=[2.0])
    spring = LagrangianSystem(np.eye(1), stiffness=[[4.0]], damping=[[0.3]],
                              gap_matrix=[[-1.0]], gap_offset=[0.5], restitution=0.7,
                              constant_force=[2.0])
    a = simulate(closed_loop(free, StateFeedback([[-4.0, -0.3]])), [0.0, 0.0], (0.0, 20.0),
                 method="event_driven")
    b = simulate(spring, [0.0, 0.0], (0.0, 20.0))
    ta, tb = a.event_times("impact"), b.event_times("impact")
    assert ta.size == tb.size >= 3
    assert np.max(np.abs(ta - tb)) < 1e-12
    # the same feedback as a law written in Python takes the DOP853 path
    c = simulate(closed_loop(free, _PD()), [0.0, 0.0], (0.0, 20.0), method="event_driven")
    tc = c.event_times("impact")[: ta.size]
    # DOP853 at the default rtol = 1e-10 per step, hundreds of steps: 1e3 rtol (measured 7e-10)
    assert np.max(np.abs(tc - ta)) < 1e-7
    # its input is the law at every sample (pre- and post-impact samples included)
    np.testing.assert_array_equal(c.signals["u"][:, 0], -4.0 * c.x[:, 0] - 0.3 * c.x[:, 1])


def test_a_state_feedback_on_a_nonlinear_plant_is_folded_too() -> None:
    # M(q) constant but given as a callable: the gain is folded into the plant's linear forces
    # (its own terms kept), the plant runs on DOP853's flow, and meets the folded loop of the
    # linear plant (impact times to the DOP853 tolerance, as above)
    K = [[-4.0, -0.3]]
    kw = dict(gap_matrix=[[-1.0]], gap_offset=[0.5], restitution=0.7, actuation=[[1.0]],
              constant_force=[2.0])
    linear = simulate(closed_loop(LagrangianSystem(np.eye(1), **kw), StateFeedback(K)),
                      [0.0, 0.0], (0.0, 20.0), method="event_driven")
    curved = closed_loop(LagrangianSystem(lambda q: np.eye(1), **kw), StateFeedback(K))
    assert curved.composition == "folded"
    c = simulate(curved, [0.0, 0.0], (0.0, 20.0), method="event_driven")
    ta = linear.event_times("impact")
    assert ta.size >= 3
    assert np.max(np.abs(c.event_times("impact")[: ta.size] - ta)) < 1e-7


def test_sampled_or_dynamic_blocks_are_refused_by_event_driven() -> None:
    from nscontrol.errors import ModelError

    ball = BouncingBall()
    with pytest.raises(ModelError, match=r"^event_driven: runs a closed loop whose controller "
                                         r"is a continuous law without state"):
        simulate(closed_loop(ball.system(), StateFeedback([[-1.0, 0.0]], period=0.1)),
                 ball.x0, (0.0, 1.0), method="event_driven")


def test_bad_options_each_their_error() -> None:
    from nscontrol.errors import DimensionError, ModelError

    ball = BouncingBall()
    s, x0 = ball.system(), ball.x0
    with pytest.raises(ModelError, match=r"^max_events: expected an integer >= 1"):
        simulate(s, x0, (0.0, 1.0), max_events=2.5)
    with pytest.raises(ModelError, match=r"^min_interval: expected a finite number >= 0"):
        simulate(s, x0, (0.0, 1.0), min_interval=-1.0)
    with pytest.raises(ModelError, match=r"^rtol: expected a finite number > 0"):
        simulate(s, x0, (0.0, 1.0), rtol=-1.0)
    with pytest.raises(ModelError, match=r"^listeners\[0\]: expected a callable"):
        simulate(s, x0, (0.0, 1.0), listeners=[3])
    with pytest.raises(ModelError, match=r"^u: event_driven needs the input as an Exosystem"):
        simulate(s, x0, (0.0, 1.0), u=lambda t: 0.0)
    with pytest.raises(DimensionError, match=r"^u: expected an Exosystem with 1 input"):
        simulate(s, x0, (0.0, 1.0), u=Exosystem.constant([1.0, 2.0]))
    with pytest.raises(DimensionError, match=r"^controller: K must have shape \(1, 2\)"):
        closed_loop(s, StateFeedback([[1.0, 2.0, 3.0]]))
    with pytest.raises(ModelError, match=r"^controller: unknown option of simulate; feedback "
                                         r"is a closed loop"):
        simulate(s, x0, (0.0, 1.0), controller=[[1.0, 2.0]])
    # the model: a zero gap row, a jacobian with the wrong sign
    with pytest.raises(ModelError, match=r"^gap_matrix: row 1 is zero"):
        LagrangianSystem(np.eye(1), gap_matrix=[[1.0], [0.0]])
    from nscontrol.errors import NscontrolWarning

    with pytest.warns(NscontrolWarning, match=r"^jacobian: disagrees"):
        LagrangianSystem(lambda q: np.eye(1), gap=lambda q: q + 1.0,
                         jacobian=lambda q: -np.eye(1), names=("x",))


def test_mass_matrix_losing_definiteness_during_the_run() -> None:
    from nscontrol.errors import ModelError

    # M(q) = diag(1, 1 - q0) is positive definite at q0 = 0, singular once coordinate 0,
    # moving at unit speed, reaches 1 (coordinate 1 is at rest and unforced: no blow-up)
    system = LagrangianSystem(lambda q: np.diag([1.0, 1.0 - q[0]]), names=("a", "b"),
                              gap=lambda q: q[:1] + 10.0, jacobian=lambda q: np.eye(1, 2))
    for method, opts in (("event_driven", {}), ("moreau_jean", {"h": 1e-3})):
        with pytest.raises(ModelError, match=r"^mass: M\(q\) is not positive definite") as err:
            simulate(system, [0.0, 0.0, 1.0, 0.0], (0.0, 5.0), method=method, **opts)
        assert err.value.trajectory.t[-1] >= 0.85  # up to the last window before t = 1
