"""Implicit Euler / θ-method for Lur'e systems: reaching, sliding without chattering, exact
one-step solutions, closed loops stepped together (issue 4 conformance)."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.laws.normal_cone import Complementarity
from nscontrol.laws.product import Product
from nscontrol.laws.relay import Relay
from nscontrol.systems.lure import LureSystem
from nscontrol.testing import setvalued_problems as sp


def _reach_index(z):
    return int(np.argmax(np.all(z == 0.0, axis=1)))


@pytest.mark.parametrize("theta", [1.0, 0.5])
def test_relay_feedback_reaches_within_one_step_and_slides_exactly(theta):
    p = sp.relay_feedback()
    h = 1e-3
    tr = simulate(p.system, p.x0, p.t_span, h=h, theta=theta)
    assert tr.stats["solver"] == "closed_form"
    k = _reach_index(tr.signal("z"))
    assert abs(tr.t[k] - p.facts["reaching_time"]) <= h
    assert np.all(tr.signal("z")[k:] == 0.0)            # never leaves: no chattering
    assert np.max(np.abs(tr.signal("y")[k:])) <= 1e-12
    err = np.max(np.abs(tr.x - p.facts["exact"](tr.t)))
    assert err <= 3 * h
    # the multiplier in sliding is the equivalent control w_eq = x1 (to first order in h)
    w = tr.signal("w")[k + 1:, 0]
    assert np.max(np.abs(w - p.facts["equivalent_control"](tr.t[k + 1:]))) <= 3 * h


def test_scalar_relay_with_disturbance_equivalent_control_exact():
    p = sp.relay_scalar()
    h = 1e-3
    tr = simulate(p.system, p.x0, p.t_span, h=h)
    k = _reach_index(tr.signal("z"))
    # the O(h) state error before reaching (backward Euler samples d at t_{k+1}) divided by
    # the approach speed 1 - |a| = 0.5 bounds the reaching-time error by about 2 steps here
    assert abs(tr.t[k] - p.facts["reaching_time"]) <= 2 * h
    assert np.max(np.abs(tr.x[k:])) <= 1e-12
    # in sliding, backward Euler cancels the disturbance at t_{k+1} exactly: w = -d(t_{k+1})
    w = tr.signal("w")[k + 1:, 0]
    assert np.max(np.abs(w - p.facts["equivalent_control"](tr.t[k + 1:]))) <= 1e-12


def test_step_halving_converges_at_first_order():
    p = sp.relay_feedback(T=3.0)
    errs = []
    for h in (2e-3, 1e-3, 5e-4):
        tr = simulate(p.system, p.x0, p.t_span, h=h)
        errs.append(np.max(np.abs(tr.x - p.facts["exact"](tr.t))))
    assert errs[2] < errs[1] < errs[0]
    assert 1.5 < errs[0] / errs[1] < 3.0


def test_diode_circuit_clamps_with_known_solution():
    p = sp.diode_circuit()
    h = 1e-4
    tr = simulate(p.system, p.x0, p.t_span, h=h)
    assert np.max(np.abs(tr.x - p.facts["exact"](tr.t))) <= 2e-4
    z, w = tr.signal("z")[:, 0], tr.signal("w")[:, 0]
    assert np.min(z) >= 0.0 and np.min(w) >= 0.0
    assert np.max(np.abs(z * w)) == 0.0                  # complementarity holds exactly
    away = np.abs(tr.t - p.facts["clamp_time"]) > 2 * h
    assert np.max(np.abs(w[away] - p.facts["diode_current"](tr.t[away]))) <= 2e-4


def test_lcp_path_matches_shared_inclusion_solver_on_coupled_relays():
    # two relays coupled through a full step matrix D_h: the compiled Lemke loop must
    # agree with the shared laws.solve_inclusion (Python) step by step
    A = np.array([[0.0, 1.0, 0.0], [-1.0, -0.2, 0.5], [0.0, 0.3, -1.0]])
    G = np.array([[0.2, 0.0], [1.0, 0.4], [-0.3, 1.0]])
    H = np.array([[0.0, 1.0, 0.0], [0.0, 0.2, 1.0]])
    from nscontrol.laws.monotone_function import MonotoneFunction  # noqa: F401

    lure = LureSystem(A, G, H, Product(Relay(1.0), Relay(0.5)))
    tr = simulate(lure, [1.0, 2.0, -1.0], (0.0, 2.0), h=1e-2)
    assert tr.stats["solver"] == "lcp"
    from nscontrol.laws.inclusion import solve_inclusion
    from nscontrol.simulate.implicit_euler import step_matrices

    m = step_matrices(lure, 1e-2)
    x = tr.x[0]
    for k in range(1, len(tr.t)):
        a = H @ (m.Phi @ x)
        ref = solve_inclusion(lure.law, m.Dh, a)
        x = m.Phi @ x + m.Gh @ ref.w
        assert np.allclose(tr.signal("w")[k], ref.w, atol=1e-12)
        assert lure.law.graph_residual(tr.signal("z")[k], -tr.signal("w")[k]) <= 1e-12
    assert np.allclose(tr.x[-1], x, atol=1e-12)


def test_plant_and_observer_stepped_together_keep_discrete_lyapunov_decay():
    # ch08 §5.1 (Siconos ObserverLCS): P = I, alpha = 1; one stacked LureSystem, Product law
    A = np.array([[1.0, 1.0], [3.0, 1.0]])
    G = np.array([[-1.0], [1.0]])
    H = np.array([[-1.0, 1.0]])
    B = np.array([[1.0], [2.0]])
    C = np.array([[2.0, 2.0]])
    L = np.array([[1.0], [1.0]])
    Z = np.zeros((2, 2))
    big = LureSystem(
        np.block([[A, Z], [L @ C, A - L @ C]]), np.block([[G, np.zeros((2, 1))],
                                                          [np.zeros((2, 1)), G]]),
        np.block([[H, np.zeros((1, 2))], [np.zeros((1, 2)), H]]),
        Product(Complementarity(1), Complementarity(1)), B=np.vstack([B, B]),
        D=np.eye(2), u=lambda t: 30 * np.sin(50 * np.asarray(t, float)).reshape(-1, 1),
        g=lambda t: np.repeat(30 * np.sin(50 * np.asarray(t, float)).reshape(-1, 1), 2, 1))
    h = 1e-3
    tr = simulate(big, [10.0, 0.0, 0.0, 0.0], (0.0, 2.0), h=h)
    e = tr.x[:, :2] - tr.x[:, 2:]
    V = np.sum(e * e, axis=1)
    assert np.all(V[1:] <= V[:-1] / (1 + 2 * h) * (1 + 1e-9) + 1e-14 * V[0])
    assert np.linalg.norm(e[-1]) <= 10 * np.exp(-2.0)


def test_monotone_function_law_uses_its_resolvent():
    from nscontrol.laws.monotone_function import MonotoneFunction

    law = MonotoneFunction(lambda z: z**3, lambda z: 3 * z**2)
    lure = LureSystem([[0.0]], [[1.0]], [[1.0]], law)
    tr = simulate(lure, [1.0], (0.0, 1.0), h=1e-3)
    assert tr.stats["solver"] == "python"
    # x' = -x^3: x(t) = 1/sqrt(1 + 2t)
    assert abs(tr.x[-1, 0] - 1 / np.sqrt(3.0)) <= 1e-3
