"""ContactMPC, the sampled MPC block of nscontrol.optimal: its first plan against the pushed
block's closed form, and the closed loop against the theorem of MPC with a terminal
equality constraint (the optimal cost V decreases by at least the stage cost, so the state
reaches the target)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import DimensionError, ModelError  # noqa: E402
from nscontrol.optimal import ContactMPC, PushedBlock, Relaxation  # noqa: E402
from nscontrol.systems import LagrangianSystem  # noqa: E402
from nscontrol.systems.feedback import Controller, Measurement  # noqa: E402

BLOCK = PushedBlock(mass=1.0, mu=0.5, distance=1.0)
U = 15.0
H, STEPS = 0.04, 25          # a horizon of 1 s
W = np.array([10.0, 0.0, 1.0, 0.0])
EFFORT = 1e-2


def frictionless_block() -> LagrangianSystem:
    """The pushed block on a floor without friction (the frictionless Moreau–Jean takes a
    closed loop's Python blocks)."""
    m, g = BLOCK.mass, BLOCK.g
    return LagrangianSystem(np.eye(2) * m, constant_force=[0.0, -m * g],
                            gap_matrix=[[0.0, 1.0]], gap_offset=[0.0],
                            actuation=[[1.0], [0.0]], names=("x", "y"))


def stage_cost(x_next: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``h ((x - x*)ᵀ W (x - x*) + effort |u|²)`` per sample."""
    err = x_next - BLOCK.x_final
    return H * (np.sum(W * err ** 2, axis=1) + EFFORT * np.sum(u ** 2, axis=1))


def check_lyapunov(cost: np.ndarray, ell: np.ndarray, residual: np.ndarray) -> None:
    """MPC with the terminal equality x_N = x*, the model exact: the shifted plan (then rest
    at x*, zero input, zero cost) is feasible at the next sample, so V_{k+1} <= V_k - ℓ_k.
    Each solve is a KKT point to IPOPT's 1e-8 of a problem relaxed by σ = 1e-6 (pairs
    a b <= σ): the cost is exact to (pairs × σ + tol) × multiplier scale; 4 pairs × 25 steps
    × 1e-6 × forces ~10 = 1e-3 bounds the slack per sample."""
    slack = 4 * STEPS * (1e-6 + 1e-8) * 10 + 10 * float(np.max(residual))
    assert np.all(cost[1:] <= cost[:-1] - ell[:-1] + slack)


@pytest.fixture(scope="module")
def frictionless_run():
    plant = frictionless_block()
    mpc = ContactMPC(plant, BLOCK.x_final, STEPS, H, state_weight=W, effort=EFFORT,
                     u_min=-U, u_max=U)
    traj = nsc.simulate(nsc.closed_loop(plant, mpc), BLOCK.x0, (0.0, 3.0),
                        method="moreau_jean", h=H)
    return mpc, traj


def test_is_a_sampled_controller():
    mpc = ContactMPC(BLOCK.system(), BLOCK.x_final, STEPS, H, u_min=-U, u_max=U)
    assert isinstance(mpc, Controller)
    assert mpc.period == H and mpc.n_outputs == 1 and mpc.n_states == 8


def test_first_plan_is_the_least_effort_push_of_the_closed_form():
    """No state weight, terminal constraint, horizon T: the first sample solves the least
    effort push of PushedBlock, whose discrete optimum is in closed form."""
    T, N = 1.0, 50
    mpc = ContactMPC(BLOCK.system(), BLOCK.x_final, N, T / N, state_weight=0.0, effort=1.0,
                     u_min=-U, u_max=U, relaxation=Relaxation(sigma_min=1e-8, tol=1e-10))
    record = mpc.solve(BLOCK.x0)
    J_h = BLOCK.effort_cost_discrete(T, N)
    # relaxed at σ = 1e-8 on 4 N pairs with multipliers of the size of the input (~10):
    # the cost is exact to 4 N σ 10, plus IPOPT's 1e-10 on ~10 N constraints
    assert abs(record[4] - J_h) <= 4 * N * 1e-8 * 10 + 1e-10 * 10 * N * (1 + J_h)
    assert record[2] <= 1e-4          # the residual reported: about √σ at most


def test_closed_loop_reaches_the_target_through_simulate(frictionless_run):
    mpc, traj = frictionless_run
    sig = mpc.signals(traj)
    assert sig["t"].size == round(3.0 / H)
    np.testing.assert_allclose(sig["t"], H * np.arange(sig["t"].size), atol=1e-12)
    # the plant's next state is the plan's first step (the model is the plant: the
    # frictionless Moreau–Jean step, solved to IPOPT's 1e-8 and the relaxation's residual)
    u = traj.signals["u"][1:]
    ell = stage_cost(traj.x[1:], u)
    check_lyapunov(sig["cost"], ell, sig["residual"])
    # V_k >= ℓ_k >= h W_x (x_{k+1} - d)²: the last sample's cost bounds the final error
    bound = np.sqrt(sig["cost"][-1] / (H * W[0]))
    assert abs(traj.x[-1, 0] - BLOCK.distance) <= bound + 1e-6
    assert bound <= 1e-2 and sig["cost"][-1] <= 1e-3 * sig["cost"][0]
    assert np.all(np.abs(u) <= U + 1e-6)
    # each sample ran IPOPT (iterations) or the mode iteration (its KKT solves)
    assert np.all(sig["iterations"] + sig["mode_iterations"] >= 1)
    assert np.all((sig["ipopt"] == 1.0) == (sig["iterations"] >= 1))
    assert np.all(sig["solve_time"] > 0)


def test_frictional_block_sample_by_sample():
    """With friction, the block driven by hand: its output and update at each sample, the
    plant integrated over the sample by simulate with the input held (the closed loop
    through simulate is tests/simulate/test_frictional_blocks.py)."""
    plant = BLOCK.system()
    mpc = ContactMPC(plant, BLOCK.x_final, STEPS, H, state_weight=W, effort=EFFORT,
                     u_min=-U, u_max=U)
    x, xc, rows, us, xs = BLOCK.x0.copy(), np.zeros(mpc.n_states), [], [], []
    for k in range(50):
        t = k * H
        m = Measurement(t, x, x)
        u = mpc.output(t, xc, m)
        xc = mpc.update(t, xc, m)
        run = nsc.simulate(plant, x, (t, t + H), method="moreau_jean", h=H,
                           u=lambda _t, u=u: u)
        x = run.x[-1]
        rows.append(xc)
        us.append(u)
        xs.append(x)
    rows, us, xs = np.array(rows), np.array(us), np.array(xs)
    check_lyapunov(rows[:, 4], stage_cost(xs, us), rows[:, 2])
    bound = np.sqrt(rows[-1, 4] / (H * W[0]))
    assert abs(x[0] - BLOCK.distance) <= bound + 1e-6 and bound <= 1e-2


def test_refusals_name_the_argument():
    with pytest.raises(DimensionError, match="state_weight"):
        ContactMPC(BLOCK.system(), BLOCK.x_final, STEPS, H, state_weight=[1.0, 2.0])
    with pytest.raises(ModelError, match="state_weight"):
        ContactMPC(BLOCK.system(), BLOCK.x_final, STEPS, H, state_weight=-1.0)
    with pytest.raises(ModelError, match="period"):
        ContactMPC(BLOCK.system(), BLOCK.x_final, STEPS, H, period=-1.0)
    with pytest.raises(DimensionError, match="x"):
        ContactMPC(BLOCK.system(), BLOCK.x_final, STEPS, H).solve(np.zeros(3))
