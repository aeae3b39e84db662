"""Compiled blocks (``CompiledBlock``): the integrators' compiled loops call the blocks'
jitted forms and reproduce the Python blocks' trajectories; bad blocks are refused.

Tolerances: where the compiled form repeats the Python method operation for operation
(chapter 7's blocks: scalar arithmetic, the same libm ``exp``/``pow``/``sin``) the two runs
are bit-identical. Where numpy's ``@`` (BLAS, possibly with fused multiply-adds) meets a
plain loop, each step differs by a few ulps of the state; a contracting loop keeps the sum,
so ``n_steps x 8 u x max|x|`` bounds the difference (8: the dot products' length 2-4 plus
the step's own additions).
"""

import numpy as np
import pytest
from numba import njit

import nscontrol as nsc
from nscontrol.design.friction_compensation import (
    FrictionCompensatingPD,
    PDLaw,
    ReducedOrderVelocityObserver,
    SetPoint,
    Sinusoid,
    compensation_model,
)
from nscontrol.errors import DimensionError, ModelError
from nscontrol.laws import Relay, Stribeck
from nscontrol.systems import LinearController, OneLinkRobot, StateFeedback
from nscontrol.systems.feedback import (
    BLOCK_SIGNATURE,
    CompiledBlock,
    StaticLaw,
    compiled_form,
)
from nscontrol.systems.lure import LureSystem

U = np.finfo(float).eps / 2
J, KP, KD, L, H = 0.05, 2.0, 0.3, 150.0, 1e-4
ROBOT = OneLinkRobot(J, Stribeck(0.4, 0.2, 0.05, 2.0, 0.02))


def friction_loop(compiled, *, reference=None, kappa=1.0, observer=True, smooth_eps=None):
    pd = PDLaw(KP, KD, J, SetPoint(1.0) if reference is None else reference)
    ctrl = FrictionCompensatingPD(pd, compensation_model(ROBOT.friction, kappa), H,
                                  smooth_eps=smooth_eps)
    obs = ReducedOrderVelocityObserver(L, pd, H).starting_at(0.0, 0.3) if observer else None
    return nsc.closed_loop(ROBOT.lure_system(), ctrl, obs, compiled=compiled)


def run(loop, x0=(0.0, 0.5), T=0.5):
    return nsc.simulate(loop, list(x0), (0.0, T), method="implicit_euler", h=H,
                        progress=False)


@pytest.mark.parametrize("case", [
    {}, {"kappa": 0.0}, {"kappa": 1.3}, {"observer": False}, {"smooth_eps": 1e-3},
    {"reference": Sinusoid(0.5, 3.0)}])
def test_chapter7_blocks_compiled_reproduce_the_python_blocks_bit_for_bit(case):
    """Same operations in the same order (module docstring): identical trajectories and
    signals, through sticking, slipping and the observer's ticks."""
    T = 3.0 if case.get("kappa") == 0.0 else 0.5     # without compensation: until it sticks
    fast, slow = (run(friction_loop(c, **case), T=T) for c in (True, False))
    assert fast.stats["controller"] == "compiled" and slow.stats["controller"] == "python"
    np.testing.assert_array_equal(fast.t, slow.t)
    np.testing.assert_array_equal(fast.x, slow.x)
    assert set(fast.signals) == set(slow.signals)
    for name in slow.signals:
        np.testing.assert_array_equal(fast.signal(name), slow.signal(name), err_msg=name)
    assert np.any(fast.x[:, 1] == 0.0) or case.get("kappa", 1.0) != 0.0   # it stuck


def test_chunks_carry_the_blocks_state():
    """A run longer than one chunk of 65536 steps: the sampling schedule and the blocks'
    states continue across the cut (bit-identical, as above)."""
    fast, slow = run(friction_loop(True), T=7.0), run(friction_loop(False), T=7.0)
    np.testing.assert_array_equal(fast.x, slow.x)
    np.testing.assert_array_equal(fast.signal("xo"), slow.signal("xo"))


def test_an_arbitrary_reference_falls_back_to_python():
    loop = friction_loop(True, reference=lambda t: (1.0, 0.0, 0.0))
    assert compiled_form(loop.controller) is None
    assert run(loop, T=0.01).stats["controller"] == "python"


def relay_plant():
    """x1' = x2, x2' = -Sign(x2) + u: a unit mass with Coulomb friction of level 1."""
    return LureSystem([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                      B=np.array([[0.0], [1.0]]), C=np.array([[1.0, 0.0]]))


@pytest.mark.parametrize("make", [
    lambda: StateFeedback([[-4.0, -2.0]], k=[0.5], period=1e-2),
    lambda: LinearController([[0.9]], [[0.1]], [[-1.0]], [[-3.0]], period=1e-2)])
def test_linear_blocks_compiled_match_python_within_roundoff(make):
    h, T = 1e-3, 3.0
    runs = [nsc.simulate(nsc.closed_loop(relay_plant(), make(), compiled=c), [2.0, 0.0],
                         (0.0, T), method="implicit_euler", h=h, progress=False)
            for c in (True, False)]
    assert [r.stats["controller"] for r in runs] == ["compiled", "python"]
    bound = (T / h) * 8 * U * np.max(np.abs(runs[1].x))   # module docstring
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=0, atol=bound)
    np.testing.assert_allclose(runs[0].signal("u"), runs[1].signal("u"), rtol=0,
                               atol=bound * 10)   # |K| <= 5 times the state's bound


@njit(BLOCK_SIGNATURE, cache=True)
def _nan_output(t, xb, y, x, xhat, lam, p):
    return np.full(1, np.nan)


