"""Saltation matrices against finite differences, for each event kind."""

import numpy as np
import pytest

from nscontrol.analysis.orbits import Forced, find_orbit, stroboscopic_map
from nscontrol.analysis.periodic import periodic_steady_state
from nscontrol.analysis.saltation import impact_jump_jacobian, saltation_matrix, time_shift_term
from nscontrol.errors import SolverError
from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
from nscontrol.numerics.lti import Exosystem

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps


def _fd_event_map(flow_minus, flow_plus, guard, jump, x, tau, h=1e-6):
    """Central differences of 'flow with f- until the guard, jump, flow with f+ until tau'
    for constant fields (explicit event time) — the definition the saltation matrix
    linearises."""
    def phi(x0):
        fm, fp = flow_minus, flow_plus
        dh = guard
        t_e = -(dh @ x0) / (dh @ fm)               # guard h(x) = dh·x, linear flow x0 + t fm
        xm = x0 + t_e * fm
        return jump @ xm + (tau - t_e) * fp
    return np.column_stack([(phi(x + h * e) - phi(x - h * e)) / (2 * h)
                            for e in np.eye(len(x))])


@pytest.mark.parametrize("kind", ["impact", "crossing", "sliding_entry"])
def test_saltation_is_the_derivative_of_the_event_map(kind):
    fm = np.array([2.0, -1.0])
    if kind == "impact":
        J, fp = np.diag([1.0, -0.5]), np.array([-1.0, -1.0])
    elif kind == "crossing":
        J, fp = np.eye(2), np.array([1.5, 3.0])
    else:                                            # sliding: the field tangent to h = 0
        J, fp = np.eye(2), np.array([0.0, -0.7])
    dh = np.array([1.0, 0.0])
    x = np.array([-0.1, 0.2])                        # reaches h = 0 at t = 0.05
    tau = 0.05                                       # evaluate right at the event
    t_e = 0.05
    S = saltation_matrix(J, fm, fp, dh)
    # all maps affine in x: the central difference is exact up to rounding eps·|x|/h
    fd = _fd_event_map(fm, fp, dh, J, x, tau)
    assert np.max(np.abs(S - fd)) <= 1e3 * EPS / 1e-6
    assert t_e == tau


def test_sliding_exit_and_fixed_time_switch_give_identity():
    f = np.array([0.3, -1.0])
    assert np.array_equal(saltation_matrix(np.eye(2), f, f, [1.0, 0.0]), np.eye(2))
    # a PWM edge at a state-dependent instant: the transition picks up (f- - f+) ∂τ/∂x
    T = time_shift_term([1.0, 0.0], [0.0, 1.0], [0.5, 0.0])
    assert T.tolist() == [[0.5, 0.0], [-0.5, 0.0]]


def test_grazing_has_no_saltation_matrix():
    with pytest.raises(SolverError, match="grazing"):
        saltation_matrix(np.eye(2), [0.0, 1.0], [0.0, 1.0], [1.0, 0.0])


def test_impact_jump_jacobian_of_one_mass():
    J = impact_jump_jacobian([[2.0]], [-1.0], 0.8)
    assert J.tolist() == [[1.0, 0.0], [0.0, -0.8]]


def _pwa():
    w = 2.9
    return Forced(one_sided_oscillator(0.1), Exosystem.sinusoid(1.0, w), 2 * np.pi / w,
                  method="switching")


def test_facet_crossing_monodromy_matches_finite_differences():
    f = _pwa()
    x0 = np.array([0.3, 0.1])
    J = stroboscopic_map(f, x0).jacobian
    h = 1e-5
    fd = np.column_stack([(stroboscopic_map(f, x0 + h * e).x - stroboscopic_map(f, x0 - h * e).x)
                          / (2 * h) for e in np.eye(2)])
    # central differences: h²/6·|P'''| (<= 1e2 for crossings at speed ~1) + eps/h
    assert np.max(np.abs(J - fd)) <= 1e-6 * max(1.0, np.max(np.abs(J)))


def test_pwa_orbit_agrees_with_periodic_steady_state():
    """The chapter-11 oscillator at ω = 2.9: period-1 orbit (unstable, multiplier -2.188)."""
    f = _pwa()
    ref = periodic_steady_state(f.system, f.period, u=f.u)
    orb = find_orbit(f, ref.x0)
    # both Newton iterations on the same map to 1e-11: cond(I - M) ~ 1 here
    assert np.max(np.abs(orb.x0 - ref.x0)) <= 1e-9
    assert np.max(np.abs(orb.multipliers - ref.floquet)) <= 1e-9
    assert orb.multipliers[0].real == pytest.approx(-2.188, abs=5e-4)   # 4 digits published


@pytest.mark.parametrize("x0, kinds", [
    ([1.5, -0.4], ["sliding_start", "sliding_exit", "crossing"]),
    ([-0.5, 1.0], ["crossing", "crossing"]),
])
def test_sliding_entry_exit_monodromy_matches_finite_differences(x0, kinds):
    """A Filippov system (Coulomb friction, sliding on q' = 0) over one forcing period."""
    from nscontrol.testing.setvalued_problems import coulomb_oscillator

    f = Forced(coulomb_oscillator(friction=1.0, amplitude=2.0).switched, None, 2 * np.pi,
               method="switching")
    x0 = np.asarray(x0)
    m = stroboscopic_map(f, x0)
    assert [k for k, _ in m.signature] == kinds
    h = 1e-4
    fd = np.column_stack([(stroboscopic_map(f, x0 + h * e).x - stroboscopic_map(f, x0 - h * e).x)
                          / (2 * h) for e in np.eye(2)])
    # central differences: h²/6·|P'''| (|P'''| <= 1e2 between events) = 2e-7, plus the event
    # times' rounding ~1e-11 over h = 1e-7; both below 1e-6
    assert np.max(np.abs(m.jacobian - fd)) <= 1e-6
