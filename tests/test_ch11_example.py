"""The ch11 example: listed, and (slow) all its checks pass with JSON-ready metrics."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("ch11-convergent-pwa")
    assert ex.chapter == "ch11"


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch11-convergent-pwa").run(tmp_path)
    numbers = {c.name.split()[0] for c in res.checks}
    assert {str(k) for k in range(1, 16)} <= numbers
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 4 and all(p.exists() for p in res.figures)
    payload = json.loads(json.dumps(res.to_json()))
    assert abs(payload["metrics"]["boundary_found"] - 1.449489742783178) < 1e-6
    assert payload["metrics"]["attenuation_ratio_at_resonance"] >= 10
