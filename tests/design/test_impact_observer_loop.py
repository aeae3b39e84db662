"""Chapter 2, simulation side (spec ch02 §7): the observer (7) on the exact event-driven
integrator, with and without impacts, its decay rates, the dead-beat observers, and the exact
impact times against an independent ODE solver."""

import numpy as np
import pytest

from nscontrol.analysis.observability import reconstructibility
from nscontrol.design.impact_observer import (
    deadbeat_1n,
    deadbeat_n1,
    design_impact_observer,
    impact_plant,
)
from nscontrol.errors import InadmissibleStateError, InfeasibleDesignError, ModelError
from nscontrol.examples.ch02_impact_observer import (
    DEADBEAT_WINDOW,
    LAMBDA1,
    M3_UNEQUAL,
    T_END,
    X0_PLANT,
    X0_PLANT_1N,
    ObserverRun,
    _contraction,
    _per_impact_prediction,
    _rate,
    bodies_1n,
    bodies_n1,
    deadbeat_error,
    input_generator,
    ivp_impact_times,
    run_observer,
    simulate_plant,
)
from nscontrol.simulate import simulate

EPS = (0.25, 0.125, 0.0625)


def _rounding_floor(run, dt=None):
    """Absolute rounding floor of the estimate error ``x~ = x - xh`` of an observer run
    (``run.design``, ``run.trajectory``) sampled every ``dt`` (default: the example's ``DT``).

    The observer runs in scaled coordinates ``xi`` and ``xh_a = T xi`` sees each rounding of
    ``xi`` through ``T``: ``u cond(T) max|x|`` per step, accumulated over the ``1 / (1 -
    exp(-dt min|Re Lambda1| / eps))`` steps the error dynamics take to forget it; times 100,
    for the roundings of the same order that the propagation (through the eigenvectors of the
    non-normal stacked flow) and the jumps add. Measured errors at the floor: 1/20 (exact
    start, any BLAS kernel) to 1/800 of it.
    """
    from nscontrol.examples.ch02_impact_observer import DT

    d, dt = run.design, DT if dt is None else dt
    forget = 1.0 / (1.0 - np.exp(-dt * np.min(np.abs(np.real(LAMBDA1))) / d.eps))
    return (100 * forget * np.finfo(float).eps / 2 * np.linalg.cond(d.placement.T)
            * np.max(np.abs(run.trajectory.x)))


def _deadbeat_bound(est):
    """Relative error a dead-beat reconstruction can reach from exact data: the least-squares
    fit's condition number times the impact amplification times ``u``, times 100 for the
    backward error of the fit over its window of samples and of the simulated data."""
    return (100 * max(est.condition, est.window_condition) * est.impact_amplification
            * np.finfo(float).eps / 2)


@pytest.fixture(scope="module")
def runs_equal():
    return {eps: run_observer(bodies_n1(1.0), eps) for eps in EPS}


@pytest.fixture(scope="module")
def runs_unequal():
    return {eps: run_observer(bodies_n1(M3_UNEQUAL), eps) for eps in (0.0625, 0.03125)}


def test_body_b_recovered_only_with_impacts(runs_equal):
    on = runs_equal[0.0625]
    off = run_observer(bodies_n1(1.0), 0.0625, impacts=False, t_end=20.0)
    eb_on = np.linalg.norm(on.error[:, 4:6], axis=1)
    eb_off = np.linalg.norm(off.error[:, 4:6], axis=1)
    assert off.trajectory.events == ()
    assert eb_off[-1] / eb_off[0] > 0.5            # measured 1.99 at t = 40: never recovered
    # down to the rounding floor (4.6e-10, i.e. 9e-10 of ||e_b(0)||; measured 3e-12 relative)
    assert eb_on[-1] <= _rounding_floor(on)
    # body a is recovered either way (its pair (C_a, A_a) is observable)
    assert np.linalg.norm(off.error[-1, :4]) <= _rounding_floor(off)
    # Theorem 2 on the two records
    p = impact_plant(bodies_n1(1.0))
    assert reconstructibility(p.A_a, p.C_a, on.trajectory.event_times("jump"),
                              (0.0, 40.0)).reconstructible
    assert not reconstructibility(p.A_a, p.C_a, off.trajectory.event_times("jump"),
                                  (0.0, 20.0)).reconstructible


def test_decay_rate_grows_as_eps_shrinks_equal_masses(runs_equal):
    # the error's contraction over the run's impacts (no rounding floor): 0.220, 0.971, 2.24
    rates = [_contraction(runs_equal[eps]).rate for eps in EPS]
    assert rates[0] > 0.1
    assert rates[1] > 2.0 * rates[0] and rates[2] > 2.0 * rates[1]


