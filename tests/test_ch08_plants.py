"""Chapter 8: plants given in other forms — non-monotone Stribeck friction through the loop
transformation (spec §2.6, example 5.7), python-control StateSpace — and their bad input."""

from types import SimpleNamespace

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.design.lure_observer import (
    design_lure_observer,
    loop_transformed_lure_system,
    lure_from_statespace,
    max_decay_rate,
)
from nscontrol.errors import DimensionError, ModelError
from nscontrol.examples import ch08_lure_observer as ex
from nscontrol.laws.set_valued import Relay, Stribeck


def _stribeck():
    p = ex.ROTOR
    return Stribeck(static=p["T_s"], coulomb=p["T_c"], stribeck_velocity=p["omega_s"],
                    delta=p["delta"], viscous=p["b"])


def _untransformed_rotor():
    s = ex.rotor_standin("alpha")
    A0 = s.A.copy()
    A0[2, 2] = 0.0  # the lower disc's own dynamics carry no linear friction term
    return s, A0


def test_non_monotone_law_without_transformation_is_refused():
    s, A0 = _untransformed_rotor()
    plant = SimpleNamespace(A=A0, G=s.G, H=s.H, C=s.C, D=None, law=_stribeck())
    with pytest.raises(ModelError, match="loop_transformation"):
        design_lure_observer(plant)


def test_loop_transformation_reproduces_the_spec_matrix_and_designs():
    s, A0 = _untransformed_rotor()
    law = _stribeck()
    assert law.sigma_tan[0] == pytest.approx(ex.ROTOR["sigma"], abs=1e-6)
    plant = loop_transformed_lure_system(A0, s.G, s.H, law, B=s.B, C=s.C, u=s.u)
    np.testing.assert_allclose(plant.A, s.A, atol=1e-5)
    assert plant.law.monotone
    # the same design through a duck-typed plant holding the non-monotone law
    raw = SimpleNamespace(A=A0, G=s.G, H=s.H, C=s.C, D=None, law=law)
    d = design_lure_observer(raw, kappa=1000.0, tol=1e-2,
                             loop_transformation=law.loop_transformation())
    assert d.loop_sigma == pytest.approx(law.sigma_tan[0])
    np.testing.assert_allclose(d.A, plant.A, atol=1e-12)
    assert 3.5 < d.alpha_max < 4.5  # spec 5.7: about 4 with ||Y|| <= 1000


def test_rotor_observer_obeys_discrete_lyapunov_bound():
    s = ex.rotor_standin("alpha")
    plant = s.plant()
    d = design_lure_observer(plant, kappa=100.0, tol=1e-2)
    h = 0.02
    traj = simulate(d.closed_loop(plant), np.r_[s.x0, s.xhat0], (0.0, 4.0), h=h,
                    progress=False)
    V = d.lyapunov(traj.signal("y"))
    bound = V[:-1] / (1 + 2 * d.alpha * h) * (1 + 1e-9) + 1e-14 * V[0]
    assert np.all(V[1:] <= bound)
    assert V[-1] < 1e-6 * V[0]
    assert np.any(np.abs(traj.x[:, 2]) > 0.1)  # the lower disc slips: not only sticking


@pytest.mark.parametrize(("output", "variant"), [("omega_u", "extended"), ("alpha", "basic"),
                                                 ("both", "basic")])
def test_rotor_infeasible_cases_of_the_spec(output, variant):
    from nscontrol.errors import InfeasibleDesignError

    s = ex.rotor_standin(output)
    with pytest.raises(InfeasibleDesignError, match="structural"):
        max_decay_rate(**s.matrices, variant=variant, kappa=1000.0)


def test_statespace_plant_gives_the_same_design():
    control = pytest.importorskip("control")
    s = ex.coulomb_oscillator(0.1)
    ss = control.ss(s.A, np.hstack([s.G, s.B]), np.vstack([s.H, s.C]), np.zeros((2, 2)))
    plant = lure_from_statespace(ss, Relay(1.0), u=s.u)
    for name in ("A", "G", "H", "C", "B"):
        np.testing.assert_array_equal(getattr(plant, name), getattr(s, name))
    d = design_lure_observer(plant, variant="basic", tol=5e-3)
    assert abs(d.alpha_max - 0.1) <= 0.002


def test_statespace_bad_input():
    control = pytest.importorskip("control")
    s = ex.coulomb_oscillator(0.1)
    with pytest.raises(ModelError, match="continuous-time"):
        lure_from_statespace(control.ss(s.A, s.G, s.C, 0, dt=0.1), Relay(1.0))
    with pytest.raises(DimensionError):
        lure_from_statespace(control.ss(s.A, s.G, s.H, 0), Relay(1.0))
    ss = control.ss(s.A, np.hstack([s.G, s.B]), np.vstack([s.H, s.C]), [[0, 0], [0, 1.0]])
    with pytest.raises(ModelError, match="feedthrough"):
        lure_from_statespace(ss, Relay(1.0))
