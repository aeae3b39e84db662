"""Periodic orbits of forced Lur'e systems under implicit time-stepping: the fixed point of the
discrete stroboscopic map (``find_orbit`` on ``method="implicit_euler"``), against the exact
orbit of the same dynamics integrated with located switchings (``method="switching"``)."""

import numpy as np
import pytest

from nscontrol.analysis.orbits import Forced, find_orbit, stroboscopic_map
from nscontrol.laws.monotone_function import PiecewiseLinearFunction
from nscontrol.laws.relay import Relay
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems.lure import LureSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

K, C, LEVEL, SLOPE, AMP, OMEGA = 1.0, 0.2, 1.0, 4.0, 3.0, 1.5
PERIOD = 2 * np.pi / OMEGA
A = np.array([[0.0, 1.0], [-K, -C]])
E2 = np.array([0.0, 1.0])


def _saturated_oscillator():
    """``q'' + C q' + K q + sat(q) = AMP sin(OMEGA t)`` with ``sat(q) = clip(SLOPE q, ±LEVEL)``,
    as a Lur'e system and as the equivalent continuous three-region PWA system."""
    u = Exosystem.sinusoid(AMP, OMEGA)
    law = PiecewiseLinearFunction.saturation(LEVEL, SLOPE)
    lure = LureSystem(A, E2[:, None], np.array([[1.0, 0.0]]), law, B=E2[:, None], u=u)
    zc = LEVEL / SLOPE
    inner = np.array([[0.0, 1.0], [-(K + SLOPE), -C]])
    pwa = PiecewiseAffineSystem(
        [A, inner, A], [[0.0, LEVEL], [0.0, 0.0], [0.0, -LEVEL]],
        [(np.array([[1.0, 0.0]]), np.array([-zc])),
         (np.array([[1.0, 0.0], [-1.0, 0.0]]), np.array([zc, zc])),
         (np.array([[-1.0, 0.0]]), np.array([-zc]))],
        E=E2[:, None], u=u, continuous=True)
    return lure, pwa


def _discrete_orbit(lure, n_steps, guess):
    forced = Forced(lure, None, PERIOD, method="implicit_euler",
                    options=(("h", PERIOD / n_steps),))
    return find_orbit(forced, guess, tol=1e-12)


def _by_angle(mu):
    return mu[np.argsort(np.angle(mu))]


@pytest.fixture(scope="module")
def saturated():
    lure, pwa = _saturated_oscillator()
    exact = find_orbit(Forced(pwa, None, PERIOD, method="switching"), [0.0, 0.0])
    steps = (200, 400, 800, 1600)
    return exact, [_discrete_orbit(lure, n, exact.x0) for n in steps]


def _orders(errors):
    return [float(np.log2(a / b)) for a, b in zip(errors[:-1], errors[1:], strict=True)]


def _fitted_order(errors):
    """Least-squares slope of ``log2 e`` against ``log2 N`` (step sizes halved each time)."""
    k = np.arange(len(errors), dtype=float)
    return float(-np.polyfit(k, np.log2(errors), 1)[0])


def test_saturated_orbit_converges_at_first_order(saturated):
    # backward Euler is first order: e(h) = C h + O(h²), so halving h halves the error up to
    # a relative O(h/T) correction, below 0.1 from 200 steps a period on
    exact, orbits = saturated
    assert exact.residual <= 1e-11        # the located-switching reference is exact to 1e-11
    errors = [np.max(np.abs(o.x0 - exact.x0)) for o in orbits]
    for p in _orders(errors):
        assert 0.9 <= p <= 1.1
    assert errors[-1] <= 0.1 * np.max(np.abs(exact.x0))   # and it is already close


def test_saturated_orbit_multipliers_converge_at_first_order(saturated):
    # each step's Jacobian is the exact flow's to O(h²), except on the four steps a period
    # that straddle a corner of the saturation: there it is one side's, an O(h) error whose
    # constant depends on where the grid falls (error·N varies by up to 1.5x from one N to the
    # next). Over a factor 8 in h that moves the fitted slope by at most log2(1.5)/3 < 0.2
    exact, orbits = saturated
    errors = [np.max(np.abs(_by_angle(o.multipliers) - _by_angle(exact.multipliers)))
              for o in orbits]
    assert 0.8 <= _fitted_order(errors) <= 1.2
    assert all(o.stable for o in orbits) and exact.stable


