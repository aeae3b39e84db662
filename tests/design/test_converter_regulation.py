"""ZAD regulation of the buck converter: the closed-form map, its Jacobian, the 1T orbit, the
perturbation series in T, regulation and the design object (acceptance checks 1-6, 8, 9, 11;
the brute-force parts of 6, 7 and 10 are in tests/analysis/test_converter_orbits.py)."""

import numpy as np
import pytest
from scipy.linalg import expm

from nscontrol import simulate
from nscontrol.design import (
    ZADController,
    critical_ks,
    design_zad,
    leading_duty,
    zad_flip_boundary,
    zad_flip_coefficients,
    zad_multipliers_series,
)
from nscontrol.design import _zad_kernels as K
from nscontrol.errors import InfeasibleDesignError, ModelError
from nscontrol.numerics.differences import central_difference_jacobian
from nscontrol.systems import BuckConverter

U = np.finfo(float).eps
DELTA, T, XREF = 0.35, 0.18, 0.8
LEVELS = [(-1.0, 1.0), (0.0, 1.0)]


def random_states(rng, n=100):
    return np.column_stack([rng.uniform(0.5, 1.1, n), rng.uniform(-0.3, 0.3, n)])


def integral_of_state(A, b, x, tau):
    """``(x(τ), ∫_0^τ x dt)`` by the exponential of the augmented matrix [[A, b, 0], [0, 0, 0],
    [I, 0, 0]] — independent of the kernels' A⁻¹ identity."""
    M = np.zeros((5, 5))
    M[:2, :2], M[:2, 2], M[3:, :2] = A, b, np.eye(2)
    z = expm(M * tau) @ np.r_[x, 1.0, 0.0, 0.0]
    return z[:2], z[3:]


@pytest.mark.parametrize("levels", LEVELS)
@pytest.mark.parametrize("variant", ["pl", "exact"])
def test_check1_closed_form_map_equals_the_generic_switching_route(rng, levels, variant):
    buck = BuckConverter.normalized(DELTA, levels)
    worst = 0.0
    for ks in (2.0, 3.25, 5.0, 8.0):
        ctrl = ZADController(buck, ks, T, XREF, variant)
        loop, sw = ctrl.loop(), ctrl.switched()
        for x in random_states(rng, 25):
            generic = simulate(sw, x, (0.0, T), method="switching").x[-1]
            worst = max(worst, float(np.max(np.abs(loop(x) - generic))))
    # both routes are exact flows of the same pieces (closed-form 2×2 exponential against
    # the shared LTIFlow): rounding of ~50 flops on |x| ≤ 2, 50 · u · 2 · 100 (safety) ≈ 2e-12;
    # the acceptance bound is 1e-9
    assert worst <= 2e-12


@pytest.mark.parametrize("variant", ["pl", "exact"])
def test_map_iterates_are_the_samples_of_the_simulated_loop(variant):
    # the map's run against simulate(method="switching") of the same closed loop over 60
    # periods from a cold start (saturated periods first, then the approach to the orbit)
    buck = BuckConverter.normalized(DELTA)
    ctrl = ZADController(buck, 5.0, T, XREF, variant)
    loop, x0, n = ctrl.loop(), np.array([0.3, 0.4]), 60
    rec = loop.run(x0, n)
    times = np.arange(n) * T
    tr = simulate(ctrl.switched(), x0, (0.0, (n - 1) * T), method="switching",
                  t_eval=times)
    at = np.searchsorted(tr.t, times)          # the samples at the instants (not the switches)
    np.testing.assert_array_equal(tr.t[at], times)
    assert np.any(rec.saturated) and not np.all(rec.saturated)
    # each period of either route is within check 1's 2e-12 of the exact one; an error made
    # at period k reaches period j through DP_{j-1} ... DP_k (first order): the bound is
    # 2e-12 times the sum over k of the largest such product's norm, times 2 (safety)
    growth = np.zeros(n)
    for k in range(n):
        M = np.eye(2)
        for j in range(k, n):
            growth[k] = max(growth[k], np.linalg.norm(M, 2))
            M = loop.jacobian(rec.states[j]) @ M
    assert np.max(np.abs(tr.x[at] - rec.states)) <= 2 * 2e-12 * np.sum(growth)


