"""``implicit_euler(sensitivity=True)``: the exact Jacobian of the discrete map ``x_0 -> x_N``
against central differences of that same map, on every solver path (closed form, LCP,
Python resolvent), and the report of degenerate (corner) steps."""

import warnings

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import ModelError, NscontrolWarning
from nscontrol.laws.monotone_function import MonotoneFunction, PiecewiseLinearFunction
from nscontrol.laws.normal_cone import NormalConeInterval
from nscontrol.laws.product import Product
from nscontrol.laws.relay import Relay
from nscontrol.simulate.methods import ImplicitEuler
from nscontrol.systems.lure import LureSystem

EPS = np.finfo(float).eps
A2 = np.array([[0.0, 1.0], [-1.0, -0.3]])


def _forcing(t):
    return np.array([2.0 * np.cos(1.3 * t)])


def _lure(law, G=((0.0,), (1.0,)), H=((1.0, 0.5),)):
    return LureSystem(A2, np.array(G), np.array(H), law, B=[[0.0], [1.0]], u=_forcing)


def _discrete_map(system, h, tf):
    return lambda x: simulate(system, x, (0.0, tf), method="implicit_euler", h=h).x[-1]


def _central_differences(P, x, delta):
    return np.column_stack([(P(x + delta * e) - P(x - delta * e)) / (2 * delta)
                            for e in np.eye(x.shape[0])])


def _rounding_bound(n_steps, x, J, delta):
    """Rounding of a central difference of the discrete map: each of the ``n_steps`` steps
    rounds the state by about ``ε(1 + |x|)``, carried to the end by at most ``1 + |J|``
    (the partial products of a contracting run), and the difference divides by ``δ``; a
    factor 4 for the two evaluations and the step's few operations."""
    return 4 * n_steps * EPS * (1 + np.max(np.abs(x))) * (1 + np.max(np.abs(J))) / delta


@pytest.mark.parametrize("law, solver", [
    (Relay(1.5), "closed_form"),                  # slides about 100 of the 400 steps
    (NormalConeInterval(-0.4, 0.4), "closed_form"),   # on a face about 225 steps
    (PiecewiseLinearFunction.saturation(1.0, 5.0), "lcp"),
])
def test_piecewise_affine_step_laws_match_central_differences(law, solver):
    # with these laws every step is affine in x_k on its active set, so the discrete map is
    # piecewise affine and its central difference is exact up to rounding when no step changes
    # its active set within ±δ (no truncation term)
    system, h, tf = _lure(law), 2 * np.pi / 1.3 / 400, 2 * np.pi / 1.3
    x0 = np.array([0.3, -0.2])
    tr = simulate(system, x0, (0.0, tf), method="implicit_euler", h=h, sensitivity=True)
    J = tr.stats["state_transition"]
    assert tr.stats["solver"] == solver and tr.stats["degenerate_steps"] == 0
    delta = 1e-5
    fd = _central_differences(_discrete_map(system, h, tf), x0, delta)
    assert np.max(np.abs(J - fd)) <= _rounding_bound(400, tr.x, J, delta)


def test_relay_sliding_makes_the_map_rank_deficient():
    # a sliding step projects on z = Hx = 0 (ρ = 0): J_k = (I - G_h D_h⁻¹ H) Φ with
    # H (I - G_h D_h⁻¹ H) = 0, so one sliding step makes the whole product singular
    system = _lure(Relay(1.0))
    tf = 2 * np.pi / 1.3
    tr = simulate(system, [0.3, -0.2], (0.0, tf), method="implicit_euler", h=tf / 400,
                  sensitivity=True)
    assert np.any(tr.signal("z") == 0.0)       # it slides on the way
    J = tr.stats["state_transition"]
    # det of a 2x2 product with a zero factor: rounding of the two products, ε|J|²
    assert abs(np.linalg.det(J)) <= 8 * EPS * np.max(np.abs(J)) ** 2


def test_trapezoidal_steps_are_differentiated_too():
    # θ = 1/2 changes Φ, G_h and D_h, not the argument: still exact up to rounding
    system, h, tf = _lure(Relay(1.5)), 0.01, 3.0
    x0 = np.array([0.3, -0.2])
    tr = simulate(system, x0, (0.0, tf), method="implicit_euler", h=h, theta=0.5,
                  sensitivity=True)
    J = tr.stats["state_transition"]

    def P(x):
        return simulate(system, x, (0.0, tf), method="implicit_euler", h=h, theta=0.5).x[-1]

    fd = _central_differences(P, x0, 1e-5)
    assert np.max(np.abs(J - fd)) <= _rounding_bound(300, tr.x, J, 1e-5)


