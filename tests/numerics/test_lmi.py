"""LMI helpers: Lyapunov feasibility decided correctly and re-checked, decay-rate bisection
matching the spectral abscissa, badly scaled data handled, bad input refused."""

import warnings

import numpy as np
import pytest

from nscontrol.errors import InaccurateCertificateWarning, InfeasibleDesignError, ModelError
from nscontrol.numerics.lmi import (
    LMIProblem,
    bisect_max,
    lyapunov_certificate,
    max_lyapunov_decay_rate,
)
from nscontrol.numerics.scaling import Scaling

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)

HURWITZ = np.array([[-1.0, 2.0, 0.0], [0.0, -3.0, 1.0], [0.5, 0.0, -2.0]])
LIGHTLY_DAMPED = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0],
                           [-2.0, 1.0, -0.02, 0.01], [1.0, -1.5, 0.01, -0.03]])


def _abscissa(A):
    return float(np.max(np.linalg.eigvals(A).real))


@pytest.mark.parametrize("solver", ["auto", "SCS"])
def test_hurwitz_matrix_has_rechecked_certificate(solver):
    res = lyapunov_certificate(HURWITZ, solver=solver)
    assert res.solver == ("CLARABEL" if solver == "auto" else "SCS")
    P = res["P"]
    assert np.linalg.eigvalsh(P)[0] > 0.0
    assert np.linalg.eigvalsh(HURWITZ.T @ P + P @ HURWITZ)[-1] < 0.0
    # margins are the re-computed smallest eigenvalues, at least half of what was required
    for name, lam in res.margins.items():
        assert lam >= 0.5 * res.required[name]


def test_non_hurwitz_matrix_is_infeasible():
    A = HURWITZ + 2.5 * np.eye(3)  # an eigenvalue with positive real part
    assert _abscissa(A) > 0
    with pytest.raises(InfeasibleDesignError) as err:
        lyapunov_certificate(A)
    assert err.value.status in ("infeasible", "infeasible_inaccurate", "recheck_failed")
    assert "Lyapunov" in str(err.value)


def test_decay_rate_bisection_matches_spectral_abscissa(rng):
    for A in (HURWITZ, LIGHTLY_DAMPED, rng.normal(size=(3, 3)) - 1.5 * np.eye(3)):
        found = max_lyapunov_decay_rate(A, tol=1e-4)
        assert abs(found.value - (-_abscissa(A))) <= 1e-3
        assert found.value <= found.upper


def test_badly_scaled_data_is_rescaled():
    # a lightly damped mechanical model in units spanning 13 orders of magnitude
    D = np.diag([1.0, 1e5, 1e-3, 1e6])
    A = D @ LIGHTLY_DAMPED @ np.linalg.inv(D)
    decay = 0.005  # spectral abscissa is about -0.0056
    res = lyapunov_certificate(A, decay=decay)
    # verify the returned P on the congruent (well-conditioned) form D_s(A'P+PA+2aP)D_s
    sc = Scaling.balanced([A])
    Pc = sc.quadratic_scaled(res["P"])
    As = sc.matrix(A)
    lyap = As.T @ Pc + Pc @ As + 2 * decay / sc.omega * Pc
    assert np.linalg.eigvalsh(lyap)[-1] < 0.0 and np.linalg.eigvalsh(Pc)[0] > 0.0
    # without scaling the same problem is not decided by the solver
    with pytest.raises(InfeasibleDesignError):
        lyapunov_certificate(A, decay=decay, scale=False)


def test_scaling_roundtrip():
    sc = Scaling.balanced([np.array([[0.0, 1.0], [-1e4, -1.0]])])
    np.testing.assert_allclose(np.abs(sc.matrix([[0.0, 1.0], [-1e4, -1.0]])).max(), 1.0,
                               rtol=0.1)
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    x = np.array([0.7, -40.0])
    xs = sc.S @ x
    assert xs @ P @ xs == pytest.approx(x @ sc.quadratic_back(P) @ x, rel=1e-14)


def test_equalities_objectives_and_variable_margins():
    # observer-type problem: P > 0, sym(A'P - C'Y' ...) with an equality P b = c
    prob = LMIProblem("test")
    P = prob.symmetric("P", 2)
    t = prob.variable("t")
    prob.positive("P >= I", P, margin=1.0)
    prob.equal("P e1 = (2, 0)", P @ np.array([1.0, 0.0]), np.array([2.0, 0.0]))
    prob.negative("A'P + PA <= -t I", HURWITZ[:2, :2].T @ P + P @ HURWITZ[:2, :2], margin=t)
    prob.positive("t <= 1", np.array([[1.0]]) - t[None, None], margin=0.0)
    res = prob.solve(maximize=t)
    assert res.residuals["P e1 = (2, 0)"] <= 1e-7
    assert res["P"][0, 0] == pytest.approx(2.0, abs=1e-7)
    assert res.objective == pytest.approx(float(res["t"]), rel=1e-6)
    assert res.margins["A'P + PA <= -t I"] >= 0.5 * float(res["t"])
    # the certificate re-check is real: demand more than the solver delivers
    prob2 = LMIProblem("tight")
    Q = prob2.symmetric("Q", 2)
    prob2.positive("Q >= I", Q, margin=1.0)
    with pytest.raises(InfeasibleDesignError) as err:
        prob2.solve(minimize=Q[0, 0] + Q[1, 1], recheck_fraction=2.0)
    assert err.value.status == "recheck_failed" and "Q >= I" in str(err.value)
    prob3 = LMIProblem("equality")
    R = prob3.symmetric("R", 2)
    prob3.positive("R >= I", R, margin=1.0)
    prob3.equal("R v = w", R @ np.array([1 / 3, 1 / 7]), np.array([np.pi, np.e]))
    with pytest.raises(InfeasibleDesignError, match="R v = w"):
        prob3.solve(eq_tol=1e-300)  # no solver meets that: the residual is measured


