"""Steps that cannot mean what they say are refused up front by the driver, for every
time-stepping method: longer than the span, so small the run would never end, not a number."""

from __future__ import annotations

import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.testing.setvalued_problems import relay_feedback


def _cases():
    return (("moreau_jean", LagrangianSystem.bouncing_ball(), [1.0, 0.0]),
            ("implicit_euler", relay_feedback().system, [1.0, 0.0]))


@pytest.mark.parametrize("h, match", [
    (10.0, r"^h: the step 10 is longer than the span 1; use h <= 1"),
    (1.0 + 1e-6, r"^h: the step 1 is longer than the span 1"),
    (1e-12, r"^h: 1e-12 on a span of 1 means 1e\+12 steps"),
    ("1e-3", r"^h: expected a real number"),
    (1e-3 + 0j, r"^h: expected a real number"),
    (-1e-3, r"^h: expected a finite number > 0"),
    (float("nan"), r"^h: expected a finite number > 0")])
def test_steps_are_checked_once_for_every_time_stepping_method(h, match):
    for method, system, x0 in _cases():
        with pytest.raises(ModelError, match=match):
            nsc.simulate(system, x0, (0.0, 1.0), method=method, h=h)


def test_a_step_equal_to_the_span_is_one_step():
    for method, system, x0 in _cases():
        tr = nsc.simulate(system, x0, (0.0, 0.01), method=method, h=0.01)
        assert tr.t[-1] == pytest.approx(0.01, abs=1e-15) and tr.stats["steps"] == 1
