"""Event-driven switching integrator: exact crossings, Filippov sliding, grazing, PWM instants,
saltation matrices and monodromy (issue 4 conformance)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nscontrol import simulate
from nscontrol.errors import ModelError, SolverError
from nscontrol.numerics.lti import Exosystem, LTIFlow
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem, PWMController, SwitchedAffineSystem
from nscontrol.testing import setvalued_problems as sp


def _relay(p, form):
    """``sp.relay_feedback``'s Filippov system as given (data: the compiled loop) or with the
    same fields as Python callables (the DOP853 path)."""
    if form == "data":
        return p.switched
    A, g, c = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), np.ones(2)
    return FilippovSystem.two_sided(lambda t, x: A @ x + g, lambda t, x: A @ x - g,
                                    lambda x: float(c @ x), 2, gradient=lambda x: c)


@pytest.mark.parametrize("form, path", [("data", "exact"), ("callables", "dop853")])
def test_relay_feedback_reaching_time_to_1e10_and_exact_sliding(form, path):
    p = sp.relay_feedback()
    tr = simulate(_relay(p, form), p.x0, p.t_span)
    assert tr.stats["propagation"] == path
    (ev,) = tr.events
    assert ev.kind == "sliding_start" and ev.mode_from == 1 and ev.mode_to == 3
    assert abs(ev.time - p.facts["reaching_time"]) <= 1e-10
    after = tr.t > ev.time
    assert np.max(np.abs(tr.x[after] @ np.ones(2))) <= 1e-12
    assert np.max(np.abs(tr.x - p.facts["exact"](tr.t))) <= 1e-9


def test_scalar_relay_reaching_time_to_1e10():
    p = sp.relay_scalar()
    tr = simulate(p.switched, p.x0, p.t_span)
    assert [e.kind for e in tr.events] == ["sliding_start"]
    assert abs(tr.events[0].time - p.facts["reaching_time"]) <= 1e-10
    assert np.max(np.abs(tr.x[tr.t > tr.events[0].time])) <= 1e-12


def test_sliding_exit_is_detected():
    # x' = -sign(x) + d(t) with |d| exceeding 1 after a while: sliding ends where d = 1
    f = FilippovSystem.two_sided(lambda t, x: np.array([1.0 + 0.5 * t]),
                                 lambda t, x: np.array([-1.0 + 0.5 * t]),
                                 lambda x: float(x[0]), 1, gradient=lambda x: np.ones(1))
    tr = simulate(f, [0.5], (0.0, 4.0))
    kinds = [e.kind for e in tr.events]
    assert kinds == ["sliding_start", "sliding_exit"]
    assert abs(tr.events[1].time - 2.0) <= 1e-9          # σ⁺ = -1 + t/2 reaches 0 at t = 2
    assert tr.events[1].mode_to == 1                      # leaves to the h > 0 side
    assert abs(tr.x[-1, 0] - 0.25 * (4.0 - 2.0) ** 2 / 1.0 * 1.0) <= 1e-9  # ∫(-1 + s/2) ds


def test_bimodal_oscillator_agrees_with_tight_ode_through_many_crossings():
    p = sp.bimodal_oscillator()
    tr = simulate(p.system, p.x0, p.t_span)
    crossings = tr.event_times("crossing")
    assert crossings.size >= 20
    ref = solve_ivp(p.facts["rhs"], p.t_span, p.x0, method="DOP853", rtol=1e-13, atol=1e-15,
                    events=lambda t, x: x[0], dense_output=True)
    assert ref.t_events[0].size == crossings.size
    assert np.max(np.abs(ref.t_events[0] - crossings)) <= 1e-9
    assert np.max(np.abs(ref.sol(tr.t).T - tr.x)) <= 1e-9
    # continuous field: every saltation matrix is the identity
    tr2 = simulate(p.system, p.x0, (0.0, 10.0), sensitivity=True)
    S = tr2.stats["saltation_matrices"]
    assert S.shape[0] == tr2.event_times("crossing").size
    assert np.max(np.abs(S - np.eye(2))) <= 1e-12


def _period_map(system, T, x, **kw):
    return simulate(system, x, (0.0, T), n_samples=2, **kw)


@pytest.mark.parametrize("continuous", [True, False])
def test_monodromy_from_saltation_matches_finite_differences(continuous):
    omega = 1.3
    T = 2 * np.pi / omega
    A1 = np.array([[0.0, 1.0], [-1.0, -0.4]])
    if continuous:
        A2 = np.array([[0.0, 1.0], [-4.0, -0.4]])
        pwa = PiecewiseAffineSystem.bimodal(A2, A1, [1.0, 0.0], E=[[0.0], [1.0]],
                                            u=Exosystem.sinusoid(2.0, omega))
    else:  # a relay-type restoring force on q: crossings with a non-identity saltation
        pwa = PiecewiseAffineSystem.bimodal(A1, A1, [1.0, 0.0], b1=[0.0, 0.3], b2=[0.0, -0.3],
                                            E=[[0.0], [1.0]], u=Exosystem.sinusoid(2.0, omega),
                                            continuous=False)
    x = np.array([0.5, 0.0])
    for _ in range(60):                                   # settle on the periodic orbit
        x = _period_map(pwa, T, x).x[-1]
    tr = _period_map(pwa, T, x, sensitivity=True)
    assert np.linalg.norm(tr.x[-1] - x) <= 1e-8
    assert tr.event_times("crossing").size == 2
    M = tr.stats["state_transition"]
    fd = np.empty((2, 2))
    for k in range(2):
        d = np.zeros(2)
        d[k] = 1e-6
        fd[:, k] = (_period_map(pwa, T, x + d).x[-1] - _period_map(pwa, T, x - d).x[-1]) / 2e-6
    assert np.max(np.abs(M - fd)) <= 1e-6
    S = tr.stats["saltation_matrices"]
    assert bool(np.max(np.abs(S - np.eye(2))) > 0.01) is (not continuous)


@pytest.mark.parametrize("form", ["data", "callables"])
def test_filippov_sensitivity_through_sliding_matches_finite_differences(form):
    p = sp.relay_feedback(T=2.0)
    system = _relay(p, form)

    def end(x0):
        return simulate(system, x0, p.t_span, n_samples=2).x[-1]

    tr = simulate(system, p.x0, p.t_span, sensitivity=True, n_samples=2)
    fd = np.column_stack([(end(p.x0 + d) - end(p.x0 - d)) / 2e-6
                          for d in (np.array([1e-6, 0.0]), np.array([0.0, 1e-6]))])
    assert np.max(np.abs(tr.stats["state_transition"] - fd)) <= 1e-6
    (S,) = tr.stats["saltation_matrices"]
    assert abs(np.linalg.det(S)) <= 1e-12                 # entering sliding projects


def test_coulomb_stick_slip_times_agree_between_integrators():
    p = sp.coulomb_oscillator(friction=1.0, amplitude=1.0, T=14.0)
    sw = simulate(p.switched, p.x0, p.t_span)
    starts = sw.event_times("sliding_start")
    exits = sw.event_times("sliding_exit")
    assert starts.size >= 2 and exits.size >= 2
    h = 1e-4
    ie = simulate(p.system, p.x0, p.t_span, h=h)
    stick = ie.signal("z")[:, 0] == 0.0
    change = np.flatnonzero(np.diff(stick.astype(int)))
    t_start = ie.t[change[~stick[change]] + 1]
    t_exit = ie.t[change[stick[change]] + 1]
    starts_in = starts[starts > 0.0]
    assert t_start.size == starts_in.size and t_exit.size == exits.size
    assert np.max(np.abs(t_start - starts_in)) <= 20 * h
    assert np.max(np.abs(t_exit - exits)) <= 20 * h
    assert np.max(np.abs(ie.x - sw.at(ie.t))) <= 20 * h


def test_grazing_is_flagged_and_mode_kept():
    A = np.array([[0.0, 1.0], [-1.0, 0.0]])
    pwa = PiecewiseAffineSystem.bimodal(A, A, [1.0, 0.0], d=1.0)  # x1 = sin t touches 1
    tr = simulate(pwa, [0.0, 1.0], (0.0, 3.0))
    (ev,) = tr.events
    assert ev.kind == "grazing" and ev.mode_from == ev.mode_to == 0
    assert abs(ev.time - np.pi / 2) <= 1e-6


def test_pwm_switching_instants_exact_and_state_matches_ode():
    delta, T, d = 0.5, 0.25, 0.15
    A = np.array([[0.0, 1.0], [-1.0, -delta]])
    buck = SwitchedAffineSystem(((A, [0.0, -1.0]), (A, [0.0, 1.0])),
                                PWMController(T, lambda t, x: d))
    tr = simulate(buck, [0.0, 0.0], (0.0, 10 * T))
    sw = tr.events_of("switch")
    expected = np.sort(np.concatenate([np.arange(10) * T + d / 2,
                                       np.arange(10) * T + T - d / 2]))
    assert np.max(np.abs(np.array([e.time for e in sw]) - expected)) <= 1e-14
    x = np.zeros(2)
    edges = np.concatenate([[0.0], expected, [10 * T]])
    for k in range(edges.size - 1):
        u = 1.0 if k % 2 == 0 else -1.0
        sol = solve_ivp(lambda t, y, u=u: A @ y + np.array([0.0, u]), (edges[k], edges[k + 1]), x,
                        method="DOP853", rtol=1e-13, atol=1e-15)
        x = sol.y[:, -1]
    assert np.max(np.abs(tr.x[-1] - x)) <= 1e-10
    assert np.allclose(tr.stats["duty"], d)


def test_discontinuous_pwa_with_sliding_goes_through_filippov_form():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    # relay feedback on x1 + x2 as a discontinuous bimodal PWA
    pwa = PiecewiseAffineSystem.bimodal(A, A, [1.0, 1.0], b1=[0.0, 1.0], b2=[0.0, -1.0],
                                        continuous=False)
    with pytest.raises(ModelError, match="FilippovSystem.from_pwa") as info:
        simulate(pwa, [1.0, 0.0], (0.0, 3.0))
    assert info.value.trajectory is not None
    tr = simulate(FilippovSystem.from_pwa(pwa), [1.0, 0.0], (0.0, 3.0))
    assert abs(tr.event_times("sliding_start")[0] - (np.sqrt(3) - 1)) <= 1e-10


def test_pwa_with_a_function_input_matches_the_exact_exosystem_path():
    p = sp.bimodal_oscillator()
    omega = p.facts["omega"]
    exact = simulate(p.system, p.x0, (0.0, 15.0), sensitivity=True)
    ode = simulate(p.system, p.x0, (0.0, 15.0), sensitivity=True,
                   u=lambda t: np.reshape(np.sin(omega * np.asarray(t, float)), (-1, 1)))
    assert ode.stats["propagation"] == "dop853" and exact.stats["propagation"] == "exact"
    assert np.max(np.abs(ode.event_times("crossing") - exact.event_times("crossing"))) <= 1e-9
    assert np.max(np.abs(ode.x[-1] - exact.x[-1])) <= 1e-9
    assert np.max(np.abs(ode.stats["state_transition"] - exact.stats["state_transition"])) \
        <= 1e-8


def test_event_budget_exceeded_raises_budget_error_with_the_computed_part():
    from nscontrol.errors import BudgetExceededError

    p = sp.bimodal_oscillator()
    with pytest.raises(BudgetExceededError, match="^max_events") as info:
        simulate(p.system, p.x0, p.t_span, max_events=5)
    assert (info.value.budget, info.value.limit, info.value.used) == ("max_events", 5, 6)
    part = info.value.trajectory
    assert part.status == -1 and len(part.events) == 6
    assert 0.0 < part.t[-1] <= part.events[-1].time


def test_conewise_system_is_homogeneous_of_degree_one():
    # four quadrant cones of a continuous conewise-linear field (rank-one jumps across axes)
    A0 = np.array([[-0.2, 1.0], [-1.0, -0.2]])
    g1, g2 = np.array([0.0, -3.0]), np.array([-0.5, 0.0])
    e1, e2 = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    As = [A0, A0 + np.outer(g1, e1), A0 + np.outer(g1, e1) + np.outer(g2, e2),
          A0 + np.outer(g2, e2)]
    cones = [[[-1.0, 0.0], [0.0, -1.0]], [[1.0, 0.0], [0.0, -1.0]], [[1.0, 0.0], [0.0, 1.0]],
             [[-1.0, 0.0], [0.0, 1.0]]]
    pwl = PiecewiseAffineSystem.conewise(As, cones)
    assert pwl.is_pwl and len(pwl.neighbours) == 8
    a = simulate(pwl, [1.0, 0.5], (0.0, 8.0))
    b = simulate(pwl, [3.0, 1.5], (0.0, 8.0))
    assert a.event_times("crossing").size >= 4
    assert np.max(np.abs(b.event_times("crossing") - a.event_times("crossing"))) <= 1e-12
    assert np.max(np.abs(b.x - 3.0 * a.x)) <= 1e-12


def test_sliding_ends_where_another_surface_is_crossed():
    # slide on x2 = 0 while x1 < 1; beyond x1 = 1 both sides push up, so sliding must end there
    def field(t, x, s):
        if s[1] < 0:
            return np.array([1.0, -1.0 if s[0] > 0 else 1.0])
        return np.array([1.0, 1.0])

    f = FilippovSystem(2, (lambda x: x[1], lambda x: x[0] - 1.0), field)
    tr = simulate(f, [0.0, 0.5], (0.0, 3.0), sensitivity=True)
    assert [(e.kind, e.index) for e in tr.events] == [
        ("sliding_start", 0), ("crossing", 1), ("sliding_exit", 0)]
    assert np.allclose(tr.event_times(), [0.5, 1.0, 1.0], atol=1e-10)
    assert np.max(np.abs(tr.x[(tr.t > 0.5) & (tr.t < 1.0), 1])) <= 1e-12
    assert np.allclose(tr.x[-1], [3.0, 2.0], atol=1e-9)
    # one saltation matrix per crossing / sliding start / sliding exit, in event order
    S = tr.stats["saltation_matrices"]
    assert S.shape == (len(tr.events), 2, 2)
    np.testing.assert_array_equal(S[2], np.eye(2))       # the crossing's S covers the exit
    # and the product with the flows is the sensitivity of the end state (x0 = (0, 0.5) +
    # perturbations: reaching x2 = 0 a little earlier or later, leaving at x1 = 1)
    def end(x0):
        return simulate(f, x0, (0.0, 3.0), n_samples=2).x[-1]

    fd = np.column_stack([(end([0.0, 0.5] + d) - end([0.0, 0.5] - d)) / 2e-6
                          for d in (np.array([1e-6, 0.0]), np.array([0.0, 1e-6]))])
    assert np.max(np.abs(tr.stats["state_transition"] - fd)) <= 1e-6


def _buck(duty, pattern="centered", T=0.25, delta=0.5):
    A = np.array([[0.0, 1.0], [-1.0, -delta]])
    return A, SwitchedAffineSystem(((A, [0.0, -1.0]), (A, [0.0, 1.0])),
                                   PWMController(T, duty, pattern=pattern))


def _constant_duty(t, x):
    return 0.15


def test_pwm_instants_do_not_drift_over_20000_periods():
    T, d, N = 0.25, 0.15, 20000
    A, buck = _buck(_constant_duty, T=T)
    tr = simulate(buck, [0.0, 0.0], (0.0, N * T), n_samples=2)
    sw = np.array([e.time for e in tr.events_of("switch")])
    k = np.arange(N)
    expected = np.sort(np.concatenate([k * T + d / 2, k * T + T - d / 2]))
    assert sw.size == expected.size == 2 * N
    # each instant is computed afresh from k T (a few u relative), not accumulated period by
    # period (which gave 1.3e-9): 1e-12 ~ 1e4 u
    assert np.max(np.abs(sw - expected) / expected) <= 1e-12
    assert tr.stats["periods"] == N and np.all(tr.stats["duty"] == d)


class _SampledDuty:
    """``d_k = T (0.5 - 0.4 x1(t_k))`` clipped by the controller: a feedback duty."""

    def __init__(self, T):
        self.T, self.calls = T, []

    def __call__(self, t, x):
        self.calls.append((t, np.array(x, float)))
        return self.T * (0.5 - 0.4 * x[0])


def test_pwm_duty_from_the_sampled_state():
    T, N = 0.25, 400
    duty = _SampledDuty(T)
    A, buck = _buck(duty, pattern="leading", T=T)
    tr = simulate(buck, [0.3, 0.0], (0.0, N * T), n_samples=2)
    times = np.array([c[0] for c in duty.calls])
    np.testing.assert_array_equal(times, np.arange(N) * T)   # sampled at t_k = kT exactly
    d = tr.stats["duty"]
    on_off = np.array([e.time for e in tr.events_of("switch") if e.mode_to == 0])
    np.testing.assert_allclose(on_off, np.arange(N) * T + d, rtol=1e-12, atol=0.0)
    # an independent reference: period by period with the augmented exponential
    from scipy.linalg import expm

    def step(x, b, tau):
        M = np.zeros((3, 3))
        M[:2, :2], M[:2, 2] = A, b
        return (expm(M * tau) @ np.r_[x, 1.0])[:2]

    x = np.array([0.3, 0.0])
    for k in range(N):
        dk = float(np.clip(T * (0.5 - 0.4 * x[0]), 0.0, T))
        np.testing.assert_allclose(duty.calls[k][1], x, atol=1e-12)
        assert abs(dk - d[k]) <= 1e-12
        x = step(step(x, np.array([0.0, 1.0]), dk), np.array([0.0, -1.0]), T - dk)
    assert np.max(np.abs(tr.x[-1] - x)) <= 1e-10
    # the modes propagate through the shared LTIFlow of [[A, b], [0, 0]]
    M = np.zeros((3, 3))
    M[:2, :2], M[:2, 2] = A, [0.0, 1.0]
    assert buck.flow(1) is LTIFlow.shared(M)
    np.testing.assert_allclose(buck.propagate(1, [0.3, 0.0], 0.2),
                               step(np.array([0.3, 0.0]), np.array([0.0, 1.0]), 0.2),
                               atol=1e-14)


def test_grazing_without_sign_change_is_flagged_on_the_ode_paths():
    # x = (sin t, cos t) touches x1 = 1 at pi/2 + 2k pi without crossing it
    rot = np.array([[0.0, 1.0], [-1.0, 0.0]])
    f = FilippovSystem.two_sided(lambda t, x: rot @ x, lambda t, x: rot @ x,
                                 lambda x: float(x[0]) - 1.0, 2,
                                 gradient=lambda x: np.array([1.0, 0.0]))
    tr = simulate(f, [0.0, 1.0], (0.0, 10.0))
    assert [e.kind for e in tr.events] == ["grazing", "grazing"]
    np.testing.assert_allclose(tr.event_times(), [np.pi / 2, 5 * np.pi / 2], atol=1e-9)
    assert all(e.mode_from == e.mode_to == 0 for e in tr.events)
    # a PWA system with a function input (DOP853 path): the same touch
    pwa = PiecewiseAffineSystem.bimodal(rot, rot, [1.0, 0.0], d=1.0, E=[[0.0], [1.0]],
                                        u=lambda t: np.zeros((np.size(t), 1)))
    tr = simulate(pwa, [0.0, 1.0], (0.0, 10.0))
    assert tr.stats["propagation"] == "dop853"
    assert [e.kind for e in tr.events] == ["grazing", "grazing"]
    np.testing.assert_allclose(tr.event_times(), [np.pi / 2, 5 * np.pi / 2], atol=1e-9)
    # a near miss is not a grazing: the circle of radius 1 - 1e-6
    tr = simulate(f, [0.0, 1.0 - 1e-6], (0.0, 10.0))
    assert tr.events == ()


def test_filippov_sliding_stays_on_a_curved_surface():
    # inside |x| = 1 the field pushes out, outside it pushes in: sliding on the unit circle
    rot = np.array([[0.0, 1.0], [-1.0, 0.0]])
    f = FilippovSystem.two_sided(lambda t, x: rot @ x + x, lambda t, x: rot @ x - x,
                                 lambda x: float(x @ x) - 1.0, 2, gradient=lambda x: 2 * x)
    tr = simulate(f, [0.5, 0.0], (0.0, 200.0))
    (ev,) = tr.events
    assert ev.kind == "sliding_start" and abs(ev.time - np.log(2.0)) <= 1e-9
    after = tr.t > ev.time
    assert np.max(np.abs(np.sum(tr.x[after] ** 2, axis=1) - 1.0)) <= 1e-12
    # x turns at unit rate throughout (the radial parts only change |x|), and on the circle
    # the Filippov field is the rotation alone: x = (cos t, -sin t) after reaching
    s = tr.t[after]
    assert np.max(np.abs(tr.x[after] - np.column_stack([np.cos(s), -np.sin(s)]))) <= 1e-8


@pytest.mark.parametrize("regions", ["half_planes", "boxes"])
@pytest.mark.parametrize("input_kind", ["none", "function"])
def test_leaving_the_pwa_domain_stops_the_run(input_kind, regions):
    # a continuous field on the box |x| <= 1 split at x1 = 0; the flow drifts out at x1 = 1.
    # "boxes": bounded regions whose outer facets lie on the domain's boundary (this used to
    # end in the misleading "sliding ... use FilippovSystem.from_pwa" error)
    A = np.array([[0.0, 0.0], [0.0, 0.0]])
    box = ([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]], [1.0, 1.0, 1.0, 1.0])
    if regions == "half_planes":
        parts = (([[1.0, 0.0]], [0.0]), ([[-1.0, 0.0]], [0.0]))
    else:
        parts = ((box[0], [0.0, 1.0, 1.0, 1.0]),
                 ([[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, -1.0]], [0.0, 1.0, 1.0, 1.0]))
    kw = {} if input_kind == "none" else {"E": [[1.0], [0.0]],
                                          "u": lambda t: np.zeros((np.size(t), 1))}
    pwa = PiecewiseAffineSystem((A, A), b=([1.0, 0.0], [1.0, 0.0]), regions=parts,
                                domain=box, **kw)
    tr = simulate(pwa, [-0.5, 0.2], (0.0, 5.0))
    assert tr.status == 1 and "left the domain" in tr.message
    assert [e.kind for e in tr.events] == ["crossing", "domain_exit"]
    exit_ = tr.events[1]
    assert exit_.index == 0 and exit_.mode_from == 1 and exit_.mode_to == -1
    assert abs(exit_.time - 1.5) <= 1e-9 and abs(tr.t[-1] - 1.5) <= 1e-9
    np.testing.assert_allclose(tr.x[-1], [1.0, 0.2], atol=1e-9)


def test_dop853_failure_is_a_solver_error_with_the_partial_trajectory():
    # x' = x^2 from 1 blows up at t = 1; with the floor of the step at rounding level (the
    # default min_rel_step stops this run earlier, tests/simulate/test_switching_budgets.py)
    # DOP853 fails by itself
    f = FilippovSystem.two_sided(lambda t, x: x**2, lambda t, x: x**2,
                                 lambda x: float(x[0]) + 10.0, 1)
    with pytest.raises(SolverError, match="DOP853 failed") as info:
        simulate(f, [1.0], (0.0, 2.0), min_rel_step=1e-300)
    part = info.value.trajectory
    assert part.status == -1 and 0.9 < part.t[-1] <= 1.0
    np.testing.assert_allclose(part.x[part.t < 0.9, 0], 1.0 / (1.0 - part.t[part.t < 0.9]),
                               rtol=1e-8)
    ret = simulate(f, [1.0], (0.0, 2.0), on_failure="return", min_rel_step=1e-300)
    assert ret.status == -1 and "DOP853 failed" in ret.message
