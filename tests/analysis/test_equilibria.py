"""Continuation of equilibria: fold, Hopf and boundary-equilibrium points at their exact
parameters, through the engine shared with periodic orbits."""

import numpy as np
import pytest

from nscontrol.analysis.continuation import Branch
from nscontrol.analysis.equilibria import continue_equilibrium
from nscontrol.errors import ModelError
from nscontrol.numerics.lti import Exosystem
from nscontrol.systems import NonlinearSystem
from nscontrol.systems.pwa import PiecewiseAffineSystem

EPS = np.finfo(float).eps
TOL = 1e-12          # corrector tolerance on max|F| (relative to max(1, |x|))
LOCATE = 1e-12       # width of the final bracket in (x, p)


def test_fold_of_p_minus_x_squared_is_at_p_zero():
    b = continue_equilibrium(lambda p: (lambda x: p - x**2), 1.0, [1.0], p_range=(-1.0, 2.0),
                             direction=-1, step=0.1, max_steps=80, tol=TOL,
                             locate_tol=LOCATE)
    (fold,) = b.special("fold")
    x = fold.nodes[0, 0]
    # |p - x²| <= TOL at a corrected point and |x| <= LOCATE (the bracket around x = 0 is
    # LOCATE wide in x): |p| <= TOL + LOCATE²; the eigenvalue -2x is 0 to 2·LOCATE
    assert abs(fold.parameter) <= TOL + LOCATE**2
    assert abs(x) <= LOCATE and abs(fold.multipliers[0]) <= 2 * LOCATE
    # stable node x = +√p before the fold, unstable x = -√p after it; p turned back
    assert b.stable[0] and not b.stable[-1] and b.x0[-1, 0] < 0
    assert b.p[-1] > 1.0 and b.solution == "equilibrium" and np.all(np.isnan(b.period))
    on = b.p - b.x0[:, 0] ** 2                     # every point solves F = 0 to TOL
    assert np.max(np.abs(on)) <= TOL * max(1.0, float(np.max(np.abs(b.x0))))


def _normal_form(mu, exact_jacobian=True):
    """x' = μx - y - x(x²+y²), y' = x + μy - y(x²+y²): Hopf at μ = 0, eigenvalues μ ± i."""
    def f(z):
        r2 = z @ z
        return np.array([mu * z[0] - z[1] - z[0] * r2, z[0] + mu * z[1] - z[1] * r2])

    def jac(z):
        x, y = z
        return np.array([[mu - 3 * x**2 - y**2, -1 - 2 * x * y],
                         [1 - 2 * x * y, mu - x**2 - 3 * y**2]])

    return NonlinearSystem(2, lambda t, z: f(z),
                           jacobian=(lambda t, z: jac(z)) if exact_jacobian else None)


def test_hopf_of_the_normal_form_is_at_mu_zero():
    b = continue_equilibrium(_normal_form, -1.0, [0.0, 0.0], p_range=(-1.0, 1.0), step=0.1,
                             tol=TOL, locate_tol=LOCATE)
    (hopf,) = b.points
    assert hopf.kind == "hopf"
    # on the branch x = 0 the bialternate product λ1 + λ2 = 2μ is affine in the arclength:
    # regula falsi lands on its zero up to rounding of μ (a few ε)
    assert abs(hopf.parameter) <= LOCATE
    np.testing.assert_allclose(np.sort_complex(hopf.multipliers), [-1j, 1j], atol=LOCATE)
    assert np.all(b.stable[b.p < 0]) and not np.any(b.stable[b.p > 0])


def test_hopf_with_a_difference_jacobian():
    """Central differences of the cubic terms at 0 return δ² (δ = 1e-6, the step of
    numerics.differences at x = 0), not 0: the Hopf moves to μ = -δ²; the rounding of the
    difference is ε|f|/δ ~ ε (|f| ~ δ). Bound 4 δ² (a factor 4 over that single term)."""
    fam = lambda mu: _normal_form(mu, exact_jacobian=False)   # noqa: E731
    b = continue_equilibrium(fam, -1.0, [0.0, 0.0], p_range=(-1.0, 1.0), step=0.1)
    (hopf,) = b.special("hopf")
    assert abs(hopf.parameter) <= 4 * 1e-6**2


def test_a_neutral_saddle_is_not_a_hopf():
    """x' = (μ + 2)x + y - x³, y' = x + μy: at μ = -1 the trace vanishes with real
    eigenvalues ±1 (the bialternate product changes sign, no pair crosses the axis)."""
    def fam(mu):
        return lambda z: np.array([(mu + 2) * z[0] + z[1] - z[0] ** 3, z[0] + mu * z[1]])

    b = continue_equilibrium(fam, -1.5, [0.0, 0.0], p_range=(-1.5, -0.5), step=0.1,
                             detect=("hopf",))
    assert b.special("hopf") == () and b.p[-1] > -0.5


