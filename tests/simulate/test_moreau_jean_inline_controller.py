"""The Python blocks of a closed loop run inside Moreau–Jean's step loop (their input before
each step, their reset after a step with an impact), whether or not other listeners observe:
the same inputs, the same trajectory, bit for bit."""

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.systems.feedback import StaticLaw
from nscontrol.systems.lagrangian import LagrangianSystem


class _Recorder(StaticLaw):
    """A PD law pushing the end effector down, recording what it was given."""

    n_outputs, period = 2, None

    def __init__(self):
        object.__setattr__(self, "seen", [])

    def output(self, t, xc, m):
        q, v = m.x[:2], m.x[2:]
        self.seen.append((t, q.copy(), v.copy(), m.lam.copy(), m.active.copy()))
        return -20.0 * (q - np.array([0.9, -1.4])) - 4.0 * v


def _run(listeners, t_end=0.7005):
    arm = LagrangianSystem.two_link_arm(restitution=0.5)
    ctrl = _Recorder()
    traj = nsc.simulate(nsc.closed_loop(arm, ctrl), [0.9, -1.6, 0.0, 0.0], (0.0, t_end),
                        method="moreau_jean", h=1e-3, listeners=listeners, progress=False)
    return traj, ctrl


def test_python_blocks_step_the_same_with_and_without_listeners():
    heard = []
    alone, c_alone = _run([])
    observed, c_observed = _run([lambda *args: heard.append(args)])
    assert alone.stats["path"] == observed.stats["path"] == "python"
    assert np.array_equal(alone.t, observed.t)
    assert np.array_equal(alone.x, observed.x)
    assert np.array_equal(alone.signals["impulse"], observed.signals["impulse"])
    assert len(c_alone.seen) == len(c_observed.seen) == alone.t.size - 1
    for a, b in zip(c_alone.seen, c_observed.seen, strict=True):
        assert a[0] == b[0]                            # step starts t0 + k h, last one too
        for x, y in zip(a[1:], b[1:], strict=True):
            assert np.array_equal(x, y)
    # the last (shortened) step starts at t0 + n h
    assert c_alone.seen[-1][0] == pytest.approx(0.7, abs=1e-15)
    # the listener heard every impact, with the step's end and its impulses
    assert len(heard) == len(observed.events_of("impact")) >= 1
    for t, _, x_plus, _, impulse in heard:
        k = int(np.argmin(np.abs(observed.t - t)))
        assert observed.t[k] == t and np.array_equal(observed.x[k], x_plus)
        assert np.array_equal(observed.signals["impulse"][k], impulse)
    # the law read the last step's impulses over h (zeros at the first step), and the
    # contacts of that step's active set carry its impulses
    p = observed.signals["impulse"]
    assert np.array_equal(c_observed.seen[0][3], [0.0]) and c_observed.seen[0][4].size == 0
    for k, seen in enumerate(c_observed.seen[1:], start=1):
        assert np.array_equal(seen[3], p[k] / 1e-3)
        assert set(np.flatnonzero(p[k])) <= set(seen[4].tolist())


def test_python_blocks_with_a_bad_output_stop_with_the_partial_run():
    arm = LagrangianSystem.two_link_arm()

    class Bad(StaticLaw):
        n_outputs, period = 2, None

        def output(self, t, xc, m):
            return np.array([np.nan, 0.0]) if t > 0.0105 else np.zeros(2)

    with pytest.raises(ModelError, match="controller") as info:
        nsc.simulate(nsc.closed_loop(arm, Bad()), [0.9, -1.6, 0.0, 0.0], (0.0, 0.05),
                     method="moreau_jean", h=1e-3, progress=False)
    assert info.value.trajectory is not None
    assert info.value.trajectory.t[-1] == pytest.approx(0.011, abs=1e-12)
