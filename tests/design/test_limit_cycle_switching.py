"""The corner design's leading-order theory: corner gain and its closed form, the gain that
reaches a corner gain, the crossing interval, the corner discontinuity map, the
piecewise-linear return map, and the design's guard against unreachable targets."""

import numpy as np
import pytest

from nscontrol.analysis.orbits import find_cycle
from nscontrol.design import (
    PWLReturnMap,
    corner_discontinuity_map,
    corner_gain,
    crossing_gain_interval,
    design_corner_controller,
    gain_for_corner_gain,
    reachable_multipliers,
)
from nscontrol.errors import InfeasibleDesignError, ModelError
from nscontrol.systems import Wedge
from nscontrol.testing.cycle_problems import polar_normal_form

EPS = np.finfo(float).eps
SIGMA = 0.02
S = np.sqrt(0.5)
N_IN, N_OUT, E = np.array([S, S]), np.array([S, -S]), np.array([1.0, 0.0])


@pytest.fixture(scope="module")
def problem_a():
    plant, _ = polar_normal_form((-4 * SIGMA, 0.0, 5 * SIGMA, 0.0, -SIGMA), omega=1.0)
    return plant, find_cycle(plant, [1.0, 0.0], 2 * np.pi, normal=[0.0, 1.0])


@pytest.mark.parametrize("k", [-0.62, -0.3, 0.3])
def test_corner_gain_closed_form_for_the_plane_field(k):
    # F1 ⊥ e: a = 2k tanα/(v − k tanα) exactly; a few roundings of O(1) numbers
    v = 1.01
    a = corner_gain([0.0, v], [k, v], N_IN, N_OUT, E)
    assert a == pytest.approx(2 * k / (v - k), rel=16 * EPS)


@pytest.mark.parametrize("k", [-0.62, -0.3, 0.3])
def test_corner_gain_with_the_true_field_at_r_1_01(problem_a, k):
    # the closed form neglects the radial part g(ρ)ρ of f(c): |g(1.01)|·1.01 ≈ 1.2e-3 of the
    # speed ωρ = 1.01, which moves a by ≲ 1e-3 relative (the accepted bound)
    plant, _ = problem_a
    f1 = plant.rhs(0.0, np.array([1.01, 0.0]))
    a = corner_gain(f1, f1 + k * E, N_IN, N_OUT, E)
    assert abs(a / (2 * k / (1.01 - k)) - 1.0) <= 1e-3


@pytest.mark.parametrize("a", [-0.9, -0.5, 0.25, 3.0])
def test_gain_for_corner_gain_inverts_corner_gain(a):
    f1, b = np.array([0.05, 1.2]), np.array([1.0, 0.3])
    k = gain_for_corner_gain(a, f1, b, N_IN, N_OUT, E)
    # a Möbius function and its inverse: relative rounding of a few ε times the condition
    # |a'(k) k / a| (≤ 10 here)
    assert corner_gain(f1, f1 + k * b, N_IN, N_OUT, E) == pytest.approx(a, rel=100 * EPS)


def test_crossing_interval_ends_at_the_sliding_thresholds():
    v = 1.0
    lo, hi = crossing_gain_interval([0.0, v], E, N_IN, N_OUT)
    assert (lo, hi) == pytest.approx((-v, v))      # n_inᵀF2 = 0 at k = −v, n_outᵀF2 at +v
    assert corner_gain([0, v], [lo * (1 - 1e-9), v], N_IN, N_OUT, E) == pytest.approx(-1.0,
                                                                                      abs=1e-8)
    lo_m, hi_m = reachable_multipliers(2.0, [0.0, v], E, N_IN, N_OUT, E)
    assert lo_m == pytest.approx(0.0, abs=1e-9) and hi_m == np.inf
    with pytest.raises(ModelError, match="F1"):
        crossing_gain_interval([0.0, -v], E, N_IN, N_OUT)


def test_corner_map_is_identity_on_the_missing_side_and_linear_on_the_other():
    w = Wedge.symmetric([1.0, 0.0], E, np.pi / 4, flow=[0.0, 1.0])
    zdm = corner_discontinuity_map([0.0, 1.0], [-0.5, 1.0], w)
    below = np.array([0.99, 0.0])
    assert np.array_equal(zdm(below), below)
    a = corner_gain([0.0, 1.0], [-0.5, 1.0], w.n_in, w.n_out, E)
    for z in (1e-3, 2e-3):
        out = zdm([1.0 + z, 0.0])
        # the displacement (F2 − F1)Δt is along e here, so the offset is read directly
        assert out[0] - 1.0 == pytest.approx(z * (1 + a), rel=16 * EPS)
    with pytest.raises(ModelError, match="F2"):
        corner_discontinuity_map([0.0, 1.0], [3.0, 1.0], w)