def test_decay_rate_saturates_for_unequal_masses(runs_unequal):
    r1, r2 = (_contraction(runs_unequal[eps]) for eps in (0.0625, 0.03125))
    assert r2.rate / r1.rate < 1.1                  # measured 1.078 (equal masses: 2.2x)
    # the saturated rate is the free mass's per-impact contraction |M22 cos(w delta)|
    predicted = _per_impact_prediction(bodies_n1(M3_UNEQUAL), r2.times)
    assert r2.rate == pytest.approx(predicted, rel=0.05)   # 1.169 vs 1.171: 0.2 % apart


def test_certified_design_meets_its_rate_and_alpha_L_caps_it(runs_unequal):
    traj = runs_unequal[0.0625].trajectory
    dwell = np.diff(traj.event_times("jump"))
    p = impact_plant(bodies_n1(M3_UNEQUAL))
    alpha_L = -np.log(abs(p.M[1, 1])) / dwell.max()
    d = design_impact_observer(bodies_n1(M3_UNEQUAL), LAMBDA1, alpha=0.5 * alpha_L,
                               delta_min=0.99 * dwell.min(), delta_max=1.01 * dwell.max())
    run = run_observer(bodies_n1(M3_UNEQUAL), design=d)
    assert _rate(run).rate >= d.certificate.alpha    # measured 1.10 vs 0.387
    with pytest.raises(InfeasibleDesignError, match="alpha_L"):
        design_impact_observer(bodies_n1(M3_UNEQUAL), LAMBDA1, alpha=1.05 * d.alpha_L,
                               delta_min=0.99 * dwell.min(), delta_max=1.01 * dwell.max())


@pytest.mark.parametrize("e", [1.0, 0.8])
def test_exact_estimate_stays_exact_through_impacts(e):
    """With xhat(0) = x(0) the jumps (7c)-(7g) (general e, Remark 1) keep xhat = x."""
    bodies = bodies_n1(1.0, e=e)
    d = design_impact_observer(bodies, LAMBDA1, 0.125)
    u = input_generator()
    loop = d.closed_loop(u)
    z0 = d.initial_state(np.concatenate([X0_PLANT, u.w0]), X0_PLANT)
    traj = simulate(loop, z0, (0.0, 20.0), method="event_driven", dt=0.05, progress=False)
    assert len(traj.events) >= 5
    run = ObserverRun(d, loop, traj)
    assert np.max(np.abs(traj.signal("error"))) <= _rounding_floor(run, dt=0.05)  # 2e-11


def test_inelastic_impacts_observer_converges():
    run = run_observer(bodies_n1(1.0, e=0.8), 0.0625, t_end=30.0)
    err = np.linalg.norm(run.error, axis=1)
    assert len(run.trajectory.events) >= 5
    assert err[-1] <= _rounding_floor(run)


def test_scaled_and_original_realisations_agree():
    d = design_impact_observer(bodies_n1(1.0), LAMBDA1, 0.25)
    u = input_generator()
    x0 = np.concatenate([X0_PLANT, u.w0])
    xh0 = np.full(6, 0.1)
    out = []
    for real in ("scaled", "original"):
        loop = d.closed_loop(u, realisation=real)
        z0 = d.initial_state(x0, xh0, realisation=real)
        out.append(simulate(loop, z0, (0.0, 10.0), method="event_driven", dt=0.05,
                            progress=False))
    assert len(out[0].events) == len(out[1].events) >= 3
    assert np.max(np.abs(out[0].signal("xhat") - out[1].signal("xhat"))) < 1e-8


def test_inadmissible_initial_state_rejected_by_the_closed_loop():
    d = design_impact_observer(bodies_n1(1.0), LAMBDA1, 0.25)
    u = input_generator()
    loop = d.closed_loop(u)
    z0 = np.concatenate([[0.0, 1.0, 0.0, 0.0, 0.5, 0.0], u.w0, np.zeros(6)])  # q2 > q3
    with pytest.raises(InadmissibleStateError):
        simulate(loop, z0, (0.0, 1.0), method="event_driven", progress=False)


# -- dead-beat observers ------------------------------------------------------------------------
def test_deadbeat_n1_exact_after_one_impact_and_a_window():
    res = deadbeat_error(bodies_n1(1.0), X0_PLANT, "n1")
    first_impact = res["trajectory"].event_times("jump")[0]
    # bound 3.4e-11 (condition 3e3), measured 9.2e-13
    assert res["relative_error_max"] <= _deadbeat_bound(res["estimate"])
    assert res["first_valid_time"] <= first_impact + DEADBEAT_WINDOW + 0.1


