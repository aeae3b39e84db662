"""Exact LTI numerics: propagation against an independent integrator, ZOH against closed
forms, guard roots (crossing, grazing, close double roots, simultaneous, none), bad input."""

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from nscontrol.errors import DimensionError, InadmissibleStateError, ModelError
from nscontrol.numerics.lti import (
    Exosystem,
    GuardEvent,
    LTIFlow,
    augment,
    discretize,
    first_event,
)

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

# two masses, springs and dampers, forced on the first mass
A_PLANT = np.array([[0.0, 0.0, 1.0, 0.0],
                    [0.0, 0.0, 0.0, 1.0],
                    [-2.0, 1.0, -0.1, 0.05],
                    [1.0, -1.5, 0.05, -0.2]])
B_PLANT = np.array([[0.0], [0.0], [1.0], [0.0]])
HARMONIC = np.array([[0.0, 1.0], [-1.0, 0.0]])  # x = (cos t, -sin t) from (1, 0)
GRAVITY = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -9.81], [0.0, 0.0, 0.0]])  # (q, v, 1)

EXOSYSTEMS = {
    "constant": Exosystem.constant(0.7),
    "polynomial": Exosystem.polynomial([0.3, -0.2, 0.05]),
    "sinusoid": Exosystem.sinusoid(1.5, omega=2.3, phase=0.4, offset=-0.2),
    "sum": Exosystem.sinusoid(1.0, omega=0.9) + Exosystem.polynomial([0.0, 0.1]),
}


@pytest.mark.parametrize("name", sorted(EXOSYSTEMS))
def test_propagation_matches_dop853(name):
    exo = EXOSYSTEMS[name]
    A = augment(A_PLANT, B_PLANT, exo)
    X0 = np.concatenate([[0.3, -0.1, 0.0, 0.2], exo.w0])
    ts = np.linspace(0.0, 12.0, 61)

    def rhs(t, x):
        return A_PLANT @ x[:4] + B_PLANT[:, 0] * exo.u(t)[0]

    ref = solve_ivp(rhs, (0.0, 12.0), X0[:4], method="DOP853", t_eval=ts, rtol=1e-13,
                    atol=1e-15).y.T
    ours = LTIFlow(A).propagate(X0, ts)
    assert ours.shape == (61, len(X0))
    assert np.max(np.abs(ours[:, :4] - ref)) <= 1e-10 * max(1.0, np.max(np.abs(ref)))
    # the exosystem part reproduces the input exactly
    u = ours[:, 4:] @ exo.Cu.T
    np.testing.assert_allclose(u, exo.u(ts), atol=1e-12)


def test_exosystem_closed_forms():
    t = np.linspace(0.0, 5.0, 11)
    np.testing.assert_allclose(EXOSYSTEMS["constant"].u(t)[:, 0], 0.7, atol=1e-15)
    np.testing.assert_allclose(EXOSYSTEMS["polynomial"].u(t)[:, 0],
                               0.3 - 0.2 * t + 0.05 * t**2, atol=1e-13)
    np.testing.assert_allclose(EXOSYSTEMS["sinusoid"].u(t)[:, 0],
                               -0.2 + 1.5 * np.sin(2.3 * t + 0.4), atol=1e-13)
    np.testing.assert_allclose(EXOSYSTEMS["sum"].u(t)[:, 0], np.sin(0.9 * t) + 0.1 * t,
                               atol=1e-13)
    vec = Exosystem.sinusoid([1.0, -2.0], omega=1.0)
    assert vec.u(0.3).shape == (2,)
    np.testing.assert_allclose(vec.u(0.3), [np.sin(0.3), -2.0 * np.sin(0.3)], atol=1e-15)


