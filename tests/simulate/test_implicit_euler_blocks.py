"""A closed loop of blocks around a Lur'e plant under implicit Euler: the blocks' output held
over each step (zero-order hold), by the Python runner or compiled in the closed form's loop;
feedback reaches the integrator only as a closed loop."""

import numpy as np
import pytest
from numba import njit

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.laws import Relay
from nscontrol.simulate import METHODS
from nscontrol.systems import LureSystem
from nscontrol.systems.feedback import BLOCK_SIGNATURE, CompiledBlock, StateFeedback, StaticLaw

EPS = np.finfo(float).eps
H = 1e-2


def relay_plant(B=((0.0,), (1.0,))):
    """x1' = x2, x2' = -Sign(x2) + u: a unit mass with Coulomb friction of level 1."""
    return LureSystem([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                      B=None if B is None else np.array(B))


class PD(StaticLaw):
    """u = -2 x1 - x2, written in Python (no compiled form: the Python runner)."""

    n_outputs, period = 1, None

    def output(self, t, xc, m):
        return np.array([-2.0 * m.x[0] - m.x[1]])


@pytest.mark.parametrize("block, path", [
    (PD(), "python"),
    (StateFeedback([[-2.0, -1.0]], period=H), "compiled"),   # sampled at every step
])
def test_held_feedback_is_the_explicit_recursion(block, path):
    """u_k = -2 x1_k - x2_k held over [t_k, t_k+1]: each step is backward Euler with the
    relay's soft threshold, written out by hand; the same operations, so 4 ulps per step."""
    tr = nsc.simulate(nsc.closed_loop(relay_plant(), block), [1.0, 0.0], (0.0, 1.0),
                      method="implicit_euler", h=H, progress=False)
    x = np.array([1.0, 0.0])
    for k in range(100):
        a = x[1] + H * (-2.0 * x[0] - x[1])
        v = np.sign(a) * max(abs(a) - H, 0.0)
        x = np.array([x[0] + H * v, v])
        np.testing.assert_allclose(tr.x[k + 1], x, rtol=0, atol=4 * (k + 1) * EPS)
    assert tr.stats["input"] == "controller" and tr.stats["controller"] == path


def test_feedback_reaches_implicit_euler_only_as_a_closed_loop():
    plant, loop = relay_plant(), nsc.closed_loop(relay_plant(), PD())
    with pytest.raises(ModelError, match=r"^controller: unknown option of simulate; feedback "
                                         r"is a closed loop.*closed_loop\(plant, block\)"):
        nsc.simulate(plant, [0.0, 0.0], (0.0, 0.1), method="implicit_euler", h=H,
                     controller=lambda t, x: [0.0])
    for name in ("controller", "compiled_blocks"):   # no longer options of the method
        assert name not in METHODS["implicit_euler"].options
    with pytest.raises(ModelError, match=r"^u: the plant of a closed loop takes its input"):
        nsc.simulate(loop, [0.0, 0.0], (0.0, 0.1), h=H, u=lambda t: np.zeros((np.size(t), 1)))
    with pytest.raises(ModelError, match=r"^controller: this LureSystem has no input"):
        nsc.simulate(nsc.closed_loop(relay_plant(B=None), PD()), [0.0, 0.0], (0.0, 0.1), h=H)
    with pytest.raises(ModelError, match=r"^sensitivity: not available for a closed loop"):
        nsc.simulate(loop, [0.0, 0.0], (0.0, 0.1), h=H, sensitivity=True)
    with pytest.raises(ModelError, match=r"^blocks: expected the BlockRunner of a closed loop"):
        nsc.simulate(plant, [0.0, 0.0], (0.0, 0.1), h=H, blocks=PD())


class _NaNAfter(StaticLaw):
    """-x1 until t = 0.5, then NaN or ``fault`` raised (a sampled block, so a compiled form
    can run it)."""

    n_outputs, period = 1, H

    def __init__(self, form=None, fault=None):
        self.form, self.fault = form, fault

    def output(self, t, xc, m):
        if t >= 0.5 - 0.5 * H and self.fault is not None:
            raise self.fault()
        return np.array([np.nan if t >= 0.5 - 0.5 * H else -m.x[0]])

    def compiled(self):
        return self.form


@njit(BLOCK_SIGNATURE, cache=True)
def _nan_after_output(t, xb, y, x, xhat, lam, p):
    out = np.empty(1)
    out[0] = np.nan if t >= 0.5 - 0.5 * p[0] else -x[0]
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def _keep(t, xb, y, x, xhat, lam, p):
    return xb


@pytest.mark.parametrize("compiled, fault", [(False, None), (True, None),
                                             (False, KeyboardInterrupt)])
def test_a_failing_block_keeps_every_step_before_it(compiled, fault):
    """A block's NaN at t = 0.5 (or a Ctrl-C while it runs) ends the run with the 50 steps
    before it, equal to a run stopped there, by the Python runner and by the compiled loop
    (whose chunk is cut short by the block's status)."""
    form = CompiledBlock(_nan_after_output, _keep, [H]) if compiled else None
    loop = nsc.closed_loop(relay_plant(), _NaNAfter(form, fault))
    error, match = (ModelError, r"^controller: returned a non-finite value at t = 0\.5") \
        if fault is None else (fault, None)
    with pytest.raises(error, match=match) as info:
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), h=H, progress=False)
    partial = info.value.trajectory
    assert partial.status == -1 and partial.t[-1] == pytest.approx(0.5, abs=1e-12)
    reference = nsc.simulate(loop, [1.0, 0.0], (0.0, 0.5), h=H, progress=False)
    assert reference.stats["controller"] == ("compiled" if compiled else "python")
    np.testing.assert_array_equal(partial.t, reference.t)
    np.testing.assert_array_equal(partial.x, reference.x)
    np.testing.assert_array_equal(partial.signal("u"), reference.signal("u"))