def test_deadbeat_1n_exact_after_n_minus_1_impacts():
    res = deadbeat_error(bodies_1n(), X0_PLANT_1N, "1n")
    assert res["impacts_needed"] == 2                       # n - 1 = 2
    second = res["trajectory"].event_times("jump")[1]
    assert res["first_valid_time"] >= second
    # bound 1.5e-13 (condition 13), measured 1.4e-14
    assert res["relative_error_max"] <= _deadbeat_bound(res["estimate"])


def test_deadbeat_1n_reports_too_few_impacts():
    traj = simulate_plant(bodies_1n(), X0_PLANT_1N, t_end=12.0)
    impacts = traj.event_times("jump")
    cut = 0.5 * (impacts[0] + impacts[1])                  # data hold one impact only
    keep = traj.t < cut
    with pytest.raises(InfeasibleDesignError, match=r"1 usable .* 2 \(= n - 1\)") as info:
        deadbeat_1n(bodies_1n(), traj.t[keep], traj.signal("y")[keep, 0], impacts[:1],
                    [cut - 0.1], window=DEADBEAT_WINDOW, u=input_generator())
    assert info.value.status == "too_few_impacts"
    assert "record longer" in str(info.value)


def test_deadbeat_1n_structurally_unobservable_body_b():
    """k23 = 0: mass 3 is not coupled to the contact mass 2, so no number of impacts can
    determine it -- a different diagnosis from 'too few impacts'."""
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    cut = ImpactingBodies.from_springs([1.0], [1.0, 1.0], {(0, 0): 3.0},
                                       {(0, 0): 2.0, (1, 1): 1.0})       # k23 = 0
    traj = simulate_plant(cut, X0_PLANT_1N)
    impacts = traj.event_times("jump")
    assert impacts.size >= 5                               # plenty of impacts
    with pytest.raises(InfeasibleDesignError, match="no number of impacts") as info:
        deadbeat_1n(cut, traj.t, traj.signal("y")[:, 0], impacts, [T_END - 1.0],
                    window=DEADBEAT_WINDOW, u=input_generator())
    assert info.value.status == "unobservable"
    assert "record longer" not in str(info.value)


def test_deadbeat_1n_degenerate_impact_times_are_rank_deficient():
    """Body b observable from the contact mass, but impacts exactly one common period
    (2 pi: modes 1 and 2 rad/s) apart give the same two equations twice."""
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    b = ImpactingBodies.from_springs([1.0], [1.0, 1.0], {(0, 0): 3.0},
                                     {(0, 0): 1.0, (0, 1): 1.5, (1, 1): 1.0})
    assert np.allclose(np.sort(np.abs(np.linalg.eigvals(b.A_b).imag)), [1, 1, 2, 2])
    t = np.arange(0.0, 10.0, 0.01)
    y = np.sin(t)                                          # any record: only the rank matters
    with pytest.raises(InfeasibleDesignError, match="degenerate impact times") as info:
        deadbeat_1n(b, t, y, [1.0, 1.0 + 2 * np.pi], [9.0], window=0.25)
    assert info.value.status == "rank_deficient"
    assert "only 2 of the 4 states" in str(info.value)


def test_deadbeat_1n_stacks_every_usable_impact():
    res = deadbeat_error(bodies_1n(), X0_PLANT_1N, "1n")
    est = res["estimate"]
    assert est.impacts_needed == 2 and est.rank == 4
    assert est.impacts_used.size > 10                      # all usable impacts, not n - 1
    assert 1.0 <= est.condition < 1e3 and est.window_condition >= 1.0
    assert est.impact_amplification == pytest.approx(1.0)  # equal masses, e = 1: 1/M12 = 1


def test_deadbeat_n1_reports_its_actual_least_squares():
    bodies = bodies_n1(M3_UNEQUAL)
    res = deadbeat_error(bodies, X0_PLANT, "n1")
    est = res["estimate"]
    assert res["relative_error_max"] <= _deadbeat_bound(est)     # 4e-11, measured 7.2e-13
    assert est.rank == 4 and est.impacts_needed == 1
    assert np.isfinite(est.condition) and est.condition > 10.0      # measured ~3e3
    assert est.condition == est.window_condition
    M = impact_plant(bodies).M
    assert est.impact_amplification == pytest.approx(1.0 / M[0, 1])   # 1.7 / 1.4