def test_pwl_map_fixed_points_and_scenarios():
    lam, a, mu = 2.12545, 0.5 / 2.12545 - 1.0, 1e-3
    P = PWLReturnMap(lam, a, mu)
    left, right = P.fixed_points()
    assert left.z == 0.0 and not left.stable
    assert right.stable and right.slope == pytest.approx(0.5, rel=4 * EPS)
    assert P(right.z) == pytest.approx(right.z, rel=16 * EPS)
    assert right.z == pytest.approx(P.q * mu) and P.q > 1.0
    assert P.classify() == "nonsmooth fold"
    assert PWLReturnMap(0.5, 0.2, 1e-3).classify() == "persistence"
    assert PWLReturnMap(0.5, -4.0, 1e-3).classify() == "flip"
    assert [p.branch for p in PWLReturnMap(lam, a, -mu).fixed_points()] == []


def test_design_places_the_corner_and_gain(problem_a):
    plant, cyc = problem_a
    d = design_corner_controller(plant, cyc, b=[1.0, 0.0], target_multiplier=0.5,
                                 target_offset=0.005, anchor=[1.0, 0.0], axis=[1.0, 0.0])
    lam = d.site.lam
    # μ_c = z_d (1 − λ_d)/(λ − λ_d), a = λ_d/λ − 1: formulas, to rounding
    assert d.mu_c == pytest.approx(0.005 * 0.5 / (lam - 0.5), rel=16 * EPS)
    assert d.a == pytest.approx(0.5 / lam - 1.0, rel=1e-12)
    assert d.predicted_multiplier == pytest.approx(0.5, rel=1e-12)
    assert d.predicted_offset == pytest.approx(0.005, rel=1e-12)
    # the anchor lies on the shot cycle: radius within find_cycle's tolerance 1e-9 of 1
    assert d.wedge.corner == pytest.approx([1.0 + d.mu_c, 0.0], abs=1e-9)
    assert d.regime == "crossing" and d.system.crosses_only()
    assert d.status.startswith("predicted only")     # nothing shot until .verified is read
    # τ: the default section is a quarter period upstream (the ray θ = −π/2); offsets on it
    # reach θ = 0 multiplied by λ^(1/4) (polar normal form, θ' = ω exactly); the
    # transition's error is the integration's, ~1e-10
    assert d.site.tau == pytest.approx(lam ** (1 / 4), rel=1e-8)


@pytest.mark.parametrize("lam_d", [-0.5, -0.1, 0.0])
def test_design_refuses_targets_needing_a_below_minus_one(problem_a, lam_d):
    plant, cyc = problem_a
    kwargs = {"b": [1.0, 0.0], "target_multiplier": lam_d, "target_offset": 0.005,
              "anchor": [1.0, 0.0]}
    with pytest.raises(InfeasibleDesignError, match="target_multiplier"):
        design_corner_controller(plant, cyc, **kwargs)
    d = design_corner_controller(plant, cyc, allow_sliding=True, **kwargs)
    assert d.regime == "sliding" and d.predicted_multiplier == 0.0
    assert d.system.face_status(d.wedge.corner, "in") == "attracting_sliding"
    # the cycle is the corner's orbit, back on Σ_c at λ μ_c to first order: the corner sits
    # at μ_c = z_d/λ (not at z_d), the cycle's predicted offset is z_d (one rounding each)
    assert d.mu_c == pytest.approx(0.005 / d.site.lam, rel=4 * EPS)
    assert d.predicted_offset == 0.005 and d.mu_c != 0.005
    assert d.wedge.corner == pytest.approx([1.0 + d.mu_c, 0.0], abs=1e-9)


def test_design_refuses_bad_arguments(problem_a):
    plant, cyc = problem_a
    base = {"b": [1.0, 0.0], "target_multiplier": 0.5, "anchor": [1.0, 0.0]}
    with pytest.raises(ModelError, match="target_offset"):
        design_corner_controller(plant, cyc, target_offset=0.0, **base)
    with pytest.raises(ModelError, match="half_angle"):
        design_corner_controller(plant, cyc, target_offset=0.005, half_angle=2.0, **base)
    with pytest.raises(InfeasibleDesignError, match="target_multiplier"):
        design_corner_controller(plant, cyc, target_offset=0.005,
                                 **{**base, "target_multiplier": cyc.nontrivial[0].real})
    with pytest.raises(ModelError, match="b"):   # b along the flow at the anchor
        design_corner_controller(plant, cyc, target_offset=0.005,
                                 **{**base, "b": [0.0, 1.0]})


@pytest.mark.parametrize("lam", [2.0, -0.5])
def test_reachable_multipliers_at_the_true_field_are_the_limits(problem_a, lam):
    # with the field at ρ = 1.01, n_outᵀ(F1 + k b) at the interval's end is a rounding of
    # O(1) numbers, not 0: evaluating the pole there gave (-2.25e16, 0). The limits are 0
    # (entry face) and ∞·sign λ (exit face), so the interval is (0, ∞) or (-∞, 0)
    plant, _ = problem_a
    f1 = plant.rhs(0.0, np.array([1.01, 0.0]))
    lo, hi = reachable_multipliers(lam, f1, E, N_IN, N_OUT, E)
    assert (lo, hi) == ((0.0, np.inf) if lam > 0 else (-np.inf, 0.0))
