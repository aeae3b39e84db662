"""Moreau–Jean with a compiled model (``LagrangianSystem(..., compiled=CompiledModel(...))``)
and compiled blocks: the compiled loop reproduces the Python path; bad models are refused.

Tolerance: both paths do the same operations except the small matrix products (BLAS on the
Python path, possibly with fused multiply-adds, plain loops here) and numpy's ``sin``/``cos``
against libm's: each step differs by a few ulps of the state. The regulated loops below are
dissipative (no error growth), so after ``N`` steps the difference is below
``N x 16 u x max|x|`` (16: the products' lengths, up to 8, times two for the M̂⁻¹ solve).
"""

from dataclasses import replace

import numpy as np
import pytest
from numba import njit

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.examples import ch04_posture_regulation as ex
from nscontrol.systems._lagrangian_kernels import (
    FORCE_JACOBIAN_SIGNATURE,
    FORCE_SIGNATURE,
    GAP_JACOBIAN_SIGNATURE,
    GAP_SIGNATURE,
    MASS_SIGNATURE,
)
from nscontrol.systems.feedback import BLOCK_SIGNATURE, RESET_SIGNATURE, CompiledBlock
from nscontrol.systems.foot_body import FOOT_BODY_ACTIVATION
from nscontrol.systems.lagrangian import CompiledModel, LagrangianSystem

U = np.finfo(float).eps / 2
H, T = 1e-3, 0.5   # the heel lands at t = 0.141 and the foot settles flat at 0.282


def bound(traj):
    return traj.stats["steps"] * 16 * U * max(1.0, float(np.abs(traj.x).max()))


@pytest.fixture(scope="module")
def foot():
    model, reg, plant = ex.foot_body_setup()
    return model, reg, plant, ex.initial_state(model, reg.design.q_star, -1.0)


def run(system, x0, **kw):
    return nsc.simulate(system, x0, (0.0, T), method="moreau_jean", h=H, progress=False,
                        activation=FOOT_BODY_ACTIVATION, **kw)


def test_foot_body_folded_law_compiled_matches_the_python_path(foot):
    _, reg, plant, x0 = foot
    fast = run(reg.folded(plant), x0)
    slow = run(replace(reg.folded(plant), compiled=None), x0)
    assert fast.stats["path"] == "compiled_model" and slow.stats["path"] == "python"
    np.testing.assert_allclose(fast.x, slow.x, rtol=0, atol=bound(slow))
    for name in ("impulse", "gap", "energy"):
        np.testing.assert_allclose(fast.signal(name), slow.signal(name), rtol=0,
                                   atol=100 * bound(slow), err_msg=name)   # x |M|, |V| <= 100
    assert [(e.kind, e.index) for e in fast.events] == [(e.kind, e.index) for e in slow.events]
    assert np.array_equal(fast.signal("impulse") > 0, slow.signal("impulse") > 0)


def test_foot_body_regulator_as_a_compiled_block_matches_its_python_methods(foot):
    _, reg, plant, x0 = foot
    fast = run(nsc.closed_loop(plant, reg), x0)
    slow = run(nsc.closed_loop(plant, reg, compiled=False), x0)
    assert fast.stats["path"] == "compiled_model" and slow.stats["path"] == "python"
    np.testing.assert_allclose(fast.x, slow.x, rtol=0, atol=bound(slow))
    np.testing.assert_allclose(fast.signal("u"), slow.signal("u"), rtol=0,
                               atol=1e3 * bound(slow))       # |K_p| = 400 amplifies


# -- a falling ball with a compiled model and a block counting its impacts ----------------
@njit(MASS_SIGNATURE, cache=True)
def _ball_mass(q, p):
    return np.full((1, 1), p[0])


@njit(FORCE_SIGNATURE, cache=True)
def _ball_force(t, q, v, p):
    return np.full(1, -p[0] * p[1])


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def _ball_jacobian(t, q, v, p):
    return np.zeros((2, 1))


@njit(GAP_SIGNATURE, cache=True)
def _ball_gap(q, p):
    return q.copy()


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def _ball_gap_jacobian(q, p):
    return np.ones((1, 1))


@njit(BLOCK_SIGNATURE, cache=True)
def _count_output(t, xb, y, x, xhat, lam, p):
    return np.zeros(1)


@njit(BLOCK_SIGNATURE, cache=True)
def _count_update(t, xb, y, x, xhat, lam, p):
    return xb.copy()


@njit(RESET_SIGNATURE, cache=True)
def _count_reset(t, xb, x_minus, x_plus, impulse, p):
    out = xb.copy()
    out[0] += 1.0
    out[1] = impulse[0]
    return out


