"""implicit_euler's controller= option: feedback held over each step (zero-order hold)."""

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.laws import Relay
from nscontrol.systems import LureSystem


def relay_plant(B=((0.0,), (1.0,))):
    """x1' = x2, x2' = -Sign(x2) + u: a unit mass with Coulomb friction of level 1."""
    return LureSystem([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                      B=None if B is None else np.array(B))


def test_held_feedback_is_the_explicit_recursion():
    """u_k = -2 x1_k - x2_k held over [t_k, t_k+1]: each step is backward Euler with the
    relay's soft threshold, written out by hand; the same operations, so 4 ulps per step."""
    h = 1e-2
    tr = nsc.simulate(relay_plant(), [1.0, 0.0], (0.0, 1.0), method="implicit_euler", h=h,
                      controller=lambda t, x: np.array([-2.0 * x[0] - x[1]]), progress=False)
    x = np.array([1.0, 0.0])
    for k in range(100):
        a = x[1] + h * (-2.0 * x[0] - x[1])
        v = np.sign(a) * max(abs(a) - h, 0.0)
        x = np.array([x[0] + h * v, v])
        np.testing.assert_allclose(tr.x[k + 1], x, rtol=0, atol=4 * (k + 1) * 2.3e-16)
    assert tr.stats["input"] == "controller"


def test_controller_option_refusals():
    sys_ = relay_plant()
    with pytest.raises(ModelError, match=r"^controller: expected a callable"):
        nsc.simulate(sys_, [0.0, 0.0], (0.0, 0.1), method="implicit_euler", h=1e-2,
                     controller=3.0)
    with pytest.raises(ModelError, match=r"^controller, u: give one of them"):
        nsc.simulate(sys_, [0.0, 0.0], (0.0, 0.1), method="implicit_euler", h=1e-2,
                     controller=lambda t, x: [0.0], u=lambda t: np.zeros((np.size(t), 1)))
    with pytest.raises(ModelError, match=r"^controller: this LureSystem has no input"):
        nsc.simulate(relay_plant(B=None), [0.0, 0.0], (0.0, 0.1), method="implicit_euler",
                     h=1e-2, controller=lambda t, x: [0.0])
    with pytest.raises(ModelError, match=r"^sensitivity: not available with a controller"):
        nsc.simulate(sys_, [0.0, 0.0], (0.0, 0.1), method="implicit_euler", h=1e-2,
                     controller=lambda t, x: [0.0], sensitivity=True)
    with pytest.raises(ModelError, match=r"^controller: expected a finite input of length 1"):
        nsc.simulate(sys_, [0.0, 0.0], (0.0, 0.1), method="implicit_euler", h=1e-2,
                     controller=lambda t, x: [np.nan])