def test_relay_orbit_converges_at_first_order():
    # q'' + 0.2 q' + q = 2 sin(0.8 t) - sign(q') (Coulomb friction): the exact orbit crosses
    # q' = 0 twice a period (Filippov form, DOP853 to 1e-11: negligible beside the O(h)
    # errors). At a crossing implicit Euler may hold z = 0 for one step, an O(h) error whose
    # constant depends on where the grid falls: the order is 1 within ±0.2
    c, friction, amp, omega = 0.2, 1.0, 2.0, 0.8
    T = 2 * np.pi / omega
    Af = np.array([[0.0, 1.0], [-1.0, -c]])
    u = Exosystem.sinusoid(amp, omega)
    lure = LureSystem(Af, E2[:, None], E2[None, :], Relay(friction), B=E2[:, None], u=u)

    def slipping_forward(t, x):
        return Af @ x + E2 * (amp * np.sin(omega * t) - friction)

    def slipping_back(t, x):
        return Af @ x + E2 * (amp * np.sin(omega * t) + friction)

    fil = FilippovSystem.two_sided(slipping_back, slipping_forward, lambda x: float(x[1]), 2,
                                   gradient=lambda x: E2)
    exact = find_orbit(Forced(fil, None, T, method="switching"), [-2.7, 1.0], tol=1e-10)
    errors = []
    for n in (250, 500, 1000):
        forced = Forced(lure, None, T, method="implicit_euler", options=(("h", T / n),))
        errors.append(np.max(np.abs(find_orbit(forced, exact.x0, tol=1e-12).x0 - exact.x0)))
    for p in _orders(errors):
        assert 0.8 <= p <= 1.2


def test_forced_input_and_map_jacobian_of_a_lure_orbit():
    # Forced(lure, u, T) passes u to implicit_euler; the orbit's monodromy is the discrete
    # map's Jacobian at the fixed point, a product of T/h exact step Jacobians
    lure, _ = _saturated_oscillator()
    bare = LureSystem(A, E2[:, None], np.array([[1.0, 0.0]]), lure.law, B=E2[:, None])
    u = Exosystem.sinusoid(AMP, OMEGA)
    forced = Forced(bare, u, PERIOD, method="implicit_euler", options=(("h", PERIOD / 300),))
    orbit = find_orbit(forced, [0.0, 0.0])
    again = stroboscopic_map(forced, orbit.x0)
    # Newton's tolerance 1e-11 relative on the residual
    assert np.max(np.abs(again.x - orbit.x0)) <= 1e-11 * max(1.0, np.max(np.abs(orbit.x0)))
    np.testing.assert_array_equal(again.jacobian, orbit.monodromy)
    assert again.trajectory.stats["steps"] == 300
    assert again.trajectory.stats["degenerate_steps"] == 0


def test_periodic_steady_state_shoots_the_same_discrete_orbit(saturated):
    # periodic_steady_state asks for the sensitivity capability, which implicit_euler now has:
    # its Newton on the same discrete map lands on the same fixed point. Both stop at a
    # residual <= 1e-11 relative on a map contracting by |μ| = 0.64: within 1e-11/(1 - 0.64)
    from nscontrol.analysis.periodic import periodic_steady_state

    lure, _ = _saturated_oscillator()
    _, orbits = saturated
    pss = periodic_steady_state(lure, PERIOD, method="implicit_euler", h=PERIOD / 400,
                                n_samples=2)
    scale = max(1.0, np.max(np.abs(orbits[1].x0)))
    assert np.max(np.abs(pss.x0 - orbits[1].x0)) <= 3e-11 * scale
    # the step Jacobians depend only on the active sets, the same at both points: the
    # monodromies differ by the rounding of 400 products, ~400 ε |J|
    np.testing.assert_allclose(pss.monodromy, orbits[1].monodromy, rtol=0, atol=1e-9)
