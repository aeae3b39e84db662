"""Moreau–Jean time-stepping against closed forms and the event-driven integrator."""

import numpy as np
import pytest

from nscontrol import closed_loop
from nscontrol.numerics.lti import Exosystem
from nscontrol.simulate import simulate
from nscontrol.systems.feedback import StaticLaw
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.testing.mechanics_problems import (
    BouncingBall,
    NewtonsCradle,
    RestingStack,
    impact_oscillator,
)


class _Law(StaticLaw):
    """A Python feedback law ``u = fn(t, q, v)`` of the plant's state (a closed loop)."""

    n_outputs, period = 1, None

    def __init__(self, fn):
        object.__setattr__(self, "fn", fn)

    def output(self, t, xc, m):
        n = m.x.size // 2
        return np.atleast_1d(np.asarray(self.fn(t, m.x[:n], m.x[n:]), dtype=float))


def test_bouncing_ball_impacts_within_two_steps_then_rest() -> None:
    ball = BouncingBall()
    h = 1e-3
    traj = simulate(ball.system(), ball.x0, (0.0, 10.0), method="moreau_jean", h=h)
    times = traj.event_times("impact")
    exact = ball.impact_times(60)
    resolved = exact[np.concatenate([[np.inf], np.diff(exact)]) > 20 * h]  # bounces >> h
    assert resolved.size >= 20
    err = times[: resolved.size] - resolved
    # each impact is captured within 2h of where its flight should end (first impact, and
    # every flight interval); the scheme's O(h) position drift at each landing accumulates
    # over the bounces (less than h per impact) (Siconos: 4.5e-3 s at h = 1e-3)
    assert abs(err[0]) <= 2 * h
    assert np.max(np.abs(np.diff(err))) <= 2 * h
    assert np.all(np.abs(err[:20]) <= (2 + np.arange(20)) * h)
    assert np.max(np.abs(err)) <= 10 * h
    # the documented penetration bound: h times the largest approach speed
    v_max = ball.impact_velocity(0)
    assert traj.stats["max_penetration"] <= h * v_max
    rest = traj.t > ball.accumulation_time + 0.2
    assert np.all(np.abs(traj.x[rest, 1]) < 1e-12)
    assert np.all(np.abs(traj.x[rest, 0]) <= h * v_max)
    # θ = 1/2: a free step keeps E = m (v²/2 + g q) exactly (midpoint rule, constant force); an
    # impact step v+ = -e v- changes it by -(1 - e²) v-²/2 + g h (1 - e) v-/2, positive only
    # in the Zeno phase (v- > 0, small, caught by the active set), at most
    # (1 - e)/(1 + e) g² h²/8 = 6.5e-8 E0 at v- = g h / (2 (1 + e)) (measured 1.4e-8 E0);
    # before it (t < 5) only the rounding of E, a few u E0 per step (measured 1.6 u E0)
    e, g = ball.restitution, ball.g
    energy = traj.signals["energy"]
    rounding = 16 * np.finfo(float).eps / 2 * energy[0]
    assert np.max(np.diff(energy)) <= ball.mass * (1 - e) / (1 + e) * g**2 * h**2 / 8 + rounding
    assert np.max(np.diff(energy[traj.t < 5.0])) <= rounding


@pytest.mark.parametrize("n", [10, 1000, 10000])
def test_stack_at_rest_impulses(n: int) -> None:
    stack = RestingStack(n)
    h = 1e-3
    traj = simulate(stack.system(), stack.x0, (0.0, 5 * h), method="moreau_jean", h=h,
                    signals=["impulse"])
    assert traj.stats["path"] == "tridiagonal"
    p = traj.signals["impulse"][1:]
    assert np.max(np.abs(p - stack.impulses(h)) / stack.impulses(h)) < 1e-10
    assert np.max(np.abs(traj.x[-1])) < 1e-12


def test_newtons_cradle_conserves_momentum_and_energy() -> None:
    cradle = NewtonsCradle(n=8)
    h = 1e-4
    traj = simulate(cradle.system(), cradle.x0, (0.0, cradle.final_time + 0.02),
                    method="moreau_jean", h=h)
    n = cradle.n
    v = traj.x[:, n:]
    assert np.max(np.abs(v.sum(axis=1) - 1.0)) < 1e-12
    assert np.max(np.abs(0.5 * (v**2).sum(axis=1) - 0.5)) < 1e-12
    assert [e.index for e in traj.events_of("impact")] == list(range(n - 1))
    assert np.max(np.abs(traj.event_times("impact") - cradle.impact_times())) <= 2 * h
    assert np.allclose(v[-1], np.eye(n)[-1], atol=1e-12)  # velocity handed along the chain


