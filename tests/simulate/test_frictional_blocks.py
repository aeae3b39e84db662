"""Frictional Moreau–Jean under a closed loop's Python blocks (``blocks=``): a block sliding
on a floor with Coulomb friction pushed by a sampled Python block against the closed form,
the same PD law as a Python block and folded into the plant against the overdamped closed
form, the blocks' reset at impacts, and ContactMPC regulating the pushed block of
``nscontrol.optimal`` through ``simulate(closed_loop(plant, mpc))``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.systems.feedback import StateFeedback, StaticLaw
from nscontrol.systems.lagrangian import LagrangianSystem

EPS = float(np.finfo(float).eps)
G = 9.81


def floor_block(m: float, mu: float) -> LagrangianSystem:
    """A block ``q = (x, y)`` of mass ``m`` on the floor ``y >= 0`` with friction ``μ``,
    gravity, a force ``u`` along ``x``."""
    return LagrangianSystem(np.eye(2) * m, constant_force=[0.0, -m * G], gap_matrix=[[0.0, 1.0]],
                            gap_offset=[0.0], friction=mu, tangent_matrix=[[1.0, 0.0]],
                            actuation=[[1.0], [0.0]], names=("x", "y"))


@dataclass(eq=False)
class SampledPush:
    """A sampled block pushing with ``F`` until ``t_off``, then nothing; it counts its
    samples and the instants it was asked at."""

    F: float
    t_off: float
    period: float
    n_states: int = 1
    n_outputs: int = 1

    def output(self, t, xc, m):
        return np.array([self.F if t < self.t_off else 0.0])

    def update(self, t, xc, m):
        return xc + 1.0

    def reset(self, t, xc, jump):
        return xc


def test_a_sampled_python_push_on_a_frictional_floor_follows_the_closed_form():
    """Pushed with ``F = 3 μ m g`` from ``v0`` until ``t1``, the block slides at
    ``a1 = F/m - μ g``, then brakes at ``μ g`` and sticks. Each slipping step of θ = ½ adds
    exactly ``h a`` to ``v`` (the friction impulse is ``μ m g h``), and ``x`` is the
    trapezoidal rule of a ``v`` linear on each step (the switch at a step boundary): exact
    but for round-off (``4 n ε`` times the sizes). The step where ``v`` would reverse
    sticks (``v = 0``) from some ``v_k <= μ g h``: the position then ends
    ``v_k/2 (h - v_k/(μ g)) <= μ g h²/8`` beyond the exact stop."""
    m, mu, v0 = 2.0, 0.5, 1.0
    h = 2.0 ** -10                          # binary: t1 = 256 h and the ticks exact
    T, t1, tf = 8 * h, 0.25, 1.5
    F = 3.0 * mu * m * G
    push = SampledPush(F, t1, T)
    loop = nsc.closed_loop(floor_block(m, mu), push)
    assert loop.composition == "blocks"
    traj = nsc.simulate(loop, [0.0, 0.0, v0, 0.0], (0.0, tf), method="moreau_jean", h=h,
                        progress=False)
    a1, b = F / m - mu * G, mu * G
    v1, x1 = v0 + a1 * t1, v0 * t1 + a1 * t1 ** 2 / 2
    t_stop = t1 + v1 / b
    t = traj.t
    v = np.where(t <= t1, v0 + a1 * t, np.maximum(v1 - b * (t - t1), 0.0))
    x = np.where(t <= t1, v0 * t + a1 * t ** 2 / 2,
                 x1 + np.where(t < t_stop, v1 * (t - t1) - b * (t - t1) ** 2 / 2,
                               v1 ** 2 / (2 * b)))
    n = t.size - 1
    scale = v1 + a1 * h
    sliding = t < t_stop - h
    assert np.abs(traj.x[sliding, 2] - v[sliding]).max() <= 4 * n * EPS * scale
    assert np.abs(traj.x[sliding, 0] - x[sliding]).max() <= 4 * n * EPS * scale * tf
    stopped = t >= t_stop + h
    assert np.all(traj.x[stopped, 2] == 0.0)
    err = traj.x[stopped, 0] - x[stopped]
    assert np.all(err >= -4 * n * EPS * scale * tf)
    assert np.all(err <= b * h ** 2 / 8 + 4 * n * EPS * scale * tf)
    # the block's samples: on the integer tick schedule, its output held between them
    n_ticks = int(np.ceil(tf / T))
    assert traj.signals["xc"][-1, 0] == n_ticks
    np.testing.assert_array_equal(traj.signals["u"][1:, 0], np.where(t[1:] - h < t1, F, 0.0))
    # slip (2) while moving, stick (1) once stopped; the floor carries m g h a step
    state = traj.signals["contact_state"][1:, 0]
    assert np.all(state[sliding[1:]] == 2) and np.all(state[stopped[1:]] == 1)
    np.testing.assert_allclose(traj.signals["impulse"][1:, 0], m * G * h, rtol=8 * EPS)


@dataclass(frozen=True)
class PD(StaticLaw):
    """``u = -KP (x - 1) - KD v + μ m g`` written as code (a continuous block)."""

    mu_mg: float
    n_outputs: int = 1
    period: None = None

    def output(self, t, xc, m):
        return np.array([-KP * (m.x[0] - 1.0) - KD * m.x[2] + self.mu_mg])


KP, KD = 4.0, 5.0   # m = 1: x'' = -KP (x - 1) - KD x' while sliding forward: roots -1, -4


def overdamped(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From rest at ``x = 0``: ``x = 1 - 4/3 e^{-t} + 1/3 e^{-4t}``, ``v > 0`` for ``t > 0``
    (the block slides forward all the way: friction is ``-μ m g``, cancelled by the law)."""
    return (1.0 - 4.0 / 3.0 * np.exp(-t) + np.exp(-4.0 * t) / 3.0,
            4.0 / 3.0 * (np.exp(-t) - np.exp(-4.0 * t)))