def test_full_step_matrix_lcp_path_matches_central_differences():
    # two relays coupled through a full D_h (one LCP a step)
    law = Product(Relay(1.0), Relay(0.5))
    G = ((1.0, 0.2), (0.3, 1.0))
    H = ((1.0, 0.1), (0.1, 1.0))     # H G has a positive definite symmetric part
    system = LureSystem(A2, np.array(G), np.array(H), law, B=[[0.0], [1.0]], u=_forcing)
    h, tf = 0.01, 3.0
    x0 = np.array([0.8, 0.4])
    tr = simulate(system, x0, (0.0, tf), method="implicit_euler", h=h, sensitivity=True)
    assert tr.stats["solver"] == "lcp" and tr.stats["degenerate_steps"] == 0
    J = tr.stats["state_transition"]
    delta = 1e-5
    fd = _central_differences(_discrete_map(system, h, tf), x0, delta)
    # the LCP's accepted residual is a second rounding source, carried like the first
    floor = tr.stats["max_residual"] * 300 * (1 + np.max(np.abs(J))) / delta
    assert np.max(np.abs(J - fd)) <= _rounding_bound(300, tr.x, J, delta) + floor


def test_curved_law_uses_its_derivative_at_the_solution():
    # w = -tanh(z) (Python resolvent path): the map is smooth, so the central difference has
    # a truncation error O(δ²); Richardson's estimate |FD(2δ) - FD(δ)| is 3x that error
    law = MonotoneFunction(np.tanh, df=lambda z: 1.0 / np.cosh(z) ** 2)
    system, h, tf = _lure(law), 0.02, 4.0
    x0 = np.array([0.5, 0.1])
    tr = simulate(system, x0, (0.0, tf), method="implicit_euler", h=h, sensitivity=True)
    J = tr.stats["state_transition"]
    P = _discrete_map(system, h, tf)
    delta = 1e-4
    fd, fd2 = _central_differences(P, x0, delta), _central_differences(P, x0, 2 * delta)
    truncation = np.max(np.abs(fd2 - fd))
    # the resolvent is solved to a few ulps of z: a rounding source like the state's own
    assert np.max(np.abs(J - fd)) <= truncation + _rounding_bound(200, tr.x, J, delta)


def test_sensitivity_without_df_uses_a_central_difference_of_f():
    # f' by a central difference of step ε^(1/3): error O(ε^(2/3)) per step, relative
    exact = MonotoneFunction(np.tanh, df=lambda z: 1.0 / np.cosh(z) ** 2)
    approx = MonotoneFunction(np.tanh)
    runs = [simulate(_lure(law), [0.5, 0.1], (0.0, 2.0), method="implicit_euler", h=0.02,
                     sensitivity=True).stats["state_transition"] for law in (exact, approx)]
    assert np.max(np.abs(runs[0] - runs[1])) <= 100 * EPS ** (2 / 3) * (1 + np.max(np.abs(runs[0])))


def test_a_step_ending_at_a_corner_of_the_graph_is_reported():
    # x' = w, w ∈ -Sign(x), x0 = h: the first step lands on z = 0 with w = -1, the corner of
    # the relay's graph where the map x -> x - h sign(x) is not differentiable
    system = LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0))
    with pytest.warns(NscontrolWarning, match="corner of the law's graph"):
        tr = simulate(system, [0.1], (0.0, 0.5), method="implicit_euler", h=0.1,
                      sensitivity=True)
    assert tr.stats["degenerate_steps"] == 1
    assert tr.stats["first_degenerate_time"] == pytest.approx(0.1, rel=1e-15)
    # the constraint-active one-sided derivative is used: after sliding, nothing is remembered
    assert tr.stats["state_transition"][0, 0] == 0.0


def test_no_warning_and_no_degenerate_step_off_the_corners():
    system = LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr = simulate(system, [0.123], (0.0, 0.5), method="implicit_euler", h=0.1,
                      sensitivity=True)
    assert tr.stats["degenerate_steps"] == 0 and tr.stats["first_degenerate_time"] is None


def test_capability_is_declared_and_input_can_be_overridden():
    assert "sensitivity" in ImplicitEuler.capabilities
    system = _lure(Relay(1.0))
    bare = LureSystem(A2, system.G, system.H, Relay(1.0), B=[[0.0], [1.0]])
    a = simulate(system, [0.3, 0.0], (0.0, 1.0), method="implicit_euler", h=0.01)
    b = simulate(bare, [0.3, 0.0], (0.0, 1.0), method="implicit_euler", h=0.01, u=_forcing)
    assert np.array_equal(a.x, b.x)


def test_input_override_needs_an_input_matrix_and_sensitivity_a_bool():
    system = LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0))
    with pytest.raises(ModelError, match=r"^u: this LureSystem has no input matrix B"):
        simulate(system, [0.1], (0.0, 1.0), method="implicit_euler", h=0.1, u=_forcing)
    with pytest.raises(ModelError, match=r"^sensitivity: expected True or False"):
        simulate(system, [0.1], (0.0, 1.0), method="implicit_euler", h=0.1, sensitivity="yes")
