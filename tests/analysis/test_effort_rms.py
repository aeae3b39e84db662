"""The RMS control effort of the steady-state responses (chapter 6's performance measures):
the closed form of a linear loop, RMS <= max, the p periods of a subharmonic brute-force
window, NaN without a control law, and its band maximum in the attenuation report."""

import dataclasses

import numpy as np
import pytest

from nscontrol.analysis import periodic as pr
from nscontrol.analysis.attenuation import attenuation_report
from nscontrol.design.convergent_pwa import design_state_feedback
from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
from nscontrol.numerics.lti import Exosystem

OMEGAS = [0.5, 1.0, 1.42, 2.9]


def _closed_form_rms(A_cl, K, D, w, a):
    """``|K (iωI − A_cl)⁻¹ D| a / √2``: the RMS of the sinusoidal steady-state effort."""
    n = A_cl.shape[0]
    return abs((K @ np.linalg.solve(1j * w * np.eye(n) - A_cl, D)).item()) * a / np.sqrt(2)


def test_rms_effort_of_a_linear_loop_matches_the_closed_form():
    plant = one_sided_oscillator(0.1, ks=0.0)
    sf = design_state_feedback(plant, sigma=0.3)
    loop = sf.closed_loop(plant)
    A_cl, D = loop.A[0], np.asarray(plant.E, float)
    a = 0.7
    frf = pr.frequency_response(loop, OMEGAS, amplitude=a, control=sf.control,
                                executor="serial", progress=False)
    want = [_closed_form_rms(A_cl, sf.K, D, w, a) for w in OMEGAS]
    # N = 1000 uniform samples of a sinusoid give its exact mean square (N > 2: the samples
    # of cos(2ωt) sum to zero), so only the shooting error remains: |x0 - x̄0| <= 1e-11
    # max(1, |x|) (periodic_steady_state's tol), propagated with a gain ~1 through a stable
    # loop; 1e-9 relative is that times 100
    np.testing.assert_allclose(frf.effort_rms, want, rtol=1e-9)
    # a sinusoid's peak over its RMS is √2 (peak refined to ~1e-6: the gamma bound above)
    np.testing.assert_allclose(frf.effort / frf.effort_rms, np.sqrt(2), rtol=1e-6)
    # the sweeps (landing by brute force, then continuation) measure the same figure
    sweep = pr.frequency_sweep(loop, OMEGAS[:2], amplitude=a, control=sf.control,
                               n_transient=60, n_record=2, directions=("up",),
                               executor="serial", progress=False)["up"]
    assert np.all(sweep.multiplicity == 1)
    # 128 samples per period (the sweeps' default) are as exact as 1000 for a sinusoid; the
    # continued orbit is shot to the sweeps' 1e-10: 1e-8 relative is that times 100
    np.testing.assert_allclose(sweep.effort_rms, want[:2], rtol=1e-8)


def test_rms_is_at_most_the_peak_for_a_piecewise_linear_loop():
    plant = one_sided_oscillator(0.1)
    sf = design_state_feedback(plant, sigma=0.3)
    frf = pr.frequency_response(sf.closed_loop(plant), OMEGAS, control=sf.control,
                                executor="serial", progress=False)
    assert np.all(np.isfinite(frf.effort_rms))
    # RMS <= max of the same samples exactly; the refined peak is >= the largest sample
    assert np.all(frf.effort_rms <= frf.effort)
    without = pr.frequency_response(sf.closed_loop(plant), [1.0], progress=False)
    assert np.all(np.isnan(without.effort_rms)) and np.all(np.isnan(without.effort))


def test_brute_force_rms_runs_over_the_p_periods_of_a_subharmonic():
    """The open one-sided oscillator at ω = 2.9 settles on a period-2T response; the RMS of a
    (made-up) control law u = x₁ is taken over both periods, the peak over both too."""
    plant = one_sided_oscillator(0.1)
    w = 2.9
    bf = pr.brute_force_steady_state(plant, 2 * np.pi / w, u=Exosystem.sinusoid(1.0, w),
                                     n_transient=300, n_record=4)
    assert bf.multiplicity == 2

    def control(x):
        return x[:, :1]

    resp = pr._brute_response(bf, w, 1.0, np.eye(1, 2), 3, control)
    _, x = bf.uniform_samples(2)
    one_period = np.sqrt(np.mean(x[x.shape[0] // 2:, 0] ** 2))
    # the same samples, the same formula: equal up to the rounding of a mean (n·u)
    assert resp.effort_rms == pytest.approx(np.sqrt(np.mean(x[:, 0] ** 2)), rel=1e-13)
    # the two periods differ (that is the subharmonic): one period would not be the figure
    assert abs(one_period / resp.effort_rms - 1) > 1e-3
    assert resp.effort_rms <= resp.effort


def test_attenuation_report_gives_the_band_maxima_of_both_efforts():
    w = 2 * np.pi * np.array([10.0, 20.0, 30.0])
    fr = pr.FrequencyResponse.from_points(w, [None] * 3, direction="up", amplitude=1.0,
                                          n_harmonics=1)
    assert fr.effort_rms.shape == (3,) and np.all(np.isnan(fr.effort_rms))
    ol = dataclasses.replace(fr, gamma=np.array([1.0, 4.0, 2.0]))
    cl = dataclasses.replace(fr, gamma=np.array([0.5, 0.5, 0.25]),
                             effort=np.array([1.0, 3.0, 2.0]),
                             effort_rms=np.array([0.7, np.nan, 1.4]))
    rep = attenuation_report([ol], cl)
    assert (rep.max_effort, rep.max_effort_rms) == (3.0, 1.4)
    assert np.isnan(attenuation_report([ol], ol).max_effort_rms)
