"""The sampled blocks' schedule (``take_sample`` in ``simulate/_block_kernels.py``): a
sampled block takes exactly one sample per instant ``t0 + n T``, at the first step start at
or after it, however long the run, on the compiled loops and on the Python block runner.

The expected samples are computed in exact integer arithmetic: with ``T = (p / q) h`` the
n-th instant's step is ``ceil(n p / q)``, and the sample is taken at that step's start, the
integrator's own ``t0 + j h`` (compared bit for bit: it is the step time the block saw;
Moreau–Jean records its step ends as ``(t0 + (j - 1) h) + h``, two roundings away). The old
scheduler (``due += T``, slack ``1e-9 T``) drifts by one rounding per tick and skipped the
sample at tick 21,441 of a 1e-4 s loop, so the implicit Euler cases run past that tick:
10⁶ ticks compiled and 10⁵ ticks in Python (10⁶ in the ``slow`` suite), for four periods
and three step sizes (1e-4, 1/3 ms and 12.5 ms: their multiples round differently).

Chapter 7's loop is compared with a loop written here in plain numpy: implicit Euler of
``J w' = u - F(w)`` with the Stribeck law's graph solved directly, the PD law with
friction compensation and the reduced-order observer at the ticks ``k h``. The two runs
differ by rounding only: per tick at most ~32 u max|x| (the observer's 6 operations, the
law's libm ``exp``/``pow`` within an ulp each, the step's 4 operations, the root to its last
bit), and the closed loop forgets an error over its decay time ``1 / (zeta omega_n) =
2 J / k_d`` (the PD loop's slowest decay; the observer, l = 150 /s, is faster), i.e.
``2 J / (k_d h)`` ticks: the bound is ``2 J / (k_d h) x 32 u x max|x|`` (~1.2e-11 here;
measured 2.3e-13 on the angle, 3.0e-12 on the velocity). The old schedule skipped the
sample of tick 21,441 and left the angle 1.6e-6 (kappa = 1) and 9.4e-5 (kappa = 1.3) away.
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


def free_mass():
    """A unit mass with no force (its gap far away): Moreau–Jean's loops, compiled (a linear
    plant under compiled blocks) and Python."""
    from nscontrol.systems.lagrangian import LagrangianSystem

    return LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[100.0],
                            actuation=[[1.0]])


def check_schedule(n_ticks, p, q, compiled, t0=0.0, h=H, method="implicit_euler"):
    period = p * h / q
    system, x0 = (plant(), [0.5]) if method == "implicit_euler" else (free_mass(), [0.0, 0.0])
    loop = nsc.closed_loop(system, Counter(period, compiled), compiled=compiled)
    traj = nsc.simulate(loop, x0, (t0, t0 + n_ticks * h), method=method, h=h,
                        progress=False)
    if method == "implicit_euler":
        assert traj.stats["controller"] == ("compiled" if compiled else "python")
    else:
        assert (traj.stats["path"] == "compiled_model") == compiled
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
    if method == "implicit_euler":
        np.testing.assert_array_equal(last[taken], t[j])
    else:      # its step starts t0 + k h and recorded ends (t0 + (k - 1) h) + h: 2 roundings
        np.testing.assert_allclose(last[taken], t[j], rtol=4 * U, atol=0)
    # and those are the instants to the step times' rounding (a few ulps of t)
    exact = t0 + np.arange(n_instants) * period
    assert np.all(t[j] >= exact - 8 * U * np.maximum(abs(t0), np.abs(exact)))
    assert np.all(t[j] - exact < h)


CASES = [(1, 1), (5, 1), (5, 2), (7, 3)]       # T = h, 5h, 2.5h, 7h/3
IDS = [f"T={p}h/{q}" for p, q in CASES]


@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_compiled_loop_one_sample_per_instant_over_a_million_ticks(p, q):
    check_schedule(1_000_000, p, q, True)          # ~2.5 s each


@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_python_runner_one_sample_per_instant_over_1e5_ticks(p, q):
    check_schedule(100_000, p, q, False)           # ~3-5 s each


# step sizes whose multiples round differently: 1/3 ms and 12.5 ms are not binary fractions
STEPS = [1e-3 / 3, 0.0125]


@pytest.mark.parametrize("h", STEPS, ids=[f"h={h:.4g}" for h in STEPS])
@pytest.mark.parametrize("p,q", [(5, 2), (7, 3)], ids=["T=5h/2", "T=7h/3"])
def test_other_step_sizes_one_sample_per_instant(p, q, h):
    check_schedule(1_000_000, p, q, True, h=h)
    check_schedule(100_000, p, q, False, h=h)


@pytest.mark.parametrize("compiled,n_ticks", [(True, 200_000), (False, 5_000)],
                         ids=["compiled", "python"])
def test_moreau_jean_loops_one_sample_per_instant(compiled, n_ticks):
    """The same stepper inside Moreau–Jean's compiled loop and beside its Python loop (a
    shorter run: its Python step costs ~10x implicit Euler's; the rule is the one checked
    over 10⁶ ticks above)."""
    check_schedule(n_ticks, 5, 2, compiled, method="moreau_jean")


def test_late_start_counts_from_the_first_instant():
    """Far from t = 0 the step times' rounding is larger; the slack scales with |t|."""
    check_schedule(50_000, 5, 2, True, t0=1234.5)
    check_schedule(50_000, 5, 2, False, t0=1234.5)


