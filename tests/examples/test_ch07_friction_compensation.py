"""The ch07 example: listed, and (slow) every check of the chapter passes, with its figures."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("ch07-friction-compensation")
    assert ex.chapter == "ch07" and ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch07-friction-compensation").run(tmp_path)
    numbers = {c.key.split("_")[1].rstrip("abcdefghij") for c in res.checks}
    assert {str(k) for k in range(1, 12)} <= numbers
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 6 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    assert m["final_x1_0.5"] != 0.0 and abs(m["final_x1_0.5"]) <= m["c_max_0.5"]
