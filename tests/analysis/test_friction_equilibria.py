"""Chapter 7 predictions: GES condition, stuck equilibria (Proposition B), the equilibrium
set's half-width and the chapter-8 Lur'e form of the loop (check 10)."""

import numpy as np
import pytest

from nscontrol.analysis.friction_equilibria import (
    closed_loop_lure_form,
    equilibrium_halfwidth,
    exact_compensation_condition,
    limit_cycle_summary,
    lure_form_certificate,
    stick_equilibria,
    stick_margin,
)
from nscontrol.design.friction_compensation import compensation_model
from nscontrol.errors import ModelError
from nscontrol.laws import Stribeck

J, KP, KD, L = 0.05, 2.0, 0.3, 150.0
F = Stribeck(0.4, 0.2, 0.05, 2.0, 0.02)
SIGMA_TAN, SIGMA_SEC = float(F.sigma_tan[0]), float(F.sigma_sec[0])


def test_exact_compensation_condition_of_the_reference_example():
    c = exact_compensation_condition(J, L, F)
    assert c.sufficient and c.necessary
    assert c.error_rate == pytest.approx(L - SIGMA_TAN / J, rel=1e-15)
    slow = exact_compensation_condition(J, 10.0, F)      # J l = 0.5 < sigma_sec
    assert not slow.sufficient and not slow.necessary
    assert SIGMA_SEC / J == pytest.approx(50.65, abs=5e-3)    # l_necessary
    assert SIGMA_TAN / J == pytest.approx(68.22, abs=5e-3)    # l_sufficient


def test_mild_stribeck_variant_thresholds():
    mild = Stribeck(0.3, 0.2, 0.2, 2.0, 0.05)
    assert float(mild.sigma_sec[0]) / J == pytest.approx(5.4, abs=0.05)
    assert float(mild.sigma_tan[0]) / J == pytest.approx(7.6, abs=0.05)


def test_stick_equilibria_exist_for_a_slow_observer_only():
    assert stick_equilibria(J, KP, KD, L, F, F) == []
    slow = stick_equilibria(J, KP, KD, 10.0, F, F)
    assert len(slow) == 1 and 0.0 < slow[0][0] < slow[0][1]
    lo, hi = slow[0]
    # the boundaries are roots of the margin (bisection to round-off of c ~ 1e-16)
    inside = stick_margin([lo, 0.5 * (lo + hi), hi], J, KP, KD, 10.0, F, F)
    assert np.all(inside >= 0.0)
    assert stick_margin(hi * (1 + 1e-9), J, KP, KD, 10.0, F, F)[0] < 0.0


def test_halfwidth_without_compensation_is_the_closed_form():
    exact = 0.4 * (J * L + KD) / (KP * J * L)
    # bisection to round-off of the boundary (spacing of c), the grid does not matter
    assert equilibrium_halfwidth(J, KP, KD, L, F, None) == pytest.approx(exact, rel=1e-12)


@pytest.mark.parametrize("kappa", [0.5, 0.8, 0.95])
def test_halfwidth_under_compensation(kappa):
    comp = compensation_model(F, kappa)
    c = equilibrium_halfwidth(J, KP, KD, L, F, comp)
    assert stick_margin(c, J, KP, KD, L, F, comp)[0] == pytest.approx(0.0, abs=1e-12)
    # T_s_hat - sigma_sec_hat s <= f_hat(s) <= T_s_hat + b_hat s (definition of sigma_sec),
    # so g(c) is squeezed between two lines and c_max between their roots
    gap = (1 - kappa) * 0.4 * (J * L + KD) / KP
    upper = gap / (J * L - float(comp.sigma_sec[0]))
    lower = gap / (J * L + float(comp.viscous[0]))
    assert lower <= c <= upper


def test_halfwidth_vanishes_for_exact_and_over_compensation():
    for kappa in (1.0, 1.1, 1.3):
        assert equilibrium_halfwidth(J, KP, KD, L, F, compensation_model(F, kappa)) == 0.0


def test_lure_form_lmi_feasible_iff_observer_beats_the_slope():
    """Check 10: P G = H^T, A^T P + P A < 0 feasible for l = 150, not for 0.9 sigma_tan/J."""
    good = lure_form_certificate(closed_loop_lure_form(J, KP, KD, L, SIGMA_TAN))
    assert good is not None
    P = good.P
    form = closed_loop_lure_form(J, KP, KD, L, SIGMA_TAN)
    # re-checked here too: the equality to round-off of P, the inequality strictly
    assert np.linalg.norm(P @ form.G - form.H.T) <= 1e-7 * max(1.0, np.linalg.norm(P))
    assert np.max(np.linalg.eigvalsh(form.A.T @ P + P @ form.A)) < 0.0
    assert np.min(np.linalg.eigvalsh(P)) > 0.0
    slow = closed_loop_lure_form(J, KP, KD, 0.9 * SIGMA_TAN / J, SIGMA_TAN)
    assert lure_form_certificate(slow) is None


def test_limit_cycle_summary_of_a_sampled_sine():
    t = np.linspace(0.0, 10.0, 100001)
    s = limit_cycle_summary(t, 0.2 * np.sin(2 * np.pi * t), 0.4 * np.pi * np.cos(2 * np.pi * t),
                            window=5.0)
    # 1e-4 sampling of a 1 s period: the peaks are within (2 pi 1e-4)^2 / 2 relative
    assert s["amplitude"] == pytest.approx(0.2, rel=2e-7)
    assert s["period"] == pytest.approx(1.0, abs=2e-4)
    assert s["asymmetry"] < 1e-6


def test_bad_input():
    with pytest.raises(ModelError, match=r"^l"):
        exact_compensation_condition(J, -1.0, F)
    with pytest.raises(ModelError, match=r"^friction"):
        exact_compensation_condition(J, 1.0, object())
