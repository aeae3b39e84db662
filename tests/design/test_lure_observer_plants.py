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
    max_observer_decay_rate,
)
from nscontrol.errors import DimensionError, ModelError
from nscontrol.examples import ch08_lure_observer as ex
from nscontrol.laws.set_valued import Relay, Stribeck


def _stribeck():
    p = ex.ROTOR
    return Stribeck(static=p["T_s"], coulomb=p["T_c"], stribeck_velocity=p["omega_s"],
                    delta=p["delta"], viscous=p["b"])


def test_a_plant_that_is_not_a_lure_system_is_refused_with_the_way_out():
    s = ex.rotor_standin("alpha")
    raw = SimpleNamespace(A=s.A, G=s.G, H=s.H, C=s.C, D=None, law=_stribeck())
    with pytest.raises(ModelError, match="plant: expected a .*LureSystem") as err:
        design_lure_observer(raw)
    assert "loop_transformed_lure_system" in str(err.value)
    assert "lure_from_statespace" in str(err.value)
    d = design_lure_observer(s.plant(), kappa=100.0, tol=1e-2)
    with pytest.raises(ModelError, match="plant"):  # not an AttributeError deep inside
        d.closed_loop(raw)
    with pytest.raises(ModelError, match="plant"):
        d.observer_system(raw, lambda t: np.zeros((np.size(t), 1)))


def test_a_lure_system_refuses_the_non_monotone_law_itself():
    s = ex.rotor_standin("alpha")
    from nscontrol.systems.lure import LureSystem

    with pytest.raises(ModelError, match="loop_transformation"):
        LureSystem(s.A, s.G, s.H, _stribeck(), C=s.C)


def test_loop_transformation_reproduces_the_spec_matrix_and_designs():
    s = ex.rotor_standin("alpha")
    law = _stribeck()
    assert law.sigma_tan[0] == pytest.approx(0.161553, abs=1e-6)  # the spec's figure
    plant = loop_transformed_lure_system(s.A, s.G, s.H, law, B=s.B, C=s.C, u=s.u)
    assert plant.A[2, 2] == pytest.approx(law.sigma_tan[0] / ex.ROTOR["J_l"], rel=1e-14)
    np.testing.assert_array_equal(plant.A[:, :2], s.A[:, :2])  # only the friction column
    assert plant.law.monotone and plant.law.viscous[0] == pytest.approx(
        ex.ROTOR["b"] + law.sigma_tan[0], rel=1e-14)
    # the example scenario builds exactly this plant
    np.testing.assert_array_equal(s.plant().A, plant.A)
    d = design_lure_observer(plant, kappa=1000.0, tol=1e-2)
    np.testing.assert_array_equal(d.A, plant.A)
    assert 3.5 < d.alpha_max < 4.5  # spec 5.7: about 4 with ||Y|| <= 1000


def test_the_loop_transformation_is_the_laws_own():
    """A slope that leaves law - slope non-monotone, or a transformation unrelated to the law,
    cannot reach a design (it would certify an observer for another plant)."""
    from nscontrol.laws.base import LoopTransformation

    s = ex.rotor_standin("alpha")
    law = _stribeck()
    with pytest.raises(ModelError, match="sigma: expected sigma >= sigma_tan"):
        loop_transformed_lure_system(s.A, s.G, s.H, law, sigma=0.5 * law.sigma_tan, C=s.C)
    with pytest.raises(ModelError, match="sigma"):
        loop_transformed_lure_system(s.A, s.G, s.H, law, sigma=0.0, C=s.C)
    steeper = loop_transformed_lure_system(s.A, s.G, s.H, law, sigma=0.3, C=s.C)
    assert steeper.A[2, 2] == pytest.approx(0.3 / ex.ROTOR["J_l"], rel=1e-14)
    with pytest.raises(ModelError, match="sigma.*already monotone"):
        loop_transformed_lure_system(s.A, s.G, s.H, Relay(1.0), sigma=0.2, C=s.C)
    with pytest.raises(ModelError, match="law: expected a SetValuedLaw"):
        loop_transformed_lure_system(s.A, s.G, s.H, "stribeck", C=s.C)
    with pytest.raises(ModelError, match="D: "):
        loop_transformed_lure_system(s.A, s.G, s.H, law, D=[[0.1]], C=s.C)
    # design_lure_observer takes no user-made transformation at all (audit finding: an
    # unrelated one gave loop_sigma = 0 and a certificate for another plant)
    bogus = LoopTransformation(monotone_part=Relay(1.0), slope=np.zeros(1))
    with pytest.raises(TypeError, match="loop_transformation"):
        design_lure_observer(s.plant(), loop_transformation=bogus)


def test_rotor_observer_obeys_discrete_lyapunov_bound():
    s = ex.rotor_standin("alpha")
    plant = s.plant()
    d = design_lure_observer(plant, kappa=100.0, tol=1e-2)
    h = 0.02
    traj = simulate(d.closed_loop(plant), np.r_[s.x0, s.xhat0], (0.0, 4.0), h=h,
                    progress=False)
    V = d.lyapunov(traj.signal("e"))
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
        max_observer_decay_rate(**s.matrices, variant=variant, kappa=1000.0)


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
    # a single-output model (only z) is accepted: it measures the whole state, as LureSystem
    np.testing.assert_array_equal(
        lure_from_statespace(control.ss(s.A, s.G, s.H, 0), Relay(1.0)).C, np.eye(len(s.A)))
    with pytest.raises(DimensionError):  # fewer inputs than the law's dimension
        lure_from_statespace(control.ss(s.A, s.G, s.H, 0), Relay(np.ones(2)))
    ss = control.ss(s.A, np.hstack([s.G, s.B]), np.vstack([s.H, s.C]), [[0, 0], [0, 1.0]])
    with pytest.raises(ModelError, match="feedthrough"):
        lure_from_statespace(ss, Relay(1.0))
    # an input u with no input column for it is refused, not silently dropped
    no_u = control.ss(s.A, s.G, np.vstack([s.H, s.C]), np.zeros((2, 1)))
    with pytest.raises(ModelError, match="^u: "):
        lure_from_statespace(no_u, Relay(1.0), u=s.u)
    assert lure_from_statespace(no_u, Relay(1.0)).B is None
    with pytest.raises(ModelError, match="law"):
        lure_from_statespace(no_u, "relay")
