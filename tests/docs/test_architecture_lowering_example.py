"""The worked lowering example of docs/architecture.md runs and does what it says: a model of
the user's own, lowered to a LagrangianSystem, simulated in its own state order."""

from __future__ import annotations

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.errors import ModelError
from nscontrol.simulate import register_lowering
from nscontrol.simulate.lowering import base

EPS = float(np.finfo(float).eps)


@pytest.fixture
def registry():
    """The registry as it was before the test (the example registers a lowering)."""
    saved = list(base._REGISTRY._entries)
    yield
    base._REGISTRY._entries[:] = saved


def test_a_user_lowering_runs_a_model_of_their_own(registry, doc_block):
    scope, _ = doc_block("### Worked example: a lowering of your own")
    traj = scope["traj"]
    v, x = traj.x.T
    # invert gave the trajectory back in the user's order, starting at the x0 given
    assert traj.state_names == ("v", "x")
    np.testing.assert_array_equal(traj.x[0], [3.0, 0.0])
    # amplitude 3 between walls at +-1: impacts on both walls
    assert len(traj.events) >= 10 and np.min(x) < -0.99 and np.max(x) > 0.99
    # exact flow (matrix exponentials) and elastic impacts conserve v²/2 + x²/2 = 4.5: each
    # flight and each impact costs a few roundoffs of the energy, 100 eps per event is ample
    energy = v ** 2 / 2 + x ** 2 / 2
    assert np.max(np.abs(energy - 4.5)) <= 100 * EPS * 4.5 * (len(traj.events) + 1)
    # the walls hold (the state leaves them by at most the same roundoff)
    assert np.max(np.abs(x)) <= 1.0 + 100 * EPS * (len(traj.events) + 1)
    # Moreau–Jean takes the same lowering: same model, its own O(h) accuracy
    rattle = scope["Rattle"](stiffness=1.0, width=1.0)
    mj = nsc.simulate(rattle, [3.0, 0.0], (0.0, 20.0), method="moreau_jean", h=1e-3)
    assert mj.state_names == ("v", "x") and np.max(np.abs(mj.x[:, 1])) <= 1.0 + 3.0 * 1e-3


def test_without_a_lowering_the_model_is_refused_by_name(registry, doc_source):
    scope: dict = {}
    source = doc_source("### Worked example: a lowering of your own")
    code = source.split("register_lowering(RattleAsLagrangian())")[0]
    exec(compile(code, "docs/architecture.md", "exec"), scope)   # noqa: S102  the classes, not registered
    rattle = scope["Rattle"](stiffness=1.0, width=1.0)
    with pytest.raises(ModelError, match=r"^event_driven: integrates .*got Rattle.*lowering"):
        nsc.simulate(rattle, [3.0, 0.0], (0.0, 1.0))
    with pytest.raises(ModelError, match=r"^lowering: expected an instance"):
        register_lowering(scope["RattleAsLagrangian"])
    # registered first, it is tried before the built-in lowerings
    lowering = scope["RattleAsLagrangian"]()
    register_lowering(lowering, first=True)
    assert base.lowerings()[0] is lowering
