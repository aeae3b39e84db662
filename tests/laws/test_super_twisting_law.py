"""The super-twisting law: its closed-form resolvent against the inclusion it solves."""

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.laws import SuperTwistingLaw, super_twisting_resolvent
from nscontrol.testing import check_system

EPS = np.finfo(float).eps


def test_resolvent_solves_the_inclusion_to_roundoff():
    rng = np.random.default_rng(3)
    x = rng.uniform(-20.0, 20.0, 400)
    a, b = rng.uniform(0.01, 5.0, 400), rng.uniform(0.0, 5.0, 400)
    z = super_twisting_resolvent(x, a, b)
    outside = np.abs(x) > b
    # z + a sqrt|z| sign z + b sign z = x: each of the three terms carries a relative
    # rounding error of a few eps, so the residual is below 8 eps times their sum.
    lhs = z + a * np.sqrt(np.abs(z)) * np.sign(z) + b * np.sign(z)
    scale = np.abs(z) + a * np.sqrt(np.abs(z)) + b + np.abs(x)
    assert np.all(np.abs(lhs - x)[outside] <= 8 * EPS * scale[outside])
    # inside the sign band the answer is exactly zero (the point of the implicit law)
    assert np.all(z[~outside] == 0.0)
    # the multiplier of the sign graph then lies in [-1, 1]
    assert np.all(np.abs(x[~outside]) <= b[~outside])


def test_resolvent_agrees_with_bisection():
    # independent: bisection on the increasing function z + a psi(z) + b sign(z) - x
    x, a, b = 7.3, 0.9, 1.2
    lo, hi = 0.0, x
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mid + a * np.sqrt(mid) + b < x else (lo, mid)
    # bisection to 200 halvings brackets the root to one ulp of x; the closed form is
    # within a few eps of it (conditioning of the quadratic is 1 for r > 0)
    assert abs(super_twisting_resolvent(x, a, b) - lo) <= 8 * EPS * x


def test_law_passes_the_contract_checks():
    check_system(SuperTwistingLaw(k1=[1.5, 0.2], k2=[2.0, 0.0]))


def test_negative_gain_refused_naming_it():
    with pytest.raises(ModelError, match="^k1: expected finite gains >= 0"):
        SuperTwistingLaw(k1=-1.0, k2=1.0)
