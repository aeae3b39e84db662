"""Chapter 3 example: the two-link arm tracking a circle cut by the ground.

The runs are long (the fine one is 300 000 Moreau–Jean steps, compiled by default), so all
but the registration test are marked slow. The bounds are the chapter's checks; those stated at
h = 1e-4 are scaled with the scheme's order where a run uses h = 1e-3 (see each comment).
"""

import math

import numpy as np
import pytest

from nscontrol.analysis.tracking_cycles import (
    check_weak_stability,
    cycle_reports,
    impact_events,
)
from nscontrol.examples import get_example
from nscontrol.examples.ch03_two_link_tracking import (
    CONFIGS,
    model_checks,
    tracking_checks,
    two_link_tracking,
)


def test_registered_with_claim_captions_and_both_configurations():
    ex = get_example("ch03-two-link-tracking")
    assert ex.claim and ex.key_figure in ex.captions
    assert set(CONFIGS) == {"siconos-current", "siconos-2007"}


def test_model_checks_pass():
    failed = [c.name for c in model_checks() if not c.passed]
    assert not failed


@pytest.mark.slow
def test_example_run_passes_every_check(tmp_path):
    """Three cycles at h = 1e-3 (30 000 steps) with the figures."""
    result = get_example("ch03-two-link-tracking").run(tmp_path)
    failed = [(c.name, c.value, c.threshold) for c in result.checks if not c.passed]
    assert not failed
    assert len(result.figures) == 3
    assert result.metrics["cycles"] == 3


def _analyse(run, v_floor):
    events = impact_events(run.traj, run.model, run.restitution)
    reports = cycle_reports(run.traj, run.controller, run.model, run.restitution)
    return events, reports, check_weak_stability(reports, v_floor=v_floor)


@pytest.fixture(scope="module")
def fine_run():
    """The chapter's setting: h = 1e-4, three cycles (300 000 steps; several minutes)."""
    return two_link_tracking("siconos-current", cycles=3, h=1e-4)


@pytest.mark.slow
def test_checks_at_the_chapters_step(fine_run):
    events, reports, verdict = _analyse(fine_run, 1e-8)
    checks = tracking_checks(fine_run, reports, events, verdict)
    failed = [(c.name, c.value, c.threshold) for c in checks if not c.passed]
    assert not failed


@pytest.mark.slow
def test_step_size_robustness(fine_run):
    """Check 13: at h = 1e-3 the same cycles complete and the V(τ0) floor grows no faster
    than h² (ratio (1e-3/1e-4)² = 100; a factor 3 of margin for the O(h³) terms)."""
    coarse = two_link_tracking("siconos-current", cycles=3, h=1e-3)
    _, fine, _ = _analyse(fine_run, 1e-8)
    _, rough, _ = _analyse(coarse, 1e-6)
    assert [math.isfinite(r.t_constrained) for r in rough] == \
        [math.isfinite(r.t_constrained) for r in fine]
    floor_fine = max(r.V_tau0 for r in fine[1:])
    floor_rough = max(r.V_tau0 for r in rough[1:])
    assert floor_rough <= 3 * 100 * max(floor_fine, 1e-14)


def _dive_bottom_lag(run, cycle):
    """Normal tracking error ``y - y*_d`` at the bottom of the dive of ``cycle`` (the arm's
    lag behind the virtual reference when it should be ``d`` below the ground)."""
    tr = run.controller.transition
    t, sig = run.traj.t, run.traj.signals
    i = int(np.searchsorted(t, cycle.tau0 + tr.delta + tr.Delta))
    return float(sig["q_task"][i, 0] - sig["qd"][i, 0])