def test_a_python_pd_block_on_a_frictional_floor_against_the_folded_law():
    """The same law as a Python block (held over each step) and as a ``StateFeedback``
    folded into the plant (implicit in the θ-method). Both follow the overdamped closed
    form; the block is first order, its error of about ``h/2`` times the variation of
    ``u`` (``KP`` = 4, m = 1) so within ``3 h``; the folded run is θ = ½ on a linear
    flow with a constant friction impulse, second order (within ``3 h`` too, and far
    closer); so their difference halves with ``h`` (ratio 2 ± 0.4)."""
    m, mu = 1.0, 0.3
    plant = floor_block(m, mu)
    mu_mg = mu * m * G
    block = nsc.closed_loop(plant, PD(mu_mg))
    folded = nsc.closed_loop(plant, StateFeedback([[-KP, 0.0, -KD, 0.0]], k=[KP + mu_mg]))
    assert block.composition == "blocks" and folded.composition != "blocks"
    diffs, T = [], 2.0
    x_T, v_T = overdamped(np.array(T))
    for h in (4e-3, 2e-3, 1e-3):
        run = dict(method="moreau_jean", h=h, progress=False)
        a = nsc.simulate(block, np.zeros(4), (0.0, T), **run)
        b = nsc.simulate(folded, np.zeros(4), (0.0, T), **run)
        assert a.stats["path"] == b.stats["path"] == "frictional"
        assert np.all(a.signals["contact_state"][1:] == 2)      # slip all along
        assert abs(a.x[-1, 0] - x_T) <= 3 * h and abs(a.x[-1, 2] - v_T) <= 3 * h
        assert abs(b.x[-1, 0] - x_T) <= 3 * h ** 2 and abs(b.x[-1, 2] - v_T) <= 3 * h ** 2
        diffs.append(np.abs(a.x[-1] - b.x[-1]).max())
    for coarse, fine in zip(diffs, diffs[1:], strict=False):
        assert 1.6 < coarse / fine < 2.4


