"""The cart-pole between walls (nscontrol.optimal.cartpole) and the contact-implicit MPC on it:
the wall-free step map against the integrator, the unconstrained MPC against the LQR
(principle of optimality), a plan through an impact replayed by simulate, and (slow) the
closed loops of the example: the contact-implicit MPC settles, the linear one loses the
pole."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import DimensionError, ModelError  # noqa: E402
from nscontrol.examples.optimal_cartpole import PARAMETERS, controllers  # noqa: E402
from nscontrol.optimal import CartPole, ContactMPC  # noqa: E402
from nscontrol.optimal.plan import ZeroOrderHold  # noqa: E402

EPS = np.finfo(float).eps
CART = CartPole()
H = PARAMETERS["h"]
W = np.array(PARAMETERS["state_weight"])
EFFORT = PARAMETERS["effort"]


def _mhat_condition() -> float:
    M = CART.system().mass_matrix()
    K = CART.system().stiffness
    return float(np.linalg.cond(M + (H / 2) ** 2 * K))


def test_step_matrices_are_the_integrators_wall_free_step():
    """x_{k+1} = A x_k + B u_k is one Moreau–Jean step of the wall-free model: the same
    M̂ solve, so they agree to κ(M̂) × eps × 100 (a few dozen operations) per unit of state.
    (The walls put far away: the same dynamics, no contact.)"""
    A, B = CART.step_matrices(H)
    far = CartPole(wall=1e6).system()
    rng = np.random.default_rng(3)
    for _ in range(5):
        x, u = rng.normal(size=4), rng.normal(size=1)
        traj = nsc.simulate(far, x, (0.0, H), method="moreau_jean", h=H,
                            u=lambda _t, u=u: u, progress=False)
        scale = 1.0 + np.abs(x).max() + np.abs(u).max()
        assert np.abs(traj.x[-1] - (A @ x + B @ u)).max() <= 100 * _mhat_condition() * EPS * scale


def test_nonlinear_cart_pole_linearises_to_the_model():
    """At the upright pole the nonlinear model's mass, force Jacobian and gaps are the
    linear model's (exactly: cos 0 = 1, sin 0 = 0); and its force is the Lagrangian's: a free
    swing from 1 rad, integrated by scipy's DOP853 at rtol 1e-11 from the model's own mass
    and force, keeps ½ vᵀM(q)v + m_p g l cos θ to 1e-8 relative (a wrong sign or factor in
    the centrifugal or gravity term changes the energy by O(1))."""
    from scipy.integrate import solve_ivp
    lin, nl = CART.system(), CART.nonlinear_system()
    z = np.zeros(2)
    np.testing.assert_array_equal(nl.mass(z), lin.mass_matrix())
    Jq, Jv = nl.force_jacobian(0.0, z, z)
    np.testing.assert_array_equal(Jq, -lin.stiffness)
    np.testing.assert_array_equal(Jv, np.zeros((2, 2)))
    np.testing.assert_array_equal(nl.gap(z), lin.gap_offset)
    np.testing.assert_array_equal(nl.jacobian(z), lin.dense_gap_matrix())
    mp, l, g = CART.pole_mass, CART.length, CART.g

    def rhs(_t, x):
        return np.r_[x[2:], np.linalg.solve(nl.mass(x[:2]), nl.force(0.0, x[:2], x[2:]))]

    def energy(x):
        return 0.5 * x[2:] @ nl.mass(x[:2]) @ x[2:] + mp * g * l * np.cos(x[1])

    x0 = np.array([0.0, 1.0, 0.3, -0.5])
    sol = solve_ivp(rhs, (0.0, 3.0), x0, method="DOP853", rtol=1e-11, atol=1e-12)
    E = np.array([energy(x) for x in sol.y.T])
    assert np.abs(E - E[0]).max() <= 1e-8 * abs(E[0])
    assert np.abs(sol.y[1]).max() > 2.0                   # it swings far: a real test
    # the small-angle error: sin θ - θ = O(θ³) in the tip's position
    x = np.array([0.01, 0.1, 0.0, 0.0])
    assert abs(CART.tip(x, linear=False) - CART.tip(x)) <= CART.length * 0.1 ** 3 / 6


def test_lqr_solves_its_riccati_equation():
    A, B = CART.step_matrices(H)
    K, P = CART.lqr(H, W, EFFORT)
    Wd = np.diag(W)
    Q, R, N = H * A.T @ Wd @ A, H * (B.T @ Wd @ B + EFFORT), H * A.T @ Wd @ B
    rhs = Q + A.T @ P @ A - (A.T @ P @ B + N) @ np.linalg.solve(R + B.T @ P @ B,
                                                                B.T @ P @ A + N.T)
    # scipy's Schur solver: backward stable, residual ~ cond × eps × |P|; cond of the
    # symplectic pencil here below 1e6
    assert np.abs(rhs - P).max() <= 1e6 * EPS * np.abs(P).max()
    assert np.abs(np.linalg.eigvals(A - B @ K)).max() < 1.0


def test_unconstrained_mpc_with_the_lqr_terminal_cost_is_the_lqr():
    """Principle of optimality: with the LQR value as terminal cost and no active bound, the
    MPC's cost over N steps is the infinite-horizon one, so its first input is -K x. IPOPT
    solves the QP to 1e-8 on the KKT conditions; the input is exact to that times the
    conditioning of the reduced Hessian (below 1e2 here): 1e-6 relative."""
    K, P = CART.lqr(H, W, EFFORT)
    mpc = ContactMPC(CART.free_system(), np.zeros(4), 20, H, state_weight=W, effort=EFFORT,
                     terminal=False, terminal_weight=P)
    for x in ([0.0, 0.05, 0.0, 0.2], [0.1, -0.02, 0.3, 0.0]):
        x = np.array(x)
        mpc.solve(x)
        u = mpc.plan["U"][:, 0]
        assert np.abs(u + K @ x).max() <= 1e-6 * (1.0 + np.abs(K @ x).max())


def test_a_plan_through_an_impact_replays_through_simulate():
    """The first plan from a pole kicked towards the right wall hits it; fed its inputs, the
    library's Moreau–Jean run gives back its states. The plan's contact law is relaxed to
    σ = 1e-6 and holds to its residual r (the largest |min(λ, G v⁺ + e G v)|): a step either
    carries a force up to r where none acts (velocities off by h ‖M̂⁻¹Gᵀ‖ r) or leaves a
    normal velocity up to r short of Newton's law (velocities off by r / min_j ‖G_j‖); over
    N steps the difference is amplified by at most ‖A‖^N (the unstable pole). The bound below
    is 10 × N × that (r floored at IPOPT's 1e-8 on the dynamics)."""
    mpc = controllers(CART)["contact"]
    x0 = np.array([0.0, 0.0, 0.0, 3.0])
    record = mpc.solve(x0)
    plan = mpc.plan
    assert plan["LN"].max() > 1.0              # the plan pushes on a wall
    replay = nsc.simulate(CART.system(), x0, (0.0, 25 * H), method="moreau_jean", h=H,
                          u=ZeroOrderHold(0.0, H, plan["U"].T), progress=False)
    s = CART.system()
    A, _ = CART.step_matrices(H)
    gain = np.linalg.norm(np.linalg.solve(s.mass_matrix() + (H / 2) ** 2 * s.stiffness,
                                          s.dense_gap_matrix().T), 2)
    amplification = np.linalg.norm(A, 2) ** 25
    per_step = H * gain + 1.0 / np.linalg.norm(s.dense_gap_matrix(), axis=1).min()
    bound = 10 * 25 * per_step * max(record[2], 1e-8) * amplification + 1e-9
    assert np.abs(replay.x - plan["X"].T).max() <= bound


def test_a_sample_that_closes_no_contact_solves():
    """Far from the walls the plan closes no contact, so it has no complementarity pair and
    σ appears nowhere in the NLP (once a CasADi error on the unused parameter); its plan
    must still start at the measured state."""
    mpc = ContactMPC(CART.system(), np.zeros(4), 10, H, u_min=-5.0, u_max=5.0,
                     terminal=False)
    x0 = np.array([0.0, 0.0, 0.0, 0.1])
    record = mpc.solve(x0)
    assert record[1] >= 1 and record[2] == 0.0
    np.testing.assert_allclose(mpc.plan["X"][:, 0], x0, atol=1e-8)


def test_terminal_weight_refusals_name_the_argument():
    with pytest.raises(DimensionError, match="terminal_weight"):
        ContactMPC(CART.system(), np.zeros(4), 5, H, terminal_weight=np.eye(3))
    with pytest.raises(ModelError, match="terminal_weight"):
        ContactMPC(CART.system(), np.zeros(4), 5, H, terminal_weight=-np.eye(4))
    with pytest.raises(ModelError, match="terminal_weight"):
        ContactMPC(CART.system(), np.zeros(4), 5, H, terminal_weight=np.triu(np.ones((4, 4))))
    with pytest.raises(ModelError, match="restitution"):
        CartPole(restitution=1.5)


@pytest.mark.slow
def test_contact_implicit_mpc_settles_where_linear_mpc_loses_the_pole():
    from nscontrol.examples.optimal_cartpole import PARAMETERS, run_controllers

    runs = run_controllers()
    mpc, traj = runs["contact"]
    _, lin = runs["linear"]
    late = traj.t >= PARAMETERS["settle_time"]
    assert np.abs(traj.x[late]).max() <= PARAMETERS["settle_bound"]
    assert np.count_nonzero(np.abs(traj.signals["impulse"]).sum(axis=1)) >= 1
    assert np.abs(lin.x[:, 1]).max() >= PARAMETERS["fallen_angle"]
    assert PARAMETERS["fallen_angle"] >= np.pi / 2           # past the horizontal
    sig = mpc.signals(traj)
    assert sig["t"].size == round(PARAMETERS["T"] / PARAMETERS["h"])
    assert np.all(sig["cpu_time"] > 0)
    assert np.all(sig["iterations"] + sig["mode_iterations"] >= 1)
    assert sig["residual"].max() <= 1e-3      # relaxed at σ = 1e-6: √σ at most