def test_impact_oscillator_periodic_orbit_agrees_with_event_driven() -> None:
    system = impact_oscillator()
    u = Exosystem.sinusoid(1.0, 1.2)
    period = 2 * np.pi / 1.2
    h, e = 1e-3, 0.8                                   # impact_oscillator's restitution
    ed = simulate(system, [0.0, 0.0], (0.0, 150.0), u=u)
    mj = simulate(system, [0.0, 0.0], (0.0, 150.0), method="moreau_jean", h=h, u=u)
    ted, tmj = ed.event_times("impact"), mj.event_times("impact")
    # a period-1 impacting orbit, reached by both methods; event-driven: still converging at
    # rate |mu| = 0.62 per period (measured 5e-6 s off at t = 150); Moreau-Jean: its impact
    # times lie on the grid, each within h of the orbit's (measured 7.6e-4 s)
    assert np.allclose(np.diff(ted[-4:]), period, rtol=1e-5)
    assert np.allclose(np.diff(tmj[-4:]), period, atol=2 * h)
    assert np.max(np.abs(ted[-3:] - tmj[-3:])) <= 3 * h
    v_ed = np.array([ev.pre[1] for ev in ed.events_of("impact")[-3:]])
    v_mj = np.array([ev.pre[1] for ev in mj.events_of("impact")[-3:]])
    # first order: an impact up to h late shifts the state by |v+ - v-| h = (1 + e) |v-| h,
    # i.e. (1 + e) h relative to v- (measured 3.4e-4 against 1.8e-3)
    assert np.allclose(v_mj, v_ed, rtol=(1 + e) * h)
    # the orbit itself: fixed point of the exact stroboscopic map by Newton (shooting), a
    # stable one, and both long runs sit on it at the strobe instants
    def strobe(x: np.ndarray) -> np.ndarray:
        return simulate(system, x, (0.0, period), u=u, dt=period).x[-1]

    x = strobe(np.array([0.0, 0.0]))
    for _ in range(30):
        x = strobe(x)  # transient first
    for _ in range(6):
        r = strobe(x) - x
        J = np.column_stack([(strobe(x + 1e-7 * e) - strobe(x - 1e-7 * e)) / 2e-7
                             for e in np.eye(2)])
        x = x - np.linalg.solve(J - np.eye(2), r)
    assert np.max(np.abs(strobe(x) - x)) < 1e-10
    assert np.max(np.abs(np.linalg.eigvals(J))) < 1.0  # |μ| = 0.616: stable
    k = np.arange(24, 29)  # strobe instants after the transient
    exact = simulate(system, [0.0, 0.0], (0.0, 150.0), u=u, dt=period)  # samples at k T
    dist = np.max(np.abs(exact.at(k * period) - x), axis=1)
    # converging onto the orbit at the linearised rate: ||V^-1 d|| shrinks by |mu| per period
    # (V the eigenvectors of J), and the max norm is within sqrt(2) of the 2-norm in R^2
    mu, V = np.linalg.eig(J)
    contraction = np.sqrt(2) * np.linalg.cond(V) * np.max(np.abs(mu)) ** (k[-1] - k[0])
    assert np.all(np.diff(dist) < 0) and dist[-1] <= contraction * dist[0]  # 8.3e-7 <= 2.6e-6
    # first order: within the state shift of an impact located h late, (1 + e) |v-| h
    # (3.1e-3; measured 9.9e-4)
    assert np.max(np.abs(mj.at(k * period) - x)) <= (1 + e) * np.max(np.abs(v_ed)) * h


