"""Bad input to the set-valued models and integrators: each its specific error, with the way
out named."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import DimensionError, ModelError
from nscontrol.laws.friction import Stribeck
from nscontrol.laws.relay import Relay
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem, PWMController, SwitchedAffineSystem

A = np.array([[0.0, 1.0], [0.0, 0.0]])
G = np.array([[0.0], [1.0]])
H = np.array([[1.0, 1.0]])


def _stribeck():
    return Stribeck(static=0.3, coulomb=0.1, stribeck_velocity=1.0, delta=2.0)


def test_non_monotone_law_is_refused_with_loop_transformation_named():
    with pytest.raises(ModelError, match="loop_transformation"):
        LureSystem(A, G, H, _stribeck())


def test_shapes_and_feedthrough_are_checked():
    with pytest.raises(DimensionError, match="H"):
        LureSystem(A, G, [[1.0, 1.0, 0.0]], Relay(1.0))
    with pytest.raises(DimensionError, match="law"):
        LureSystem(A, G, H, Relay(1.0, dim=2))
    with pytest.raises(ModelError, match="D \\+ D\\^T"):
        LureSystem(A, G, H, Relay(1.0), D=[[-1.0]])
    with pytest.raises(ModelError, match="B"):
        LureSystem(A, G, H, Relay(1.0), u=lambda t: 0.0)


def test_implicit_euler_options_and_ill_posed_steps():
    lure = LureSystem(A, G, H, Relay(1.0))
    with pytest.raises(ModelError, match="h: implicit_euler needs a step"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0))
    with pytest.raises(ModelError, match="unknown option"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-3, rtol=1e-3)
    with pytest.raises(ModelError, match="theta"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), h=1e-3, theta=0.2)
    # H G < 0: the one-step matrix is not positive definite
    bad = LureSystem(A, G, -H, Relay(1.0))
    with pytest.raises(ModelError, match="not positive definite"):
        simulate(bad, [1.0, 0.0], (0.0, 1.0), h=1e-3)
    # I - h A singular
    sing = LureSystem(np.eye(2) * 100.0, G, H, Relay(1.0))
    with pytest.raises(ModelError, match="singular"):
        simulate(sing, [1.0, 0.0], (0.0, 1.0), h=1e-2)
    with pytest.raises(ModelError, match="implicit_euler"):
        simulate(lure, [1.0, 0.0], (0.0, 1.0), method="switching")


def test_partition_errors():
    A1 = [[0.0, 1.0], [-1.0, 0.0]]
    with pytest.raises(ModelError, match="overlap"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [1.0]), ([[-1.0, 0.0]], [1.0])))
    with pytest.raises(ModelError, match="do not cover"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]),
                                                 ([[-1.0, 0.0]], [-1.0])))
    # a bounded domain makes the same gap-free cover acceptable
    PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]), ([[-1.0, 0.0]], [0.0])),
                          domain=([[1.0, 0.0], [-1.0, 0.0]], [1.0, 1.0]))
    with pytest.raises(ModelError, match="continuous=False"):
        PiecewiseAffineSystem.bimodal(A1, [[0.0, 1.0], [-2.0, 0.0]], [0.0, 1.0])
    with pytest.raises(DimensionError, match="regions"):
        PiecewiseAffineSystem((A1, A1), regions=(([[1.0, 0.0]], [0.0]),))


def test_switched_model_errors():
    A1 = np.array([[0.0, 1.0], [-1.0, 0.0]])
    with pytest.raises(DimensionError, match="field"):
        FilippovSystem(2, (lambda x: x[0],), lambda t, x, s: np.zeros(3))
    with pytest.raises(ModelError, match="at least two modes"):
        SwitchedAffineSystem(((A1, [0.0, 0.0]),))
    with pytest.raises(ModelError, match="pattern"):
        PWMController(0.1, lambda t, x: 0.05, pattern="random")
    with pytest.raises(ModelError, match="PWMController"):
        simulate(SwitchedAffineSystem(((A1, [0, 0]), (A1, [0, 1]))), [0.0, 0.0], (0.0, 1.0))
    # repelling sliding: both sides push away from x = 0
    rep = FilippovSystem.two_sided(lambda t, x: np.array([-1.0]), lambda t, x: np.array([1.0]),
                                   lambda x: float(x[0]), 1)
    with pytest.raises(ModelError, match="repelling"):
        simulate(rep, [0.0], (0.0, 1.0))
