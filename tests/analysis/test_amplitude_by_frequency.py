"""Forcing whose amplitude depends on the frequency (a rotating unbalance, a(ω) = m_e r_e ω²)
in the frequency responses and sweeps, the sweeps' fixed transient time, and the attenuation
figures of chapter 6 (attenuation_report, local_maxima)."""

import dataclasses

import numpy as np
import pytest

from nscontrol.analysis.attenuation import attenuation_report, local_maxima, response_amplitude
from nscontrol.analysis.periodic import FrequencyResponse, frequency_response, frequency_sweep
from nscontrol.errors import DimensionError, ModelError
from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
from nscontrol.systems.beam import Unbalance


def _gain(w):
    return abs(1 / (1 - w**2 + 0.1j * w))   # linear oscillator m = k = 1, c = 0.1


def test_frequency_response_divides_by_the_amplitude_at_each_frequency():
    linear = one_sided_oscillator(0.1, ks=0.0)
    w = np.array([0.5, 1.0, 2.0])
    frf = frequency_response(linear, w, amplitude=Unbalance(0.3), executor="serial",
                             progress=False)
    G = np.array([_gain(v) for v in w])
    # shooting to 1e-11 and a parabola-refined peak of 1000 samples (bias (π/N)²/2 ~ 5e-6 of
    # a sinusoid's peak, before refinement): 1e-6 relative
    assert np.allclose(frf.gamma, G, rtol=1e-6)
    assert np.allclose(frf.amplitudes, 0.3 * w**2, rtol=1e-15)
    assert np.isnan(frf.amplitude)
    assert np.allclose(response_amplitude(frf), 0.3 * w**2 * G, rtol=1e-6)


def test_sweep_with_amplitude_map_and_transient_time():
    linear = one_sided_oscillator(0.1, ks=0.0)
    w = np.array([0.8, 0.9, 1.0])
    res = frequency_sweep(linear, w, amplitude=Unbalance(0.3), transient_time=150.0,
                          n_record=4, executor="serial", progress=False)
    G = np.array([_gain(v) for v in w])
    for d in ("up", "down"):
        # a linear system has one T-periodic steady state: the shot orbit, same bound as above
        assert np.allclose(res[d].gamma, G, rtol=1e-6)
        assert np.all(res[d].multiplicity == 1)
        assert np.allclose(res[d].amplitudes, 0.3 * w**2, rtol=1e-15)


def test_bad_amplitudes_and_transient_times_are_refused():
    linear = one_sided_oscillator(0.1, ks=0.0)
    with pytest.raises(ModelError, match="amplitude"):
        frequency_response(linear, [1.0], amplitude=-1.0, progress=False)
    with pytest.raises(ModelError, match="amplitude: the callable returned -1.0"):
        frequency_response(linear, [1.0], amplitude=lambda w: -w, executor="serial",
                           progress=False)
    with pytest.raises(ModelError, match="transient_time"):
        frequency_sweep(linear, [1.0], transient_time=0.0, progress=False)


def _response(w, gamma, effort=None):
    fr = FrequencyResponse.from_points(w, [None] * w.size, direction="up", amplitude=1.0,
                                       n_harmonics=1)
    out = dataclasses.replace(fr, gamma=np.asarray(gamma, float))
    if effort is not None:
        out = dataclasses.replace(out, effort=np.asarray(effort, float))
    return out


def test_attenuation_report_figures():
    f = np.array([10.0, 12.0, 14.0, 16.0, 28.0, 30.0, 55.0])
    w = 2 * np.pi * f
    up = _response(w, [1.0, 2.0, 1.5, 1.0, 8.0, 3.0, 2.0])
    down = _response(w, [1.0, 2.0, 1.5, 1.0, 8.0, 3.0, 6.0])   # coexistence at 55 Hz
    cl = _response(w, [0.5, 0.5, 0.5, 0.5, 0.4, 0.4, 0.3], effort=[1, 2, 3, 4, 5, 6, 7])
    rep = attenuation_report([up, down], cl, points={"harmonic": (25.0, 30.0),
                                                     "superharmonic": (11.0, 15.0),
                                                     "sub": 55.0})
    assert rep.sup_ratio == pytest.approx(8.0 / 0.5)
    assert rep.ratios == pytest.approx({"harmonic": 20.0, "superharmonic": 4.0, "sub": 20.0})
    assert rep.at == {"harmonic": 28.0, "superharmonic": 12.0, "sub": 55.0}
    assert rep.max_effort == 7.0
    assert rep.coexistence == [(55.0, 55.0)]
    assert rep.closed_loop_maxima.size == 0
    with pytest.raises(ModelError, match="points"):
        attenuation_report([up], cl, points={"empty": (40.0, 50.0)})
    with pytest.raises(DimensionError, match="open_loop"):
        attenuation_report([_response(w[:3], [1, 2, 3])], cl)


def test_local_maxima():
    assert list(local_maxima([0, 2, 1, 3, np.nan, 1, 5])) == [1]
    with pytest.raises(DimensionError, match="values"):
        local_maxima(np.ones((2, 2)))
