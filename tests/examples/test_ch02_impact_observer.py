"""The ch02-impact-observer example: every check passes, the issue's JSON metrics are
there, and the five figures are written."""

import json

from nscontrol.examples import get_example


def test_ch02_example_runs_and_passes(tmp_path):
    result = get_example("ch02-impact-observer").run(tmp_path)
    failed = [(c.name, c.value, c.op, c.threshold) for c in result.checks if not c.passed]
    assert not failed
    payload = json.loads(json.dumps(result.to_json()))
    metrics = payload["metrics"]
    for key in ("observable", "impacts", "decay_rate_equal_masses",
                "decay_rate_unequal_masses", "alpha_L", "deadbeat_error_after"):
        assert key in metrics
    assert metrics["observable"] is True and metrics["impacts"] >= 10
    assert len(metrics["decay_rate_equal_masses"]) == 4
    assert all(v < 1e-9 for v in metrics["deadbeat_error_after"].values())
    assert all(metrics["theorem1_other_units"].values())
    assert "guarantees for the worst dwell" in metrics["alpha_L_note"]
    assert metrics["alpha_at_alpha_L"] == "alpha_unreachable"
    assert metrics["impact_counts_0_20s"]["exact"] == metrics["impact_counts_0_20s"]["dop853"]
    assert metrics["restitution"]["m3_0.7_e0.8"]["energy_change_max"] < 0.0
    keys = {c["key"] for c in payload["checks"]}
    for name in ("restitution_momentum_rel_err", "impact_count_exact_minus_dop853",
                 "unequal_masses_alpha_L_refused_status", "realised_observer_spectrum_error",
                 "equal_masses_certified_run_rate_over_alpha",
                 "equal_masses_rate_grows_as_eps_halves_min_ratio",
                 "fitted_rates_match_error_contraction_over_rate_error",
                 "theorem1_observable_in_other_units"):
        assert name in keys
    assert len(payload["checks"]) >= 20
    # the equal-mass rates (the error's contraction over each run's impacts) at least double
    # per halving of eps (Theorem 3: rate ~ 1/eps), and the report's line says so with numbers
    ratios = metrics["rate_ratio_per_halving_equal_masses"]
    assert len(ratios) == 3 and min(ratios) >= 2.0
    verdict = get_example("ch02-impact-observer").verdict(result)
    rates = metrics["decay_rate_equal_masses"]
    assert verdict.startswith("equal masses: decay rate ") and "as ε halves" in verdict
    assert all(f"{r:.3g}" in verdict for r in rates.values())
    assert all(f"x{q:.2f}" in verdict for q in ratios)
    # each fit of the simulated error agrees with the propagated error at its impacts
    assert metrics["fit_vs_contraction_over_rate_error"] <= 1.0
    assert sorted(p.name for p in result.figures) == sorted(
        f"ch02_{n}.png" for n in ("positions", "unobserved_mass", "error_norm", "rate_vs_eps",
                                  "impacts_prevented"))
    assert all(p.stat().st_size > 10_000 for p in result.figures)
