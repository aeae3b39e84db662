"""The finite-element beam builder: reduced static flexibility at the midpoint, modal
frequencies against closed forms and against a larger basis, bad input refused."""

import numpy as np
import pytest

from nscontrol.errors import ModelError
from nscontrol.systems.beam import beam_fe_model

GEOM = dict(L=1.6, E=2.1e11, rho=7850.0, b=0.05, t=0.01)
EPS = np.finfo(float).eps


def _flexibility(model):
    h = model.support.h
    return float(h @ np.linalg.solve(model.K, h))


def test_reduced_static_flexibility_is_the_full_one():
    model = beam_fe_model(**GEOM, k_leaf=1e5, m_motor=1.0, k_s=1e6)
    EI = GEOM["E"] * GEOM["b"] * GEOM["t"] ** 3 / 12
    # midpoint load: rigid translation on the two leaf springs plus the simply supported
    # beam's L³/48EI; Hermite elements are exact for nodal loads, the reduction keeps the
    # static deflection in its basis: equal up to the roundoff of solves with κ(K) ~ 1e9
    exact = 1 / (2 * 1e5) + GEOM["L"] ** 3 / (48 * EI)
    assert _flexibility(model) == pytest.approx(exact, rel=1e-10)


def test_first_frequency_of_a_pinned_beam():
    # stiff end springs, no motor: the first bending mode of a pinned-pinned beam,
    # f1 = (π / 2L²) √(EI/ρA); 20 cubic elements are within 1e-6 of it (h⁴ convergence),
    # the springs (1e12 N/m against EI/L³ ~ 2e5) shift it by ~1e-7
    model = beam_fe_model(**GEOM, k_leaf=1e12, m_motor=0.0, k_s=1e6, n_modes=1)
    EI = GEOM["E"] * GEOM["b"] * GEOM["t"] ** 3 / 12
    rhoA = GEOM["rho"] * GEOM["b"] * GEOM["t"]
    f1 = np.pi / (2 * GEOM["L"] ** 2) * np.sqrt(EI / rhoA)
    assert model.frequencies(contact=False)[0][0] == pytest.approx(f1, rel=1e-5)


def test_reduced_frequencies_match_a_larger_basis():
    small = beam_fe_model(**GEOM, k_leaf=1e5, m_motor=1.0, k_s=1e6, n_modes=2)
    large = beam_fe_model(**GEOM, k_leaf=1e5, m_motor=1.0, k_s=1e6, n_modes=10)
    f_small, f_large = small.frequencies(False)[0], large.frequencies(False)[0]
    # the kept modes are exact eigenvectors of the full model, present in both bases: their
    # frequencies agree to the eigensolver's roundoff (1e-8 leaves κ-amplified room)
    assert np.allclose(f_small[:2], f_large[:2], rtol=1e-8)
    # with the support engaged the static correction carries the support's flexibility:
    # the lowest contact frequency within 0.5 % of the 10-mode model (measured 3.6e-5; the
    # second, 84.35 against 83.86 Hz, is off by 0.6 %: two modes are too few for it)
    c_small, c_large = small.frequencies(True)[0], large.frequencies(True)[0]
    assert c_small[0] == pytest.approx(c_large[0], rel=5e-3)
    assert np.allclose(small.M, small.M.T, rtol=0, atol=16 * EPS * np.abs(small.M).max())


@pytest.mark.parametrize("kwargs, word", [
    ({"n_el": 7}, "n_el"), ({"n_el": 1}, "n_el"), ({"n_modes": 0}, "n_modes"),
    ({"n_modes": 40}, "n_modes"), ({"L": -1.0}, "L"), ({"k_s": 0.0}, "k_s"),
    ({"m_motor": -1.0}, "m_motor"), ({"zeta": -0.1}, "zeta")])
def test_bad_builder_arguments_are_refused(kwargs, word):
    args = {**GEOM, "k_leaf": 1e5, "m_motor": 1.0, "k_s": 1e6, **kwargs}
    with pytest.raises(ModelError, match=word):
        beam_fe_model(**args)
