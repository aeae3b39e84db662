"""Feedback reaches an integrator one way: :func:`nscontrol.simulate` lowers every closed
loop, and an integrator receives a model and, for blocks run as code, the loop's block
runner as the internal option ``blocks=`` (``docs/architecture.md``, "How feedback reaches
an integrator").

What is checked, for a loop of every composition (stacked, folded, blocks around each plant
family, the sampled loop of ``sampled_zoh`` included): no built-in method's ``supports``
accepts a closed loop; the ``integrate`` each method is handed gets a model, never a
:class:`ClosedLoop`, with ``blocks=`` a :class:`BlockRunner` of that very loop exactly when
the loop's blocks run as code; a caller cannot hand ``blocks=`` to ``simulate`` (nor to a
sweep's up-front checks); and ``sampled_zoh``, which integrated the loop itself before,
refuses one given directly.
"""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.design import FirstOrderSMC
from nscontrol.errors import ModelError
from nscontrol.laws import Relay
from nscontrol.simulate._block_runner import BlockRunner
from nscontrol.simulate.driver import METHODS, check_run
from nscontrol.systems import SlidingModePlant
from nscontrol.systems.closed_loop import ClosedLoop
from nscontrol.systems.feedback import StateFeedback
from nscontrol.systems.lagrangian import LagrangianSystem
from nscontrol.systems.lure import LureSystem


class Damper:
    """A law written in Python, ``u = -c v`` (sampled with ``period``, or continuous)."""

    n_states, n_outputs = 0, 1

    def __init__(self, c, period=None):
        self.c, self.period = c, period

    def output(self, t, xc, m):
        return np.array([-self.c * m.x[-1]])

    def update(self, t, xc, m):
        return xc

    def reset(self, t, xc, jump):
        return xc


def _lure():
    """x1' = x2, x2' = -Sign(x2) + u: a unit mass with Coulomb friction, driven by u."""
    return LureSystem([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[0.0, 1.0]], Relay(1.0),
                      B=np.array([[0.0], [1.0]]))


def _mass():
    return LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
                            constant_force=[-1.0], actuation=[[1.0]])


def _loops():
    """``(name, loop, x0, options, composition)``: one loop per way a loop is composed."""
    lure = _lure()
    smc = SlidingModePlant.double_integrator()
    return [
        ("stacked", nsc.closed_loop(lure, StateFeedback([[-2.0, -1.0]])),
         [1.0, 0.0], {"h": 1e-3}, "stacked"),
        ("folded", nsc.closed_loop(_mass(), StateFeedback([[-4.0, -1.0]], k=[5.0])),
         [0.2, 0.0], {}, "folded"),
        ("blocks, moreau_jean", nsc.closed_loop(_mass(), Damper(1.0, period=1e-2)),
         [0.2, 0.0], {"h": 1e-3}, "blocks"),
        ("blocks, event_driven", nsc.closed_loop(_mass(), Damper(1.0)), [0.2, 0.0],
         {"method": "event_driven"}, "blocks"),
        ("blocks, implicit_euler", nsc.closed_loop(lure, Damper(1.0, period=1e-2)),
         [1.0, 0.0], {"h": 1e-3}, "blocks"),
        ("blocks, sampled_zoh", nsc.closed_loop(smc, FirstOrderSMC(smc, 1.0, 1e-2)),
         [1.0, 0.0], {}, "blocks"),
    ]


@pytest.mark.parametrize("name, loop, x0, options, composition", _loops(),
                         ids=[case[0] for case in _loops()])
def test_an_integrator_receives_a_model_and_the_loops_blocks(monkeypatch, name, loop, x0,
                                                             options, composition):
    assert loop.composition == composition
    assert not any(METHODS[m].supports(loop) for m in METHODS)   # no method takes a loop
    handed = []
    for method in METHODS:
        cls = METHODS[method]

        def spy(self, system, x0, t_span, _run=cls.integrate, **opts):
            handed.append((self.name, system, opts.get("blocks")))
            return _run(self, system, x0, t_span, **opts)
        monkeypatch.setattr(cls, "integrate", spy)
    traj = nsc.simulate(loop, x0, (0.0, 0.2), progress=False, **options)
    assert len(handed) == 1
    method, system, blocks = handed[0]
    assert traj.method == method == options.get("method", loop.default_method)
    assert not isinstance(system, ClosedLoop)
    assert METHODS[method].supports(system)
    if composition == "blocks":     # the blocks as code: the loop's own runner
        assert isinstance(blocks, BlockRunner) and blocks.loop is loop
        assert "blocks" in METHODS[method].options
    else:                           # the blocks are in the model
        assert blocks is None


def test_blocks_reach_an_integrator_only_through_the_lowering():
    """``blocks=`` is no option a caller gives: ``simulate`` and a sweep's up-front checks
    refuse it for every method, even the runner of a real loop."""
    smc = SlidingModePlant.double_integrator()
    runner = BlockRunner(nsc.closed_loop(smc, FirstOrderSMC(smc, 1.0, 1e-2)))
    for method, system, x0, opts in (
            ("sampled_zoh", smc, [1.0, 0.0], {}),
            ("moreau_jean", _mass(), [0.2, 0.0], {"h": 1e-3}),
            ("event_driven", _mass(), [0.2, 0.0], {}),
            ("implicit_euler", _lure(), [1.0, 0.0], {"h": 1e-3})):
        with pytest.raises(ModelError, match=r"^blocks: expected the BlockRunner of a closed "
                                             r"loop \(set by simulate\(closed_loop"):
            nsc.simulate(system, x0, (0.0, 0.1), method=method, blocks=runner, **opts)
        with pytest.raises(ModelError, match=r"^blocks: expected the BlockRunner"):
            check_run(system, method, {"blocks": runner, **opts})


def test_sampled_zoh_takes_the_plant_not_the_loop():
    """The method that integrated the closed loop itself now takes the plant and the loop's
    runner like the others: a loop handed to it directly is refused, and so is a plant
    without a controller."""
    from nscontrol.simulate import sampled_zoh

    smc = SlidingModePlant.double_integrator()
    loop = nsc.closed_loop(smc, FirstOrderSMC(smc, 1.0, 1e-2))
    with pytest.raises(ModelError, match=r"^sampled_zoh: integrates a SlidingModePlant"):
        sampled_zoh.integrate(loop, [1.0, 0.0], (0.0, 1.0))
    with pytest.raises(ModelError, match=r"^controller: sampled_zoh runs a sampled "
                                         r"controller on the plant, got none"):
        nsc.simulate(smc, [1.0, 0.0], (0.0, 1.0))
    direct = sampled_zoh.integrate(smc, [1.0, 0.0], (0.0, 1.0), blocks=BlockRunner(loop))
    lowered = nsc.simulate(loop, [1.0, 0.0], (0.0, 1.0), progress=False)
    np.testing.assert_array_equal(direct.x, lowered.x)   # the same run, by the same route
