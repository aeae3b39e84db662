"""The impact-oscillator-bifurcation example: listed, and its checks (the known answers) pass."""

import pytest

from nscontrol.examples import get_example


def test_example_is_listed_with_a_parameter_family():
    from nscontrol.examples.impact_oscillator_bifurcation import bifurcation_family

    ex = get_example("impact-oscillator-bifurcation")
    assert ex.chapter == "orbits"
    assert bifurcation_family("forcing")(1.0).period == pytest.approx(2 * 3.141592653589793 / 2.5)


@pytest.mark.slow
def test_example_checks_pass(tmp_path):
    res = get_example("impact-oscillator-bifurcation").run(tmp_path)
    assert res.passed, [c for c in res.checks if not c.passed]
    assert res.figures and res.figures[0].exists()