def test_the_blocks_reset_at_an_impact_and_read_the_contact():
    """A block dropped on the frictional floor: the Python block's reset runs once, at the
    landing step (the listener of the impact), and its measurement reads the floor's mean
    force ``λ̂ = P/h = m g`` and the active contact once the block rests."""
    seen, resets = [], []

    @dataclass(eq=False)
    class Watch:
        n_states: int = 0
        n_outputs: int = 1
        period: None = None

        def output(self, t, xc, m):
            seen.append((t, float(m.lam[0]), m.active.tolist()))
            return np.zeros(1)

        def update(self, t, xc, m):
            return xc

        def reset(self, t, xc, jump):
            resets.append((jump.t, jump.indices.tolist()))
            return xc

    h, m = 1e-3, 1.0
    plant = LagrangianSystem(np.eye(2) * m, constant_force=[0.0, -m * G],
                             gap_matrix=[[0.0, 1.0]], gap_offset=[0.0], friction=0.5,
                             tangent_matrix=[[1.0, 0.0]], restitution=0.0,
                             actuation=[[1.0], [0.0]])
    traj = nsc.simulate(nsc.closed_loop(plant, Watch()), [0.0, 0.01, 0.5, 0.0], (0.0, 0.2),
                        method="moreau_jean", h=h, progress=False)
    impacts = traj.event_times("impact")
    assert impacts.size == 1 and len(resets) == 1 and resets[0][1] == [0]
    # the listener is called with the landing step's end: within a step after the event
    assert impacts[0] <= resets[0][0] <= impacts[0] + h
    assert seen[0] == (0.0, 0.0, [])
    # resting: the normal impulse is m g h (θ = ½, e = 0), so λ̂ = m g
    assert seen[-1][2] == [0] and abs(seen[-1][1] - m * G) <= 8 * EPS * m * G


def test_contact_mpc_pushes_the_block_on_a_frictional_floor_through_simulate():
    """ContactMPC with the terminal equality ``x_N = x*`` on the pushed block with Coulomb
    friction, in ``simulate(closed_loop(plant, mpc))``: the model is the plant (the same
    frictional Moreau–Jean step), so the optimal cost decreases by the stage cost from
    sample to sample (up to the relaxation's slack, as tests/optimal/test_mpc.py derives),
    and the last cost bounds the final position error."""
    pytest.importorskip("casadi")
    from nscontrol.optimal import ContactMPC, PushedBlock

    block = PushedBlock(mass=1.0, mu=0.5, distance=1.0)
    U, H, STEPS = 15.0, 0.04, 25
    W, EFFORT = np.array([10.0, 0.0, 1.0, 0.0]), 1e-2
    plant = block.system()
    mpc = ContactMPC(plant, block.x_final, STEPS, H, state_weight=W, effort=EFFORT,
                     u_min=-U, u_max=U)
    traj = nsc.simulate(nsc.closed_loop(plant, mpc), block.x0, (0.0, 2.0),
                        method="moreau_jean", h=H, progress=False)
    assert traj.stats["path"] == "frictional"
    sig = mpc.signals(traj)
    assert sig["t"].size == round(2.0 / H)
    np.testing.assert_allclose(sig["t"], H * np.arange(sig["t"].size), atol=1e-12)
    u = traj.signals["u"][1:]
    err = traj.x[1:] - block.x_final
    ell = H * (np.sum(W * err ** 2, axis=1) + EFFORT * np.sum(u ** 2, axis=1))
    slack = 4 * STEPS * (1e-6 + 1e-8) * 10 + 10 * float(np.max(sig["residual"]))
    assert np.all(sig["cost"][1:] <= sig["cost"][:-1] - ell[:-1] + slack)
    bound = np.sqrt(sig["cost"][-1] / (H * W[0]))
    assert abs(traj.x[-1, 0] - block.distance) <= bound + 1e-6 and bound <= 1e-2
    assert np.all(np.abs(u) <= U + 1e-6)
    # the floor holds: no penetration beyond round-off, the block slid and stopped
    assert traj.stats["max_penetration"] <= 1e-12
    assert np.any(traj.signals["contact_state"][1:, 0] == 2)


def test_listeners_observe_the_frictional_landing():
    """Without blocks, the listeners observe: called once for the landing step (after its
    chunk), with the step's start and end states and the floor's impulse."""
    calls = []
    h = 1e-3
    plant = floor_block(1.0, 0.5)
    traj = nsc.simulate(plant, [0.0, 0.01, 0.5, 0.0], (0.0, 0.2), method="moreau_jean", h=h,
                        progress=False, listeners=[lambda *args: calls.append(args)])
    (t, x_minus, x_plus, contacts, impulse), = calls
    t_impact = traj.event_times("impact")[0]
    assert t_impact <= t <= t_impact + h and contacts.tolist() == [0]
    assert x_minus[3] < 0.0 and x_plus[3] >= 0.0 and impulse[0] > 0.0