class ImpactCounter:
    """Counts the plant's impacts (its state: count, last impulse); outputs nothing."""

    n_states, n_outputs, period = 2, 1, 0.01

    def output(self, t, xc, m):
        return np.zeros(1)

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return np.array([xc[0] + 1.0, jump.impulse[0]])

    def compiled(self):
        return CompiledBlock(_count_output, _count_update, [], _count_reset)


def ball(compiled=True, mass=2.0):
    model = CompiledModel(_ball_mass, _ball_force, _ball_jacobian, _ball_gap,
                          _ball_gap_jacobian, [mass, 9.81]) if compiled else None
    return LagrangianSystem(lambda q: np.array([[mass]]), constant_force=[0.0],
                            force=lambda t, q, v: np.array([-mass * 9.81]),
                            force_jacobian=lambda t, q, v: (np.zeros((1, 1)),
                                                            np.zeros((1, 1))),
                            gap=lambda q: q.copy(), jacobian=lambda q: np.ones((1, 1)),
                            restitution=0.8, actuation=[[1.0]], compiled=model)


def test_block_resets_at_impacts_as_on_the_python_path():
    """Seven bounces in 3 s: the counter's state after each reset, the impulse it read."""
    runs = [nsc.simulate(nsc.closed_loop(ball(), ImpactCounter(), compiled=c), [1.0, 0.0],
                         (0.0, 3.0), method="moreau_jean", h=1e-3, progress=False)
            for c in (True, False)]
    assert [r.stats["path"] for r in runs] == ["compiled_model", "python"]
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=0, atol=bound(runs[1]))
    xc = [r.signal("xc") for r in runs]
    np.testing.assert_array_equal(xc[0][:, 0], xc[1][:, 0])
    assert xc[0][-1, 0] >= 5
    np.testing.assert_allclose(xc[0][:, 1], xc[1][:, 1], rtol=0, atol=100 * bound(runs[1]))


def test_bad_compiled_models_are_refused():
    with pytest.raises(ModelError, match=r"^mass: a CompiledModel needs a function compiled"):
        CompiledModel(lambda q, p: q, _ball_force, _ball_jacobian, _ball_gap,
                      _ball_gap_jacobian, [])
    with pytest.raises(ModelError, match=r"^compiled.mass: disagrees with the system's mass"):
        LagrangianSystem(lambda q: np.array([[3.0]]), names=("y",),
                         gap=lambda q: q.copy(), jacobian=lambda q: np.ones((1, 1)),
                         compiled=ball().compiled)
    with pytest.raises(ModelError, match=r"^compiled: expected a CompiledModel"):
        LagrangianSystem(np.eye(1), gap_matrix=[[1.0]], compiled="fast")


def test_listeners_observe_the_compiled_run_as_the_python_one():
    """Without a controller a compiled model runs compiled; a user's listener sees the same
    impacts (times, contacts) as on the Python path."""
    seen = {True: [], False: []}
    for c in (True, False):
        system = ball() if c else replace(ball(), compiled=None)
        traj = nsc.simulate(system, [1.0, 0.0], (0.0, 3.0), method="moreau_jean", h=1e-3,
                            progress=False,
                            listeners=[lambda t, xm, xp, idx, imp, c=c:
                                       seen[c].append((round(t, 9), idx.tolist()))])
        assert traj.stats["path"] == ("compiled_model" if c else "python")
    assert seen[True] == seen[False] and len(seen[True]) >= 5


@njit(BLOCK_SIGNATURE, cache=True)
def _late_nan(t, xb, y, x, xhat, lam, p):
    return np.full(1, np.nan if t > 0.5 else 0.0)


class LateNaN(ImpactCounter):
    def compiled(self):
        return CompiledBlock(_late_nan, _count_update, [], _count_reset)


def test_a_block_failing_mid_run_stops_it_with_the_steps_so_far():
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value at "
                                         r"t = 0\.5") as info:
        nsc.simulate(nsc.closed_loop(ball(), LateNaN()), [1.0, 0.0], (0.0, 3.0),
                     method="moreau_jean", h=1e-3, progress=False)
    assert info.value.trajectory is not None and info.value.trajectory.t[-1] >= 0.5


def test_a_linear_plant_under_compiled_blocks_runs_compiled():
    """A mass regulated against a wall by a sampled state feedback (chapter 4's wall, a
    linear plant without a compiled model of its own): its affine model runs compiled and
    matches the Python blocks' run (bound of the module docstring)."""
    from nscontrol.systems.feedback import StateFeedback

    wall = LagrangianSystem([[1.0]], gap_matrix=[[-1.0]], gap_offset=[0.0],
                            restitution=0.5, actuation=[[1.0]])
    ctrl = StateFeedback([[-20.0, -3.0]], k=[1.0], period=1e-2)
    runs = [nsc.simulate(nsc.closed_loop(wall, ctrl, compiled=c), [-0.2, 0.0], (0.0, 3.0),
                         method="moreau_jean", h=1e-3, progress=False) for c in (True, False)]
    # the Python blocks step the plant's own linear path (tridiagonal), one step per chunk
    assert [r.stats["path"] for r in runs] == ["compiled_model", "tridiagonal"]
    assert runs[1].events_of("impact")
    np.testing.assert_allclose(runs[0].x, runs[1].x, rtol=0, atol=bound(runs[1]))
    np.testing.assert_allclose(runs[0].signal("u"), runs[1].signal("u"), rtol=0,
                               atol=20 * bound(runs[1]))       # |K| <= 20


