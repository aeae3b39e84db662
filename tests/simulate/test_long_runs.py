"""Long runs stay valid: 10⁵-period runs of an elastic ball, a forced piecewise-affine
oscillator and the forced impact oscillator, far past the times at which round-off used to
stop them with InadmissibleStateError (4602 s, 8200 s and 32,802 s), and the one round-off
projection every restart goes through. Each 10⁵-period run takes under 20 s (about 8, 14
and 4 s), so all are in the default suite."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import InadmissibleStateError
from nscontrol.numerics.lti import TAYLOR_DEGREE, Exosystem
from nscontrol.systems import LagrangianSystem
from nscontrol.systems.hybrid import LinearHybridSystem

EPS = np.finfo(float).eps
G_ACC = 9.81


def _guard_sums(n: int) -> float:
    """The stated factor of the restart tolerance, ``4 (K + 1 + n)``
    (:func:`nscontrol.numerics._lti_kernels.restart_tolerance`)."""
    return 4.0 * (TAYLOR_DEGREE + 1 + n)


# -- elastic ball -------------------------------------------------------------------------------

def _elastic_ball(n_periods: int):
    ball = LagrangianSystem.bouncing_ball(restitution=1.0)
    period = 2.0 * np.sqrt(2.0 / G_ACC)          # from q = 1 at rest: fall, bounce, rise
    tf = n_periods * period
    traj = nsc.simulate(ball, [1.0, 0.0], (0.0, tf), max_events=2 * n_periods,
                        dt=tf / 200, progress=False)
    return ball, traj, tf, period


def test_elastic_ball_runs_past_the_old_failure_and_keeps_its_energy():
    n_periods = 100_000                           # about 8 s
    ball, traj, tf, period = _elastic_ball(n_periods)
    assert tf > 4602.4                            # where round-off used to stop the run
    assert traj.status == 0 and traj.t[-1] == tf
    impacts = traj.event_times("impact")
    assert abs(len(impacts) - n_periods) <= 1
    # each flight and bounce rounds the state by at most the restart tolerance's factor of
    # ulps (the flow is exact, the bounce flips v exactly): the energy error is at most
    # (events) × 4 (K + 1 + n) eps relative — round-off adding up, never a drift
    E = ball.energy(traj.x)
    bound = len(impacts) * _guard_sums(3) * EPS
    assert np.max(np.abs(E - E[0])) / E[0] <= bound
    # the apex height stays 1 (same bound through E = g h) and every impact is one period
    # after the previous: the time labels carry their rounding (two-sum clock), so they stay
    # within a few ulps of tf per event instead of drifting by eps·t per event
    assert np.max(np.abs(np.diff(impacts) - period)) <= 64 * EPS * tf
    assert traj.stats["largest_projection_ratio"] < 1.0


# -- forced piecewise-affine oscillator -------------------------------------------------------

def _one_sided(n_periods: int):
    from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator

    omega = 1.42                                  # the chapter's resonance, W_RES
    system = one_sided_oscillator(0.1, u=Exosystem.sinusoid(1.0, omega))
    T = 2.0 * np.pi / omega
    traj = nsc.simulate(system, [0.0, 0.0], (0.0, n_periods * T), method="switching",
                        n_samples=2, max_events=10 * n_periods, progress=False)
    return traj, n_periods * T


def test_forced_pwa_oscillator_stays_on_its_periodic_orbit():
    n_periods = 100_000                           # about 14 s
    ref, t_ref = _one_sided(600)                  # long settled: e^{-c t/2} = e^{-130}
    traj, tf = _one_sided(n_periods)
    assert tf > 8200.0                            # where round-off used to stop the run
    assert traj.status == 0 and traj.t[-1] == tf
    # both end at a multiple of the period on the same attracting orbit (two crossings per
    # period). Their difference: the label tf is exact to eps·tf, over which the state
    # moves at |x'| <= |v| + |a| < 32 (|q| < 4.5, stiffness 6); each period's round-off (two
    # restarts of 4 (K + 1 + n) eps relative, n = 4 for the augmented state, times a
    # condition below 100) is contracted by the damping (a factor 1/(1 - ρ) < 10)
    scale = float(np.max(np.abs(ref.x[-1]))) + 1.0
    tol = 8.0 * EPS * (tf + t_ref) * 32.0 + 10 * 2 * _guard_sums(4) * 100 * EPS * scale
    assert np.max(np.abs(traj.x[-1] - ref.x[-1])) <= tol
    assert traj.stats["n_crossing"] == pytest.approx(2 * n_periods, abs=2)
    assert traj.stats["largest_projection_ratio"] < 1.0


# -- impact oscillator ---------------------------------------------------------------------------

def test_impact_oscillator_stays_on_its_attractor():
    n_periods = 100_000                           # about 4 s
    from nscontrol.examples.impact_oscillator_bifurcation import oscillator

    osc = oscillator().with_(forcing=1.5)         # the stable period-1 one-impact orbit
    orbit = osc.admissible_orbit()
    rho = float(np.max(np.abs(orbit.multipliers)))
    assert orbit.stable and rho < 0.75
    tf = n_periods * osc.period
    traj = nsc.simulate(osc.system(), orbit.x0, (0.0, tf), u=osc.input(),
                        max_events=2 * n_periods, dt=tf / 100, progress=False)
    assert tf > 32_802.0                          # where round-off used to stop the run
    assert traj.status == 0 and traj.t[-1] == tf
    assert len(traj.event_times("impact")) == n_periods
    # at every period the closed-form state: the label's rounding eps·tf at speed <= 2,
    # and each period's round-off (one flight and one impact, 4 (K + 1 + n) eps relative
    # with n = 5, a condition below 100) contracted by the multipliers, 1/(1 - ρ) < 4
    tol = 8.0 * EPS * tf * 2.0 + 4 * 2 * _guard_sums(5) * 100 * EPS
    assert np.max(np.abs(traj.x[-1] - orbit.x0)) <= tol


# -- the shared round-off projection --------------------------------------------------------------

def _hybrid_ball(shift: float) -> LinearHybridSystem:
    """A ball as a bare hybrid system whose jump leaves the height ``shift`` below the
    ground: an integrator's own round-off when tiny, a broken jump map when not."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -G_ACC], [0.0, 0.0, 0.0]])
    return LinearHybridSystem(A, [[1.0, 0.0, 0.0]], [0.0],
                              lambda t, x, idx: np.array([x[0] - shift, -x[1], x[2]]))


