"""Class 3: a FilippovSystem whose callables return NaN, infinity, complex or text values is
refused at construction (probed once at a generic state), not discovered mid-run.

No tolerance: finiteness is exact.
"""

from __future__ import annotations

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.systems.switched import FilippovSystem

C = np.array([1.0, 1.0])


def relay(field=None, surface=None, gradient=None, jacobian=None) -> FilippovSystem:
    """Relay feedback x1' = x2, x2' = -sign(x1 + x2), with one part replaced."""
    good = lambda t, x, s: np.array([x[1], -float(s[0])])           # noqa: E731
    return FilippovSystem(2, (surface or (lambda x: float(C @ x)),), field or good,
                          gradients=None if gradient is None else (gradient,),
                          jacobian=jacobian)


def assert_refused(call, name: str) -> str:
    with pytest.raises(ModelError) as info:
        call()
    msg = str(info.value)
    assert msg.startswith(name), msg
    assert "finite" in msg or "expected" in msg, msg
    return msg


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_field_non_finite_everywhere(bad):
    msg = assert_refused(lambda: relay(field=lambda t, x, s: np.array([bad, 1.0])), "field")
    assert "signs" in msg and "guard" in msg


def test_field_nan_on_one_side_only():
    def field(t, x, s):
        return np.array([x[1], np.nan if s[0] < 0 else 1.0])

    msg = assert_refused(lambda: relay(field=field), "field")
    assert "signs = (-1,)" in msg


def test_field_nan_for_one_of_several_surfaces_patterns():
    def field(t, x, s):
        return np.array([x[1], np.nan if s == (1, -1) else -1.0])

    with pytest.raises(ModelError, match=r"signs = \(1, -1\)"):
        FilippovSystem(2, (lambda x: x[0], lambda x: x[1]), field)


def test_field_complex_or_text_refused():
    assert_refused(lambda: relay(field=lambda t, x, s: np.array([1j, 0.0])), "field")
    assert_refused(lambda: relay(field=lambda t, x, s: ["0.5", "1"]), "field")


def test_surface_gradient_jacobian_non_finite():
    assert_refused(lambda: relay(surface=lambda x: np.nan), "surfaces[0]")
    assert_refused(lambda: relay(gradient=lambda x: np.array([np.inf, 1.0])), "gradients[0]")
    assert_refused(lambda: relay(jacobian=lambda t, x, s: np.full((2, 2), np.nan)),
                   "jacobian")


def test_field_singular_only_at_the_origin_accepted():
    """x/|x| is NaN at 0 only: the probe uses a generic state, so it is not refused."""
    sys = relay(field=lambda t, x, s: -float(s[0]) * x / np.linalg.norm(x))
    assert sys.n_surfaces == 1