@pytest.mark.parametrize("A", [A_PLANT, GRAVITY, np.zeros((2, 2))], ids=["eig", "jordan", "zero"])
def test_flow_expm_matches_scipy(A):
    flow = LTIFlow(A)
    ts = np.array([-0.5, 0.0, 0.7, 3.0])
    E = flow.expm(ts)
    for t, Et in zip(ts, E, strict=True):
        np.testing.assert_allclose(Et, scipy.linalg.expm(A * t), atol=1e-12, rtol=1e-12)
    np.testing.assert_allclose(flow.expm(0.7), E[2], atol=1e-15)


def test_flow_method_choice():
    assert LTIFlow(A_PLANT).method == "eig"
    assert LTIFlow(GRAVITY).method == "expm"  # defective: a Jordan block


def test_discretize_closed_forms():
    a, b, h = -0.8, 2.0, 0.3
    Ad, Bd = discretize([[a]], [[b]], h)
    assert Ad[0, 0] == pytest.approx(np.exp(a * h), rel=1e-15)
    assert Bd[0, 0] == pytest.approx((np.exp(a * h) - 1.0) / a * b, rel=1e-14)
    # double integrator (singular A): Bd = [h^2/2, h]
    d = discretize([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], h)
    np.testing.assert_allclose(d.Ad, [[1.0, h], [0.0, 1.0]], atol=1e-15)
    np.testing.assert_allclose(d.Bd, [[h**2 / 2], [h]], atol=1e-15)


def test_discretize_matches_exact_response_to_held_input():
    h = 0.25
    Ad, Bd = discretize(A_PLANT, B_PLANT, h)
    x0, u0 = np.array([0.1, 0.2, -0.3, 0.0]), 0.9
    A = augment(A_PLANT, B_PLANT, Exosystem.constant(u0))
    exact = LTIFlow(A).propagate(np.append(x0, u0), h)[:4]
    np.testing.assert_allclose(Ad @ x0 + Bd[:, 0] * u0, exact, atol=1e-14)


def test_discretize_reuses_its_exponential_and_hands_out_copies(monkeypatch):
    """The exponential of a model discretised before is reused (one ``expm`` for two calls),
    the values are the same bits, and a caller that edits its result leaves the next
    caller's intact; another step or matrix is a new exponential."""
    import scipy.linalg

    from nscontrol.numerics import lti

    calls = []
    expm = scipy.linalg.expm
    monkeypatch.setattr(scipy.linalg, "expm", lambda M: (calls.append(1), expm(M))[1])
    A, B = np.array([[0.0, 1.0], [-4.0, -0.3]]), np.array([[0.0], [1.0]])
    h = 0.0123456789           # a step no other test uses: not cached before
    first = lti.discretize(A, B, h)
    first.Ad[0, 0] = 99.0
    second = lti.discretize(A.copy(), B.copy(), h)
    assert len(calls) == 1
    assert second.Ad[0, 0] != 99.0
    fresh = scipy.linalg.expm(np.block([[A, B], [np.zeros((1, 3))]]) * h)
    np.testing.assert_array_equal(second.Ad, fresh[:2, :2])
    lti.discretize(A, B, 2 * h)
    lti.discretize(2 * A, B, h)
    assert len(calls) == 4      # two new keys (the reference above was the third call)


# ----------------------------------------------------------------------------- guards
def test_plain_crossing_to_machine_precision():
    ev = first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [0.0], 10.0)
    assert isinstance(ev, GuardEvent)
    assert ev.indices == (0,) and not ev.grazing
    # |g'| = 1 at the root: the rounding of g (~u ||x||) / |g'| plus one spacing of t
    assert abs(ev.t - np.pi / 2) <= 2 * np.spacing(np.pi / 2)


