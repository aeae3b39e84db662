"""An observer loop through :func:`nscontrol.closed_loop` names what it records the way a
control engineer reads it: the plant's states ``x``, the estimate ``xhat``, the estimation
error ``e`` and the measured output ``y`` (the stacked Lur'e model's own output is the error,
which the loop recorded as ``y`` before)."""

from __future__ import annotations

import matplotlib
import numpy as np

import nscontrol as nsc
from nscontrol.design import design_lure_observer
from nscontrol.laws import Relay
from nscontrol.systems import LureSystem

matplotlib.use("Agg")


def test_the_observer_loop_records_x_xhat_e_and_the_true_y_and_plots_them():
    plant = LureSystem(A=[[0.0, 1.0], [-1.0, -0.2]], G=[[0.0], [1.0]], H=[[0.0, 1.0]],
                       law=Relay(1.0), B=[[0.0], [1.0]], C=[[1.0, 0.0]],
                       u=lambda t: 2.0 * np.sin(t))           # no state names: x1, x2
    design = design_lure_observer(plant)
    loop = nsc.closed_loop(plant, observer=design.observer(plant))
    tr = nsc.simulate(loop, loop.initial_state([1.0, 0.0], observer=[-1.0, 2.0]), (0.0, 2.0),
                      h=1e-3, progress=False)
    assert tr.state_names == ("x1", "x2", "xhat1", "xhat2")
    x, xhat = tr.x[:, :2], tr.x[:, 2:]
    # e is x - x̂ read off the same state (one matrix product: a few ulps of |x| <= 3)
    np.testing.assert_allclose(tr.signal("e"), x - xhat, rtol=0, atol=8 * 3 * np.finfo(float).eps)
    np.testing.assert_array_equal(tr.signal("xhat"), xhat)
    # y is the measured position, not the error (it was the error before)
    np.testing.assert_array_equal(tr.signal("y")[:, 0], tr.x[:, 0])
    assert np.abs(tr.signal("y")[:, 0] - tr.signal("e")[:, 0]).max() > 0.5
    fig = tr.plot(signals=["e", "y"])
    legend = fig.axes[0].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == ["x1", "x2", "xhat1", "xhat2"]
    assert [a.get_ylabel() for a in fig.axes[1:]] == ["e", "y"]