def test_deadbeat_window_with_too_few_samples_is_rank_deficient():
    traj = simulate_plant(bodies_n1(1.0), X0_PLANT, t_end=6.0)
    sparse = slice(None, None, 40)                         # one sample every 0.4 s
    with pytest.raises(InfeasibleDesignError, match="samples") as info:
        deadbeat_n1(bodies_n1(1.0), traj.t[sparse], traj.signal("y")[sparse, 0],
                    traj.event_times("jump"), [5.5], window=DEADBEAT_WINDOW,
                    u=input_generator())
    assert info.value.status == "rank_deficient"


# -- exact integration vs an independent ODE solver -------------------------------------------
def test_impact_times_agree_with_tight_dop853():
    exact = simulate_plant(bodies_n1(1.0), X0_PLANT, t_end=20.0).event_times("jump")
    ref = ivp_impact_times(bodies_n1(1.0), X0_PLANT, 20.0)
    assert exact.size == ref.size >= 8
    # the reference's error dominates: DOP853 at tol 1e-13 per step over ~500 steps (global
    # error <= 5e-11 in the state) over approach speeds >= 1.2: 4e-11; bound 1e-9 leaves 25x
    # for the error growth between impacts (measured 2.8e-13)
    assert np.max(np.abs(exact - ref)) < 1e-9


def test_certified_design_equal_masses_meets_its_rate(runs_equal):
    dwell = np.diff(runs_equal[0.25].trajectory.event_times("jump"))
    d = design_impact_observer(bodies_n1(1.0), LAMBDA1, alpha=0.3, delta_min=0.99 * dwell.min(),
                               delta_max=1.01 * dwell.max())
    assert d.certificate.condition == "theorem3" and d.alpha_L == np.inf
    run = run_observer(bodies_n1(1.0), design=d)
    # eps = 0.0124 reaches the rounding floor (_rounding_floor: 1.1e-8 relative to ||x~(0)||)
    # at the second impact (norms at the floor measured 4.6e-11 .. 1.7e-10 relative on
    # different BLAS kernels: the library's default floor, 1e-10, sits among them)
    from nscontrol.analysis.observability import impact_decay_rate

    error = run.loop.outputs["error"]
    floor = _rounding_floor(run) / np.linalg.norm(error @ run.trajectory.x[0])
    # the fit of ln||x~(t_i-)|| runs through the first norm under the floor, a lower bound of
    # the rate (measured 11.0 on 2 impacts)
    fit = impact_decay_rate(run.trajectory, error, floor=floor, through_floor=True)
    assert fit.times.size == 2 and fit.norms[0] > 0.1 * fit.initial_norm
    assert fit.rate >= d.certificate.alpha
    # without the floor point there is nothing to fit: the error says what to do
    with pytest.raises(ModelError, match="through_floor=True"):
        impact_decay_rate(run.trajectory, error, floor=floor)


@pytest.mark.parametrize("factors", [{"mass_factor": 1e-6}, {"spring_factor": 1e6}])
def test_closed_loop_in_other_units_behaves_the_same(factors):
    """The unequal-mass example with time x 1e-3 (masses x 1e-6, or springs x 1e6 with the force
    x 1e6): Lambda1 x 1e3, same eps. The impact times scale by 1e-3 and the measured decay rate
    by 1e3 (the error norm weights velocities x 1e3, hence a few more fit points)."""
    from nscontrol.analysis.observability import impact_decay_rate
    from nscontrol.numerics.lti import Exosystem

    c = 1e3
    ref = run_observer(bodies_n1(M3_UNEQUAL), 0.125)
    bodies = bodies_n1(M3_UNEQUAL, **factors)
    u = Exosystem.sinusoid(3.0 * factors.get("spring_factor", 1.0), omega=2.0 * c)
    d = design_impact_observer(bodies, np.asarray(LAMBDA1) * c, 0.125)
    # bound as in test_ch02_design (kappa of the balanced companion x N u): 5e-12, unit-free
    assert d.observability.observable and d.conditioning.spectrum_error < 1e-11
    loop = d.closed_loop(u)
    x0 = np.array(X0_PLANT)
    x0[[2, 3, 5]] *= c                                     # velocities in the new units
    z0 = d.initial_state(np.concatenate([x0, u.w0]), np.zeros(6))
    traj = simulate(loop, z0, (0.0, 40.0 / c), method="event_driven", dt=0.01 / c,
                    progress=False)
    t_ref, t_new = ref.trajectory.event_times("jump"), traj.event_times("jump")
    assert t_new.size == t_ref.size == 22
    assert np.max(np.abs(c * t_new - t_ref)) < 1e-9
    rate = impact_decay_rate(traj, loop.outputs["error"]).rate / c
    assert rate == pytest.approx(_rate(ref).rate, rel=0.02)   # 0.963 vs 0.960