def _bimodal(A2, p):
    """Continuous two-region field: A2 on x1 >= 1, A1 = A2 + g cᵀ with b1 = -g on x1 <= 1
    (equal on the facet), constant input p through E = (0, 1)."""
    g, c = np.array([0.0, -5.0]), np.array([1.0, 0.0])
    A1 = np.asarray(A2, float) + np.outer(g, c)
    return PiecewiseAffineSystem.bimodal(A1, A2, c, d=1.0, b1=-g, E=[[0.0], [1.0]],
                                         u=np.array([p]))


class _Persist:
    """Region 0: x1 = (5 + p)/6, region 1: x1 = p; det A1 = 6, det A2 = 1 (same sign):
    the equilibrium crosses the facet x1 = 1 at p = 1 and keeps going (persistence)."""
    A2 = [[0.0, 1.0], [-1.0, -0.5]]

    def __call__(self, p):
        return _bimodal(self.A2, p)


class _NonsmoothFold:
    """Region 0: x1 = (5 + p)/4, region 1 (a saddle, det A2 = -1): x1 = -p; they meet on
    the facet at p = -1 and exist only for p <= -1 (a non-smooth fold)."""
    A2 = [[0.0, 1.0], [1.0, -0.5]]

    def __call__(self, p):
        return _bimodal(self.A2, p)


# The slack x1 - 1 is affine in p on each region's branch, so regula falsi is exact up to
# the corrector: |δx| <= cond(A1)·TOL·max(1, |x|) with cond(A1) < 40 here, and |δp| = 6|δx|
# (region 0) — bound 6·40·TOL·|x| with |x| <= 2.
BEB = 6 * 40 * TOL * 2


def test_boundary_equilibrium_with_persistence():
    b = continue_equilibrium(_Persist(), 0.0, [0.5, 0.0], p_range=(-1.0, 3.0), step=0.1,
                             tol=TOL, locate_tol=LOCATE)
    (beb,) = b.points
    assert beb.kind == "boundary_equilibrium"
    assert abs(beb.parameter - 1.0) <= BEB
    np.testing.assert_allclose(beb.nodes[0], [1.0, 0.0], atol=BEB)
    before, after = b.p < 1.0 - 1e-9, b.p > 1.0 + 1e-9
    assert np.all(b.n_impacts[before] == 0) and np.all(b.n_impacts[after] == 1)
    assert np.all(np.diff(b.p) > 0)                         # p keeps its direction
    np.testing.assert_allclose(b.x0[after, 0], b.p[after], atol=1e-10)   # x1 = p
    assert np.all(b.stable)


def test_boundary_equilibrium_as_a_nonsmooth_fold():
    b = continue_equilibrium(_NonsmoothFold(), -3.0, [0.5, 0.0], p_range=(-5.0, 3.0),
                             step=0.1, tol=TOL, locate_tol=LOCATE)
    (beb,) = b.points
    assert abs(beb.parameter + 1.0) <= BEB
    i = beb.index
    assert np.all(np.diff(b.p[: i + 1]) > 0) and np.all(np.diff(b.p[i:]) < 0)  # turns back
    assert np.all(b.stable[:i]) and not np.any(b.stable[i + 1:])    # node, then saddle
    np.testing.assert_allclose(b.x0[i + 1:, 0], -b.p[i + 1:], atol=1e-10)


def test_equilibrium_branch_table_plot_and_hdf5(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    b = continue_equilibrium(_NonsmoothFold(), -3.0, [0.5, 0.0], p_range=(-5.0, 3.0),
                             step=0.2, parameter_name="u0", state_names=("q", "v"))
    df = b.to_pandas()
    assert list(df["special"][df["special"] != ""]) == ["boundary_equilibrium"]
    assert {"Re lambda0", "Im lambda1", "region"} <= set(df.columns)
    ax = b.plot()
    assert ax.get_xlabel() == "u0" and "equilibrium" in ax.get_ylabel()
    c = Branch.load(b.save(tmp_path / "eq.h5"))
    assert c.solution == "equilibrium" and np.array_equal(c.eigenvalues, b.eigenvalues)
    assert np.array_equal(c.n_impacts, b.n_impacts) and c.points[0].kind == b.points[0].kind


def test_bad_input():
    with pytest.raises(ModelError, match="factory"):
        continue_equilibrium(lambda p: "not a field", 0.0, [0.0], p_range=(0, 1))
    moving = lambda p: PiecewiseAffineSystem.bimodal(  # noqa: E731
        [[-1.0]], [[-2.0]], [1.0], E=[[1.0]], u=Exosystem.sinusoid(1.0, 1.0))
    with pytest.raises(ModelError, match="time-varying"):
        continue_equilibrium(moving, 0.0, [0.0], p_range=(0, 1))
    with pytest.raises(ModelError, match="detect"):
        continue_equilibrium(lambda p: (lambda x: p - x), 0.0, [0.0], p_range=(0, 1),
                             detect=("flip",))
    orbits = Branch("p", np.zeros(1), np.zeros((1, 1, 1)), np.zeros(1), np.zeros((1, 1)),
                    np.ones(1, bool), np.zeros(1, int), (), "")
    with pytest.raises(ModelError, match="eigenvalues"):
        _ = orbits.eigenvalues
