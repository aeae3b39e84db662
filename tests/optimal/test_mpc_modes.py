"""ContactMPC's warm samples solved as a QP with complementarity by the active-set iteration
on the contact modes (nscontrol.optimal.mpc._ModeQP): the same input as the IPOPT path where
both converge, exact complementarity, the LQR where nothing is active, the fallback to IPOPT
when the iteration does not settle, and the record's columns."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("casadi")

import nscontrol as nsc  # noqa: E402
from nscontrol.errors import ModelError  # noqa: E402
from nscontrol.examples.optimal_cartpole import PARAMETERS, controllers  # noqa: E402
from nscontrol.optimal import CartPole, ContactMPC, Relaxation  # noqa: E402
from nscontrol.optimal.mpc import RECORD  # noqa: E402

EPS = np.finfo(float).eps
CART = CartPole()
H = PARAMETERS["h"]
W = np.array(PARAMETERS["state_weight"])
EFFORT = PARAMETERS["effort"]
COL = {name: i for i, name in enumerate(RECORD)}


def block(**kw):
    """The example's contact-implicit MPC (25 steps, |u| <= 5 N, the LQR terminal cost)."""
    return controllers(CART, **kw)["contact"]


def input_condition(mpc: ContactMPC) -> float:
    """Condition number of the condensed Hessian in the inputs (the states eliminated):
    how much an error in the optimality conditions moves the planned inputs."""
    qp = mpc._mode_qp()
    u = qp.pair_a.min() if qp.pair_a.size else qp.Hy.shape[0]
    return float(np.linalg.cond(qp.Hy[:u, :u]))


def test_the_mode_iteration_gives_the_ipopt_input_along_the_closed_loop():
    """The IPOPT block (relaxed to σ = 1e-8, tol 1e-10) drives the cart-pole through its
    impact on the wall; at each of its samples the mode iteration, started from its own
    shifted plan, returns the same first input. IPOPT accepts a point at its acceptable
    level (1e-6 on the scaled optimality conditions) and the relaxation moves the solution
    by about σ per pair; an error e in the optimality conditions moves the inputs by at most
    cond(H_uu) e: the bound is cond × (1e-6 + 50 σ) × (1 + |u|)."""
    ip = block(solver="ipopt",
               relaxation=Relaxation(sigma_min=1e-8, tol=1e-10))
    traj = nsc.simulate(nsc.closed_loop(CART.system(), ip), [0.0, 0.0, 0.0, 3.0], (0.0, 0.6),
                        method="moreau_jean", h=H, progress=False)
    assert np.count_nonzero(np.abs(traj.signals["impulse"]).sum(axis=1)) >= 1   # the impact
    us = traj.signals["u"][1:, 0]
    qp = block()
    got, records = [], []
    for x in traj.x[:-1]:
        records.append(qp.solve(x))
        got.append(qp.plan["U"][0, 0])
    records = np.array(records)
    assert records[0, COL["ipopt"]] == 1.0 and np.all(records[1:, COL["ipopt"]] == 0.0)
    bound = input_condition(qp) * (1e-6 + 50 * 1e-8) * (1.0 + 5.0)
    assert np.abs(np.array(got) - us).max() <= bound
    assert bound < 1e-2                         # small against the 5 N bound: a real test


def test_a_mode_plan_is_complementary_to_roundoff():
    """A sample solved by the mode iteration holds one side of every pair at zero exactly
    (a force fixed at 0) or to the KKT solve's roundoff (a velocity row held at 0):
    cond(H) × eps × scale, with scale the largest force (~1e3 N) — 1e-9 covers it."""
    mpc = block()
    traj = nsc.simulate(nsc.closed_loop(CART.system(), mpc), [0.0, 0.0, 0.0, 3.0], (0.0, 0.4),
                        method="moreau_jean", h=H, progress=False)
    sig = mpc.signals(traj)
    warm = sig["ipopt"][1:] == 0.0
    assert warm.all() and sig["ipopt"][0] == 1.0
    assert sig["residual"][1:].max() <= 1e-9
    assert np.all(sig["mode_iterations"][1:] >= 1) and np.all(sig["iterations"][1:] == 0)