@pytest.mark.slow
def test_linear_depth_law_without_floor_stalls():
    """Check 16, the documented known failure, where it appears. With ``d = φ V1(τ0)`` and no
    lower clip the depth is quadratic in the tracking error while the arm's lag behind the
    dive is linear in it (and, once the error sits at the scheme's floor, both are set by h:
    V1 ~ h², lag ~ h). The arm reaches the ground only if the dive goes deeper than the lag.
    At h = 1e-3 cycle 1 starts with V1 = 3.9e-9 and lags the dive by 1.3 µm:

    * φ = 1e3: d = 3.9 µm (the depth φ = 1e5 gives at h = 1e-4, where the lag is ten times
      smaller) — the arm lands at the dive's crossing speed, 0.7 mm/s, and its rebounds take
      3.0 s to settle, beyond the 2.5 s of check 7: a degraded transition, not a stall;
    * φ = 10: d = 39 nm, 33 times smaller than the lag — no impact at all in cycle 1, the
      arm still above the ground at the planned take-off: the stall.

    Both are failures of the transition; the test passes when they are reproduced. They are
    the reason for the lower clip of the depth (``depth_min = 5 mm`` by default)."""
    late = two_link_tracking("siconos-current", cycles=2, h=1e-3, depth_law="linear",
                             depth_min=0.0, phi=1e3)
    c = late.controller.cycles[1]
    assert c.depth < 1e-5                          # a micrometre dive ...
    assert math.isfinite(c.t_first_impact)         # ... that still lands
    assert abs(c.u_star) < 1e-3                    # at under 1 mm/s
    assert c.t_constrained - c.t_first_impact > 2.5   # and settles too slowly (check 7)

    stall = two_link_tracking("siconos-current", cycles=2, h=1e-3, depth_law="linear",
                              depth_min=0.0, phi=10.0)
    c = stall.controller.cycles[1]
    assert c.depth < _dive_bottom_lag(stall, c) / 10   # the dive hides inside the lag
    assert math.isnan(c.t_first_impact)                # no impact in cycle 1
    after = stall.traj.t >= c.tau0
    assert stall.traj.signals["gap"][after, 0].min() > 0.0   # never touches until the end


@pytest.mark.slow
def test_2007_configuration_repeats_identical_cycles():
    """Ten 3 s cycles at h = 5e-3: one landing per period near x = 0.55, a slide to
    x = 0.75, V at the transition starts the same every cycle (to the scheme's O(h)
    accuracy on numbers of size 0.5: 0.05)."""
    run = two_link_tracking("siconos-2007", cycles=10)
    _, reports, verdict = _analyse(run, 1e-8)
    assert len(reports) == 10
    assert all(math.isfinite(r.t_constrained) for r in reports)
    assert verdict.holds, verdict.message
    V = np.array([r.V_tau0 for r in reports[1:]])
    assert np.ptp(V) <= 0.05 * V.max()
    x = run.traj.signals["q_task"][:, 1]
    landings = [x[np.searchsorted(run.traj.t, r.t_first_impact)] for r in reports]
    assert np.allclose(landings, 0.55, atol=0.01)
    assert x.max() == pytest.approx(0.75, abs=0.01)


@pytest.mark.slow
def test_restitution_sets_the_number_of_impacts_not_the_outcome():
    """Check 14 (one cycle each, h = 1e-3): every e reaches the constrained phase, e = 0 lands
    with a single impact event, and the accumulation lasts longer as e grows."""
    durations = []
    for e in (0.0, 0.3, 0.7, 0.9):
        run = two_link_tracking("siconos-current", cycles=1, h=1e-3, restitution=e)
        _, reports, _ = _analyse(run, 1e-6)
        (r,) = reports
        assert math.isfinite(r.t_constrained)
        if e == 0.0:
            assert r.n_impacts == 1
        durations.append(r.t_constrained - r.t_first_impact)
    assert all(np.diff(durations) > 0.0), durations


@pytest.mark.slow
@pytest.mark.parametrize("scale", [0.9, 1.1])
def test_model_error_keeps_the_cycles_and_predicts_early_liftoff(scale):
    """Check 15 (two cycles, h = 1e-3): the controller's M, C, g scaled by 0.9 or 1.1.
    Every cycle completes, V(τ0) grows by at most 10 % per cycle, the free-phase error at
    τ0 stays below 3 cm and the dive hits its upper clip. With 1.1 the model-error force
    pulls the arm off the ground before t_d: the gap opens (by a few mm) about
    Δλ/c_λ seconds early, Δλ = λ̂ - λ_d measured in contact, within 0.1 s."""
    run = two_link_tracking("siconos-current", cycles=2, h=1e-3, model_scale=scale)
    _, reports, verdict = _analyse(run, 1e-6)
    assert len(reports) == 2 and all(math.isfinite(r.t_constrained) for r in reports)
    V = [r.V_tau0 for r in reports]
    assert V[1] <= 1.1 * V[0] + 1e-8
    assert max(r.tracking_error_tau0 for r in reports) <= 0.03
    assert all(r.depth == run.controller.transition.depth_max for r in reports)
    if scale > 1.0:
        t, sig = run.traj.t, run.traj.signals
        gap, c_lam = sig["gap"][:, 0], run.controller.contact.lam_rate
        for c in run.controller.cycles[:2]:
            contact = (t >= c.t_constrained) & (t < c.t_detach)
            opened = t[contact & (gap > 1e-6)]
            assert opened.size and gap[contact].max() <= 5e-3
            settled = contact & (t < opened[0]) & (t > c.t_constrained + 0.5)
            dlam = float(np.median(sig["lam_hat"][settled] - sig["lam_d"][settled]))
            assert opened[0] == pytest.approx(c.t_detach + dlam / c_lam, abs=0.1)