@pytest.mark.slow
@pytest.mark.parametrize("p,q", CASES, ids=IDS)
def test_python_runner_one_sample_per_instant_over_a_million_ticks(p, q):
    check_schedule(1_000_000, p, q, False)         # ~20-25 s each


def independent_friction_loop(robot, pd, l, kappa, h, n_ticks, theta0, omega0, omega_hat0):
    """Chapter 7's digital loop at the exact ticks ``k h``, written without the library:
    the reduced-order observer and the compensating PD law (the chapter's formulas), and
    implicit Euler of ``J w' = u - F(w)`` with the Stribeck graph solved directly: at rest
    when ``|w + h u / J| <= h T_s / J``, else ``v + (h / J) f(v) = |w + h u / J|`` for the
    speed ``v > 0`` (increasing in ``v`` since ``h sigma < J``), by bisection to the last
    bit."""
    ts, tc, ws, dl, b = (float(np.ravel(a)[0]) for a in (
        robot.friction.static, robot.friction.coulomb, robot.friction.stribeck_velocity,
        robot.friction.delta, robot.friction.viscous))
    J, kp, kd, r = pd.J, pd.kp, pd.kd, float(pd.reference.value)

    def f(v):
        return tc + (ts - tc) * np.exp(-(v / ws) ** dl) + b * v

    def torque(theta, omega_hat):
        return -kp * (theta - r) - kd * omega_hat

    xi_prev = omega_hat0 - l * theta0
    xi_prev = xi_prev * (1.0 + h * l) + h * l * l * theta0
    upd_prev = 0.0
    theta, omega = theta0, omega0
    x = np.empty((n_ticks + 1, 2))
    x[0] = theta, omega
    for k in range(n_ticks):                 # the tick k h: observer, controller, step
        xi = (xi_prev + h * (-l * l * theta + upd_prev / J)) / (1.0 + h * l)
        omega_hat = xi + l * theta
        upd = torque(theta, omega_hat)
        comp = 0.0 if kappa == 0.0 or omega_hat == 0.0 else \
            np.copysign(kappa * f(abs(omega_hat)), omega_hat)
        u = upd + comp
        xi_prev, upd_prev = xi, upd
        c = omega + h * u / J
        if abs(c) <= h * ts / J:
            omega = 0.0
        else:
            lo, hi = 0.0, abs(c)
            while True:
                mid = 0.5 * (lo + hi)
                if mid <= lo or mid >= hi:
                    break
                if mid + h / J * f(mid) > abs(c):
                    hi = mid
                else:
                    lo = mid
            omega = np.copysign(lo, c)
        theta = theta + h * omega
        x[k + 1] = theta, omega
    return x


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
@pytest.mark.parametrize("kappa", [1.0, 1.3])
def test_chapter7_loop_matches_an_independent_loop_over_50000_ticks(kappa, compiled):
    from nscontrol.design.friction_compensation import PDLaw, SetPoint, simulate_friction_loop
    from nscontrol.laws import Stribeck
    from nscontrol.systems import OneLinkRobot

    J, n_ticks = 0.05, 50_000
    robot = OneLinkRobot(J, Stribeck(0.4, 0.2, 0.05, 2.0, 0.02))
    pd = PDLaw(2.0, 0.3, J, SetPoint(1.0))
    run = simulate_friction_loop(robot, pd, l=150.0, kappa=kappa, h=H, T=n_ticks * H,
                                 omega_hat0=0.3, compiled=compiled)
    ref = independent_friction_loop(robot, pd, 150.0, kappa, H, n_ticks, 0.0, 0.0, 0.3)
    assert run.t.size == n_ticks + 1
    got = np.column_stack([run.theta, run.omega])
    bound = 2 * J / (pd.kd * H) * 32 * U * np.max(np.abs(ref))    # module docstring
    np.testing.assert_allclose(got, ref, rtol=0, atol=bound)
