"""The sampled blocks' schedule (``take_sample`` in ``simulate/_block_kernels.py``): a
sampled block takes exactly one sample per instant ``t0 + n T``, at the first step start at
or after it, however long the run, on the compiled loops and on the Python block runner.

The expected samples are computed in exact integer arithmetic: with ``T = (p / q) h`` the
n-th instant's step is ``ceil(n p / q)``, and the sample is taken at that step's start, the
integrator's own ``t0 + j h`` (compared bit for bit: it is the step time the block saw).
The old scheduler (``due += T``, slack ``1e-9 T``) drifts by one rounding per tick and
skipped the sample at tick 21,441 of a 1e-4 s loop, so every case runs past that tick.

Chapter 7's loop is compared with a loop written here in plain numpy: implicit Euler of
``J w' = u - F(w)`` with the Stribeck law's graph solved in closed form, the PD law with
exact friction compensation and the reduced-order observer at the ticks ``k h``. Both sides
perform the same operations in the same order up to the library's own grouping; the two
runs then differ by rounding only: per tick a few ulps of the state (the observer's update
has 6 operations, the step 4), and the closed loop contracts, so the sum over the ticks
stays below ``n_ticks x 16 u x max|x|`` (16: the operations counted, with a factor ~1.5).
"""

import numpy as np
import pytest
from numba import njit

import nscontrol as nsc
from nscontrol.laws import Relay
from nscontrol.systems.feedback import BLOCK_SIGNATURE, CompiledBlock, StaticLaw
from nscontrol.systems.lure import LureSystem

U = np.finfo(float).eps / 2
H = 1e-4


@njit(BLOCK_SIGNATURE, cache=True)
def _count_output(t, xb, y, x, xhat, lam, p):
    return np.zeros(1)


@njit(BLOCK_SIGNATURE, cache=True)
def _count_update(t, xb, y, x, xhat, lam, p):
    return np.array([xb[0] + 1.0, t])


class Counter(StaticLaw):
    """A sampled block whose state is (samples taken, time of the last sample); u = 0."""

    n_states, n_outputs = 2, 1

    def __init__(self, period, compiled):
        self.period, self.has_compiled = period, compiled

    def output(self, t, xc, m):
        return np.zeros(1)

    def update(self, t, xc, m):
        return np.array([xc[0] + 1.0, t])

    def compiled(self):
        return CompiledBlock(_count_output, _count_update, []) if self.has_compiled else None


def plant():
    """x' = -Sign(x) + u with u = 0: the cheapest plant implicit Euler runs with blocks."""
    return LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0), B=np.array([[1.0]]),
                      C=np.array([[1.0]]))


def check_schedule(n_ticks, p, q, compiled, t0=0.0):
    period = p * H / q
    loop = nsc.closed_loop(plant(), Counter(period, compiled), compiled=compiled)
    traj = nsc.simulate(loop, [0.5], (t0, t0 + n_ticks * H), method="implicit_euler", h=H,
                        progress=False)
    assert traj.stats["controller"] == ("compiled" if compiled else "python")
    t, xc = traj.t, traj.signal("xc")
    assert t.size == n_ticks + 1
    # the instants t0 + n T, n = 0..: their steps j_n = ceil(n p / q) before the last tick
    n_instants = (n_ticks - 1) * q // p + 1
    j = -((-np.arange(n_instants) * p) // q)
    # the blocks' state is recorded with the step's end: row i + 1 holds it after the
    # (possible) sample at the step start t[i]
    count, last = xc[1:, 0], xc[1:, 1]
    assert int(count[-1]) == n_instants, "a sample was skipped or doubled"
    taken = np.flatnonzero(np.diff(np.concatenate([[0.0], count])))
    np.testing.assert_array_equal(taken, j)
    np.testing.assert_array_equal(last[taken], t[j])
    # and those are the instants to the step times' rounding (a few ulps of t)
    exact = t0 + np.arange(n_instants) * period
    assert np.all(t[j] >= exact - 8 * U * np.maximum(abs(t0), np.abs(exact)))
    assert np.all(t[j] - exact < H)


CASES = [(1, 1), (5, 1), (5, 2), (7, 3)]       # T = h, 5h, 2.5h, 7h/3
IDS = [f"T={p}h/{q}" for p, q in CASES]


@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_compiled_loop_one_sample_per_instant_over_a_million_ticks(p, q):
    check_schedule(1_000_000, p, q, True)          # ~2.5 s each


@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_python_runner_one_sample_per_instant_past_tick_21441(p, q):
    check_schedule(50_000, p, q, False)


def test_late_start_counts_from_the_first_instant():
    """Far from t = 0 the step times' rounding is larger; the slack scales with |t|."""
    check_schedule(50_000, 5, 2, True, t0=1234.5)
    check_schedule(50_000, 5, 2, False, t0=1234.5)


@pytest.mark.slow
@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_python_runner_one_sample_per_instant_over_a_million_ticks(p, q):
    check_schedule(1_000_000, p, q, False)         # ~20-25 s each