@pytest.mark.slow
def test_robustness_point_runs_through_a_sweep():
    """One point of the robustness grid through nscontrol.sweep (serial): the record a
    robustness map is drawn from."""
    from nscontrol import sweep
    from nscontrol.examples.ch03_two_link_tracking import robustness_point

    result = sweep.run(robustness_point, [{"restitution": 0.0, "cycles": 1}],
                       executor="serial", progress=False)
    (rec,) = result.values
    assert rec["cycles_completed"] == 1 and rec["impacts_per_cycle"] == [1]
    assert rec["weakly_stable"] and rec["penetration"] <= 1e-4


def test_tracking_runs_take_moreau_jeans_forces_option():
    """``forces=`` reaches Moreau–Jean. The mass's only force is gravity, constant: the
    implicit forces' Jacobians are zero and the explicit θ-method takes the same steps; the
    explicit run is on the Python path, the default one compiled, and the two loops group
    the same products differently (a few ulps per step, carried without amplification by
    more than a modest factor: 100 ulps per step over the run, as for the compiled and Python
    paths of the controller)."""
    from nscontrol.errors import ModelError
    from nscontrol.examples.ch03_two_link_tracking import one_dof_tracking

    implicit = one_dof_tracking(cycles=1, h=1e-3)
    explicit = one_dof_tracking(cycles=1, h=1e-3, forces="explicit")
    assert implicit.traj.stats["path"] == "compiled_model"
    assert explicit.traj.stats["path"] == "python"
    assert explicit.traj.stats["forces"] == "explicit"
    assert explicit.traj.stats["path_reason"].startswith("forces='explicit'")
    bound = (implicit.traj.t.size - 1) * np.finfo(float).eps * 100
    assert np.array_equal(explicit.traj.t, implicit.traj.t)
    assert np.abs(explicit.traj.x - implicit.traj.x).max() <= bound
    for bad in ("semi", 1):
        with pytest.raises(ModelError, match="^forces: expected 'implicit' or 'explicit'"):
            one_dof_tracking(cycles=1, h=1e-3, forces=bad)
        with pytest.raises(ModelError, match="^forces: expected 'implicit' or 'explicit'"):
            two_link_tracking(cycles=1, h=1e-3, forces=bad)


def test_cycles_are_public_tracking_cycle_records():
    """The per-cycle record is the documented ``TrackingCycle`` of ``nscontrol.design``:
    the instants in the order of the phases, NaN for what the last cycle has not reached."""
    from nscontrol.design import TrackingCycle
    from nscontrol.examples.ch03_two_link_tracking import one_dof_tracking

    run = one_dof_tracking(cycles=1, h=1e-3)
    cycles = run.controller.cycles
    assert cycles and all(isinstance(c, TrackingCycle) for c in cycles)
    first = cycles[0]
    assert first.index == 0
    assert first.tau0 <= first.t_first_impact < first.t_constrained < first.t_detach
    # the dive (default δ = 0.4 s, Δ = 1 s) crosses q1 = 0 within its own interval
    assert first.tau0 + 0.4 <= first.t_star <= first.tau0 + 0.4 + 1.0
    assert first.q2_star.shape == (0,)          # one coordinate: no tangential part
    assert cycles[-1].index == len(cycles) - 1
    if len(cycles) > 1:                          # the cycle begun at the end of the run
        assert math.isnan(cycles[-1].t_first_impact)
