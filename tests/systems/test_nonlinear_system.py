"""NonlinearSystem: validation, the state transition of the DOP853 path against closed forms,
inputs (a forced orbit by shooting), pickling, and check_system."""

import pickle

import numpy as np
import pytest
import scipy.linalg

from nscontrol import simulate
from nscontrol.analysis.orbits import Forced, find_orbit
from nscontrol.errors import DimensionError, ModelError
from nscontrol.systems import NonlinearSystem
from nscontrol.testing import check_system
from nscontrol.testing.cycle_problems import polar_normal_form

RTOL = 1e-11            # the switching method's default DOP853 tolerances
A = np.array([[0.0, 1.0], [-1.0, -0.5]])     # damped oscillator, |e^{At}| <= ~1.2


def _linear(t, x):
    return A @ x


def _linear_jacobian(t, x):
    return A


def _forced(t, x, u):
    return A @ x + np.array([0.0, u[0]])


W = 1.3     # forcing frequency


def _cosine(t):
    return np.cos(W * np.asarray(t))


@pytest.mark.parametrize(("args", "kwargs", "error", "match"), [
    ((0, _linear), {}, DimensionError, r"n_states"),
    ((2, "x'"), {}, ModelError, r"field: expected a callable field\(t, x\)"),
    ((2, lambda t, x: np.zeros(3)), {}, DimensionError,
     r"field: expected field\(t, x\) of shape \(2,\), got \(3,\)"),
    ((2, lambda t, x: np.full(2, np.nan)), {}, ModelError, r"field: returned non-finite values"),
    ((2, _linear, lambda t, x: np.eye(3)), {}, DimensionError, r"jacobian: expected shape"),
    ((2, _linear, 3.0), {}, ModelError, r"jacobian: expected a callable"),
    ((2, _linear), {"state_names": ("x",)}, DimensionError, r"state_names: expected 2 names"),
    ((2, _linear), {"u": 1.0}, ModelError, r"u: an input was given but n_inputs = 0"),
    ((2, _forced), {"n_inputs": 1, "u": [1.0, 2.0]}, DimensionError, r"u"),
], ids=["n_states", "field-type", "field-shape", "field-nan", "jacobian-shape",
        "jacobian-type", "names", "u-without-inputs", "u-length"])
def test_construction_refuses_bad_models(args, kwargs, error, match):
    with pytest.raises(error, match=match):
        NonlinearSystem(*args, **kwargs)


def test_a_run_refuses_an_input_for_a_system_without_inputs():
    with pytest.raises(ModelError, match=r"u: an input was given but the system has"):
        simulate(NonlinearSystem(2, _linear), [1.0, 0.0], (0.0, 1.0), u=1.0)


@pytest.mark.parametrize("jacobian", [_linear_jacobian, None], ids=["exact", "differences"])
def test_state_transition_of_a_linear_field_is_the_exponential(jacobian):
    sys_ = NonlinearSystem(2, _linear, jacobian)
    tr = simulate(sys_, [1.0, -0.3], (0.0, 5.0), sensitivity=True)
    expected = scipy.linalg.expm(5.0 * A)
    # DOP853 keeps each step's local error below rtol·|y|; over the ~50 steps of this
    # contracting flow the global error stays below 100·rtol (a factor 2 margin on the steps);
    # central differences add rounding ε/δ = ε^{2/3} ~ 4e-11 per Jacobian (f''' = 0 here)
    tol = 100 * RTOL + (0.0 if jacobian else 100 * np.finfo(float).eps ** (2 / 3))
    assert np.max(np.abs(tr.stats["state_transition"] - expected)) <= tol
    assert np.max(np.abs(tr.x[-1] - expected @ [1.0, -0.3])) <= 100 * RTOL
    assert tr.method == "switching" and tr.stats["saltation_matrices"].shape == (0, 2, 2)


def test_forced_orbit_by_shooting_matches_the_harmonic_response():
    # x'' + 0.5x' + x = cos(ωt): the periodic response is Re(e^{iωt}/(1 - ω² + 0.5iω))
    w, cosine = W, _cosine
    sys_ = NonlinearSystem(2, _forced, lambda t, x, u: A, n_inputs=1, u=cosine)
    H = 1.0 / (1.0 - w ** 2 + 0.5j * w)
    exact = np.array([H.real, (1j * w * H).real])
    T = 2 * np.pi / w
    orbit = find_orbit(Forced(sys_, cosine, T), [0.0, 0.0])
    # Newton converges to within the map's integration error (100·rtol, as above) divided by
    # the smallest singular value of (M - I), M = e^{AT} (|μ| = e^{-T/4} ~ 0.3: σ_min >= 0.7)
    assert np.max(np.abs(orbit.x0 - exact)) <= 100 * RTOL / 0.7
    assert np.max(np.abs(orbit.monodromy - scipy.linalg.expm(A * T))) <= 100 * RTOL
    # the system's own input is used when simulate gets none; an override replaces it
    free = simulate(sys_, exact, (0.0, T)).x[-1]
    assert np.max(np.abs(free - exact)) <= 100 * RTOL
    zero = simulate(sys_, [0.0, 0.0], (0.0, T), u=0.0).x[-1]
    assert np.all(zero == 0.0)


def test_a_system_of_module_level_callables_pickles():
    sys_, _ = polar_normal_form()
    back = pickle.loads(pickle.dumps(sys_))
    a = simulate(sys_, [1.5, 0.0], (0.0, 2.0))
    b = simulate(back, [1.5, 0.0], (0.0, 2.0))
    np.testing.assert_array_equal(a.x, b.x)


def test_check_system_passes():
    assert check_system(NonlinearSystem(2, _linear, state_names=("q", "v"))).passed
    assert check_system(polar_normal_form()[0]).passed