def test_crossing_of_defective_flow_free_fall():
    # q(t) = 1 - 9.81 t^2 / 2 reaches 0 at sqrt(2/9.81)
    ev = first_event(GRAVITY, [1.0, 0.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 10.0)
    # |g'| = 4.4: rounding of g (~u) / |g'| + spacing of t (5.6e-17), well under 1e-15 ~ 9u
    assert abs(ev.t - np.sqrt(2 / 9.81)) <= 1e-15 and not ev.grazing


def test_grazing_touch_is_reported():
    # g = 1 + cos t touches 0 at t = pi without crossing
    ev = first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [1.0], 10.0)
    assert ev.grazing and ev.indices == (0,)
    assert abs(ev.t - np.pi) <= 1e-7  # a double root: sqrt(eps) conditioning
    # a ball thrown up exactly to the ceiling at height 1 touches it at its apex
    v0 = np.sqrt(2 * 9.81)
    ev = first_event(GRAVITY, [0.0, v0, 1.0], [[-1.0, 0.0, 0.0]], [1.0], 5.0)
    assert ev is not None and ev.grazing
    assert abs(ev.t - v0 / 9.81) <= 1e-7


def test_search_restarted_at_a_grazing_point_finds_the_next_touch():
    flow = LTIFlow(HARMONIC)
    ev = first_event(flow, [1.0, 0.0], [[1.0, 0.0]], [1.0], 10.0)
    for x_shift in (0.0, -3e-9, 3e-9):  # the touch located exactly, or off by ~sqrt(eps)
        x = flow.propagate([1.0, 0.0], ev.t + x_shift)
        nxt = first_event(flow, x, [[1.0, 0.0]], [1.0], 10.0)
        assert nxt.grazing and abs(nxt.t - 2 * np.pi + x_shift) <= 1e-7


@pytest.mark.parametrize("delta", [1e-4, 1e-8])
def test_two_roots_closer_than_the_grid(delta):
    # g = 1 - delta + cos t dips to -delta around pi: roots pi -+ 2 asin(sqrt(delta/2))
    flow = LTIFlow(HARMONIC)
    assert flow.guard_context().h == pytest.approx(1.0)  # the grid step
    ev = first_event(flow, [1.0, 0.0], [[1.0, 0.0]], [1.0 - delta], 10.0)
    t_exact = np.pi - 2 * np.arcsin(np.sqrt(delta / 2))
    assert not ev.grazing and ev.indices == (0,)
    # conditioning |g'| = sqrt(2 delta): the error is eps / |g'|
    assert abs(ev.t - t_exact) <= 1e-15 / np.sqrt(delta)


def test_no_root():
    # min of 1 + 1e-8 + cos t is 1e-8 > 0: nothing happens
    assert first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [1.0 + 1e-8], 20.0) is None
    # the root lies after the horizon
    assert first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [0.0], 1.5) is None
    # decaying guard never reaching zero, many cells
    assert first_event([[-0.1]], [1.0], [[1.0]], [0.0], 500.0) is None


