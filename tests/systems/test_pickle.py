"""Set-valued and switched systems survive pickling (process pools, Dask workers) whenever
their inputs can; a lambda input fails only when pickled, with a clear error."""

import pickle

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.errors import ModelError
from nscontrol.laws.relay import Relay
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem

A_FREE = np.array([[0.0, 1.0], [-1.0, -0.1]])
A_SPRING = np.array([[0.0, 1.0], [-6.0, -0.1]])


def _forcing(t):
    return np.reshape(np.sin(2.9 * np.asarray(t, float)), (-1, 1))


@pytest.mark.parametrize("u", [[0.3], Exosystem.sinusoid(1.0, 2.9), _forcing],
                         ids=["constant", "exosystem", "function"])
def test_pwa_and_lure_round_trip_through_pickle(u):
    pwa = PiecewiseAffineSystem.bimodal(A_SPRING, A_FREE, [1.0, 0.0], E=[[0.0], [1.0]], u=u)
    back = pickle.loads(pickle.dumps(pwa))
    for t in (0.0, 0.37, 2.0):
        np.testing.assert_array_equal(back.input_at(t), pwa.input_at(t))
    a = simulate(pwa, [0.5, 0.0], (0.0, 6.0))
    b = simulate(back, [0.5, 0.0], (0.0, 6.0))
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.event_times(), b.event_times())

    lure = LureSystem(A_FREE, [[0.0], [1.0]], [[0.0, 1.0]], Relay(0.2), B=[[0.0], [1.0]], u=u)
    back = pickle.loads(pickle.dumps(lure))
    a = simulate(lure, [0.5, 0.0], (0.0, 3.0), h=1e-3)
    b = simulate(back, [0.5, 0.0], (0.0, 3.0), h=1e-3)
    np.testing.assert_array_equal(a.x, b.x)
    assert a.stats["input"] == b.stats["input"]


def test_a_lambda_input_is_refused_only_when_pickling():
    pwa = PiecewiseAffineSystem.bimodal(A_SPRING, A_FREE, [1.0, 0.0], E=[[0.0], [1.0]],
                                        u=lambda t: np.zeros((np.size(t), 1)))
    simulate(pwa, [0.5, 0.0], (0.0, 1.0))                      # usable in this process
    with pytest.raises(ModelError, match=r"u: the input u\(t\) = <function .*<lambda>.* cannot "
                                         r"be pickled .*Exosystem, a constant, or a function "
                                         r"defined at module level"):
        pickle.dumps(pwa)
    lure = LureSystem(A_FREE, [[0.0], [1.0]], [[0.0, 1.0]], Relay(0.2), g=lambda t: 0.0)
    with pytest.raises(ModelError, match=r"g: the input g\(t\)"):
        pickle.dumps(lure)
