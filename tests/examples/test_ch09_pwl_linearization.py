"""The ch09 example: listed with its claim and captions; (slow) all eight acceptance checks
measured and passing, figures written, JSON-ready metrics."""

import json

import pytest

from nscontrol.examples import get_example


def test_example_is_listed_with_claim_and_captions():
    ex = get_example("ch09-pwl-linearization")
    assert ex.chapter == "ch09" and ex.claim and ex.verdict is not None
    assert ex.key_figure in ex.captions and len(ex.captions) == 3


@pytest.mark.slow
def test_example_runs_all_checks(tmp_path):
    res = get_example("ch09-pwl-linearization").run(tmp_path)
    numbers = {int(c.key.split("_")[1]) for c in res.checks}
    assert numbers == set(range(1, 9))          # every acceptance check is measured
    assert res.passed, [c for c in res.checks if not c.passed]
    assert len(res.figures) == 3 and all(p.exists() for p in res.figures)
    m = json.loads(json.dumps(res.to_json()))["metrics"]
    assert m["conjugacy_crossings"]["ex9_2"] == 2 and m["outer_law_crossings"] == 1
    assert m["perturbed_two_layer_accepted"] == 0
    assert "k = 1" in m["perturbed_one_layer_reason"]
    verdict = get_example("ch09-pwl-linearization").verdict(res)
    assert "(0 mismatches)" in verdict and "12 of 12 checks pass" in verdict, verdict
