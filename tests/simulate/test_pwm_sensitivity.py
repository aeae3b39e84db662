"""PWM sensitivities (``method="switching"``, ``sensitivity=True``): the transition through
switching instants that move with the sampled state, against central differences and a
closed-form stroboscopic map of a buck converter; a period-1 orbit and its multipliers."""

import warnings

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq

from nscontrol import simulate
from nscontrol.analysis.orbits import Forced, find_orbit
from nscontrol.errors import NscontrolWarning
from nscontrol.simulate.switching._pwm import _OFFSET_RATES
from nscontrol.systems.switched import PWMController, SwitchedAffineSystem

EPS = np.finfo(float).eps
# normalised buck converter: L i' = E s - v, C v' = i - v/R (s = 1 in the on mode)
A = np.array([[0.0, -1.0], [1.0, -0.5]])
B_ON = np.array([1.0, 0.0])
T = 0.5
GAIN = np.array([-0.3, -0.8])          # d = T (0.5 + GAIN·(x - (0, 0.4))): proportional


def proportional_duty(t, x):
    return T * (0.5 + GAIN[0] * x[0] + GAIN[1] * (x[1] - 0.4))


def saturated_duty(t, x):
    return T * (3.0 + 0.1 * x[1])            # always above T: clipped to the whole period


def _buck(duty, pattern="leading"):
    return SwitchedAffineSystem(((A, [0.0, 0.0]), (A, B_ON)),
                                PWMController(T, duty, pattern=pattern))


def _central_differences(system, x0, tf, delta=1e-6):
    def P(x):
        return simulate(system, x, (0.0, tf), t_eval=[0.0, tf]).x[-1]
    return np.column_stack([(P(x0 + delta * e) - P(x0 - delta * e)) / (2 * delta)
                            for e in np.eye(x0.shape[0])])


@pytest.mark.parametrize("pattern", ["leading", "centered", "trailing"])
def test_monodromy_matches_central_differences(pattern):
    # the map over 5 periods is smooth in x0 while no duty saturates: the central difference
    # errs by O(δ²)·|P'''| (δ = 1e-6: ~1e-12 for this unit-scale map) plus rounding
    # ~ ε|x|/δ ≈ 1e-10 (the run's instants and flows are exact to rounding), so 1e-6 holds
    # with a wide margin
    system = _buck(proportional_duty, pattern)
    x0, tf = np.array([0.3, 0.35]), 5 * T
    tr = simulate(system, x0, (0.0, tf), sensitivity=True)
    assert np.all((tr.stats["duty"] > 0) & (tr.stats["duty"] < T))
    J = tr.stats["state_transition"]
    assert np.max(np.abs(J - _central_differences(system, x0, tf))) <= 1e-6
    assert tr.stats["saltation_matrices"].shape == (0, 2, 2)   # S = I at every instant
    assert tr.stats["degenerate_periods"] == 0


def test_a_saturated_duty_has_no_switching_time_dependence():
    # the duty is clipped to T in every period: the instants do not move, the transition is
    # the flow's alone, e^{5AT}; the product of five e^{AT} rounds by ~5 ε |e^{AT}|
    system = _buck(saturated_duty)
    x0, tf = np.array([0.3, 0.35]), 5 * T
    tr = simulate(system, x0, (0.0, tf), sensitivity=True)
    assert np.all(tr.stats["duty"] == T)
    J = tr.stats["state_transition"]
    np.testing.assert_allclose(J, expm(5 * T * A), rtol=0, atol=50 * EPS)
    assert np.max(np.abs(J - _central_differences(system, x0, tf))) <= 1e-6


def test_duty_exactly_on_a_bound_is_reported_as_a_corner():
    # a duty law that reaches exactly T at x0 = (0, 0.4) and would vary there: the clipped law
    # has a corner, its one-sided derivatives differ (0 and ∇d)
    def at_bound(t, x):
        return T * (1.0 - 0.8 * (x[1] - 0.4))

    system = _buck(at_bound)
    with pytest.warns(NscontrolWarning, match="corner of the clipped duty law"):
        tr = simulate(system, [0.0, 0.4], (0.0, T), sensitivity=True)
    assert tr.stats["degenerate_periods"] == 1
    with warnings.catch_warnings():   # a constant duty on a bound is no corner
        warnings.simplefilter("error")
        simulate(_buck(lambda t, x: T), [0.0, 0.4], (0.0, T), sensitivity=True)


@pytest.mark.parametrize("pattern", sorted(_OFFSET_RATES))
def test_offset_rates_are_the_derivatives_of_the_controllers_offsets(pattern):
    # offsets are affine in d: a central difference is exact up to rounding ε T / δ
    ctrl = PWMController(T, proportional_duty, pattern=pattern)
    d, delta = 0.2, 1e-3
    hi, lo = ctrl.offsets(d + delta), ctrl.offsets(d - delta)
    rates = [(a[0] - b[0]) / (2 * delta) for a, b in zip(hi, lo, strict=True)]
    np.testing.assert_allclose(rates, _OFFSET_RATES[pattern], rtol=0, atol=16 * EPS * T / delta)


def _closed_form_orbit():
    """Leading-edge buck (both modes share A): one period maps x to
    ``e^{AT} x + e^{A(T-d)} Ψ(d) b`` with ``Ψ(d) = ∫_0^d e^{As} ds``. The fixed point for a
    duty d is ``x*(d) = (I - e^{AT})⁻¹ e^{A(T-d)} Ψ(d) b``; d solves ``duty(x*(d)) = d``
    (a scalar root). The map's Jacobian is ``e^{AT} + e^{A(T-d)} b ∇dᵀ``."""
    def psi(d):
        M = np.zeros((4, 4))
        M[:2, :2], M[:2, 2:] = A, np.eye(2)
        return expm(M * d)[:2, 2:]

    def fixed_point(d):
        return np.linalg.solve(np.eye(2) - expm(A * T), expm(A * (T - d)) @ psi(d) @ B_ON)

    d = brentq(lambda d: proportional_duty(0.0, fixed_point(d)) - d, 1e-9, T - 1e-9,
               xtol=1e-15)
    jac = expm(A * T) + np.outer(expm(A * (T - d)) @ B_ON, T * GAIN)
    return fixed_point(d), np.linalg.eigvals(jac)


def test_period_one_orbit_and_multipliers_match_the_closed_form():
    x_star, mu_star = _closed_form_orbit()
    orbit = find_orbit(Forced(_buck(proportional_duty), None, T, method="switching"),
                       [0.0, 0.0])
    # Newton's residual 1e-11 through a contracting map (|μ| < 1): x within ~1e-11/(1 - |μ|)
    assert np.max(np.abs(orbit.x0 - x_star)) <= 1e-10
    # the duty gradient is a central difference of an affine law: rounding ε|d|/δ with
    # δ = 1e-7, ~1e-9 relative, carried into the multipliers by the eigenvalue condition
    # (well-separated eigenvalues: order 1)
    order = np.argsort(np.angle(mu_star))
    got = orbit.multipliers[np.argsort(np.angle(orbit.multipliers))]
    assert np.max(np.abs(got - mu_star[order])) <= 1e-8
    assert orbit.stable
