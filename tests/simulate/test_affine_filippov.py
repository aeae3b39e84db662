"""Filippov systems with affine sides (``FilippovSystem.from_pwa`` of a bimodal PWA whose two
fields differ by a constant) run in the compiled PWA loop with a sliding mode (issue 31):
against the closed forms of a sliding run and of a sliding exit, and against the Python
(DOP853) path of the same fields given as Python callables."""

import numpy as np
import pytest

from nscontrol import simulate
from nscontrol.systems.pwa import PiecewiseAffineSystem
from nscontrol.systems.switched import FilippovSystem
from nscontrol.testing import setvalued_problems as sp

EPS = np.finfo(float).eps
RTOL, ATOL = 1e-11, 1e-13   # the Python path's DOP853 tolerances (the method's defaults)


def _both(A, b_minus, b_plus, c, d=0.0):
    """The same Filippov system twice: from a PWA (compiled path) and as Python callables
    (DOP853 path)."""
    A, c = np.asarray(A, float), np.asarray(c, float)
    bm, bp = np.asarray(b_minus, float), np.asarray(b_plus, float)
    pwa = PiecewiseAffineSystem.bimodal(A, A, c, d=d, b1=bm, b2=bp, continuous=False)
    python = FilippovSystem.two_sided(lambda t, x: A @ x + bm, lambda t, x: A @ x + bp,
                                      lambda x: float(c @ x) - d, A.shape[0],
                                      gradient=lambda x: c)
    return FilippovSystem.from_pwa(pwa), python


def _relay():
    # x1' = x2, x2' = -sign(x1 + x2): sp.relay_feedback's fields
    return _both([[0.0, 1.0], [0.0, 0.0]], [0.0, 1.0], [0.0, -1.0], [1.0, 1.0])


def _exit():
    # x1' = -x2, x2' = -sign(x1 + x2) + ... : on x1 + x2 = 0 the sliding motion has x2' = x2,
    # sigma- = 1 - x2 > 0 > sigma+ = -1 - x2 while |x2| < 1; from x2 = 0.1 it leaves to the
    # side h < 0 at t = ln 10, x = (-1, 1)
    return _both([[0.0, -1.0], [0.0, 0.0]], [0.0, 1.0], [0.0, -1.0], [1.0, 1.0])


def test_relay_sliding_run_meets_its_closed_form():
    compiled, _ = _relay()
    p = sp.relay_feedback(T=2.0)
    tr = simulate(compiled, p.x0, p.t_span)
    assert tr.stats["propagation"] == "exact"
    (ev,) = tr.events
    assert (ev.kind, ev.mode_from, ev.mode_to) == ("sliding_start", 1, 3)
    # the reaching time is the root of h(t) = 1 - t - t²/2, |h'| = √3 there: a guard rounding
    # of a few eps |x| (|x| < 2) moves it by that over √3; 100 covers the propagation's
    # rounding of the piece
    t_r = p.facts["reaching_time"]
    assert abs(ev.time - t_r) <= 100 * EPS * 2.0 / np.sqrt(3.0)
    # on the surface to the loop's event tolerance (1e-12 relative), every sliding sample
    after = tr.t >= ev.time
    assert after.sum() > 600
    h = tr.x[after] @ np.ones(2)
    assert np.max(np.abs(h) / (1.0 + np.abs(tr.x[after]).sum(axis=1))) <= 1e-12
    # the sliding motion x1 = x1(t_r) e^{-(t - t_r)}: exact flows, the reaching time's error
    # times |x'| <= 2 and 100 eps of rounding per sample
    assert np.max(np.abs(tr.x - p.facts["exact"](tr.t))) <= 1e3 * EPS


