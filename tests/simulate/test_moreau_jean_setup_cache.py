"""The step matrices of Moreau–Jean's compiled paths are kept per system and step
(``moreau_jean._runners._SETUPS``): a second run reuses them, another step or another system does
not, and a run's result does not depend on what the cache held before it."""

from __future__ import annotations

import gc

import numpy as np
import pytest

import nscontrol as nsc
from nscontrol.simulate.moreau_jean import _runners as _mj_runners
from nscontrol.systems.lagrangian import LagrangianSystem


def _tridiagonal() -> LagrangianSystem:
    # a mass on a spring above the floor q = 0: diagonal M, one contact on one coordinate
    return LagrangianSystem([[2.0]], stiffness=[[3.0]], constant_force=[-9.81],
                            gap_matrix=[[1.0]], gap_offset=[0.0], restitution=0.5)


def _dense() -> LagrangianSystem:
    # a coupled mass matrix: the dense path
    return LagrangianSystem([[2.0, 0.5], [0.5, 1.0]], stiffness=[[3.0, 0.0], [0.0, 1.0]],
                            constant_force=[-9.81, 0.0], gap_matrix=[[1.0, 0.0]],
                            gap_offset=[0.0], restitution=0.5)


def _run(system: LagrangianSystem, h: float) -> nsc.Trajectory:
    x0 = np.r_[0.3 * np.ones(system.n_dof), np.zeros(system.n_dof)]
    return nsc.simulate(system, x0, (0.0, 0.5), method="moreau_jean", h=h, progress=False)


@pytest.mark.parametrize(("make", "path"), [(_tridiagonal, "tridiagonal"), (_dense, "dense")])
def test_a_second_run_reuses_the_setup_and_another_step_or_system_does_not(make, path):
    system = make()
    first = _run(system, 1e-3)
    assert first.stats["path"] == path
    assert first.events, "the run should contain impacts (the LCP uses the kept W / M̂⁻¹)"
    kept = _mj_runners._SETUPS[system][(path, 1e-3, 0.5)]
    again = _run(system, 1e-3)
    assert _mj_runners._SETUPS[system][(path, 1e-3, 0.5)] is kept   # reused, not rebuilt
    np.testing.assert_array_equal(again.x, first.x)

    # another step: its own matrices, and the run equals that of a fresh system (nothing
    # of the first step's setup leaks into it)
    other_h = _run(system, 2e-3)
    assert _mj_runners._SETUPS[system][(path, 2e-3, 0.5)] is not kept
    np.testing.assert_array_equal(other_h.x, _run(make(), 2e-3).x)

    # another system (equal matrices): its own entry, not this one's
    twin = make()
    _run(twin, 1e-3)
    assert _mj_runners._SETUPS[twin][(path, 1e-3, 0.5)] is not kept


def test_the_setup_does_not_keep_the_system_alive():
    system = _tridiagonal()
    _run(system, 1e-3)
    gc.collect()     # systems of earlier tests left in reference cycles (a traceback's frames)
    before = len(_mj_runners._SETUPS)
    del system
    gc.collect()
    assert len(_mj_runners._SETUPS) == before - 1
