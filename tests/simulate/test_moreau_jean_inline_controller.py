"""A controller on the Python path of Moreau–Jean runs inside the step loop when no listener
needs it stepped chunk by chunk: the same inputs, the same trajectory, bit for bit."""

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.systems.lagrangian import LagrangianSystem


class _Recorder:
    """A PD law pushing the end effector down, recording what it was given."""

    def __init__(self):
        self.seen = []

    def __call__(self, t, q, v, *, lam_hat, active):
        self.seen.append((t, q.copy(), v.copy(), lam_hat.copy(), active.copy()))
        return -20.0 * (q - np.array([0.9, -1.4])) - 4.0 * v


def _run(listeners, t_end=0.1005):
    arm = LagrangianSystem.two_link_arm(restitution=0.5)
    ctrl = _Recorder()
    traj = nsc.simulate(arm, [0.9, -1.6, 0.0, 0.0], (0.0, t_end), method="moreau_jean",
                        h=1e-3, controller=ctrl, listeners=listeners, progress=False)
    return traj, ctrl


def test_inline_controller_matches_the_per_step_path_exactly():
    inline, c_inline = _run([])
    stepped, c_stepped = _run([lambda *args: None])
    assert np.array_equal(inline.t, stepped.t)
    assert np.array_equal(inline.x, stepped.x)
    assert np.array_equal(inline.signals["impulse"], stepped.signals["impulse"])
    assert len(c_inline.seen) == len(c_stepped.seen) == inline.t.size - 1
    for a, b in zip(c_inline.seen, c_stepped.seen, strict=True):
        assert a[0] == b[0]                            # step starts t0 + k h, last one too
        for x, y in zip(a[1:], b[1:], strict=True):
            assert np.array_equal(x, y)
    # the last (shortened) step starts at t0 + n h
    assert c_inline.seen[-1][0] == pytest.approx(0.1, abs=1e-15)


def test_inline_controller_with_a_bad_output_stops_with_the_partial_run():
    arm = LagrangianSystem.two_link_arm()

    def bad(t, q, v):
        return np.array([np.nan, 0.0]) if t > 0.0105 else np.zeros(2)

    with pytest.raises(ModelError, match="controller") as info:
        nsc.simulate(arm, [0.9, -1.6, 0.0, 0.0], (0.0, 0.05), method="moreau_jean", h=1e-3,
                     controller=bad, progress=False)
    assert info.value.trajectory is not None
    assert info.value.trajectory.t[-1] == pytest.approx(0.011, abs=1e-12)