def test_simultaneous_guards_all_reported():
    G = [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    ev = first_event(GRAVITY, [1.0, 0.0, 1.0], G, [0.0, 0.0, 0.5], 10.0)
    assert ev.indices == (0, 1)  # the third reaches zero later (q = -0.5)
    # at pi/2, guard 0 (1 - sin t) touches while guard 1 (cos t) crosses: both reported, and
    # the event is not a pure grazing one
    ev = first_event(HARMONIC, [1.0, 0.0], [[0.0, 1.0], [1.0, 0.0]], [1.0, 0.0], 10.0)
    assert ev.indices == (0, 1) and not ev.grazing and abs(ev.t - np.pi / 2) < 1e-15
    ev = first_event(HARMONIC, [1.0, 0.0], [[0.0, 1.0], [1.0, 0.0]], [1.5, 0.0], 10.0)
    assert ev.indices == (1,)


def test_guards_starting_at_zero():
    # leaving the surface (after an impact): the root at 0 is not an event
    ev = first_event(GRAVITY, [0.0, 3.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 10.0)
    assert abs(ev.t - 6.0 / 9.81) <= 1e-15
    # zero velocity, positive acceleration: leaves too (second derivative decides)
    lift = GRAVITY * np.array([1.0, -1.0, 1.0])[:, None]  # q'' = +9.81
    assert first_event(lift, [0.0, 0.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 1.0) is None
    # ... and zero velocity with negative acceleration is an event at t = 0
    ev = first_event(GRAVITY, [0.0, 0.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 1.0)
    assert ev == GuardEvent(0.0, (0,), False)
    # a guard identically zero (sliding along the surface) never fires
    assert first_event(HARMONIC, [1.0, 0.0], [[0.0, 0.0]], [0.0], 5.0) is None
    # at zero and decreasing: an event at t = 0
    ev = first_event(GRAVITY, [0.0, -1.0, 1.0], [[1.0, 0.0, 0.0]], [0.0], 1.0)
    assert ev == GuardEvent(0.0, (0,), False)


def test_random_systems_agree_with_dense_sampling(rng):
    for _ in range(20):
        n = 4
        A = rng.normal(size=(n, n)) - 0.3 * np.eye(n)
        x0 = rng.normal(size=n)
        G = rng.normal(size=(2, n))
        g0 = np.abs(G @ x0) + 0.5 - G @ x0  # positive at 0 (g(0) = |.| + 0.5)
        flow = LTIFlow(A)
        ev = first_event(flow, x0, G, g0, 5.0)
        ts = np.linspace(0.0, 5.0, 20001)
        g = flow.propagate(x0, ts) @ G.T + g0
        neg = np.flatnonzero((g <= 0.0).any(axis=1))
        if ev is None:
            assert neg.size == 0
            continue
        i = ev.indices[0]
        g_at = G[i] @ flow.propagate(x0, ev.t) + g0[i]
        assert abs(g_at) <= 1e-12 * (np.abs(G[i]) @ np.abs(flow.propagate(x0, ev.t)) + 1)
        if neg.size:
            assert ev.t <= ts[neg[0]] + 1e-12
        assert (g[ts < ev.t - 1e-9] > 0.0).all()


def test_bad_input_each_its_error():
    with pytest.raises(DimensionError, match=r"^A: expected a square matrix, got shape \(2, 3\)"):
        LTIFlow(np.ones((2, 3)))
    with pytest.raises(ModelError, match=r"^A: expected finite entries"):
        LTIFlow([[np.nan, 0.0], [0.0, 1.0]])
    with pytest.raises(DimensionError, match=r"^x0: expected a vector of length 2, got length 3"):
        first_event(HARMONIC, [1.0, 0.0, 0.0], [[1.0, 0.0]], [0.0], 1.0)
    with pytest.raises(DimensionError, match=r"^G: expected 2 columns"):
        first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0, 0.0]], [0.0], 1.0)
    with pytest.raises(DimensionError, match=r"^g0: expected a vector of length 1"):
        first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [0.0, 1.0], 1.0)
    with pytest.raises(ModelError, match=r"^t_max: expected a finite number > 0"):
        first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [0.0], 0.0)
    with pytest.raises(ModelError, match=r"^x0: expected finite entries"):
        first_event(HARMONIC, [np.inf, 0.0], [[1.0, 0.0]], [0.0], 1.0)
    with pytest.raises(InadmissibleStateError, match=r"^x0: guard 0 is negative at t = 0"):
        first_event(HARMONIC, [1.0, 0.0], [[1.0, 0.0]], [-2.0], 1.0)
    with pytest.raises(DimensionError, match=r"^Cu: expected 2 columns"):
        Exosystem(np.zeros((2, 2)), np.ones((1, 3)), [1.0, 0.0])
    with pytest.raises(DimensionError, match=r"^B: expected 4 rows"):
        augment(A_PLANT, np.ones((3, 1)), EXOSYSTEMS["constant"])
    with pytest.raises(ModelError, match=r"^h: expected a finite number > 0"):
        discretize(A_PLANT, B_PLANT, -0.1)
    with pytest.raises(ModelError, match=r"^omega: expected a finite number >= 0, got nan"):
        Exosystem.sinusoid(1.0, omega=np.nan)
    with pytest.raises(DimensionError, match=r"^t: expected a scalar or a 1-d array of times"):
        LTIFlow(HARMONIC).propagate([1.0, 0.0], np.zeros((2, 2)))