def test_controller_hook_and_jump_listener() -> None:
    # a feedback u = -k (q - 0.5) - c v drives the mass into the wall; the listener sees
    # every impact with the post-impact state
    system = impact_oscillator(stiffness=0.0, damping=0.0, wall=0.3, restitution=0.5)
    seen = []
    law = _Law(lambda t, q, v: -4.0 * (q - 0.5) - 1.0 * v)
    traj = simulate(closed_loop(system, law), [0.0, 0.0], (0.0, 10.0), method="moreau_jean",
                    h=1e-3, listeners=[lambda t, xm, xp, c, p: seen.append((t, xm, xp, p))])
    assert len(seen) == len(traj.events_of("impact")) >= 1
    t, xm, xp, p = seen[0]
    assert xm[1] > 0 and xp[1] < 0 and p[0] > 0
    # in the end the controller presses the mass on the wall: resting at the wall, within the
    # documented penetration h |u-| (u- the fastest approach, 0.71: 7e-4; measured 2.3e-7),
    # contact force P/h equal to the controller's push 4 (0.5 - q): 0.8 within 4 h |u-| / 0.8
    h, approach = 1e-3, max(ev.pre[1] for ev in traj.events_of("impact"))
    assert traj.x[-1, 0] == pytest.approx(0.3, abs=h * approach)
    assert traj.signals["impulse"][-1, 0] / h == pytest.approx(0.8, rel=5 * h * approach)


@pytest.mark.parametrize("compiled", [True, False])
def test_configuration_dependent_mass_path(compiled: bool) -> None:
    """The arm's M(q) on its compiled model (its own loop) and on the Python path."""
    from dataclasses import replace

    arm = LagrangianSystem.two_link_arm(restitution=0.0)
    arm = arm if compiled else replace(arm, compiled=None)
    h = 1e-3
    traj = simulate(arm, [0.8, -1.2, 0.0, 0.0], (0.0, 1.5), method="moreau_jean", h=h)
    assert traj.stats["path"] == ("compiled_model" if compiled else "python")
    assert traj.events_of("impact")
    # the documented h |u-| (u- = J v before the landing step), plus the gap's curvature over
    # the step, h^2 max|g''| (g'' from the recorded flight; 3e-6): 9.56e-4, measured 9.45e-4
    approach = max(np.abs(arm.gap_jacobian(ev.pre[:2]) @ ev.pre[2:]).max()
                   for ev in traj.events_of("impact"))
    gap = np.array([arm.gaps(x[:2]) for x in traj.x])[:, 0]
    flight = traj.t < traj.events_of("impact")[0].time - 2 * h
    curvature = np.max(np.abs(np.diff(gap[flight], 2))) / h**2
    assert traj.stats["max_penetration"] <= h * approach + h**2 * curvature
    assert traj.signals["energy"][-1] < traj.signals["energy"][0]


def test_impacting_bodies_moreau_jean_keeps_state_order() -> None:
    plant = ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 1.0, (0, 1): 1.0},
                                         {(0, 0): 1.0}, restitution=1.0)
    u = Exosystem.sinusoid(2.0, 1.3)
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.3, 0.0])
    seen_ed, seen_mj = [], []
    ed = simulate(plant, x0, (0.0, 10.0), u=u,
                  listeners=[lambda t, xm, xp, c, p: seen_ed.append(xp)])
    mj = simulate(plant, x0, (0.0, 10.0), method="moreau_jean", h=1e-4, u=u,
                  listeners=[lambda t, xm, xp, c, p: seen_mj.append(xp)])
    assert mj.state_names == plant.state_names
    # listeners see the chapter's [x_a; x_b] order, like the trajectories
    assert np.allclose(seen_ed[0], ed.events_of("impact")[0].post)
    assert np.allclose(seen_mj[0], mj.events_of("impact")[0].post)
    assert plant.gap(seen_ed[0]) == pytest.approx(0.0, abs=1e-12)
    tj, tm = ed.event_times("impact"), mj.event_times("impact")
    assert len(tj) == len(tm) >= 2
    # each MJ impact time is on the grid, within h of where its flight ends, and the O(h)
    # phase error of the flights adds up over the impacts: 10 h for these few
    assert np.max(np.abs(tj - tm)) < 10 * 1e-4


def test_the_last_step_ends_exactly_at_the_end_of_the_span() -> None:
    ball = BouncingBall()
    traj = simulate(ball.system(), ball.x0, (0.0, 1.0), method="moreau_jean", h=0.3)
    assert traj.t[-1] == 1.0 and np.all(traj.t <= 1.0)
    assert np.allclose(np.diff(traj.t)[:3], 0.3) and np.diff(traj.t)[-1] == pytest.approx(0.1)
    # free fall with a shorter last step is still the θ = ½ (exact for constant force) flight
    free = simulate(ball.system(), [10.0, 0.0], (0.0, 1.0), method="moreau_jean", h=0.3)
    assert free.x[-1] == pytest.approx([10.0 - 9.81 / 2, -9.81], rel=1e-12)


