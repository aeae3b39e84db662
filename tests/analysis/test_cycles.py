"""Autonomous orbits: a relay-feedback limit cycle with a closed-form period, the trivial
multiplier, and the hyperplane Poincaré map."""

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize

from nscontrol.analysis.orbits import find_cycle, hyperplane_map
from nscontrol.systems.pwa import PiecewiseAffineSystem

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

EPS = np.finfo(float).eps
# plant 1/(s+1)^3 in relay feedback u = -sign(y): x' = A x + b u, y = c x
A = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, -1.0]])
B = np.array([0.0, 0.0, 1.0])
C = np.array([1.0, 0.0, 0.0])


def _relay():
    return PiecewiseAffineSystem.bimodal(A, A, C, b1=B, b2=-B, continuous=False)


def _symmetric_orbit():
    """Half period h and start x0 (c·x0 = 0, u = -1 next) from x(h) = -x0:
    x0 = -(I + e^{Ah})^{-1}(e^{Ah} - I) A^{-1}(-b)... with u = -1 on y > 0."""
    Ainv_b = np.linalg.solve(A, B)

    def x0_of(h):
        E = scipy.linalg.expm(A * h)
        # x(h) = E x0 - (E - I) A^{-1} b = -x0  ->  x0 = (I + E)^{-1} (E - I) A^{-1} b
        return np.linalg.solve(np.eye(3) + E, (E - np.eye(3)) @ Ainv_b)

    h = scipy.optimize.brentq(lambda h: C @ x0_of(h), 0.5, 3.0, xtol=1e-15)
    return h, x0_of(h)


def _mid_point():
    """The orbit at t = h/2 (away from the switching surface) and the field there, the
    normal of a transversal section."""
    h, x0 = _symmetric_orbit()
    E = scipy.linalg.expm(A * h / 2)
    xs = E @ x0 - (E - np.eye(3)) @ np.linalg.solve(A, B)      # u = -1 on (0, h)
    return h, x0, xs, A @ xs - B


def test_relay_cycle_period_matches_the_symmetric_orbit_condition():
    h, x0, xs, fs = _mid_point()
    assert C @ (A @ x0 - B) > 0          # leaves y = 0 upwards, into the u = -1 region
    cyc = find_cycle(_relay(), xs + [0.0, 1e-3, -1e-3], 2 * h * 1.01, normal=fs,
                     offset=float(fs @ xs))
    # Newton to tol = 1e-9 on the residual; its error <= cond(bordered J)·1e-9, cond ~ 10
    # here, squared by Newton's last step (quadratic), so well below 1e-8
    assert cyc.period == pytest.approx(2 * h, rel=1e-8)
    assert np.allclose(cyc.x0, xs, atol=1e-8)
    # the trivial multiplier is 1 (to the flow-velocity difference's O(δ²) ~ 1e-10 and the
    # transition's rounding), the two others inside the unit circle: a stable cycle
    assert abs(cyc.multipliers[cyc.trivial_index] - 1.0) <= 1e-8
    assert cyc.stable and len(cyc.nontrivial) == 2
    assert len(cyc.signature) == 2                                   # two switchings


def test_hyperplane_map_jacobian_and_its_fixed_point():
    h, x0, xs, fs = _mid_point()
    sys_ = _relay()
    sec = dict(normal=fs, offset=float(fs @ xs), t_max=3 * h)
    ret = hyperplane_map(sys_, xs, **sec)
    # return time and point: secant to rounding on exact flows (switch instants ~1e-11)
    assert ret.time == pytest.approx(2 * h, rel=1e-9) and np.allclose(ret.x, xs, atol=1e-9)
    # Jacobian vs central differences of the map (d = 1e-6: error d²·|P'''| plus the return
    # time's rounding 1e-11/d, at worst ~1e-5)
    d = 1e-6
    fd = np.column_stack([(hyperplane_map(sys_, xs + d * e, **sec).x
                           - hyperplane_map(sys_, xs - d * e, **sec).x) / (2 * d)
                          for e in np.eye(3)])
    assert np.max(np.abs(ret.jacobian - fd)) <= 1e-5
    # the map's eigenvalues are the cycle's non-trivial multipliers and 0 (the flow direction
    # is projected out); both from the same transition, differing by the O(δ²) velocity
    cyc = find_cycle(sys_, xs, 2 * h, normal=fs)
    ev = np.sort_complex(np.linalg.eigvals(ret.jacobian))
    expected = np.sort_complex(np.append(cyc.nontrivial, 0.0))
    assert np.max(np.abs(ev - expected)) <= 1e-7


def test_relay_cycle_under_implicit_euler_converges_at_first_order():
    """The same relay loop in Lur'e form (w ∈ -sign(c·x), the multiplier solved in each
    implicit step) settles on a discrete cycle of a whole number of steps N, and N·h tends to
    the exact period at first order: e(h) = |N h - T| = K h + O(h²)."""
    from nscontrol import simulate
    from nscontrol.laws import Relay
    from nscontrol.systems import LureSystem

    half, x0 = _symmetric_orbit()
    T = 2 * half
    lure = LureSystem(A, B[:, None], C[None, :], Relay(1.0))
    errors = []
    for n in (200, 400, 800):
        h = T / n
        tr = simulate(lure, x0 + [0.0, 1e-3, 0.0], (0.0, 30 * T), method="implicit_euler", h=h)
        y, t = tr.x[:, 0], tr.t
        up = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
        crossings = (t[up] - y[up] * (t[up + 1] - t[up]) / (y[up + 1] - y[up]))
        periods = np.diff(crossings[crossings > 10 * T])
        # a discrete cycle: every period is the same whole number of steps (to the rounding of
        # t = k h and of the interpolated crossing, ~1e3 ε T)
        steps = periods / h
        assert np.ptp(periods) <= 1e3 * EPS * T
        assert abs(steps[0] - round(steps[0])) <= 1e3 * EPS * n
        errors.append(abs(periods.mean() - T) / h)      # the error in steps, e(h)/h
    # first order: e(h)/h converges to K; it changes by O(h) between step sizes, plus at most
    # one whole step when the grid's rounding of a crossing flips: consecutive values within 1
    assert all(0.0 < e < 10.0 for e in errors)
    for a, b in zip(errors, errors[1:], strict=False):
        assert abs(a - b) <= 1.0