@pytest.mark.parametrize("levels", LEVELS)
def test_check2_pl_duty_zeroes_the_piecewise_linear_average(rng, levels):
    buck = BuckConverter.normalized(DELTA, levels)
    A, B, du = buck.A, buck.B, buck.u_on - buck.u_off
    inside = 0
    for ks in (3.5, 5.0):
        g = np.array([1.0, ks])
        ctrl = ZADController(buck, ks, T, XREF)
        for x in random_states(rng):
            d, _ = K.pl_duty_raw(ctrl.params(), x[0], x[1])
            if not 0.0 < d < T:
                continue
            inside += 1
            s0 = x[0] - XREF + ks * x[1]
            on, off = g @ (A @ x + B * buck.u_on), g @ (A @ x + B * buck.u_off)
            # trapezoids of the three-piece line: values at 0, d/2, T - d/2, T
            s1 = s0 + on * d / 2
            s2 = s1 + off * (T - d)
            s3 = s2 + on * d / 2
            integral = d / 2 * (s0 + s1) / 2 + (T - d) * (s1 + s2) / 2 + d / 2 * (s2 + s3) / 2
            # ~20 flops on terms |s| T ≲ 0.5: 20 · u · 0.5 · 100 (safety) ≈ 2e-13 (bound 1e-12)
            assert abs(integral) <= 2e-13
            assert du > 0
    assert inside >= 20


@pytest.mark.parametrize("levels", LEVELS)
def test_check2_exact_duty_zeroes_the_true_average(rng, levels):
    buck = BuckConverter.normalized(DELTA, levels)
    A, B = buck.A, buck.B
    inside = 0
    for ks in (3.5, 5.0):
        g = np.array([1.0, ks])
        ctrl = ZADController(buck, ks, T, XREF, "exact")
        for x in random_states(rng):
            d = ctrl.duty(x)
            if not 0.0 < d < T:
                continue
            inside += 1
            total, y = 0.0, x
            for u, tau in ((buck.u_on, d / 2), (buck.u_off, T - d), (buck.u_on, d / 2)):
                y, ix = integral_of_state(A, B * u, y, tau)
                total += g @ ix - XREF * tau
            # Newton stops at |Δd| ≤ 1e-16 T; expm of the 5×5 augmented matrix is accurate to
            # ~1e-15 relative: 1e-15 · |∫s| scale (~1) · 1000 (safety) = 1e-12 (bound 1e-10)
            assert abs(total) <= 1e-12
    assert inside >= 20


@pytest.mark.parametrize("levels", LEVELS)
@pytest.mark.parametrize("variant", ["pl", "exact"])
def test_check3_jacobian_matches_central_differences(rng, levels, variant):
    buck = BuckConverter.normalized(DELTA, levels)
    worst = 0.0
    for ks in (3.0, 5.0, 8.0):
        loop = ZADController(buck, ks, T, XREF, variant).loop()
        orbit = loop.fixed_point()
        pts = [orbit.states[0], *(orbit.states[0] + 0.01 * rng.standard_normal((5, 2)))]
        for x in pts:
            if not 0.0 < loop.duties(x)[0] < T:
                continue
            worst = max(worst, float(np.max(np.abs(
                loop.jacobian(x) - central_difference_jacobian(loop, x)))))
    # step h = 1e-6(1 + |x|): truncation h²|P'''|/6 ≈ 1e-12 · 10, rounding u|P|/h ≈ 2e-10, and
    # the exact duty's Newton tolerance 1e-16 T / h ≈ 2e-11: expected ≲ 1e-9 (bound 1e-7)
    assert worst <= 1e-8


