"""The smooth-cycles example: listed under orbits, and its checks (the known answers) pass."""

import pytest

from nscontrol.examples import get_example


def test_example_is_listed():
    ex = get_example("smooth-cycles")
    assert ex.chapter == "orbits" and "smooth_cycles" in ex.captions


@pytest.mark.slow
def test_example_checks_pass(tmp_path):
    res = get_example("smooth-cycles").run(tmp_path)
    assert res.passed, [c for c in res.checks if not c.passed]
    assert res.figures and res.figures[0].exists()
