"""``method="sampled_zoh"``: a plant and a sampled controller, the plant stepped by its exact
zero-order-hold matrices between the ticks ``t0 + n T``.

What is checked: the ticks are counted (every one at exactly ``t0 + n T``, the controller
sampled at each, over 10⁶ ticks too), the compiled and the Python paths take the same steps
bit for bit, both agree with an independent loop written here, ``record_every`` thins as the
other methods do, a failing block or a Ctrl-C keeps every sample computed before it, and the
loops the method does not run are refused with a message naming the part."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.linalg
from numba import njit

import nscontrol as nsc
from nscontrol.design import FirstOrderSMC, SuperTwistingController, super_twisting_gains
from nscontrol.errors import DimensionError, ModelError
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import SlidingModePlant
from nscontrol.systems.feedback import (
    BLOCK_SIGNATURE,
    CompiledBlock,
    LinearObserver,
    Measurement,
    StateFeedback,
)

EPS = np.finfo(float).eps
K1, K2 = super_twisting_gains(1.5)


def _plant():
    return SlidingModePlant.double_integrator(disturbance=Exosystem.sinusoid(0.3, omega=5.0))


# -- a block that counts its samples (compiled form and Python methods) ------------------------
@njit(BLOCK_SIGNATURE, cache=True)
def _count_output(t, xb, y, x, xhat, lam, params):
    out = np.zeros(1)
    if t >= params[0]:          # a fault from the instant params[0] on
        out[0] = np.nan
    return out


@njit(BLOCK_SIGNATURE, cache=True)
def _count_update(t, xb, y, x, xhat, lam, params):
    out = xb.copy()
    out[0] += 1.0
    return out


class Counter:
    """``u = 0``; its state counts the samples it took (NaN output from ``fail_at`` on)."""

    n_states, n_outputs = 1, 1

    def __init__(self, period, fail_at=np.inf, compiled=True):
        self.period, self.fail_at, self.has_form = period, fail_at, compiled

    def output(self, t, xc, m):
        return np.array([np.nan if t >= self.fail_at else 0.0])

    def update(self, t, xc, m):
        return xc + 1.0

    def reset(self, t, xc, jump):
        return xc

    def compiled(self):
        if not self.has_form:
            return None
        return CompiledBlock(_count_output, _count_update, np.array([self.fail_at]))


def _run_counter(t0, T, n, **kw):
    loop = nsc.closed_loop(SlidingModePlant.double_integrator(), Counter(T, **kw))
    return nsc.simulate(loop, [1.0, 0.0], (t0, t0 + n * T), method="sampled_zoh",
                        progress=False)


def _check_ticks(tr, t0, T, n):
    k = np.arange(n + 1)
    assert tr.stats["steps"] == n and tr.t.size == n + 1
    # every tick at t0 + k T formed from the integer count: equal, not close
    np.testing.assert_array_equal(tr.t, t0 + k * T)
    # the block sampled once at every tick: its count at tick k is k (exact in float64)
    np.testing.assert_array_equal(tr.signal("xc")[:, 0], k)


@pytest.mark.parametrize("t0, T", [(0.0, 1e-4), (0.7, 1e-3), (-3.0, 0.3), (1e3, 1.0 / 3.0)])
def test_ticks_are_counted_and_each_one_samples(t0, T):
    n = 20_000          # past tick 21,441 of issue 30's accumulated schedule, times 5 below
    tr = _run_counter(t0, T, n)
    assert tr.stats["controller"] == "compiled"
    _check_ticks(tr, t0, T, n)
    py = _run_counter(t0, T, 2_000, compiled=False)
    assert py.stats["controller"] == "python"
    _check_ticks(py, t0, T, 2_000)


@pytest.mark.slow
@pytest.mark.parametrize("t0, T", [(0.0, 1e-4), (0.7, 1e-3), (1e3, 1.0 / 3.0)])
def test_a_million_ticks_take_a_million_samples(t0, T):
    _check_ticks(_run_counter(t0, T, 10**6), t0, T, 10**6)


# -- the same steps by both paths, and as an independent loop ---------------------------------
def _loops(ctrl):
    plant = _plant()
    return (nsc.closed_loop(plant, ctrl), nsc.closed_loop(plant, ctrl, compiled=False))


@pytest.mark.parametrize("make", [
    lambda p: FirstOrderSMC(p, 1.0, 1e-2),
    lambda p: FirstOrderSMC(p, 1.0, 1e-2, "explicit"),
    lambda p: SuperTwistingController(p, K1, K2, 1e-2),
    lambda p: SuperTwistingController(p, K1, K2, 1e-2, "explicit")])
def test_compiled_and_python_paths_agree_bit_for_bit(make):
    compiled, python = _loops(make(_plant()))
    a = nsc.simulate(compiled, [0.5, 0.0], (0.2, 3.2), method="sampled_zoh", progress=False)
    b = nsc.simulate(python, [0.5, 0.0], (0.2, 3.2), method="sampled_zoh", progress=False)
    assert (a.stats["controller"], b.stats["controller"]) == ("compiled", "python")
    # one tick function and one law (the Python methods call the compiled forms)
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.x, b.x)
    for name in a.signals:
        np.testing.assert_array_equal(a.signal(name), b.signal(name))


def test_agrees_with_an_independent_loop():
    plant, h, t0 = _plant(), 1e-2, 0.2
    ctrl = SuperTwistingController(plant, K1, K2, h)
    tr = nsc.simulate(nsc.closed_loop(plant, ctrl), [0.5, 0.0], (t0, 3.2), progress=False)
    assert tr.method == "sampled_zoh"        # the loop's default method
    # the ZOH step of [x; w] from scipy's expm of the block matrix [[A, B], [0, 0]] h
    A, B, _ = plant.augmented()
    N = A.shape[0]
    M = np.zeros((N + 1, N + 1))
    M[:N, :N], M[:N, N:] = A, B
    E = scipy.linalg.expm(M * h)
    Phi, Gam = E[:N, :N], E[:N, N]
    X = np.concatenate([[0.5, 0.0], plant.disturbance.w(t0)])
    xc = ctrl.x0
    for k in range(tr.t.size - 1):
        m = Measurement(t0 + k * h, y=X[:2], x=X[:2])
        u = ctrl.output(m.t, xc, m)[0]
        assert tr.signal("u")[k, 0] == pytest.approx(u, rel=0, abs=1e-12)
        xc = ctrl.update(m.t, xc, m)
        X = Phi @ X + Gam * u
    # two expm algorithms (a few eps |A h| each) and 300 steps of a contracting loop, summed
    # in another order: below 300 * 16 eps of the state's scale (1)
    np.testing.assert_allclose(tr.x[-1], X[:2], rtol=0, atol=300 * 16 * EPS)


def test_record_every_keeps_every_kth_tick_and_the_last():
    ctrl = SuperTwistingController(_plant(), K1, K2, 1e-3)
    loop = nsc.closed_loop(_plant(), ctrl)
    full = nsc.simulate(loop, [0.5, 0.0], (0.0, 20.0), method="sampled_zoh", progress=False)
    thin = nsc.simulate(loop, [0.5, 0.0], (0.0, 20.0), method="sampled_zoh", progress=False,
                        record_every=7, signals=["u"])
    keep = np.zeros(full.t.size, dtype=bool)
    keep[::7] = True
    keep[-1] = True
    np.testing.assert_array_equal(thin.t, full.t[keep])
    np.testing.assert_array_equal(thin.x, full.x[keep])
    np.testing.assert_array_equal(thin.signal("u"), full.signal("u")[keep])
    assert set(thin.signals) == {"u"}


# -- failures keep what was computed --------------------------------------------------------
@pytest.mark.parametrize("compiled", [True, False])
def test_a_failing_block_keeps_every_sample_before_it(compiled):
    T, n_ok = 1e-3, 20_000        # the fault in the third compiled chunk
    with pytest.raises(ModelError, match="^controller: .*non-finite") as err:
        _run_counter(0.0, T, 30_000, fail_at=n_ok * T, compiled=compiled)
    part = err.value.trajectory
    assert part.status == -1
    np.testing.assert_array_equal(part.t, np.arange(n_ok) * T)
    np.testing.assert_array_equal(part.signal("xc")[:, 0], np.arange(n_ok))


@pytest.mark.parametrize("compiled", [True, False])
def test_ctrl_c_stops_within_0_2_s_with_the_samples_so_far(compiled):
    """A Ctrl-C 0.3 s into a run of 10^9 ticks: the run stops within 0.2 s of its thread's
    CPU time and keeps every tick so far. Run in a process of its own: an interrupt sent to
    a test worker's main thread must never reach the worker (it ended the worker of a whole
    suite, at random, where the test itself passed alone). The main thread's own CPU clock,
    not the process's: the process's also counts other threads (a BLAS pool spinning after a
    numpy call, the interrupting thread), which read 0.2 s once in a loaded full suite."""
    script = _CTRL_C_SCRIPT.format(compiled=compiled)
    env = dict(os.environ, NSCONTROL_COMPILE="wait")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=240, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    latency, n, status, on_ticks, finite, u_shape = proc.stdout.split()[-6:]
    assert float(latency) <= 0.2, latency
    assert int(n) > 1 and int(status) == -1
    assert on_ticks == finite == "True" and u_shape == f"({n},1)"


_CTRL_C_SCRIPT = """
import _thread, threading, time
import numpy as np
import nscontrol as nsc
from nscontrol.design import SuperTwistingController, super_twisting_gains
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import SlidingModePlant