# -- one step for both paths ----------------------------------------------------------------
_K, _A, _C = np.array([40.0, 25.0]), np.array([3.0, 1.5]), np.array([0.2, 0.1])


@njit(MASS_SIGNATURE, cache=True)
def _pair_mass(q, p):
    return np.array([[2.0, 0.5], [0.5, 1.0]])


@njit(FORCE_SIGNATURE, cache=True)
def _pair_force(t, q, v, p):
    k, a, c = p[0:2], p[2:4], p[4:6]
    return -k * q - a * q * q * q - c * v


@njit(FORCE_JACOBIAN_SIGNATURE, cache=True)
def _pair_jacobian(t, q, v, p):
    k, a, c = p[0:2], p[2:4], p[4:6]
    J = np.zeros((4, 2))
    for i in range(2):
        J[i, i] = -k[i] - 3.0 * a[i] * q[i] * q[i]
        J[2 + i, i] = -c[i]
    return J


@njit(GAP_SIGNATURE, cache=True)
def _pair_gaps(q, p):
    return np.array([q[0] + 1.0, q[1] - q[0] + 0.5])


@njit(GAP_JACOBIAN_SIGNATURE, cache=True)
def _pair_gap_jacobian(q, p):
    return np.array([[1.0, 0.0], [-1.0, 1.0]])


def coupled_pair(compiled):
    """Two coupled masses on hardening springs falling onto a floor and onto each other;
    the Python callables do the compiled functions' operations in the same order."""
    model = CompiledModel(_pair_mass, _pair_force, _pair_jacobian, _pair_gaps,
                          _pair_gap_jacobian, np.concatenate([_K, _A, _C])) \
        if compiled else None
    return LagrangianSystem(
        lambda q: np.array([[2.0, 0.5], [0.5, 1.0]]), constant_force=[-19.62, -9.81],
        force=lambda t, q, v: -_K * q - _A * q * q * q - _C * v,
        force_jacobian=lambda t, q, v: (np.diag(-_K - 3.0 * _A * q * q), np.diag(-_C)),
        gap=lambda q: np.array([q[0] + 1.0, q[1] - q[0] + 0.5]),
        jacobian=lambda q: np.array([[1.0, 0.0], [-1.0, 1.0]]), restitution=0.5,
        names=("lower", "upper"),
        compiled=model)


def test_the_python_path_and_the_compiled_loop_take_the_same_step():
    """Both paths call the one compiled step (``mj_step``) and differ only in how the model
    is evaluated: with a model whose Python and compiled forms do the same operations in the
    same order, the two runs agree to the last bit, impacts on both contacts included."""
    runs = [nsc.simulate(coupled_pair(c), [0.3, 0.1, 0.0, 0.0], (0.0, 2.0),
                         method="moreau_jean", h=1e-3, progress=False) for c in (True, False)]
    assert [r.stats["path"] for r in runs] == ["compiled_model", "python"]
    assert {e.index for e in runs[1].events_of("impact")} == {0, 1}   # both contacts act
    np.testing.assert_array_equal(runs[0].x, runs[1].x)
    np.testing.assert_array_equal(runs[0].signal("impulse"), runs[1].signal("impulse"))


@njit(RESET_SIGNATURE, cache=True)
def _nan_reset(t, xb, x_minus, x_plus, impulse, p):
    return np.full(xb.size, np.nan)


class NaNReset(ImpactCounter):
    """A block whose reset leaves a non-finite state (Python and compiled alike)."""

    def reset(self, t, xc, jump):
        return np.full(2, np.nan)

    def compiled(self):
        return CompiledBlock(_count_output, _count_update, [], _nan_reset)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_a_reset_to_a_non_finite_state_is_refused_on_both_paths(compiled):
    """The one block stepper checks a reset's state as it checks an update's (the compiled
    loop used to keep the NaN state silently). First impact: sqrt(2 / 9.81) = 0.4515 s."""
    with pytest.raises(ModelError, match=r"^controller: returned a non-finite value at "
                                         r"t = 0\.45") as info:
        nsc.simulate(nsc.closed_loop(ball(), NaNReset(), compiled=compiled), [1.0, 0.0],
                     (0.0, 3.0), method="moreau_jean", h=1e-3, progress=False)
    assert info.value.trajectory is not None and 0.44 < info.value.trajectory.t[-1] < 0.46