@njit(BLOCK_SIGNATURE, cache=True)
def _grow(t, xb, y, x, xhat, lam, p):
    return np.zeros(xb.size + 1)


@njit(BLOCK_SIGNATURE, cache=True)
def _zero_output(t, xb, y, x, xhat, lam, p):
    return np.zeros(1)


class _Compiled(StaticLaw):
    n_outputs, period = 1, 1e-2

    def __init__(self, form, n_states=0):
        self.form, self.n_states = form, n_states

    def output(self, t, xc, m):
        return np.zeros(1)

    def compiled(self):
        return self.form


def test_bad_compiled_blocks_are_refused():
    with pytest.raises(ModelError, match=r"^output: a CompiledBlock needs a function "
                                         r"compiled by numba.njit\(BLOCK_SIGNATURE\)"):
        CompiledBlock(lambda *a: None, _grow, [])
    with pytest.raises(ModelError, match=r"^update: a CompiledBlock needs a function"):
        CompiledBlock(_grow, njit(lambda t, xb, y, x, xh, lam, p: xb), [])   # undeclared
    with pytest.raises(ModelError, match=r"^compiled: _Compiled.compiled\(\) must return"):
        compiled_form(_Compiled(3.0))
    loop = nsc.closed_loop(relay_plant(), _Compiled(CompiledBlock(_nan_output, _grow, [])))
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value at t = 0"):
        run(loop, x0=(1.0, 0.0), T=0.1)
    loop = nsc.closed_loop(relay_plant(), _Compiled(CompiledBlock(_zero_output, _grow, []),
                                                    n_states=1))
    with pytest.raises(DimensionError, match=r"^controller: update returned a state of the "
                                             r"wrong length"):
        run(loop, x0=(1.0, 0.0), T=0.1)
    with pytest.raises(ModelError, match=r"^compiled: expected True or False"):
        nsc.closed_loop(relay_plant(), StateFeedback([[-1.0, -1.0]]), compiled="yes")


@njit(BLOCK_SIGNATURE, cache=True)
def _state_output(t, xb, y, x, xhat, lam, p):
    return xb                    # the state itself, which the update then replaces


@njit(BLOCK_SIGNATURE, cache=True)
def _count_up(t, xb, y, x, xhat, lam, p):
    return xb + 1.0


class _SampleCounter(StaticLaw):
    """Outputs its state (the samples taken so far), then counts one more; u = n at the
    n-th sample (from 0), held for 10 steps."""

    n_states, n_outputs, period = 1, 1, 1e-2

    def output(self, t, xc, m):
        return xc

    def update(self, t, xc, m):
        return xc + 1.0

    def compiled(self):
        return CompiledBlock(_state_output, _count_up, [])


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_a_held_output_is_the_value_before_the_update_even_if_it_is_the_state(compiled):
    """The output is held before the state moves on: an output that is the state array
    itself (no copy) is not changed by the update (the compiled stepper held the updated
    state). Exact: small integers."""
    h = 1e-3
    traj = nsc.simulate(nsc.closed_loop(relay_plant(), _SampleCounter(), compiled=compiled),
                        [1.0, 0.0], (0.0, 0.1), method="implicit_euler", h=h, progress=False)
    assert traj.stats["controller"] == ("compiled" if compiled else "python")
    steps = np.arange(traj.t.size - 1)      # row j + 1: the input held over step j
    np.testing.assert_array_equal(traj.signal("u")[1:, 0], steps // 10)
    np.testing.assert_array_equal(traj.signal("xc")[1:, 0], steps // 10 + 1)


class _ShortEstimate(StaticLaw):
    n_outputs, period = 2, None

    def output(self, t, xc, m):
        return np.zeros(1)


def test_a_python_observer_estimate_of_the_wrong_length_is_refused():
    """The Python blocks are checked by the compiled stepper's rules (its code, run as
    Python): an estimate shorter than the observer's n_outputs is refused."""
    loop = nsc.closed_loop(relay_plant(), observer=_ShortEstimate(), compiled=False)
    with pytest.raises(DimensionError, match=r"^observer: output returned an estimate of the "
                                             r"wrong length, expected 2 \(at t = 0\): it "
                                             r"returned 1 values"):
        run(loop, x0=(1.0, 0.0), T=0.01)


@njit(BLOCK_SIGNATURE, cache=True)
def _divide_output(t, xb, y, x, xhat, lam, p):
    out = np.zeros(1)
    out[0] = 1.0 / p[0]          # p[0] = 0: numba's Python error model raises
    return out


def test_an_error_a_compiled_block_raises_comes_out_of_the_run():
    """The loops call a block through its C wrapper, which cannot pass an exception on:
    the run still raises the block's own error (not a length or finiteness status), and
    leaves the interpreter's unraisable hook as it found it."""
    import sys

    hook = sys.unraisablehook
    loop = nsc.closed_loop(relay_plant(), _Compiled(CompiledBlock(_divide_output, _grow,
                                                                  [0.0])))
    with pytest.raises(ZeroDivisionError, match="division by zero"):
        run(loop, x0=(1.0, 0.0), T=0.1)
    assert sys.unraisablehook is hook


def test_compiled_entries_have_the_dispatchers_type_found_once():
    """The loops' argument for the blocks has the type numba gives the dispatchers (so the
    cached loops are the same) and is made once per process."""
    from numba import typeof

    from nscontrol.systems._feedback_kernels import compiled_entries

    entries = compiled_entries(_state_output, _count_up)
    assert entries.numba_type == typeof((_state_output, _count_up))
    assert compiled_entries(_state_output, _count_up) is entries
