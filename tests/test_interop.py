"""python-control interop: a ``control.StateSpace`` is accepted wherever a linear part is
needed, through one converter; ``Trajectory.to_pandas`` (python-control's name)."""

import sys

import numpy as np
import pytest

from nscontrol.errors import DimensionError, ModelError
from nscontrol.laws import Relay
from nscontrol.numerics import LTIFlow, state_space_matrices
from nscontrol.systems import LureSystem, PiecewiseAffineSystem

control = pytest.importorskip("control")

EPS = np.finfo(float).eps
# damped Coulomb oscillator: x = (q, q'), w enters q'', z = q' feeds the relay, y = q
A = np.array([[0.0, 1.0], [-1.0, -0.1]])
G = np.array([[0.0], [1.0]])
H = np.array([[0.0, 1.0]])
B = np.array([[0.0], [1.0]])
C = np.array([[1.0, 0.0]])


def test_converter_accepts_single_input_single_output_models():
    m = state_space_matrices(control.ss(A, B, C, 0))
    assert (m.A.shape, m.B.shape, m.C.shape, m.D.shape) == ((2, 2), (2, 1), (1, 2), (1, 1))
    np.testing.assert_array_equal(m.A, A)
    with pytest.raises(ModelError, match="continuous-time"):
        state_space_matrices(control.ss(A, B, C, 0, dt=0.1))
    with pytest.raises(ModelError, match="^ss: expected a state-space model"):
        state_space_matrices(A)


def test_lure_system_from_statespace_equals_the_matrices():
    ss = control.ss(A, np.hstack([G, B]), np.vstack([H, C]), np.zeros((2, 2)))
    plant = LureSystem(ss, Relay(1.0), u=np.array([0.5]))
    ref = LureSystem(A, G, H, Relay(1.0), B=B, C=C, u=np.array([0.5]))
    for key in ("A", "G", "H", "B", "C", "D"):  # a pure split: bit-for-bit equal
        np.testing.assert_array_equal(getattr(plant, key), getattr(ref, key))
    assert isinstance(plant.law, Relay)
    assert LureSystem(ss, law=Relay(1.0)).n_multipliers == 1


def test_single_output_statespace_is_a_lure_system():
    """Only z (no measured output): accepted; C is what C= says, else the whole state."""
    ss = control.ss(A, G, H, 0)
    np.testing.assert_array_equal(LureSystem(ss, Relay(1.0)).C, np.eye(2))
    np.testing.assert_array_equal(LureSystem(ss, Relay(1.0), C=C).C, C)


def test_statespace_with_too_few_channels_or_extra_matrices_is_refused():
    with pytest.raises(DimensionError, match="at least 2 inputs"):
        LureSystem(control.ss(A, G, H, 0), Relay(np.ones(2)))
    with pytest.raises(ModelError, match="^G: a StateSpace already holds"):
        LureSystem(control.ss(A, G, H, 0), G, law=Relay(1.0))


def test_missing_channels_are_explained():
    with pytest.raises(ModelError) as info:
        LureSystem(A, law=Relay(1.0))
    msg = str(info.value)
    assert msg.startswith("G, H: missing")
    assert "input channel" in msg and "output channel" in msg and "B and C" in msg


def test_lti_flow_of_a_statespace_is_the_flow_of_its_a():
    ss = control.ss(A, B, C, 0)
    t = np.linspace(0.0, 3.0, 7)
    # the same matrix reaches the same code: bit-for-bit equal
    np.testing.assert_array_equal(LTIFlow(ss).expm(t), LTIFlow(A).expm(t))
    assert LTIFlow.shared(ss) is LTIFlow.shared(A)


