"""The frictional-contacts example: listed, and (slow) every check passes with its figures."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("frictional-contacts")
    assert ex.chapter == "contacts" and ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("frictional-contacts").run(tmp_path)
    assert {c.key for c in res.checks} == {f"check_{k}" for k in range(1, 16)}
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 4 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    assert m["ball_penetration_without_projection_m"] > 1e-3
