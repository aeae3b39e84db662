"""The ch06 example: listed, and (slow) all its checks pass with JSON-ready metrics."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("ch06-beam-attenuation")
    assert ex.chapter == "ch06" and ex.key_figure in ex.captions


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch06-beam-attenuation").run(tmp_path)
    numbers = {int(c.key.split("_")[1]) for c in res.checks}
    assert numbers == set(range(1, 15))        # every acceptance check 1-14 is measured
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 5 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    # coexisting open-loop solutions at 48 Hz: period 1 sweeping up, period 2 sweeping down
    assert m["open_loop_48hz_down_m"] > 1.5 * m["open_loop_48hz_up_m"]
    assert m["closed_loop_max_floquet"] < 1.0