def test_sliding_exit_meets_its_closed_form():
    compiled, _ = _exit()
    tr = simulate(compiled, [-0.1, 0.1], (0.0, 3.0))
    assert tr.stats["propagation"] == "exact"
    assert [e.kind for e in tr.events] == ["sliding_start", "sliding_exit"]
    assert [(e.mode_from, e.mode_to) for e in tr.events] == [(0, 2), (2, 0)]
    ex = tr.events[1]
    # sigma- = 1 - x2(t) with x2 = 0.1 e^t falls through zero with slope -1: its rounding
    # (a few eps) is the exit time's; 100 covers the flow's rounding
    assert abs(ex.time - np.log(10.0)) <= 100 * EPS * np.log(10.0)
    np.testing.assert_allclose(ex.pre, [-1.0, 1.0], rtol=0, atol=1e3 * EPS)
    sliding = (tr.t > 0.0) & (tr.t < ex.time)
    x2 = 0.1 * np.exp(tr.t[sliding])
    np.testing.assert_allclose(tr.x[sliding], np.column_stack([-x2, x2]), rtol=1e3 * EPS,
                               atol=0)
    # after the exit, F- = (-x2, 1): x2 = 1 + τ, x1 = -1 - τ - τ²/2
    tau = tr.t[tr.t > ex.time] - ex.time
    np.testing.assert_allclose(tr.x[tr.t > ex.time],
                               np.column_stack([-1.0 - tau - tau**2 / 2, 1.0 + tau]),
                               rtol=1e3 * EPS, atol=1e3 * EPS)


@pytest.mark.parametrize("case, x0, span", [(_relay, [1.0, 0.0], (0.0, 2.0)),
                                            (_exit, [-0.1, 0.1], (0.0, 3.0)),
                                            (_relay, [-0.5, 0.5], (0.0, 1.0))])
@pytest.mark.parametrize("sensitivity", [False, True])
def test_compiled_and_python_paths_agree(case, x0, span, sensitivity):
    compiled, python = case()
    a = simulate(compiled, x0, span, sensitivity=sensitivity)
    b = simulate(python, x0, span, sensitivity=sensitivity)
    assert a.stats["propagation"] == "exact" and b.stats["propagation"] == "dop853"
    assert [(e.kind, e.index, e.mode_from, e.mode_to) for e in a.events] == \
        [(e.kind, e.index, e.mode_from, e.mode_to) for e in b.events]
    assert a.stats["final_mode"] == b.stats["final_mode"]
    # DOP853 at (rtol, atol): a local error of rtol |x| + atol per unit time, carried over
    # spans <= 3 by flows of growth <= e^3, the events moved by as much: 100 (rtol + atol)
    # for states of size <= 2.5
    tol = 100.0 * (RTOL * 2.5 + ATOL) * np.exp(3.0)
    np.testing.assert_allclose(a.event_times(), b.event_times(), rtol=0, atol=tol)
    np.testing.assert_allclose(a.at(b.t), b.x, rtol=0, atol=tol)
    if sensitivity:
        # the Python path differentiates F_s by central differences: rounding eps/δ with
        # δ ~ 1e-8 relative, about 1e-8 per entry; 100 times that
        np.testing.assert_allclose(a.stats["state_transition"], b.stats["state_transition"],
                                   rtol=0, atol=1e-6)
        np.testing.assert_allclose(a.stats["saltation_matrices"],
                                   b.stats["saltation_matrices"], rtol=0, atol=1e-6)


def test_an_event_the_loop_does_not_settle_goes_to_the_python_path():
    # harmonic oscillator on the side x1 < 1: the unit circle touches x1 = 1 tangentially at
    # t = π/2 (σ⁻ = x2 = 0 there): a grazing, which the compiled loop hands back
    A = [[0.0, 1.0], [-1.0, 0.0]]
    compiled, python = _both(A, [0.0, 0.0], [-1.0, 0.0], [1.0, 0.0], d=1.0)
    a = simulate(compiled, [0.0, 1.0], (0.0, 3.0))
    b = simulate(python, [0.0, 1.0], (0.0, 3.0))
    assert a.stats["propagation"] == "exact, then dop853"
    assert [e.kind for e in a.events] == [e.kind for e in b.events] == ["grazing"]
    assert abs(a.events[0].time - np.pi / 2) <= 1e-6   # a double root: located to √(tol)
    tol = 100.0 * (RTOL + ATOL) * np.exp(3.0)
    np.testing.assert_allclose(a.at(b.t), b.x, rtol=0, atol=tol)
    np.testing.assert_allclose(a.x, np.column_stack([np.sin(a.t), np.cos(a.t)]), rtol=0,
                               atol=tol)


