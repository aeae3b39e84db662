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
    # keys "check_<number>_...": every item of the acceptance list 1-15 is measured
    numbers = {int(c.key.split("_")[1]) for c in res.checks if c.key.startswith("check_")}
    assert set(range(1, 16)) <= numbers
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 4 and all(p.exists() for p in res.figures)
    payload = json.loads(json.dumps(res.to_json()))
    m = payload["metrics"]
    assert abs(m["boundary_found"] - 1.449489742783178) < 1e-6
    assert m["attenuation_ratio_at_resonance"] >= 10
    # check 10 over the whole 60-frequency grid: sup|x̄| = 0.571 near ω = 1.94 (spec: 0.57)
    assert abs(m["max_steady_state"] - 0.5713) < 5e-4
    assert abs(m["max_steady_state_omega"] - 1.94) < 0.05
    assert set(m["crossings_per_period_fd_check"]) == {2, 4, 6}  # check 11
    # control effort max|u| per frequency of u = Kx, and at the resonance
    efforts = m["closed_loop_effort_per_omega"]
    assert len(efforts) == 60 and all(v > 0 for v in efforts.values())
    assert m["closed_loop_effort_max"] == max(efforts.values())
    assert 0 < m["closed_loop_effort_at_resonance"] <= m["closed_loop_effort_max"]