def plant():
    return SlidingModePlant.double_integrator(disturbance=Exosystem.sinusoid(0.3, omega=5.0))

K1, K2 = super_twisting_gains(1.5)
T, t0 = 1e-4, 0.5
loop = nsc.closed_loop(plant(), SuperTwistingController(plant(), K1, K2, T),
                       compiled={compiled})
nsc.simulate(loop, [0.5, 0.0], (t0, t0 + 10 * T), method="sampled_zoh", progress=False)
sent = []
main_clock = time.pthread_getcpuclockid(threading.main_thread().ident)

def interrupt():
    time.sleep(0.3)
    sent.append(time.clock_gettime(main_clock))
    _thread.interrupt_main()

thread = threading.Thread(target=interrupt)
thread.start()
try:
    nsc.simulate(loop, [0.5, 0.0], (t0, t0 + 1e5), method="sampled_zoh",
                 progress=False)       # 10^9 ticks: hours, were it not stopped
    raise SystemExit("the run was not interrupted")
except KeyboardInterrupt as err:
    # the main thread's CPU time from the interrupt to the raise: what the run spends before
    # it stops (a chunk's rest, the partial trajectory)
    latency = time.clock_gettime(main_clock) - sent[0]
    part = err.trajectory
finally:
    thread.join()
