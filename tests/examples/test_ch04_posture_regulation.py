"""The ch04 example: listed; Example C's checks 4-5 (fast, compiled path); Example A's
scenarios and the whole example (slow)."""

import json

import numpy as np
import pytest

from nscontrol.examples import get_example
from nscontrol.examples.ch04_posture_regulation import (
    WALL_FORCE,
    WALL_KP,
    random_impact_checks,
    run_foot,
    run_wall,
    sequential_impact_checks,
)


def test_example_is_listed():
    ex = get_example("ch04-posture-regulation")
    assert ex.chapter == "ch04" and ex.key_figure == "ch04_robot"


@pytest.mark.parametrize("e", [0.0, 0.5, 0.9])
def test_wall_contact_energy_rest_and_force(e):
    """§5 checks 4-5: θ = 1/2, h = 2, 1, 0.5 ms."""
    for h in (2e-3, 1e-3, 5e-4):
        r = run_wall(e, h)
        # the acceptance bound on one step's energy increase (θ = ½ is conservative on the
        # linear flow; the increase comes from impacts landing within a step)
        assert r["max_energy_step"] <= 1e-6 * r["E0"] and r["E_final"] < r["E0"]
        # at rest the LCP gives v = 0 exactly up to round-off of v_free + M̂⁻¹P (|v| ~ 1e-16)
        assert abs(r["v_final"]) <= 1e-12
        # discrete static balance: P/h = k_p (q_d - q) + λ_d - ... to round-off of forces ~5 N
        assert r["balance_error"] <= 1e-9
        assert abs(r["force_final"] - WALL_KP * (WALL_FORCE / WALL_KP - r["q_final"])) <= 1e-9
        # drift bound of a velocity-level scheme: 0 <= q_end <= h |U⁻|
        assert 0.0 <= r["q_final"] <= h * abs(r["approach_velocity"])
        if e > 0:
            assert r["impacts"] >= 2            # an accumulation of impacts before sticking


def test_impact_map_helpers_of_the_example():
    imp = random_impact_checks(draws=100)
    assert imp["energy_identity_over_estimate"] <= 100 and imp["negative_impulse"] <= 0.0
    seq = sequential_impact_checks(draws=200)
    assert seq["helper_disagreements"] == 0 and seq["non_obtuse_draws"] > 20
    # two projections in the M metric, each backward stable (κ(M) <= 10 here): 1e-12
    assert seq["worst_difference_non_obtuse"] <= 1e-12


@pytest.mark.slow
def test_push_forward_lifts_the_heel_and_recovers():
    """§5 check 8 on A1 at h = 1 ms."""
    r = run_foot(-1.0)
    g = r["gap"][:, 0]
    lifted = np.flatnonzero(g > 1e-3)
    assert lifted.size and np.any(g[lifted[-1]:] <= 1e-9)     # opens, then closes again
    # θ = ½ with the law folded in (implicit): no step increases E beyond round-off of
    # E ≈ 170 J (1e-9 J is 3e4 ε E)
    assert r["max_energy_step"] <= 1e-9
    assert r["final_deviation"] <= 5e-3 and r["x_com_drift"] <= 1e-3
    lam = r["regulator"].design.lam_star
    assert np.abs(r["final_force"] - lam).max() <= 0.03 * lam.max()


def test_the_foot_models_activation_is_the_default_and_removes_the_toe_drift():
    """Moreau–Jean's own threshold (1e-12 m) lets the toe fall out of the index set when the
    heel lands (A1, h = 1 ms): the toe sinks by ~0.3 mm and the rest offset grows ~4×. The
    model's threshold, taken by default, keeps the toe closed: its gap stays within the
    threshold (1e-6 m), while the heel's landing drift h|U⁻| (~1e-4 m) is the only one left."""
    from nscontrol.systems.foot_body import FOOT_BODY_ACTIVATION, foot_body_model

    assert foot_body_model().contact_activation == FOOT_BODY_ACTIVATION == 1e-6
    default = run_foot(-1.0, T=3.0)
    tight = run_foot(-1.0, T=3.0, activation=1e-12)
    h, heel_landing = 1e-3, 0.1                       # |U⁻| of the heel < 0.1 m/s
    assert default["gap"][:, 1].min() >= -FOOT_BODY_ACTIVATION      # the toe held
    assert tight["gap"][:, 1].min() < -h * heel_landing             # the toe sank
    assert default["gap"][:, 0].min() >= -h * heel_landing          # the landing drift only
    assert tight["final_deviation"] > 3 * default["final_deviation"]
    np.testing.assert_array_equal(
        default["trajectory"].x,
        run_foot(-1.0, T=3.0, activation=FOOT_BODY_ACTIVATION)["trajectory"].x)


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch04-posture-regulation").run(tmp_path)
    numbers = {c.key.split("_")[1].rstrip("abcdefg") for c in res.checks}
    assert {str(k) for k in range(1, 12)} <= numbers
    failing = [c.name for c in res.checks if not c.passed]
    assert not failing, failing
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    assert m["A4"]["max_theta_error_5s"] > 0.1 and m["A4"]["unstable_rate_linearised"] > 0
    # the 3 s of the reconstructed scenario is one run's figure; ours leaves 0.1 rad later
    # than 3 s but before 5 s, at the time the linearised rate predicts (checked by its rate)
    assert 3.0 < m["A4"]["time_to_leave_0.1_rad"] < 5.0
    assert len(res.figures) == 5 and all(p.exists() for p in res.figures)


@pytest.mark.slow
def test_failing_designs_and_undamped_posture():
    """§5 checks 9-10: A5 (posture beyond the toe) falls, A4 (k_p < k̄) diverges, A6
    (k_d = 0) keeps oscillating with energy kept to the scheme's accuracy."""
    a5 = run_foot(0.0, theta_star=-0.25, T=2.0)
    assert a5["theta_error"].max() > 1.0
    a4 = run_foot(-0.05, kp=120.0, T=5.0)
    err = a4["theta_error"]
    t = a4["trajectory"].t
    assert err[t <= 3.0].max() > 0.05 and err.max() > 0.1      # diverging (0.074 at 3 s)
    a6 = run_foot(-0.3, kd=0.0, T=5.0)
    tr6 = a6["trajectory"]
    assert np.ptp(tr6.x[tr6.t >= 4.0, 3]) / 2 > 0.01
    # θ = ½ with a configuration-dependent M frozen at the step start conserves E only to
    # O(h²) per step: the acceptance bound 1e-7 E0 (measured 7.8e-10 E0)
    assert a6["max_energy_step"] <= 1e-7 * a6["E0"]
