"""Chapter 11 steady states: shooting with the integrator's monodromy, Floquet multipliers,
uniqueness, brute force, homogeneity, frequency responses and bounds, observer and output
feedback (spec §5 checks 5–14)."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.analysis import convergence as cv
from nscontrol.analysis import periodic as pr
from nscontrol.design import convergent_pwa as d
from nscontrol.errors import DimensionError, ModelError
from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
from nscontrol.numerics.lti import Exosystem

W_RES, W_SUB = 1.420, 2.9


@pytest.fixture(scope="module")
def plant():
    return one_sided_oscillator(0.1)


@pytest.fixture(scope="module")
def sf(plant):
    return d.design_state_feedback(plant, sigma=0.3)


@pytest.fixture(scope="module")
def loop(plant, sf):
    return sf.closed_loop(plant)


@pytest.fixture(scope="module")
def obs(plant):
    return d.design_observer(plant, sigma=1.0)


def _orbit(system, omega, a=1.0, **kw):
    return pr.periodic_steady_state(system, 2 * np.pi / omega, u=Exosystem.sinusoid(a, omega),
                                    **kw)


def _linear_gain(A, B, C, w):
    return abs((C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B)).item())


def test_check5_periodicity_and_constant_input(loop):
    orbit = _orbit(loop, W_SUB)
    assert orbit.residual <= 1e-9
    assert np.all(np.abs(orbit.floquet) < 1)
    assert orbit.max_multiplier == pytest.approx(0.136, abs=1e-3)  # spec §4.1
    # constant input: the steady state is the equilibrium of §2.2
    x_eq = cv.equilibrium(loop, [0.3])
    steady = pr.periodic_steady_state(loop, 1.0, u=Exosystem.constant(0.3))
    np.testing.assert_allclose(steady.x0, x_eq, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.ptp(steady.trajectory.x, axis=0), 0, atol=1e-9)


def test_check6_uniqueness_and_incremental_bound(loop, sf):
    check = pr.check_uniqueness(loop, 2 * np.pi / W_SUB, u=Exosystem.sinusoid(1.0, W_SUB))
    assert check.unique and check.max_relative_spread <= 1e-8
    T = 2 * np.pi / W_SUB
    times = np.arange(21) * T
    runs = [simulate(loop, x0, (0, 20 * T), method="switching", t_eval=times,
                     u=Exosystem.sinusoid(1.0, W_SUB)) for x0 in ([3.0, -1.0], [-2.0, 4.0])]
    xs = [r.x[np.searchsorted(r.t, times, side="left")] for r in runs]
    delta = np.linalg.norm(xs[0] - xs[1], axis=1)
    lam = np.linalg.eigvalsh(sf.P)
    bound = np.sqrt(lam[-1] / lam[0]) * np.exp(-0.3 * times) * delta[0] * (1 + 1e-6)
    assert np.all(delta[1:] <= bound[1:])


def test_check7_open_loop_not_convergent(plant):
    T = 2 * np.pi / W_SUB
    orbit = _orbit(plant, W_SUB)
    real = orbit.floquet[np.abs(orbit.floquet.imag) < 1e-12].real
    assert real.min() < -1.5 and not orbit.stable
    bf = pr.brute_force_steady_state(plant, T, u=Exosystem.sinusoid(1.0, W_SUB),
                                     n_transient=300)
    assert bf.multiplicity == 2
    assert 1.1 <= np.max(np.abs(bf.trajectory.x[:, 0])) <= 1.35


def test_check8_homogeneity_and_gap(plant, sf, loop):
    gammas = [pr.harmonic_response(_orbit(loop, W_SUB, a), amplitude=a, system=loop).gamma
              for a in (0.1, 1.0, 10.0)]
    assert gammas[0] == pytest.approx(0.18919, abs=1e-5)
    np.testing.assert_allclose(gammas, gammas[1], rtol=1e-6)
    gap_loop = sf.closed_loop(one_sided_oscillator(0.1, gap=0.5))
    lin = _linear_gain(plant.A[1] + plant.E @ sf.K, plant.E, plant.C, W_SUB)
    assert lin == pytest.approx(0.125325, abs=1e-6)
    for a in (0.01, 1.0):
        g = pr.harmonic_response(_orbit(gap_loop, W_SUB, a), amplitude=a, system=gap_loop).gamma
        assert g == pytest.approx(lin, rel=1e-5)
    big = pr.harmonic_response(_orbit(gap_loop, W_SUB, 10.0), amplitude=10.0, system=gap_loop)
    assert big.gamma >= 1.1 * lin


def test_check9_linear_sanity():
    linear = one_sided_oscillator(0.1, ks=0.0)
    omegas = np.geomspace(0.2, 5.0, 20)
    frf = pr.frequency_response(linear, omegas, progress=False)
    exact = [_linear_gain(linear.A[1], linear.E, linear.C, w) for w in omegas]
    np.testing.assert_allclose(frf.gamma, exact, rtol=1e-5)
    np.testing.assert_allclose(frf.rms_gain, exact, rtol=1e-5)  # RMS ratio of a sinusoid
    np.testing.assert_allclose(frf.harmonics[:, 0], exact, rtol=1e-5)


@pytest.mark.parametrize("n_omega", [pytest.param(60, marks=pytest.mark.slow), 16])
def test_check10_bounds_hold(plant, sf, loop, n_omega):
    omegas = np.geomspace(0.1, 10.0, n_omega)
    if n_omega < 60:  # quick variant: a log grid plus the neighbourhood of the peaks
        omegas = np.sort(np.r_[np.geomspace(0.1, 10.0, 8), np.linspace(1.5, 2.6, 8)])
    frf = pr.frequency_response(loop, omegas, n_samples=400, progress=False)
    assert all(e is None for e in frf.errors)
    p2p = cv.peak_to_peak_bound(loop.A, loop.E, loop.C).bound
    l2 = cv.incremental_l2_bound(loop.A, loop.E, loop.C).bound
    assert p2p == pytest.approx(1.127, abs=2e-3) and l2 == pytest.approx(0.804, abs=2e-3)
    assert frf.gamma.max() <= p2p and frf.rms_gain.max() <= l2
    # P6: with the (SF-σ) certificate every Floquet multiplier obeys |μ| <= e^{-σT}
    assert np.all(frf.max_floquet <= np.exp(-0.3 * 2 * np.pi / omegas) * (1 + 1e-9))
    assert frf.gamma.max() == pytest.approx(0.415, abs=1e-2)
    assert frf.rms_gain.max() == pytest.approx(0.329, abs=1e-2)
    eps = 2 * 0.3 * np.linalg.eigvalsh(sf.P)[0]
    g_isc = cv.isc_gain(sf.P, loop.E, eps)
    x_max = max(np.max(np.linalg.norm(_orbit(loop, w).trajectory.x, axis=1))
                for w in (0.5, W_RES, W_SUB))
    assert x_max <= g_isc * 1.0 and g_isc == pytest.approx(12.9, abs=0.1)


@pytest.mark.parametrize("omega", [W_SUB, 0.95, 0.6])
def test_check11_monodromy_equals_finite_differences(plant, omega):
    orbit = _orbit(plant, omega)
    assert 2 <= orbit.n_crossings <= 6
    T = orbit.period
    u = Exosystem.sinusoid(1.0, omega)
    h = 1e-7 * max(1.0, np.linalg.norm(orbit.x0))
    J = np.empty((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        ends = [simulate(plant, orbit.x0 + s * e, (0, T), method="switching", u=u,
                         t_eval=[0, T]).x[-1] for s in (1, -1)]
        J[:, j] = (ends[0] - ends[1]) / (2 * h)
    np.testing.assert_allclose(orbit.monodromy, J, rtol=1e-5,
                               atol=1e-5 * np.abs(J).max())
    tr = simulate(plant, orbit.x0, (0, T), method="switching", u=u, sensitivity=True)
    for S in tr.stats["saltation_matrices"]:  # continuous field: no saltation
        np.testing.assert_allclose(S, np.eye(2), atol=1e-9)


def test_check12_attenuation_at_resonance(plant, loop):
    open_max = np.max(np.abs(_orbit(plant, W_RES).trajectory.x[:, 0]))
    closed_max = np.max(np.abs(_orbit(loop, W_RES).trajectory.x[:, 0]))
    assert open_max == pytest.approx(9.72, abs=0.01)
    assert open_max / closed_max >= 10


def test_check13_observer_error_bound_with_nonconvergent_plant(plant, obs):
    both = d.output_feedback_loop(plant, obs, None)
    t = np.linspace(0, 8, 200)
    tr = simulate(both, [1.0, 0.0, -1.0, 2.0], (0, 8), method="switching", t_eval=t,
                  u=Exosystem.sinusoid(1.0, W_SUB))
    x = tr.x[np.searchsorted(tr.t, t, side="left")]
    e = np.linalg.norm(x[:, :2] - x[:, 2:], axis=1)
    assert np.all(e <= obs.error_bound(t, e[0]) * (1 + 1e-6))
    assert len(tr.events) > 0  # the plant and the estimate do switch


@pytest.mark.parametrize("omega", [1.0, W_RES, W_SUB])
def test_check14_output_feedback_equals_state_feedback(plant, sf, obs, loop, omega):
    out = _orbit(d.output_feedback_loop(plant, obs, sf), omega)
    ref = _orbit(loop, omega)
    np.testing.assert_allclose(out.x0[:2], ref.x0, rtol=1e-8, atol=1e-8 * np.abs(ref.x0).max())
    assert np.linalg.norm(out.x0[:2] - out.x0[2:]) <= 1e-10 * np.linalg.norm(out.x0[:2])
    assert out.stable


def test_period_multiplicity_and_peak_helpers():
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    assert pr.refined_peak(np.sin(t + 0.05)) == pytest.approx(1.0, abs=1e-5)
    assert np.max(np.sin(t + 0.05)) < 1 - 1e-4
    np.testing.assert_allclose(pr.dft_harmonics(np.sin(t) + 0.5 * np.cos(3 * t), 3),
                               [1.0, 0.0, 0.5], atol=1e-12)
    x = np.array([[1.0, 0.0], [2.0, 1.0], [1.0, 0.0], [2.0, 1.0], [1.0, 0.0]])
    assert pr.period_multiplicity(x) == 2
    assert pr.period_multiplicity(np.arange(10.0)[:, None]) == 0


def test_bad_input_periodic(loop):
    with pytest.raises(ModelError, match="period"):
        pr.periodic_steady_state(loop, 0.0)
    with pytest.raises(ModelError, match="period"):
        pr.periodic_steady_state(loop, -1.0)
    with pytest.raises(DimensionError):
        pr.periodic_steady_state(loop, 1.0, x0=[0.0, 0.0, 0.0])
    with pytest.raises(ModelError, match="omegas"):
        pr.frequency_response(loop, [1.0, -2.0])
    with pytest.raises(DimensionError):
        pr.frequency_response(loop, [1.0], output=np.ones(3))


def test_frequency_sweep_up_and_down_reveals_period_doubling(plant):
    branches = pr.frequency_sweep(plant, [2.7, 2.9], n_transient=150, n_record=6,
                                  progress=False)
    assert set(branches) == {"up", "down"}
    for res in branches.values():
        assert res.direction in ("up", "down") and res.errors == ()
        assert res.multiplicity[1] == 2  # ω = 2.9: the 2T orbit of check 7
        assert 1.1 <= res.gamma[1] <= 1.35
    with pytest.raises(ModelError, match="directions"):
        pr.frequency_sweep(plant, [1.0], directions=("sideways",))


def test_frequency_response_in_worker_processes_matches_serial(loop):
    from concurrent.futures import ProcessPoolExecutor

    omegas = [0.8, W_SUB]
    serial = pr.frequency_response(loop, omegas, progress=False)
    with ProcessPoolExecutor(2) as pool:
        parallel = pr.frequency_response(loop, omegas, executor=pool, progress=False)
    np.testing.assert_allclose(parallel.gamma, serial.gamma, rtol=1e-12)
    assert parallel.gamma[1] == pytest.approx(0.18919, abs=1e-5)
