"""The ch10 example: listed, and all its checks pass with JSON-ready metrics."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("ch10-zad-buck")
    assert ex.chapter == "ch10" and ex.key_figure == "ch10_duty_diagram"


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch10-zad-buck").run(tmp_path)
    numbers = {int(c.key.split("_")[1].rstrip("abcde")) for c in res.checks}
    assert numbers == set(range(1, 12))          # every acceptance check 1-11 is measured
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 5 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    # the bisected flip of the reference example and the brute force one grid step apart
    assert abs(m["ks_critical"] - m["ks_brute_force"]) <= 0.005
    assert m["ks_flip_first_order"] < m["ks_critical"] < m["ks_flip_poly3"]
