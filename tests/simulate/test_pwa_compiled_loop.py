"""The compiled piece loop of the exact PWA integrator: refilled event buffers, samples at event
times, lazily prepared regions and the per-model cache give the same run as one pass would."""

import numpy as np
from scipy.integrate import solve_ivp

from nscontrol import simulate
from nscontrol.numerics.lti import Exosystem
from nscontrol.simulate.switching import _pwa as _switching_pwa
from nscontrol.simulate.switching._pwa import _Buffers
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.testing import setvalued_problems as sp


def test_more_crossings_than_one_buffer_agree_with_a_tight_ode():
    """Over 320 periods the oscillator crosses its facet 320 times, more than one buffer of
    the compiled loop (256): the refilled run matches DOP853 at rtol 1e-13 on every crossing
    time. Tolerance: the ODE's local error 1e-13 relative, accumulated over ~700 time units
    of a damped flow (x 10) and the event root's conditioning |x'| ~ 0.3 (x 3): 1e-9."""
    p = sp.bimodal_oscillator()
    T = p.facts["period"]
    tr = simulate(p.system, p.x0, (0.0, 320 * T), n_samples=2)
    crossings = tr.event_times("crossing")
    assert crossings.size > _Buffers.EVENTS
    ref = solve_ivp(p.facts["rhs"], (0.0, 320 * T), p.x0, method="DOP853", rtol=1e-13,
                    atol=1e-15, events=lambda t, x: x[0])
    assert ref.t_events[0].size == crossings.size
    assert np.max(np.abs(ref.t_events[0] - crossings)) <= 1e-9
    assert np.max(np.abs(ref.y[:, -1] - tr.x[-1])) <= 1e-9
    assert np.all(np.diff(tr.t) >= 0.0)


def test_sensitivity_over_refilled_buffers_is_the_product_of_the_pieces():
    """Φ of a run with 320 crossings (lightly damped: Φ stays of order 0.05) equals the
    product of the Φ of its four quarters (each under one buffer), restarted from the quarter
    ends. Rounding only: ~640 products of 2x2 factors (pieces and saltations) at ~8 u each,
    x cond(Φ) ~ 7 -> 8e-12 relative to ``max|Φ|``; bound 5e-11."""
    p = sp.bimodal_oscillator(c=0.01)
    T = p.facts["period"]
    whole = simulate(p.system, p.x0, (0.0, 320 * T), n_samples=2, sensitivity=True)
    assert whole.event_times("crossing").size > _Buffers.EVENTS
    x, Phi = p.x0, np.eye(2)
    for k in range(4):
        part = simulate(p.system, x, (80 * k * T, 80 * (k + 1) * T), n_samples=2,
                        sensitivity=True)
        x, Phi = part.x[-1], part.stats["state_transition"] @ Phi
    M = whole.stats["state_transition"]
    assert float(np.max(np.abs(M))) > 1e-2
    assert np.max(np.abs(M - Phi)) <= 5e-11 * float(np.max(np.abs(M)))
    assert whole.stats["saltation_matrices"].shape[0] == whole.event_times("crossing").size


def test_a_sample_at_an_event_time_comes_before_the_event_sample():
    """A requested time equal to a crossing time is recorded once from the piece and once as
    the event's forced sample, in non-decreasing time order, both on the facet ``q = 0``."""
    p = sp.bimodal_oscillator()
    first = simulate(p.system, p.x0, (0.0, 10.0)).event_times("crossing")[0]
    t_eval = np.array([0.0, 0.5 * first, first, 9.0])
    tr = simulate(p.system, p.x0, (0.0, 10.0), t_eval=t_eval)
    at = np.flatnonzero(tr.t == first)
    assert at.size == 2 and np.all(np.diff(tr.t) >= 0.0)
    assert np.max(np.abs(tr.x[at, 0])) <= 1e-12


def test_the_model_cache_keeps_inputs_and_models_apart():
    """Runs of one model under two forcing frequencies, and of a changed copy, each equal a
    run with the cache emptied (the cache key holds every matrix of the model and input)."""
    A1 = np.array([[0.0, 1.0], [-1.0, -0.2]])
    A2 = np.array([[0.0, 1.0], [-6.0, -0.2]])

    def model(omega, k2=6.0):
        A = A2.copy()
        A[1, 0] = -k2
        return PiecewiseAffineSystem.bimodal(A, A1, [1.0, 0.0], E=[[0.0], [1.0]],
                                             u=Exosystem.sinusoid(1.0, omega))

    runs = [(model(1.0), 1.0), (model(1.7), 1.7), (model(1.0, 3.0), 1.0)]
    cached = [simulate(s, [0.3, 0.0], (0.0, 20.0), n_samples=5).x for s, _ in runs]
    fresh = []
    for s, _ in runs:
        _switching_pwa._MODES.clear()
        fresh.append(simulate(s, [0.3, 0.0], (0.0, 20.0), n_samples=5).x)
    for a, b in zip(cached, fresh, strict=True):
        assert np.array_equal(a, b)
    assert np.min(np.abs(cached[0][-1] - cached[1][-1])) > 1e-3
    assert np.min(np.abs(cached[0][-1] - cached[2][-1])) > 1e-3