def test_bisection_helper():
    calls = []

    def feasible(s):
        calls.append(s)
        if s > np.pi:
            raise InfeasibleDesignError("too big", status="infeasible")
        return {"s": s}

    out = bisect_max(feasible, 0.0, 10.0, tol=1e-9)
    assert abs(out.value - np.pi) <= 1e-9 and out.result == {"s": out.value}
    assert out.iterations == len(calls)
    with pytest.raises(InfeasibleDesignError, match="lower end"):
        bisect_max(feasible, 4.0, 10.0)
    assert bisect_max(feasible, 0.0, 1.0).value == 1.0


def test_bad_input_each_its_error():
    prob = LMIProblem("bad")
    P = prob.symmetric("P", 2)
    with pytest.raises(ModelError, match="already declared"):
        prob.symmetric("P", 2)
    with pytest.raises(ModelError, match="margin"):
        prob.positive("P > 0", P, margin=-1.0)
    prob.positive("P > 0", P, margin=1.0)
    with pytest.raises(ModelError, match="already used"):
        prob.positive("P > 0", P, margin=1.0)
    with pytest.raises(ModelError, match="square"):
        prob.negative("rect", P[:, :1], margin=1.0)
    with pytest.raises(ModelError, match="objective"):
        prob.solve(minimize=P[0, 0], maximize=P[0, 0])
    with pytest.raises(ModelError, match="lo, hi"):
        bisect_max(lambda s: s, 1.0, 0.0)
    with pytest.raises(ModelError, match="A"):
        lyapunov_certificate(np.array([[np.nan, 0.0], [0.0, -1.0]]))


def test_thin_margin_warns_and_accurate_solution_does_not():
    # a well-posed problem solved accurately does not warn
    with warnings.catch_warnings():
        warnings.simplefilter("error", InaccurateCertificateWarning)
        lyapunov_certificate(HURWITZ)
    # minimising trace Q with Q >= I puts lambda_min(Q) on its margin (1.0): passes the
    # re-check (>= 0.5) but is below a demanded 1.5 x margin -> warned, named
    prob = LMIProblem("thin")
    Q = prob.symmetric("Q", 2)
    prob.positive("Q >= I", Q, margin=1.0)
    with pytest.warns(InaccurateCertificateWarning, match="Q >= I"):
        res = prob.solve(minimize=Q[0, 0] + Q[1, 1], warn_fraction=1.5)
    assert res.margins["Q >= I"] == pytest.approx(1.0, abs=1e-6)


def test_solver_names_are_checked_before_solving():
    import cvxpy as cp

    from nscontrol.numerics.lmi import SDP_SOLVERS, solver_order

    assert solver_order(None) == solver_order("auto") == ["CLARABEL", "SCS"]
    assert solver_order("Scs") == ["SCS"]
    for bad in ("BOGUS", "", 3, "ECOS"):  # ECOS: installed or not, it has no SDP cone
        with pytest.raises(ModelError, match="solver: expected one of 'auto', 'CLARABEL'"):
            solver_order(bad)
    missing = [n for n in SDP_SOLVERS if n not in cp.installed_solvers()]
    if missing:
        with pytest.raises(ModelError, match="not installed"):
            solver_order(missing[0])
    # LMIProblem and the helpers built on it use the same check (no InfeasibleDesignError)
    with pytest.raises(ModelError, match="got 'BOGUS'"):
        lyapunov_certificate(HURWITZ, solver="BOGUS")
    with pytest.raises(ModelError, match="got 'BOGUS'"):
        max_lyapunov_decay_rate(HURWITZ, solver="BOGUS")


def test_clarabel_failure_falls_back_to_scs(clarabel_fails):
    attempts = clarabel_fails
    res = lyapunov_certificate(HURWITZ)
    assert attempts == ["CLARABEL", "SCS"] and res.solver == "SCS"
    P = res["P"]
    assert np.linalg.eigvalsh(P)[0] > 0.0
    assert np.linalg.eigvalsh(HURWITZ.T @ P + P @ HURWITZ)[-1] < 0.0
    # Clarabel alone has no fallback: the failure is reported, naming the solver
    with pytest.raises(InfeasibleDesignError, match="CLARABEL") as err:
        lyapunov_certificate(HURWITZ, solver="CLARABEL")
    assert err.value.status == "solver_error"