def test_pwa_modes_as_statespaces():
    A1 = np.array([[0.0, 1.0], [-6.0, -0.1]])
    pwa = PiecewiseAffineSystem.bimodal(control.ss(A1, B, C, 0), control.ss(A, B, C, 0),
                                        [1.0, 0.0])
    ref = PiecewiseAffineSystem.bimodal(A1, A, [1.0, 0.0], E=B, C=C)
    for a, b in zip(pwa.A, ref.A, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(pwa.E, B)
    np.testing.assert_array_equal(pwa.C, C)
    with pytest.raises(ModelError, match="^E: the StateSpace modes have different B"):
        PiecewiseAffineSystem.bimodal(control.ss(A1, B, C, 0), control.ss(A, 2 * B, C, 0),
                                      [1.0, 0.0])


def _lyapunov_max_eig(Acl, P, sigma):
    M = Acl.T @ P + P @ Acl + 2.0 * sigma * P
    # rounding of forming M: n u |Acl| |P| per product (Higham), factor 10 for the sums
    tol = 10 * len(P) * EPS * (np.linalg.norm(Acl, 2) + sigma) * np.linalg.norm(P, 2)
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[-1]), tol


def test_convergent_designs_take_a_statespace():
    from nscontrol.design import design_observer, design_state_feedback

    ss = control.ss(A, B, C, 0)
    sf = design_state_feedback(ss, sigma=0.3)  # B from the StateSpace
    lam, tol = _lyapunov_max_eig(A + B @ sf.K, sf.P, 0.3)
    assert lam <= tol
    obs = design_observer(ss, sigma=0.3)  # C from the StateSpace
    np.testing.assert_array_equal(obs.C, C)
    lam, tol = _lyapunov_max_eig(A - obs.L @ C, obs.P, 0.3)
    assert lam <= tol


def test_lure_observer_design_takes_a_statespace_with_its_law():
    from nscontrol.design import design_lure_observer

    ss = control.ss(A, np.hstack([G, B]), np.vstack([H, C]), np.zeros((2, 2)))
    d = design_lure_observer(ss, law=Relay(1.0), variant="basic", tol=1e-2)
    ref = design_lure_observer(LureSystem(A, G, H, Relay(1.0), B=B, C=C), variant="basic",
                               tol=1e-2)
    # the same matrices reach the same bisection: the same certified rate
    assert d.alpha_max == ref.alpha_max
    with pytest.raises(ModelError, match="^law: a StateSpace plant"):
        design_lure_observer(ss)


def test_to_pandas_and_its_alias():
    pytest.importorskip("pandas")
    from nscontrol.simulate import Trajectory

    traj = Trajectory(t=np.array([0.0, 1.0]), x=np.array([[1.0, 2.0], [3.0, 4.0]]),
                      state_names=("q", "v"))
    df = traj.to_pandas()
    assert list(df.columns) == ["q", "v"] and df.index.name == "t"
    assert Trajectory.to_dataframe is Trajectory.to_pandas


def test_missing_pandas_names_the_extra(monkeypatch):
    from nscontrol.simulate import Trajectory

    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas -> ImportError
    traj = Trajectory(t=np.array([0.0, 1.0]), x=np.zeros((2, 1)))
    with pytest.raises(ImportError, match=r"nscontrol\[dataframe\]"):
        traj.to_pandas()


def test_state_names_of_a_state_space_carry_through_the_observer_loop():
    control = pytest.importorskip("control")
    from nscontrol.laws.set_valued import Relay
    from nscontrol.systems.lure import LureSystem

    A, BB, CC = [[0, 1], [-1, -0.1]], [[0, 0], [1, 1]], [[0, 1], [1, 0]]
    named = control.ss(A, BB, CC, 0, states=["pos", "vel"])
    plant = LureSystem(named, Relay(1.0))
    assert plant.state_names == ("pos", "vel")
    from nscontrol.design import design_lure_observer

    d = design_lure_observer(named, law=Relay(1.0), variant="basic", tol=1e-2)
    assert d.closed_loop(plant).state_names == ("pos", "vel", "pos_hat", "vel_hat")
    # python-control's default labels x[0], x[1] are no names: the loop numbers them
    bare = LureSystem(control.ss(A, BB, CC, 0), Relay(1.0))
    assert bare.state_names == ()
    assert d.closed_loop(bare).state_names == ("x1", "x2", "xhat1", "xhat2")
