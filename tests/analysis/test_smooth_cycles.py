"""Limit cycles of smooth autonomous flows (NonlinearSystem, DOP853 + variational equation):
polar normal forms with exact cycles, Van der Pol against its Poincaré–Lindstedt series and
against an independent SciPy reference, and continuation of the Hopf normal form's cycle."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from nscontrol.analysis import Autonomous, continue_orbit, find_cycle
from nscontrol.errors import DimensionError, ModelError
from nscontrol.testing.cycle_problems import (
    hopf_normal_form,
    polar_normal_form,
    van_der_pol,
    van_der_pol_series,
)

RTOL = 1e-11        # the switching method's default DOP853 tolerance
# DOP853 keeps every local error below rtol·|y|; over one period (tens to a few hundred steps
# of a flow that at most multiplies errors by the multiplier) the global error of the state
# and of the variational equation stays below K·rtol·max(1, |μ|), K = 100.
K = 100
INTEGRATION = K * RTOL


@pytest.mark.parametrize("which", [0, 1], ids=["r=1 stable", "r=2 unstable"])
def test_polar_normal_form_cycles_are_exact(which):
    omega = 4.0
    system, cycles = polar_normal_form(omega=omega)      # r' = r(1 - r)(2 - r), θ' = ω
    known = cycles[which]
    r = known.x0[0]
    assert known.period == 2 * np.pi / omega
    assert known.multiplier == pytest.approx(np.exp((-2 * np.pi if r == 1 else 4 * np.pi)
                                                    / omega), rel=4 * np.finfo(float).eps)
    # start 1 % off in radius (for r = 2, inside: outside, r' ~ r³ blows up within a period)
    guess = known.x0 * (1.0 - 0.01 * (-1) ** which)
    cyc = find_cycle(system, guess, 1.02 * known.period, normal=known.normal, offset=0.0,
                     tol=10 * RTOL)
    mu = known.multiplier
    # the radius is the fixed point of the radial return map: an error e of the map moves it
    # by e/|1 - μ|; e <= the integration error plus Newton's stopping residual 10·rtol
    assert abs(np.hypot(*cyc.x0) - r) <= (INTEGRATION + 10 * RTOL) * r / abs(1 - mu)
    # θ' = ω: the period is the time to turn by 2π, off by the phase's integration error
    assert abs(cyc.period - known.period) <= INTEGRATION * known.period
    # the monodromy carries the variational equation's relative error K·rtol
    assert abs(cyc.nontrivial[0] - mu) <= INTEGRATION * max(1.0, abs(mu))
    assert abs(cyc.multipliers[cyc.trivial_index] - 1.0) <= INTEGRATION * max(1.0, abs(mu))
    assert cyc.stable == (which == 0) and cyc.signature == ()


@pytest.mark.parametrize("eps", [0.05, 0.1])
def test_van_der_pol_small_eps_against_the_poincare_lindstedt_series(eps):
    series = van_der_pol_series(eps)
    cyc = find_cycle(van_der_pol(eps), [series["amplitude"], 0.0], series["period"],
                     normal=[0.0, 1.0], offset=0.0, tol=10 * RTOL)
    mu = cyc.nontrivial[0].real
    # on v = 0 the cycle is at its maximum: x0 = (x_max, 0). Series remainders (module
    # docstring of cycle_problems): amplitude O(ε⁴) with coefficient 1033/552960 < 1/500,
    # bounded by ε⁴/100; period O(ε⁶), multiplier's log O(ε⁵), their coefficients bounded by 1
    # (the series' coefficients 1/16, 5/3072 and 2π, π/4 decrease); plus integration error
    assert abs(cyc.x0[0] - series["amplitude"]) <= eps ** 4 / 100 + INTEGRATION
    assert abs(cyc.period - series["period"]) <= eps ** 6 + INTEGRATION * cyc.period
    assert abs(np.log(mu) - series["log_multiplier"]) <= eps ** 5 + INTEGRATION
    # averaging's exp(-2πε): off by the expansion's next term, ln μ + 2πε = -(π/4)ε³ + O(ε⁵)
    averaging_error = np.log(mu / series["averaging_multiplier"])
    assert abs(averaging_error + np.pi / 4 * eps ** 3) <= eps ** 5 + INTEGRATION
    assert cyc.stable and abs(cyc.multipliers[cyc.trivial_index] - 1.0) <= INTEGRATION


def test_van_der_pol_multiplier_is_liouvilles_integral_of_the_divergence():
    # planar flow: det M = exp(∮ div f dt) exactly, div f = ε(1 - x²) — no expansion involved
    eps = 0.1
    system = van_der_pol(eps)
    series = van_der_pol_series(eps)
    cyc = find_cycle(system, [series["amplitude"], 0.0], series["period"],
                     normal=[0.0, 1.0], tol=10 * RTOL)
    from nscontrol import simulate

    n = 64
    t = np.linspace(0.0, cyc.period, n + 1)
    x = simulate(system, cyc.x0, (0.0, cyc.period), t_eval=t).x[:, 0]
    # trapezoidal rule on a periodic analytic integrand: exact for harmonics below n, and the
    # harmonics of x² at order 64 are O(ε^30) — the quadrature error is below rounding
    integral = eps * cyc.period / n * np.sum(1.0 - x[:-1] ** 2)
    # samples off by K·rtol·|x| (|x| <= 2.01): the integrand by 2|x|·that, times ε·T
    tol = INTEGRATION + eps * cyc.period * 4.02 * 2.01 * INTEGRATION
    assert abs(np.log(cyc.nontrivial[0].real) - integral) <= tol


def _reference_cycle(eps, rtol=1e-13):
    """SciPy-only reference: the return map to v = 0 (x > 0, downwards) by solve_ivp with
    event location, its fixed point by brentq, the monodromy by central differences of the
    flow at the fixed period."""
    def f(t, y):
        return [y[1], -y[0] + eps * (1 - y[0] ** 2) * y[1]]

    def down(t, y):
        return y[1]

    down.direction = -1

    def ret(a):
        sol = solve_ivp(f, (0.0, 20.0), [a, 0.0], method="DOP853", rtol=rtol, atol=rtol,
                        events=down)
        k = np.flatnonzero(sol.t_events[0] > 1.0)[0]       # not the start on the section
        return sol.y_events[0][k][0], float(sol.t_events[0][k])

    a = brentq(lambda a: ret(a)[0] - a, 1.5, 2.5, xtol=1e-14, rtol=4 * np.finfo(float).eps)
    T = ret(a)[1]
    x0 = np.array([a, 0.0])

    def flow(y0):
        return solve_ivp(f, (0.0, T), y0, method="DOP853", rtol=rtol, atol=rtol).y[:, -1]

    h = rtol ** (1 / 3)       # central differences: truncation h²|φ'''| ~ rounding rtol/h
    M = np.column_stack([(flow(x0 + h * e) - flow(x0 - h * e)) / (2 * h) for e in np.eye(2)])
    return x0, T, M, h


def test_van_der_pol_moderate_eps_against_an_independent_scipy_reference():
    eps = 1.0
    x_ref, T_ref, M_ref, h = _reference_cycle(eps)
    cyc = find_cycle(van_der_pol(eps), [2.0, 0.0], 6.6, normal=[0.0, 1.0], offset=0.0,
                     tol=10 * RTOL)
    # both are DOP853 runs: ours at rtol 1e-11 (error K·rtol), the reference at 1e-13 with its
    # event and brentq located to rounding; the cycle point's error is amplified by
    # 1/|1 - μ| ~ 1 (μ ~ 0.001 at ε = 1)
    assert abs(cyc.period - T_ref) <= INTEGRATION * T_ref
    assert np.max(np.abs(cyc.x0 - x_ref)) <= 2 * INTEGRATION
    # the difference monodromy has error h²|φ'''|/6 + rtol_ref/h ~ 2·(1e-13)^{2/3} ≈ 4e-9
    # times |φ'''| and |M| of order 10 here: 1e-7 absolute bounds both
    fd_error = 1e-7
    assert np.max(np.abs(cyc.monodromy - M_ref)) <= fd_error + INTEGRATION
    mu_ref = np.linalg.det(M_ref)            # the trivial multiplier is 1: det M = μ
    assert abs(cyc.nontrivial[0].real - mu_ref) <= 2 * fd_error * np.max(np.abs(M_ref))


def test_hopf_cycle_is_continued_in_mu():
    omega = 2.0

    def factory(mu):
        system, _ = hopf_normal_form(mu, omega)
        return Autonomous(system, 1.01 * 2 * np.pi / omega, normal=[0.0, 1.0], offset=0.0)

    T = 2 * np.pi / omega
    # the start gives the state alone: the factory's period is the guess of T
    branch = continue_orbit(factory, 0.25, [0.51, 0.0], p_range=(0.1, 1.0),
                            step=0.05, step_max=0.2, parameter_name="mu")
    assert branch.stop_reason.startswith("left p_range") and branch.points == ()
    mu = branch.p
    assert len(branch) >= 5 and mu.min() <= 0.25 and mu.max() > 1.0
    assert branch.nodes.shape == (len(branch), 1, 3)   # the unknowns (x, y, T)
    assert branch.multipliers.shape == (len(branch), 1)  # the trivial multiplier left out
    # corrector tolerance 1e-10·max(1, |X|) = 1e-10·T on the residual; the bordered
    # Jacobian's inverse is bounded by 1/min(|1 - μ_mult|, ω√μ) <= 1/0.47 on μ >= 0.1
    res = 1e-10 * T + INTEGRATION
    err = res / 0.47
    assert np.max(np.abs(branch.x0[:, 0] - np.sqrt(mu))) <= err
    assert np.max(np.abs(branch.period - T)) <= err
    # the multiplier exp(∮(μ - 3r²)dt) = exp(-4πμ/ω), shifted by the radius error through
    # ∂/∂r of the exponent, 6 r T
    expected = np.exp(-4 * np.pi * mu / omega)
    rel = np.abs(branch.multipliers[:, 0].real / expected - 1.0)
    assert np.max(rel) <= INTEGRATION + 6 * np.sqrt(mu.max()) * T * err
    assert branch.stable.all()


def test_a_cycle_is_continued_from_one_node_only():
    system, _ = hopf_normal_form(0.25, 2.0)

    def factory(mu):
        return Autonomous(system, np.pi, normal=[0.0, 1.0])

    with pytest.raises(ModelError, match=r"n_periods: a cycle is shot from one node"):
        continue_orbit(factory, 0.25, [0.5, 0.0], p_range=(0.1, 1.0), n_periods=2)
    with pytest.raises(DimensionError, match=r"x0"):
        continue_orbit(factory, 0.25, [0.5, 0.0, np.pi, 1.0], p_range=(0.1, 1.0))
    with pytest.raises(DimensionError, match=r"normal"):
        Autonomous(system, np.pi, normal=[0.0, 1.0, 0.0])
