"""Per-impact events, cycle reports and the weak-stability verdict, on the one-degree-of-
freedom tracking task (a mass above the ground under the chapter's controller)."""

import math

import numpy as np
import pytest

from nscontrol.analysis.tracking_cycles import (
    CycleReport,
    accumulation_estimate,
    check_weak_stability,
    cycle_reports,
    free_phase_growth,
    impact_events,
)
from nscontrol.examples.ch03_two_link_tracking import one_dof_tracking

H = 1e-3
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def run():
    """Two cycles (16 s, 16 000 steps) at h = 1e-3, e = 0.7."""
    return one_dof_tracking(cycles=2, h=H, restitution=0.7)


@pytest.fixture(scope="module")
def reports(run):
    return cycle_reports(run.traj, run.controller, run.model, run.restitution)


def test_newton_law_holds_at_every_impact(run):
    events = impact_events(run.traj, run.model, run.restitution)
    assert events
    for ev in events:
        # the LCP imposes u+ = -e u- exactly; a few roundings of numbers of size |u-|
        assert abs(ev.u_plus + 0.7 * ev.u_minus) <= 16 * EPS * abs(ev.u_minus)


def test_later_impacts_lose_exactly_the_kinetic_energy_of_newtons_law(run):
    events = [ev for ev in impact_events(run.traj, run.model, run.restitution)
              if not ev.first and abs(ev.u_minus) >= 1e-3]
    assert len(events) >= 4
    for ev in events:
        # σ_V also holds the smooth change of V over the impact step: V' = O(γ1 γ2 d |u|)
        # times h, against ΔT = O(u²): relative O(γ1 γ2 d h / |u|) <= 25·0.005·1e-3/1e-3 = 0.13
        assert abs(ev.sigma_V - ev.dT_predicted) <= 0.13 * abs(ev.dT_predicted)


def test_first_impact_happens_where_the_dive_crosses_the_ground(reports):
    for r in reports:
        assert abs(r.t_first_impact - r.t_star) <= 2 * H        # impact time exact to O(h)
        assert r.events[0].u_minus == pytest.approx(r.u_star, rel=0.05)


def test_impacts_accumulate_with_flight_ratios_approaching_e(reports):
    for r in reports:
        assert 1 <= r.n_impacts <= 60
        ratios = np.array(r.flight_ratios[1:6])
        # flights of ~0.03 s measured to ±h: ratio error up to ~4h/0.03 = 0.13
        assert np.all(ratios >= 0.7 - 0.2) and np.all(ratios <= 0.7 + 0.02 + 4 * H / 0.03)
        assert r.t_constrained - r.t_first_impact <= 2.5


def test_weak_stability_and_free_phase_decay(run, reports):
    verdict = check_weak_stability(reports, v_floor=1e-8 * (H / 1e-4) ** 2)
    assert verdict.holds, verdict.message
    assert verdict.cycles_completed == 2
    # O(h²) floor of the discrete V at the reference's acceleration jumps: 1e-8 at h = 1e-4
    assert free_phase_growth(run.traj) <= 1e-8 * (H / 1e-4) ** 2


def test_contact_phase_keeps_contact_and_tracks_the_force(run, reports):
    gap = run.traj.signals["gap"][:, 0]
    cons = run.traj.signals["phase"] == 3
    assert gap[cons].min() >= -1e-5 * (H / 1e-4)        # O(h u-) drift of the impact steps
    assert gap[cons].max() <= 1e-6
    for r in reports:
        assert r.force_error_last_second <= 1e-2


def test_inelastic_contact_gives_one_impact_per_cycle():
    r = cycle_reports(*(lambda t: (t.traj, t.controller, t.model, t.restitution))(
        one_dof_tracking(cycles=1, h=H, restitution=0.0)))
    assert [c.n_impacts for c in r] == [1]


def test_accumulation_estimate_is_exact_on_a_geometric_sequence():
    r, t = 0.7, [0.0]
    for k in range(6):
        t.append(t[-1] + r**k)
    assert accumulation_estimate(t) == pytest.approx(1 / (1 - r), rel=64 * EPS)
    assert math.isnan(accumulation_estimate([0.0, 1.0]))
    assert math.isnan(accumulation_estimate([0.0, 1.0, 2.5]))     # growing flights


def _report(V):
    return CycleReport(0, 0.0, V, V, 0.005, 1.0, 0.0, 0.0, 1, math.nan, (), 2.0, 0.0, 3.0,
                       0.0, 0.0, 0.0, 0.0)


def test_verdict_refuses_growth():
    assert not check_weak_stability([_report(1e-6), _report(1e-4)]).holds
    assert check_weak_stability([_report(1e-4), _report(1e-6)]).holds
    assert check_weak_stability([_report(1e-4), _report(1.05e-4)], growth=1.1).holds
    assert not check_weak_stability([]).holds