@pytest.mark.parametrize("levels", LEVELS)
def test_check4_one_period_orbit_duty_and_newton_iterations(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    D0 = leading_duty(buck, XREF)
    for ks in np.linspace(3.5, 8.0, 10):
        orbit = ZADController(buck, ks, T, XREF).loop().fixed_point(max_iter=10)
        # acceptance: |D* - D0| ≤ 1e-3 (the O(T²) ripple offset, ≈ 3e-4 at k_s = 8)
        assert abs(orbit.duties[0] / T - D0) <= 1e-3
        assert orbit.iterations <= 10



def test_period_two_orbit_just_past_the_flip_is_found_from_on_and_near_it():
    # k_s = 3.251, just past the flip of the 1T orbit: the 2T orbit born there has a
    # multiplier of DP² within ~4e-5 of 1, so DP² - I is nearly singular and a residual of
    # rounding size gives Newton steps of rounding size / 4e-5, which a step tolerance of
    # 1e-13 does not bound (before: 5 of these 22 starts on the orbit raised SolverError)
    loop = ZADController(BuckConverter.normalized(DELTA), 3.251, T, XREF).loop()
    one = loop.fixed_point()
    assert np.min(one.multipliers.real) < -1.0            # the 1T orbit has flipped
    # the 2T attractor: 2e6 periods contract a start 1e-3 away by (1 - 4e-5)^1e6 ≈ e^-40
    orbit = loop.run(one.states[0] + [1e-3, 0.0], 2, n_transient=2_000_000).states
    assert np.ptp(orbit[:, 1]) > 0.02                     # two points, not the 1T orbit
    gap = 1.0 - np.max(np.abs(np.linalg.eigvals(loop.jacobian(orbit[1])
                                                @ loop.jacobian(orbit[0]))))
    assert 0.0 < gap < 1e-4
    for start in orbit:
        for i in range(-5, 6):                            # on it, to rounding
            x = start.copy()
            x[1] += i * np.spacing(x[1])
            found = loop.fixed_point(x, period=2)
            assert found.iterations <= 2
            assert np.max(np.abs(found.states[0] - start)) <= 1e-12
        # 1e-8 off: Newton converges to within the residual's rounding floor / gap
        # (2 · 64 eps · (1 + |x|) / gap ≈ 1.5e-9, the accuracy the map's rounding allows)
        found = loop.fixed_point(start + [1e-8, -1e-8], period=2)
        floor = 2 * 64 * U * (1.0 + np.sum(np.abs(start)))
        assert np.max(np.abs(found.states[0] - start)) <= floor / gap
        assert found.iterations <= 10

def test_check5_multipliers_follow_the_first_order_series():
    buck = BuckConverter.normalized(DELTA)
    Ts, ks = 0.01, 4.0
    lam = np.sort(ZADController(buck, ks, Ts, XREF).loop().fixed_point().multipliers.real)
    fast, slow = sorted(zad_multipliers_series(DELTA, ks, 0.9, Ts))
    # remainder O(T²) with a coefficient below 1 (the T² terms of tr J, det J are O(1)):
    # T² = 1e-4, the acceptance bound (measured 2.4e-5 and 3.2e-6)
    assert abs(lam[1] - slow) <= Ts**2
    assert abs(lam[0] - fast) <= Ts**2


@pytest.mark.parametrize("delta, ks, D", [(0.35, 3.25, 0.9), (0.35, 5.0, 0.8), (0.7, 2.0, 0.3)])
def test_flip_polynomial_is_the_taylor_expansion_of_the_jacobian(delta, ks, D):
    """1 + tr J + det J - (c1 T + c2 T² + c3 T³) = O(T⁴): the remainder over T⁴ settles."""
    A, B, g = np.array([[0, 1], [-1, -delta]]), np.array([[0.0], [1.0]]), np.array([[1, ks]])
    c = zad_flip_coefficients(delta, ks, D)
    ratios = []
    for Ts in (0.04, 0.02, 0.01):
        J = expm(A * Ts) - (expm(A * (Ts - D * Ts / 2)) + expm(A * D * Ts / 2)) @ B @ (
            2 * g + Ts * g @ A) / (2 * ks)
        f = 1 + np.trace(J) + np.linalg.det(J)
        ratios.append((f - c[0] * Ts - c[1] * Ts**2 - c[2] * Ts**3) / Ts**4)
    # a wrong c2 or c3 makes the ratio grow like 1/T² or 1/T (×4 or ×2 per halving); O(T⁴)
    # keeps it within O(T) = 5 % of its value, plus rounding u/T⁴ ≈ 1e-9
    assert abs(ratios[2] - ratios[1]) <= 0.05 * abs(ratios[1]) + 1e-6
    assert abs(ratios[1] - ratios[0]) <= 0.05 * abs(ratios[0]) + 1e-6


@pytest.mark.parametrize("levels", LEVELS)
def test_check6_predictions_against_the_exact_boundary(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    D0 = leading_duty(buck, XREF)
    for Ts, rtol_flip in ((0.18, 0.02), (0.05, 0.002)):
        kc = critical_ks(buck, T=Ts, x_ref=XREF)
        # acceptance bounds of the first-order (FLIP) prediction: 2 % at T = 0.18, 0.2 % at
        # 0.05 (the O(T²) remainder; measured 0.94 % and 0.077 % for u ∈ {-1, 1})
        assert abs(zad_flip_boundary(DELTA, D0, Ts, 1) / kc - 1) <= rtol_flip
    kc = critical_ks(buck, T=T, x_ref=XREF)
    # the T³-truncated polynomial: remainder O(T³) relative, acceptance 0.2 % (measured 0.05 %)
    assert abs(zad_flip_boundary(DELTA, D0, T, "poly3") / kc - 1) <= 0.002
    for Ts in (0.05, 0.1, 0.18):
        kc_exact = critical_ks(buck, T=Ts, x_ref=XREF, variant="exact")
        # exact ZAD: 1/δ + O(T²) with a small coefficient; acceptance 0.5 % (0.34 % at 0.18)
        assert abs(zad_flip_boundary(DELTA, D0, Ts, 0) / kc_exact - 1) <= 0.005


def test_check6_flip_function_changes_sign_at_the_bisected_boundary():
    buck = BuckConverter.normalized(DELTA)
    kc = critical_ks(buck, T=T, x_ref=XREF, tol=1e-10)
    above = ZADController(buck, kc + 1e-6, T, XREF).loop().fixed_point()
    below = ZADController(buck, kc - 1e-6, T, XREF).loop().fixed_point()
    # d(1 + tr J + det J)/dk_s ≈ 2T/k_s² ≈ 0.034: ±1e-6 moves it by ±3.4e-8, far above its
    # rounding (~1e-15); the interval is 1e-10 wide
    assert above.flip_function > 0 > below.flip_function
    assert above.stable and not below.stable


@pytest.mark.parametrize("levels", LEVELS)
def test_check8_regulation_error_is_second_order_in_T(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    for ks in (3.5, 4.0, 6.0, 8.0):
        e = {Ts: abs(ZADController(buck, ks, Ts, XREF).loop().fixed_point().mean_x1 - XREF)
             for Ts in (0.045, 0.0225, T)}
        # acceptance: below 0.1 % of x_ref at T = 0.18 (measured ≤ 6.6e-4 = 0.083 %)
        assert e[T] <= 1e-3 * XREF
        # O(T²): halving T divides the error by 4, the O(T³) term moves it by ≈ ±25 %
        # at these T (acceptance interval [3.5, 5]; measured 4.18-4.59)
        assert 3.5 <= e[0.045] / e[0.0225] <= 5.0
        exact = ZADController(buck, ks, T, XREF, "exact").loop().fixed_point()
        # mean(e) = 0 exactly on an exact-ZAD orbit; Newton on the orbit to 1e-13 relative
        # moves it by ~1e-13 (acceptance 1e-10)
        assert abs(exact.mean_x1 - XREF) <= 1e-12


@pytest.mark.parametrize("plant_delta", [0.175, 0.7])
def test_check9_regulation_is_robust_to_the_load(plant_delta):
    model = BuckConverter.normalized(DELTA)
    orbit = ZADController(model, 5.0, T, XREF).loop(
        BuckConverter.normalized(plant_delta)).fixed_point()
    assert orbit.stable
    # acceptance: mean error ≤ 0.2 % of x_ref under a factor-2 load change
    assert abs(orbit.mean_x1 - XREF) <= 2e-3 * XREF


@pytest.mark.parametrize("levels", LEVELS)
def test_check11_design_has_margin_and_a_rechecked_certificate(levels):
    buck = BuckConverter.normalized(DELTA, levels)
    des = design_zad(buck, T=T, x_ref=XREF, margin=0.2)
    # k_s = 1.2 k_s,c up to one rounding of the product
    assert des.controller.ks >= 1.2 * des.ks_critical * (1 - 4 * U)
    assert des.status == "certified" and des.orbit.stable
    # central-difference multipliers: error ≈ 2e-10 (see test_check3), re-check bound 1e-6
    assert des.recheck_error <= 1e-6
    assert np.all(np.abs(des.recheck_multipliers) < 1)
    assert des.stability_margin > 0


def test_check11_unreachable_reference_is_refused():
    with pytest.raises(InfeasibleDesignError, match="^x_ref") as err:
        design_zad(BuckConverter.normalized(DELTA, (0.0, 1.0)), T=T, x_ref=1.05)
    assert err.value.status == "unreachable_reference"


def test_offset_compensation_removes_the_pl_offset():
    buck = BuckConverter.normalized(DELTA)
    plain = design_zad(buck, T=T, x_ref=XREF)
    comp = design_zad(buck, T=T, x_ref=XREF, compensate_offset=True)
    # one Newton step on an error that is O(T²) and smooth in x_ref: the residual is the
    # error's change over the shift, O(T²)·|shift| ≈ 2e-4 · 2e-4 → well below 1 % of it
    assert abs(comp.mean_error) <= 0.01 * abs(plain.mean_error)


@pytest.mark.parametrize("kwargs, name", [({"ks": 0.0}, "ks"), ({"T": -1.0}, "T"),
                                          ({"x_ref": float("nan")}, "x_ref"),
                                          ({"variant": "sliding"}, "variant")])
def test_controller_refuses_bad_input(kwargs, name):
    args = {"model": BuckConverter.normalized(DELTA), "ks": 5.0, "T": T, "x_ref": XREF}
    args.update(kwargs)
    with pytest.raises(ModelError, match=f"^{name}"):
        ZADController(**args)


def test_plant_with_other_switch_levels_is_refused():
    ctrl = ZADController(BuckConverter.normalized(DELTA), 5.0, T, XREF)
    with pytest.raises(ModelError, match="^plant"):
        ctrl.loop(BuckConverter.normalized(DELTA, (0.0, 1.0)))


def test_design_reports_the_smallest_inductor_current():
    des = design_zad(BuckConverter.normalized(DELTA, (0.0, 1.0)), T=T, x_ref=XREF)
    # mean normalised current on the orbit is δ x_ref = 0.28; the ripple over one period is
    # O(T) ≈ 0.18 peak to peak at most, so the current stays positive
    assert 0.0 < des.min_current < DELTA * XREF
