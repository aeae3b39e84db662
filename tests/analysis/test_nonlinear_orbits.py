"""Periodic orbits of nonlinear mechanics: stroboscopic_map / find_orbit / continue_orbit on
the event-driven integrator's state transition (DOP853, variational equation, saltation)."""

from dataclasses import dataclass

import numpy as np
import pytest

from nscontrol.analysis.continuation import continue_orbit
from nscontrol.analysis.impact_oscillator import ImpactOscillator
from nscontrol.analysis.orbits import Forced, find_orbit, stroboscopic_map
from nscontrol.numerics.differences import central_difference_jacobian
from nscontrol.testing.mechanics_problems import ImpactingPendulum

# DOP853's global error over one period: at most (steps <= 200) local errors of
# rtol·max(1, |x|), carried by |Φ| <= 5
STEP_BOUND = 1e3
RTOL = 1e-12
OPTIONS = dict(rtol=RTOL, atol=RTOL * 1e-2, progress=False)


def test_impact_oscillator_through_the_nonlinear_path_gives_the_closed_form():
    osc = ImpactOscillator(omega=2.5, stop=0.1, forcing=2.0)
    cf = osc.admissible_orbit()
    f = osc.forced(drive_as_force=True, **OPTIONS)    # DOP853, not exponentials
    assert not f.system.is_linear
    orb = find_orbit(f, cf.x0 + [1e-3, -1e-3])
    assert orb.signature == (("impact", 0),)
    delta = STEP_BOUND * RTOL * max(1.0, np.max(np.abs(cf.x0)))   # the map's error
    kappa = np.linalg.cond(np.eye(2) - cf.monodromy)
    # Newton's fixed point of a map off by delta: off by cond(I - M)·delta
    assert np.max(np.abs(orb.x0 - cf.x0)) <= kappa * delta
    # Bauer–Fike: |δμ| <= cond(V)·|δM|; δM: the variational equation's own error
    # (STEP_BOUND·rtol relative) and the fixed point's offset times |∂M/∂x| ~ |M|
    _, V = np.linalg.eig(cf.monodromy)
    dM = np.linalg.norm(cf.monodromy) * (STEP_BOUND * RTOL + kappa * delta)
    assert np.max(np.abs(orb.multipliers - cf.multipliers)) <= np.linalg.cond(V) * dM
    # det M = r² e^{-cT} (Liouville, det S = r²); two columns off by STEP_BOUND·rtol each
    assert np.prod(orb.multipliers).real == pytest.approx(
        osc.restitution ** 2 * np.exp(-osc.damping * osc.period), rel=2 * STEP_BOUND * RTOL)
    assert orb.min_impact_speed == pytest.approx(cf.impact_velocity, rel=kappa * delta)


@pytest.fixture(scope="module")
def pendulum_orbit():
    p = ImpactingPendulum()
    return p, find_orbit(p.forced(**OPTIONS), p.x_guess)


def test_impacting_pendulum_period_one_orbit_and_its_monodromy(pendulum_orbit):
    p, orb = pendulum_orbit
    assert orb.signature == (("impact", 0),) and orb.stable
    # x_guess: 8 decimals of a 150-period run at rtol 1e-8 (converged to ~1e-9 per period)
    assert np.max(np.abs(orb.x0 - p.x_guess)) <= 1e-7
    # differences of a tighter map (rtol 1e-13: error STEP_BOUND·rtol·max(1, |x|) = 1e-10,
    # |x| <= 1), fourth order with step d >= 7.4e-4: truncation d⁴/30·|P⁽⁵⁾| (<= 1e4 at an
    # impact speed ~1: 1e-9) plus 1.5·1e-10/d = 2e-7; the monodromy's own error 1e-9
    f = p.forced(rtol=1e-13, atol=1e-15, progress=False)
    fd = central_difference_jacobian(lambda x: stroboscopic_map(f, x).x, orb.x0, order=4)
    assert np.max(np.abs(orb.monodromy - fd)) <= 1e-6 * max(1.0, np.max(np.abs(orb.monodromy)))
    assert np.linalg.det(orb.monodromy) == pytest.approx(p.monodromy_determinant(),
                                                         rel=2 * STEP_BOUND * RTOL)


@dataclass(frozen=True)
class _PendulumInForcing:
    """``a -> Forced``: the pendulum at forcing ``a`` (picklable)."""

    base: ImpactingPendulum

    def __call__(self, a: float) -> Forced:
        return self.base.with_(forcing=float(a)).forced(**OPTIONS)


def test_continuation_of_the_pendulum_orbit_in_the_forcing(pendulum_orbit):
    p, orb = pendulum_orbit
    family = _PendulumInForcing(p)
    br = continue_orbit(family, p.forcing, orb.x0, p_range=(0.5, 0.6), step=0.02,
                        max_steps=3)
    assert br.n_steps == 3 and br.stop_reason.startswith("max_steps")
    assert np.all(np.diff(br.p) > 0) and br.p[-1] > 0.53 and not br.points
    assert np.all(br.stable) and np.all(br.n_impacts == 1)
    # the determinant does not depend on the forcing: e² e^{-cT} all along the branch
    det = np.prod(br.multipliers, axis=1).real
    np.testing.assert_allclose(det, p.monodromy_determinant(), rtol=2 * STEP_BOUND * RTOL)
    # the last point is a period-1 orbit of its own system: corrector tolerance 1e-10
    x_end = br.nodes[-1, 0]
    m = stroboscopic_map(family(br.p[-1]), x_end)
    assert np.max(np.abs(m.x - x_end)) <= 1e-10 * max(1.0, np.max(np.abs(x_end)))


@dataclass(frozen=True)
class _DriveAsForce:
    """``F -> Forced``: the impact oscillator at forcing ``F``, drive written as a force."""

    base: ImpactOscillator

    def __call__(self, F: float) -> Forced:
        return self.base.with_(forcing=float(F)).forced(drive_as_force=True, **OPTIONS)


def test_non_impacting_branch_grazes_at_the_closed_form_forcing_through_the_nonlinear_path():
    osc = ImpactOscillator(omega=2.5, stop=0.1)
    Fg = osc.grazing_forcing()
    family = _DriveAsForce(osc)
    orb = find_orbit(family(0.4), osc.with_(forcing=0.4).non_impacting_state(0.0))
    # the smallest gap of the free orbit, d - A (closed form): the samples' minimum refined
    # on ġ = 0, as accurate as the runs (STEP_BOUND·rtol·max(1, |x|) = 1e-9)
    delta = STEP_BOUND * RTOL
    assert orb.n_impacts == 0
    assert orb.min_gap == pytest.approx(osc.stop - osc.with_(forcing=0.4).amplitude(),
                                        abs=delta)
    br = continue_orbit(family, 0.4, orb.x0, p_range=(0.0, 1.0), step=0.05, step_max=0.2)
    (g,) = br.special("grazing")
    # the monitor d - A(F) has slope -d/F_g at grazing: an error delta in it moves the zero
    # by delta·F_g/d, i.e. delta/d relative; plus the location tolerance 1e-10
    assert abs(g.parameter - Fg) / Fg <= 1e-10 + delta / osc.stop
    assert br.stop_reason.startswith("grazing")