def test_fields_that_differ_by_more_than_a_constant_stay_on_the_python_path():
    A1, A2 = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [-1.0, 0.0]])
    pwa = PiecewiseAffineSystem.bimodal(A1, A2, [1.0, 1.0], b1=[0.0, 1.0], b2=[0.0, -1.0],
                                        continuous=False)
    tr = simulate(FilippovSystem.from_pwa(pwa), [1.0, 0.0], (0.0, 1.0))
    assert tr.stats["propagation"] == "dop853"


def test_two_sided_given_as_data_runs_the_compiled_loop():
    # sp.relay_feedback's switched system is given as data: the same PWA as from_pwa's, the
    # same run to the bit (the same compiled computation)
    p = sp.relay_feedback(T=2.0)
    tr = simulate(p.switched, p.x0, p.t_span)
    assert tr.stats["propagation"] == "exact"
    compiled, _ = _relay()
    ref = simulate(compiled, p.x0, p.t_span)
    np.testing.assert_array_equal(tr.t, ref.t)
    np.testing.assert_array_equal(tr.x, ref.x)
    assert p.switched.state_names == ("x1", "x2")


def test_two_sided_data_with_different_state_matrices_is_the_python_path_of_its_callables():
    A1, A2 = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [-1.0, 0.0]])
    bm, bp, c = np.array([0.0, 1.0]), np.array([0.0, -1.0]), np.ones(2)
    data = FilippovSystem.two_sided((A1, bm), (A2, bp), c, 2)
    python = FilippovSystem.two_sided(lambda t, x: A1 @ x + bm, lambda t, x: A2 @ x + bp,
                                      lambda x: float(c @ x), 2, gradient=lambda x: c)
    a = simulate(data, [1.0, 0.0], (0.0, 1.0))
    b = simulate(python, [1.0, 0.0], (0.0, 1.0))
    assert a.stats["propagation"] == b.stats["propagation"] == "dop853"
    # the same DOP853 run but for the rounding of the fields' evaluation (a few eps |x|),
    # carried by flows of growth <= e over the span: 100 eps
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=100 * EPS)


@pytest.mark.parametrize("args, kw, error, message", [
    ((lambda t, x: x, ([[0.0]], [1.0]), [1.0], 1), {}, "ModelError",
     r"^f_minus, f_plus, h: expected three callables, or the data form"),
    ((([[0.0]], [1.0]), ([[0.0]], [-1.0]), [1.0], 1), {"gradient": lambda x: np.ones(1)},
     "ModelError", r"^gradient: the data form's gradient is the normal c"),
    ((([[0.0, 1.0]], [1.0]), ([[0.0]], [-1.0]), [1.0], 1), {}, "DimensionError",
     r"^f_minus\[0\] \(A\): expected a square matrix"),
    ((([[0.0]], [1.0]), 3.0, [1.0], 1), {}, "DimensionError",
     r"^f_plus: expected a callable \(t, x\) -> \(n,\) array or a pair \(A, b\)"),
    ((([[0.0]], [1.0]), ([[0.0]], [-1.0]), [1.0, 0.0], 1), {}, "DimensionError",
     r"^h: expected a vector of length 1"),
    ((([[0.0]], [1.0]), ([[0.0]], [-1.0]), [0.0], 1), {}, "ModelError",
     r"^h: expected a nonzero normal vector c"),
])
def test_two_sided_data_form_refuses_bad_data(args, kw, error, message):
    from nscontrol import errors

    with pytest.raises(getattr(errors, error), match=message):
        FilippovSystem.two_sided(*args, **kw)
