"""The ch02-impact-observer example: every spec §7 check passes, the issue's JSON metrics are
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
    assert len(payload["checks"]) >= 12
    assert sorted(p.name for p in result.figures) == sorted(
        f"ch02_{n}.png" for n in ("positions", "unobserved_mass", "error_norm", "rate_vs_eps",
                                  "impacts_prevented"))
    assert all(p.stat().st_size > 10_000 for p in result.figures)