def test_redundant_contacts_fall_back_to_lemke() -> None:
    # the same ground contact twice: a singular (positive semi-definite) Delassus matrix
    ball = LagrangianSystem(np.eye(1), constant_force=[-9.81], gap_matrix=[[1.0], [1.0]],
                            restitution=[0.0, 0.0])
    traj = simulate(ball, [0.0, 0.0], (0.0, 0.01), method="moreau_jean", h=1e-3)
    assert traj.stats["path"] == "tridiagonal+dense"
    assert np.max(np.abs(traj.x)) < 1e-12
    assert traj.signals["impulse"][-1].sum() == pytest.approx(9.81e-3, rel=1e-12)


def test_listeners_do_not_change_the_run() -> None:
    # listeners observe after each compiled chunk: same trajectory, one call per impact step
    system = impact_oscillator()
    u = Exosystem.sinusoid(1.0, 1.2)
    seen = []
    a = simulate(system, [0.0, 0.0], (0.0, 30.0), method="moreau_jean", h=1e-3, u=u)
    b = simulate(system, [0.0, 0.0], (0.0, 30.0), method="moreau_jean", h=1e-3, u=u,
                 listeners=[lambda t, xm, xp, c, p: seen.append((t, c.tolist(), p[0]))])
    assert np.array_equal(a.x, b.x)
    assert len(seen) == len(a.events_of("impact")) > 5
    assert all(c == [0] and p > 0 for _, c, p in seen)


def test_bad_moreau_jean_options_each_their_error() -> None:
    from nscontrol.errors import DimensionError, ModelError

    ball = BouncingBall()
    s, x0 = ball.system(), ball.x0
    with pytest.raises(ModelError, match=r"^activation: expected a finite number >= 0"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3, activation=np.nan)
    with pytest.raises(DimensionError, match=r"^u: expected an Exosystem with 1 input"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3,
                 u=Exosystem.constant([1.0, 2.0]))
    with pytest.raises(ModelError, match=r"^listeners\[0\]: expected a callable"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3, listeners=["no"])
    with pytest.raises(ModelError, match=r"^signals: unknown name\(s\) \['impulses'\]"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3, signals=["impulses"])
    # blocks= is the closed loop's own (its BlockRunner): a raw callable is refused, the
    # controller= keyword is gone (a closed loop carries the law)
    with pytest.raises(ModelError, match=r"^blocks: expected the BlockRunner of a closed loop"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3,
                 blocks=lambda t, q, v: np.zeros(1))
    with pytest.raises(ModelError, match=r"^controller: unknown option of simulate; feedback "
                                         r"is a closed loop"):
        simulate(s, x0, (0.0, 1.0), method="moreau_jean", h=1e-3,
                 controller=lambda t, q, v: np.zeros(1))
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value at "
                       r"t = 0\.501") as err:
        simulate(closed_loop(s, _Law(lambda t, q, v: np.nan if t > 0.5 else 0.0)), x0,
                 (0.0, 1.0), method="moreau_jean", h=1e-3)
    assert err.value.trajectory.t[-1] == pytest.approx(0.5, abs=2e-3)   # the last step before


def test_a_system_without_contacts_runs_as_the_theta_method() -> None:
    """No gap at all (an empty gap matrix): the run has no gap to report a penetration of, and
    is the θ = ½ (Crank–Nicolson) step of the free oscillator q'' = -q. Its phase error at
    T = 1 is ω³ T h² / 12 ≈ 8.3e-8 (ω = 1, h = 1e-3); bound: twice that."""
    free = LagrangianSystem(mass=np.eye(1), stiffness=np.eye(1),
                            gap_matrix=np.zeros((0, 1)), gap_offset=np.zeros(0))
    traj = simulate(free, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3)
    assert "max_penetration" not in traj.stats
    bound = 2 * 1e-6 / 12
    assert np.allclose(traj.x[-1], [np.cos(1.0), -np.sin(1.0)], rtol=0, atol=bound)
