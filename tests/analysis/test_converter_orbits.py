"""Brute-force diagrams of the ZAD buck against k_s: the flip seen by iteration agrees with
the bisected boundary (check 6), it is a flip (check 7), saturation is handled (check 10)."""

import numpy as np
import pytest

from nscontrol.analysis import (
    brute_force_flip,
    duty_diagram,
    duty_period,
    mean_error_against_period,
    multiplier_branch,
)
from nscontrol.design import ZADController, critical_ks
from nscontrol.systems import BuckConverter

DELTA, T, XREF = 0.35, 0.18, 0.8
LEVELS = [(-1.0, 1.0), (0.0, 1.0)]


@pytest.mark.parametrize("levels", LEVELS)
def test_check6_brute_force_flip_agrees_with_the_bisection(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    kc = critical_ks(buck, T=T, x_ref=XREF)
    ks = np.round(np.arange(round(kc, 2) - 0.1, round(kc, 2) + 0.1, 0.005), 6)
    dd = duty_diagram(buck, ks, T=T, x_ref=XREF, n_transient=40_000, n_record=128)
    # the transients decay like |λ_fast|^n with 1 + λ_fast ≈ 2T(k_s - k_s,c)/k_s² per unit
    # of k_s: 40 000 periods resolve the boundary to a few grid steps (acceptance 0.01;
    # measured 0.001 for u ∈ {-1, 1}, 0.004 for {0, 1})
    assert abs(brute_force_flip(dd) - kc) <= 0.01
    assert dd.period[-1] == 1 and dd.period[0] != 1


@pytest.mark.parametrize("levels", LEVELS)
def test_check7_the_one_period_orbit_loses_stability_by_a_flip(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    kc = critical_ks(buck, T=T, x_ref=XREF)
    lam, _ = multiplier_branch(buck, np.linspace(8.0, kc + 0.01, 60), T=T, x_ref=XREF)
    # real multipliers: the imaginary parts are exactly 0 from numpy's real-eigenvalue branch
    assert np.all(lam.imag == 0.0)
    assert np.all(np.abs(lam.real) < 1.0)
    below, _ = multiplier_branch(buck, [kc - 0.01], T=T, x_ref=XREF)
    assert below[0, 0].real < -1.0 < 0.0 < below[0, 1].real < 1.0   # the negative one leaves
    # just below the flip the iteration settles on a 2T orbit around x* (P² fixed, P not):
    # its multiplier ≈ 1 - 2(λ_fast² - 1) ≈ 1 - 1.4e-4 at 0.002 below, so 200 000 periods
    # contract the start by e^{-14}
    loop = ZADController(buck, kc - 0.002, T, XREF).loop()
    x_star = loop.fixed_point().states[0]
    X = loop.run(x_star + [1e-6, 0.0], 4, n_transient=200_000).states
    separation = np.linalg.norm(X[1] - X[0])
    assert np.linalg.norm(X[2] - X[0]) <= 1e-4 * separation        # a fixed point of P²
    assert separation > 1e-7                                        # distinct from P's
    assert np.linalg.norm(0.5 * (X[0] + X[1]) - x_star) <= separation   # born from x*


def test_check10_saturation_keeps_the_duty_in_range_and_appears_below_3_2():
    buck = BuckConverter.normalized(DELTA)
    ks = np.round(np.arange(0.1, 3.6 + 1e-9, 0.05), 6)
    # near the flip transients last ~1/(T|δ - 1/k_s|) periods: 40 000 as in check 6
    dd = duty_diagram(buck, ks, T=T, x_ref=XREF, n_transient=40_000, n_record=256)
    assert np.all(np.isfinite(dd.duty_ratios))
    assert np.all((dd.duty_ratios >= 0.0) & (dd.duty_ratios <= 1.0))   # d ∈ [0, T], exactly
    low = ks <= 3.2
    assert np.all(dd.saturated[low].any(axis=1))     # d = T occurs on every attractor there
    assert not dd.saturated[ks >= 3.3].any()


def test_duty_period_classifies_recurrences():
    d = np.tile([0.1, 0.4, 0.7, 0.2], 40)
    assert duty_period(d) == 4 and duty_period(np.arange(10.0)) == 0


def test_mean_error_against_period_is_second_order():
    err = mean_error_against_period(BuckConverter.normalized(DELTA), 5.0, [0.04, 0.02],
                                    x_ref=XREF)
    assert 3.5 <= err[0] / err[1] <= 5.0      # O(T²), O(T³) terms ±25 % (see check 8)


@pytest.mark.slow
def test_check6_full_diagram_over_the_whole_range():
    buck = BuckConverter.normalized(DELTA)
    ks = np.round(np.arange(0.05, 8.0 + 1e-9, 0.005), 6)
    dd = duty_diagram(buck, ks, T=T, x_ref=XREF, n_transient=40_000, n_record=128,
                      chunk_size=200)
    kc = critical_ks(buck, T=T, x_ref=XREF)
    assert abs(brute_force_flip(dd) - kc) <= 0.01
