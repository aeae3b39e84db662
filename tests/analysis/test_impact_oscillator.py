"""Closed-form period-1 orbits of the impact oscillator against shooting and simulation."""

import numpy as np
import pytest

from nscontrol.analysis.impact_oscillator import ImpactOscillator, OscillatorFamily
from nscontrol.analysis.orbits import find_orbit, stroboscopic_map
from nscontrol.errors import ModelError

EPS = np.finfo(float).eps
BASE = ImpactOscillator(omega=2.5, stop=0.1)       # grazing F_g = 0.5256, flip F_f = 1.283


def test_grazing_forcing_is_d_times_the_dynamic_stiffness():
    osc = ImpactOscillator(mass=2.0, damping=0.3, stiffness=5.0, omega=1.2, stop=0.4)
    expected = 0.4 * np.hypot(5.0 - 2.0 * 1.2 ** 2, 0.3 * 1.2)
    # one hypot and one product: a few ulps
    assert osc.grazing_forcing() == pytest.approx(expected, rel=4 * EPS)
    # at F_g the non-impacting steady state's amplitude is the stop
    assert osc.with_(forcing=osc.grazing_forcing()).amplitude() == pytest.approx(0.4,
                                                                                 rel=8 * EPS)


def test_closed_form_orbit_is_a_fixed_point_of_the_simulated_map():
    osc = BASE.with_(forcing=3 * BASE.grazing_forcing())
    cf = osc.admissible_orbit()
    assert cf.admissible and cf.impact_velocity > 0 and cf.stable
    m = stroboscopic_map(osc.forced(), cf.x0)
    # one period of exact flows and one impact: error ~ (few flow products)·eps·|Φ|·|x|;
    # |Φ(T)| < 5 here, 100 covers the products and the event time's Newton polish
    assert np.max(np.abs(m.x - cf.x0)) <= 100 * EPS * 5 * max(1.0, np.max(np.abs(cf.x0)))
    assert m.signature == (("impact", 0),)


def test_shooting_matches_closed_form_orbit_and_multipliers():
    osc = BASE.with_(forcing=3 * BASE.grazing_forcing())
    cf = osc.admissible_orbit()
    orb = find_orbit(osc.forced(), cf.x0 + [1e-3, -1e-3])
    kappa = np.linalg.cond(np.eye(2) - cf.monodromy)
    # Newton's fixed point is off by cond(I - M) times the map's rounding (bound above)
    assert np.max(np.abs(orb.x0 - cf.x0)) <= kappa * 500 * EPS
    # eigenvalues (Bauer-Fike): |δμ| <= cond(V)·|δM|; the monodromy at the shooting fixed
    # point differs from the closed form's through δx (above) times |∂M/∂x| ~ |M|
    _, V = np.linalg.eig(cf.monodromy)
    dM = np.linalg.norm(cf.monodromy) * kappa * 500 * EPS
    assert np.max(np.abs(orb.multipliers - cf.multipliers)) <= np.linalg.cond(V) * dM
    # det M = r² e^{-cT/m} exactly (Liouville + det S = r²)
    T = osc.period
    assert np.prod(orb.multipliers).real == pytest.approx(0.8 ** 2 * np.exp(-0.1 * T),
                                                          rel=1e-12)


def test_saltation_monodromy_matches_finite_differences_of_the_flow():
    """Impact with restitution: the Jacobian from flows and saltation matrices vs central
    differences of the simulated map."""
    osc = BASE.with_(forcing=2.0)
    x0 = osc.admissible_orbit().x0
    f = osc.forced()
    J = stroboscopic_map(f, x0).jacobian
    h = 1e-5
    fd = np.column_stack([(stroboscopic_map(f, x0 + h * e).x - stroboscopic_map(f, x0 - h * e).x)
                          / (2 * h) for e in np.eye(2)])
    # central differences: h²/6·|P'''| + eps|P|/h; |P'''| <= 1e3 for an impact speed ~1
    # (derivatives of the impact time grow like 1/v^k) -> 1.7e-7 + 1e-11 < 1e-6
    assert np.max(np.abs(J - fd)) <= 1e-6 * max(1.0, np.max(np.abs(J)))


def test_non_impacting_orbit_and_its_grazing_distance():
    osc = BASE.with_(forcing=0.5 * BASE.grazing_forcing())
    orb = find_orbit(osc.forced(), [0.0, 0.0])
    assert orb.signature == ()
    # linear steady state, shooting from zeros: cond(I - Φ(T))·eps scale
    kappa = np.linalg.cond(np.eye(2) - osc.homogeneous_flow(osc.period))
    assert np.max(np.abs(orb.x0 - osc.non_impacting_state(0.0))) <= 100 * kappa * EPS
    # smallest gap d - A, refined by Newton on the exact flow: rounding of A ~ 0.05
    assert orb.min_gap == pytest.approx(osc.stop - osc.amplitude(), abs=100 * EPS)


def test_fold_of_the_closed_form_pair_and_refusals():
    assert BASE.with_(forcing=0.9 * BASE.grazing_forcing()).one_impact_orbits()[0].admissible \
        is False
    with pytest.raises(ModelError, match="forcing"):
        BASE.with_(forcing=0.5 * BASE.grazing_forcing()).admissible_orbit()
    with pytest.raises(ModelError, match="restitution"):
        ImpactOscillator(restitution=0.0)
    with pytest.raises(ModelError, match="parameter"):
        OscillatorFamily(BASE, "nonsense")


def test_flip_forcing_is_where_a_closed_form_multiplier_is_minus_one():
    F = BASE.flip_forcing((1.1 * BASE.grazing_forcing(), 4 * BASE.grazing_forcing()))
    mu = BASE.with_(forcing=F).admissible_orbit().multipliers
    # Brent to a few ulps of F; dμ/dF ~ O(10) here
    assert np.min(np.abs(mu + 1.0)) <= 1e-12