n = part.t.size
print(latency, n, part.status, bool(np.array_equal(part.t, t0 + np.arange(n) * T)),
      bool(np.isfinite(part.x).all()), str(part.signal("u").shape).replace(" ", ""))
"""


# -- what the method refuses ------------------------------------------------------------------
def test_refusals_name_the_part():
    plant = SlidingModePlant.double_integrator()
    with pytest.raises(ModelError, match="^controller: sampled_zoh runs a sampled controller"):
        nsc.simulate(nsc.closed_loop(plant, StateFeedback([[-1.0, -1.0]])), [1.0, 0.0],
                     (0.0, 1.0), method="sampled_zoh")
    obs = LinearObserver(-np.eye(2), np.eye(2))
    with pytest.raises(ModelError, match="^observer: sampled_zoh runs a plant"):
        nsc.simulate(nsc.closed_loop(plant, FirstOrderSMC(plant, 1.0, 1e-2), observer=obs),
                     [1.0, 0.0], (0.0, 1.0), method="sampled_zoh")
    loop = nsc.closed_loop(plant, FirstOrderSMC(plant, 1.0, 1e-2))
    with pytest.raises(DimensionError, match="^t_span: the span 0.005 is shorter than"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 0.005), method="sampled_zoh")
    with pytest.raises(DimensionError, match="^x0: "):
        nsc.simulate(loop, [1.0, 0.0, 0.0], (0.0, 1.0), method="sampled_zoh")
    with pytest.raises(ModelError, match="^moreau_jean: a SlidingModePlant plant runs with "
                                         "its sampled controller by method='sampled_zoh'"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-3)
    with pytest.raises(ModelError, match=r"^signals: expected a sequence of signal names"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), signals="u")
    with pytest.raises(ModelError, match=r"^signals: unknown name\(s\) \['xc'\]"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), signals=["xc"])   # FirstOrderSMC: no state
    with pytest.raises(ModelError, match=r"^sampled_zoh: unknown option\(s\) \['h'\]"):
        nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), method="sampled_zoh", h=1e-3)


def test_the_block_stepper_frees_every_array_a_block_returns():
    """The block stepper runs without reference counting and gives back each array a
    block's compiled function returns itself: over 2·10⁴ ticks (two arrays each, the
    output and the new state) numba's runtime counts as many frees as allocations."""
    code = (
        "import nscontrol as nsc\n"
        "from numba.core.runtime import rtsys\n"
        "from nscontrol.design import SuperTwistingController, super_twisting_gains\n"
        "from nscontrol.systems import SlidingModePlant\n"
        "p = SlidingModePlant.double_integrator()\n"
        "loop = nsc.closed_loop(p, SuperTwistingController(p, *super_twisting_gains(1.5), "
        "1e-3))\n"
        "nsc.simulate(loop, [0.5, 0.0], (0.0, 0.01), progress=False)\n"
        "a = rtsys.get_allocation_stats()\n"
        "nsc.simulate(loop, [0.5, 0.0], (0.0, 20.0), progress=False, record_every=10**6)\n"
        "b = rtsys.get_allocation_stats()\n"
        "print(b.alloc - a.alloc, b.free - a.free)\n")
    env = dict(os.environ, NUMBA_NRT_STATS="1")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=600)
    alloc, free = map(int, out.stdout.split()[-2:])
    assert alloc >= 2 * 20_000
    assert free == alloc