def test_a_round_off_violation_after_a_jump_is_projected_and_counted():
    # 1e-15 below the ground: about 4 ulps of the impact speed sqrt(2 g) ≈ 4.4, far below
    # the restart tolerance (88 eps × the state's scale × a condition >= 1)
    traj = nsc.simulate(_hybrid_ball(1e-15), [1.0, 0.0, 1.0], (0.0, 5.0), progress=False)
    jumps = traj.event_times("jump")
    assert len(jumps) == 6                        # t1 (1 + 2k) <= 5 s
    assert traj.stats["projections"] == len(jumps)
    assert 0.0 < traj.stats["largest_projection"] <= 2e-15
    assert 0.0 < traj.stats["largest_projection_ratio"] < 1.0
    # the projected state is the true one: every later impact where the closed form has it
    t1 = np.sqrt(2.0 / G_ACC)
    np.testing.assert_allclose(jumps, t1 * (1 + 2 * np.arange(6)), rtol=0, atol=1e-12)


def test_a_violation_beyond_the_round_off_tolerance_is_refused():
    with pytest.raises(InadmissibleStateError, match="round-off tolerance") as info:
        nsc.simulate(_hybrid_ball(1e-6), [1.0, 0.0, 1.0], (0.0, 5.0), progress=False)
    assert info.value.trajectory is not None
    assert len(info.value.trajectory.events_of("jump")) == 1


def test_the_users_state_is_never_projected():
    ball = LagrangianSystem.bouncing_ball(restitution=1.0)
    with pytest.raises(InadmissibleStateError, match="^x0"):
        nsc.simulate(ball, [-1e-9, 0.0], (0.0, 1.0), progress=False)


def test_the_projection_moves_only_the_plant_entries_along_the_guard():
    """The kernel itself: a guard -δ (δ within the tolerance) becomes zero by the smallest
    step along ``G_i D`` on the free entries; beyond the tolerance it reports the guard."""
    from nscontrol.numerics._lti_kernels import project_restart, restart_tolerance

    K1, n = TAYLOR_DEGREE + 1, 3
    W = np.zeros((K1, 2, n))
    W[0, 0] = [1.0, 2.0, 5.0]          # guard 0 also reads the (fixed) third entry
    W[0, 1] = [0.0, 1.0, 0.0]
    W[1, 0] = [0.0, 1.0, 0.0]          # a slope, for the tolerance's time term
    g0 = np.array([-5.0, 3.0])
    y = np.array([-1e-14, 0.0, 1.0])   # guard 0 = -1e-14, guard 1 = 3
    a, proj = np.empty(K1), np.zeros(5)
    tol = restart_tolerance(W, 0, 1.0, np.linalg.norm(y), g0[0], 0.0, 1.0, 0.0)
    assert tol == pytest.approx(4 * (K1 + n) * EPS * (np.linalg.norm(y) * np.sqrt(30) + 5))
    assert project_restart(W, g0, 1.0, 1.0, 0.0, 2, y, a, proj) == -1
    assert y[2] == 1.0 and abs(W[0, 0] @ y + g0[0]) <= 8 * EPS
    np.testing.assert_allclose(y[:2], np.array([-1e-14, 0.0]) + 1e-14 * np.array([1, 2]) / 5,
                               rtol=0, atol=4 * EPS * 5)   # g rounds near g0 = -5
    assert proj[0] == 1 and proj[1] == pytest.approx(1e-14)
    y = np.array([-1e-6, 0.0, 1.0])
    assert project_restart(W, g0, 1.0, 1.0, 0.0, 2, y, a, proj) == 0
    assert proj[3] == pytest.approx(-1e-6) and 0 < proj[4] < 1e-6


def test_the_python_entry_is_the_same_projection():
    """``numerics.lti.project_restart`` (the frictional runner's restarts) calls the kernel:
    within the tolerance the guard comes to zero on the free entries, beyond it refuses."""
    from nscontrol.numerics import LTIFlow, project_restart

    flow = LTIFlow(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -G_ACC], [0.0, 0.0, 0.0]]))
    G, g0 = np.array([[1.0, 0.0, 0.0]]), np.zeros(1)
    proj = np.zeros(5)
    x = np.array([-1e-15, 4.4, 1.0])
    y = project_restart(flow, x, G, g0, 1e3, proj, n_free=2)
    assert y[0] == 0.0 and y[1:].tolist() == [4.4, 1.0] and proj[0] == 1
    assert x[0] == -1e-15                                # the argument is left alone
    with pytest.raises(InadmissibleStateError, match="round-off tolerance"):
        project_restart(flow, np.array([-1e-6, 4.4, 1.0]), G, g0, 1e3, proj, n_free=2)
