"""``nscontrol.testing.check_system``: every built-in law and system passes; laws and systems
that break the contract are refused, naming the property with its numbers."""

from dataclasses import dataclass

import numpy as np
import pytest

from nscontrol.errors import DimensionError, InadmissibleStateError, ModelError
from nscontrol.laws.base import ComplementarityForm, SetValuedLaw
from nscontrol.laws.impact import NewtonImpactLaw
from nscontrol.laws.set_valued import (
    AsymmetricStribeck,
    Complementarity,
    Coulomb,
    MonotoneFunction,
    NormalConeBox,
    NormalConeInterval,
    PiecewiseLinearFunction,
    Product,
    Relay,
    Stribeck,
)
from nscontrol.systems.hybrid import LinearHybridSystem
from nscontrol.systems.impacting_bodies import ImpactingBodies
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.nonlinear import NonlinearSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem, PWMController, SwitchedAffineSystem
from nscontrol.testing import CheckReport, check_system

LAWS = [
    Relay([1.0, 2.0]), Relay(0.0), Coulomb(0.5, [1.0, 2.0]),
    NormalConeBox([0.0, -1.0, -np.inf], [1.0, np.inf, 2.0]), NormalConeInterval(-1.0, 1.0, dim=2),
    Complementarity(3), MonotoneFunction(np.tanh, lambda z: 1.0 - np.tanh(z) ** 2, dim=2),
    MonotoneFunction(lambda z: z ** 3), Stribeck(0.3, 0.1, 1.0, viscous=0.01),
    AsymmetricStribeck(Stribeck(0.3, 0.1, 1.0), Stribeck(0.5, 0.2, 0.5, viscous=0.1)),
    PiecewiseLinearFunction.saturation(1.0, 2.0, dim=2),
    PiecewiseLinearFunction([-1.0, 0.0, 2.0], [0.0, 0.0, 1.0], slope_left=2.0, slope_right=0.5),
    Product(Relay(1.0), Complementarity(2), MonotoneFunction(np.arctan)),
    NewtonImpactLaw(0.7), NewtonImpactLaw([0.5, 0.9]),
]


def _systems():
    c = np.array([1.0, 1.0])
    A = np.array([[0.0, 1.0], [-1.0, -0.5]])
    return [
        LagrangianSystem.bouncing_ball(), LagrangianSystem.stack(3),
        LagrangianSystem.chain([1.0, 2.0, 1.0]), LagrangianSystem.newtons_cradle(3),
        LagrangianSystem.two_link_arm(),
        ImpactingBodies.from_springs([1.0, 1.0], [1.0], {(0, 0): 4.0, (0, 1): 6.0},
                                     {(0, 0): 4.0}),
        LureSystem([[0, 1], [0, 0]], [[0], [1]], [[1, 1]], Relay(1.0)),
        PiecewiseAffineSystem.bimodal([[0, 1], [-6, -0.1]], [[0, 1], [-1, -0.1]], [1.0, 0.0]),
        FilippovSystem.two_sided(lambda t, x: np.array([x[1], 1.0]),
                                 lambda t, x: np.array([x[1], -1.0]), lambda x: float(c @ x), 2,
                                 gradient=lambda x: c),
        SwitchedAffineSystem(((A, [0.0, 0.0]), (A, [0.0, 1.0])),
                             PWMController(0.25, lambda t, x: 0.15)),
        LinearHybridSystem([[0, 1, 0], [0, 0, -9.81], [0, 0, 0]], [[1, 0, 0]], [0.0],
                           np.diag([1.0, -0.5, 1.0])),
        NonlinearSystem(2, lambda t, x: np.array([x[1], -x[0] + 0.5 * (1 - x[0] ** 2) * x[1]])),
    ]


@pytest.mark.parametrize("law", LAWS, ids=lambda law: type(law).__name__)
def test_every_builtin_law_passes(law):
    report = check_system(law)
    assert isinstance(report, CheckReport) and report.passed
    names = " ".join(i.name for i in report.items)
    if isinstance(law, SetValuedLaw):
        assert "resolvent lands in the graph" in names and "select(z) lies in the graph" in names
        assert "monotone" in names
        graph = [i for i in report.items if i.name.startswith("resolvent lands")]
        assert graph[0].value <= 1e-12 and graph[0].threshold == 1e-12
    else:
        assert "momentum" in names
    assert str(report).startswith(f"check_system({report.subject})")


def test_laws_with_a_complementarity_form_are_checked_against_the_resolvent():
    report = check_system(Product(Relay([1.0, 0.5]), NormalConeBox(-1.0, 2.0)))
    agree = [i for i in report.items if "agrees with the resolvent" in i.name]
    assert agree and agree[0].value <= 1e-12
    curved = check_system(MonotoneFunction(np.tanh))
    assert any("none offered" in i.name for i in curved.items)


@pytest.mark.parametrize("system", _systems(), ids=lambda s: type(s).__name__)
def test_every_builtin_system_passes(system):
    report = check_system(system)
    assert report.kind == "system" and report.passed
    names = [i.name for i in report.items]
    assert "simulate refuses an x0 of length n_states + 1 with DimensionError" in names
    assert "x has shape (len(t), n_states)" in names


