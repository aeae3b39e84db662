"""The optimal-cartpole example: listed, and (slow) every check passes with its figures."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("optimal-cartpole")
    assert ex.chapter == "optimal" and ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    pytest.importorskip("casadi")
    res = get_example("optimal-cartpole").run(tmp_path)
    assert {c.key for c in res.checks} == {
        "contact_settles", "contact_uses_walls", "contact_residual", "linear_falls",
        "nonlinear_contact_settles", "nonlinear_linear_falls"}
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 2 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    assert m["contact_cpu_per_sample_median_s"] > 0