def test_the_mode_iteration_without_active_constraints_is_the_lqr():
    """Away from walls and bounds the QP is the unconstrained LQ problem whose first input
    is -K x (principle of optimality, the LQR value as terminal cost); the KKT solve is exact
    to cond(H_uu) × eps per unit of input, plus the Riccati solution's own error (its test:
    1e6 eps relative)."""
    K, P = CART.lqr(H, W, EFFORT)
    mpc = ContactMPC(CART.free_system(), np.zeros(4), 20, H, state_weight=W, effort=EFFORT,
                     terminal=False, terminal_weight=P)
    for x in ([0.0, 0.05, 0.0, 0.2], [0.1, -0.02, 0.3, 0.0]):
        x = np.array(x)
        mpc.solve(x)
        record = mpc.solve(x)                     # the second sample: the mode iteration
        assert record[COL["ipopt"]] == 0.0
        u = mpc.plan["U"][:, 0]
        scale = 1.0 + np.abs(K @ x).max()
        bound = (input_condition(mpc) * 100 + 1e6) * EPS * scale
        assert np.abs(u + K @ x).max() <= bound


def test_a_sample_the_iteration_does_not_settle_falls_back_to_ipopt():
    """The plan shifted from a sample at the same state is a poor start at the wall; with
    one KKT solve allowed the iteration cannot settle, and IPOPT solves the sample (its
    residual within √σ)."""
    mpc = block(max_mode_iterations=1)
    x = np.array([0.0, 0.0, 0.0, 3.0])
    mpc.solve(x)
    record = mpc.solve(x)
    assert record[COL["ipopt"]] == 1.0 and record[COL["iterations"]] >= 1
    assert record[COL["residual"]] <= np.sqrt(1e-6)


def test_solver_refusals_name_the_argument():
    with pytest.raises(ModelError, match="solver"):
        block(solver="qp")
    with pytest.raises(ModelError, match="max_mode_iterations"):
        block(max_mode_iterations=0)


def test_dependent_rows_held_are_solved_without_ipopt():
    """The frictionless block resting on its floor with the terminal equality x_N = x*: the
    floor's velocity rows held at zero already imply the terminal y and y', so the KKT
    matrix has dependent rows. They are consistent; the least-norm solve keeps the sample
    in the mode iteration, and the plan matches the IPOPT block's within cond(H_uu) × (1e-6
    + pairs × σ) × (1 + |u|), as above."""
    from nscontrol.optimal import PushedBlock
    from nscontrol.systems import LagrangianSystem

    pushed = PushedBlock(mass=1.0, mu=0.5, distance=1.0)
    plant = LagrangianSystem(np.eye(2), constant_force=[0.0, -9.81], gap_matrix=[[0.0, 1.0]],
                             gap_offset=[0.0], actuation=[[1.0], [0.0]], names=("x", "y"))
    kw = dict(state_weight=[10.0, 0.0, 1.0, 0.0], effort=1e-2, u_min=-15.0, u_max=15.0)
    mpc = ContactMPC(plant, pushed.x_final, 25, 0.04, **kw)
    ip = ContactMPC(plant, pushed.x_final, 25, 0.04, solver="ipopt",
                    relaxation=Relaxation(sigma_min=1e-8, tol=1e-10), **kw)
    traj = nsc.simulate(nsc.closed_loop(plant, ip), pushed.x0, (0.0, 0.4), method="moreau_jean",
                        h=0.04, progress=False)
    got, records = [], []
    for x in traj.x[:-1]:
        records.append(mpc.solve(x))
        got.append(mpc.plan["U"][0, 0])
    warm = np.array(records)[1:]
    assert np.all(warm[:, COL["ipopt"]] == 0.0) and warm[:, COL["residual"]].max() <= 1e-9
    bound = input_condition(mpc) * (1e-6 + 25 * 1e-8) * (1.0 + 15.0)
    assert np.abs(np.array(got) - traj.signals["u"][1:, 0]).max() <= bound
    assert bound < 1.0                                       # against 15 N
