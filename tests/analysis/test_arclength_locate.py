"""The zero location of the shared pseudo-arclength engine on a test function whose regula
falsi is one-sided (convex on the bracket)."""

import numpy as np

from nscontrol.analysis._arclength import Point, locate


def _on_branch():
    """A straight branch ``y = (p, p)`` (every prediction is already corrected) and a counter
    of the corrections asked."""
    calls = []

    def correct(y_pred, t):
        calls.append(float(y_pred[-1]))
        return Point(np.array(y_pred, float), None, {})

    return correct, calls


def test_a_convex_test_function_is_located_in_few_trials():
    """``f(p) = e^{-8p} - 0.3`` (zero at ``ln(10/3)/8``) from ``p = 0`` with a first trial at
    ``p = 1/√2``: every chord's zero lies past the zero (the curve is below its chords), so
    plain regula falsi keeps the end at ``p = 0`` and contracts by ≈ 0.9 per trial (over 100
    trials to 1e-10); Illinois halves a kept end on either side and converges superlinearly.
    Bound: 25 trials (a generous multiple of the ~12 an order-1.4 method needs from the first
    ratio 0.3). The zero to the bracket width asked (1e-10) plus the last step's."""
    correct, calls = _on_branch()
    t = np.array([1.0, 1.0]) / np.sqrt(2.0)
    a = Point(np.zeros(2), None, {})
    pt = locate(correct, a, t, 1.0, lambda q: float(np.exp(-8.0 * q.y[-1]) - 0.3), 1e-10)
    assert pt is not None
    assert abs(pt.y[-1] - np.log(10.0 / 3.0) / 8.0) <= 2e-10
    assert len(calls) <= 25


def test_the_mirror_case_is_located_as_well():
    """The same function seen from the far side (``p = 1/√2`` going down, ``f < 0`` there):
    the chords' zeros now fall short of the zero, on the start's side."""
    correct, calls = _on_branch()
    t = -np.array([1.0, 1.0]) / np.sqrt(2.0)
    start = 1.0 / np.sqrt(2.0)
    a = Point(np.array([start, start]), None, {})
    pt = locate(correct, a, t, 0.5, lambda q: float(np.exp(-8.0 * q.y[-1]) - 0.3), 1e-10)
    assert pt is not None
    assert abs(pt.y[-1] - np.log(10.0 / 3.0) / 8.0) <= 2e-10
    assert len(calls) <= 25