def test_a_given_x0_and_options_are_used():
    ball = LagrangianSystem.bouncing_ball()
    report = check_system(ball, x0=[0.1, 0.0], t_span=(0.0, 1.0))    # impacts inside the span
    assert report.passed
    lure = LureSystem([[0, 1], [0, 0]], [[0], [1]], [[1, 1]], Relay(1.0))
    assert check_system(lure, options={"h": 1e-4}).passed
    # options reach simulate: the integrator refuses an unknown one, and the check says so
    with pytest.raises(ModelError, match=r"fails 'simulate refuses an x0 of length n_states \+ 1 "
                                         r"with DimensionError': no; it raised ModelError: "
                                         r"implicit_euler: unknown option\(s\) \['stepsize'\]"):
        check_system(lure, options={"h": 1e-3, "stepsize": 1.0})


# ----------------------------------------------------------------------------- broken objects


@dataclass(frozen=True, eq=False, repr=False)
class MissingResolvent(Relay):
    """A user law whose resolvent ignores the law (returns x): it misses the graph."""

    def _resolvent(self, x, gamma):
        return x.copy()


class Decreasing(SetValuedLaw):
    """phi(z) = -z, wrongly declared monotone (its resolvent is exact)."""

    dim = 1
    monotone = True
    componentwise = True

    def _resolvent(self, x, gamma):
        return x / (1.0 - gamma)          # z - gamma z = x

    def _graph_distance(self, z, v):
        return float(np.linalg.norm(v + z) / np.sqrt(2.0))

    def _select(self, z):
        return -z


@dataclass(frozen=True, eq=False, repr=False)
class WrongForm(Relay):
    """A relay whose complementarity form encodes the bound 2c instead of c."""

    def complementarity_form(self) -> ComplementarityForm:
        form = super().complementarity_form()
        return ComplementarityForm(2.0 * form.w0, form.E, form.Nz, form.Nxi, 2.0 * form.r,
                                   "wrong")


def test_a_resolvent_that_misses_the_graph_is_refused():
    with pytest.raises(ModelError, match=r"^check_system\(MissingResolvent\(\.\.\.\)\): "
                                         r"set-valued law fails 'resolvent lands in the graph "
                                         r"\(max graph_residual over 50 points\)': ") as err:
        check_system(MissingResolvent(1.0))
    msg = str(err.value)
    assert "> 1e-12" in msg and "worst at x = [" in msg and "gamma = [" in msg
    worst = float(msg.split("': ")[1].split(" >")[0])
    assert worst > 0.1                    # the measured distance, not a placeholder
    assert err.value.report.items[-1].name.startswith("resolvent lands")
    assert not err.value.report.passed


def test_a_law_declared_monotone_that_is_not_is_refused():
    with pytest.raises(ModelError, match=r"fails 'monotone: max of -\(z1 - z2\)·\(v1 - v2\) "
                                         r"over 25 pairs': "):
        check_system(Decreasing())


def test_a_complementarity_form_inconsistent_with_the_graph_is_refused():
    with pytest.raises(ModelError, match=r"fails 'complementarity form: its solutions lie in "
                                         r"the graph"):
        check_system(WrongForm(1.0))


@dataclass(frozen=True)
class _FakeSystem:
    n_states: int = 2
    default_method: str = "event_driven"


def test_systems_with_broken_declarations_are_refused():
    with pytest.raises(ModelError, match=r"fails 'n_states is a positive integer': no; "
                                         r"n_states = 0"):
        check_system(_FakeSystem(n_states=0))
    with pytest.raises(ModelError, match=r"fails 'default_method is one of simulate's methods': "
                                         r"no; default_method = 'rk4'"):
        check_system(_FakeSystem(default_method="rk4"))
    with pytest.raises(ModelError, match=r"fails 'simulate refuses an x0 of length n_states \+ 1 "
                                         r"with DimensionError'"):
        check_system(_FakeSystem())       # simulate raises ModelError (unsupported system)


def test_check_system_refuses_other_objects_and_bad_options():
    with pytest.raises(ModelError, match=r"^obj: expected a SetValuedLaw, a NewtonImpactLaw or "
                                         r"a system"):
        check_system(np.eye(2))
    with pytest.raises(ModelError, match=r"^n_points: expected an integer >= 2"):
        check_system(Relay(1.0), n_points=1)
    with pytest.raises(ModelError, match=r"^tol: expected a finite number > 0"):
        check_system(Relay(1.0), tol=0.0)
    with pytest.raises(DimensionError, match=r"^x0: expected a vector of length 2"):
        check_system(LagrangianSystem.bouncing_ball(), x0=[1.0, 0.0, 0.0])
    with pytest.raises(InadmissibleStateError, match=r"^x0: contact 0 is penetrated"):
        check_system(LagrangianSystem.bouncing_ball(), x0=[-1.0, 0.0])
