"""Corner control of limit cycles, measured: the controlled cycles by shooting through the
saltation matrices against the piecewise-linear prediction (the chapter's acceptance checks;
examples A, polar normal form, and B, Van der Pol, of ``examples.ch12_corner_control``)."""

import numpy as np
import pytest

from nscontrol.analysis import (
    CornerFamily,
    corner_diagram,
    section_returns,
    verify_corner_design,
    wedge_events,
)
from nscontrol.examples import ch12_corner_control as ch12
from nscontrol.simulate import simulate

#: DOP853 tolerance of the switching integrator; global errors over a period stay below
#: K·RTOL with K = 100 (tens to hundreds of steps, errors adding up; tests/analysis of the
#: smooth cycles use the same factor).
RTOL, K = 1e-11, 100


@pytest.fixture(scope="module")
def problem_a():
    return ch12.example_a()


@pytest.fixture(scope="module")
def problem_b():
    return ch12.example_b()


@pytest.fixture(scope="module")
def design_a(problem_a):
    return ch12.design_a(0.005, 0.5, problem_a)


def test_uncontrolled_references(problem_a, problem_b):
    _, cyc_a, _ = problem_a
    # λ(r = 1) = exp(12πσ/ω) (the radial equation linearised over one period); shooting
    # error: the variational equation's global error K·RTOL relative
    lam_a = np.exp(12 * np.pi * ch12.SIGMA / ch12.OMEGA)
    assert abs(cyc_a.nontrivial[0].real - lam_a) <= K * RTOL * lam_a
    plant_b, cyc_b, _ = problem_b
    grid = np.linspace(0.0, cyc_b.period, 4097)
    x = simulate(plant_b, cyc_b.x0, (0.0, cyc_b.period), t_eval=grid).x[:, 0]
    # Liouville: det M = exp(∮ div f dt); the trapezoid rule on a periodic analytic integrand
    # converges exponentially, so the integral is exact to the samples' K·RTOL
    liouville = np.exp(np.sum(ch12.EPS * (1 - x[:-1] ** 2)) * (grid[1] - grid[0]))
    assert abs(cyc_b.nontrivial[0].real - liouville) <= K * RTOL
    # averaging: exp(−2πε) with relative error ε²/8 + O(ε⁴) = 1.25e-3 < 1 %
    assert abs(cyc_b.nontrivial[0].real / np.exp(-2 * np.pi * ch12.EPS) - 1) <= 0.01


def test_controlled_cycle_monodromy_and_finite_difference_slope(design_a):
    cc = design_a.verified
    # the trivial multiplier: 1 to the monodromy's accuracy (flows K·RTOL, the saltation
    # matrices' relative error ~ event-time error / dwell time ≈ 1e-13/1e-3)
    assert cc.trivial_error <= 1e-7
    assert cc.events == ("enters through H_in", "leaves through H_out")
    # central differences with h = 1e-7: truncation h²|P'''| ≲ 1e-12, rounding of the
    # returns (correlated integration errors, ~RTOL) over 2h ≈ 5e-5 < 1e-4
    assert abs(ch12.fd_slope(design_a) - cc.multiplier) <= 1e-4


def test_design_achieves_multiplier_and_amplitude_example_a(design_a):
    d = design_a
    # first order in z_d: |λ_new − λ_d| ≤ 3|z_d| (the fields frozen at the corner, the map
    # linearised: O(z_d) relative, coefficient measured ≈ 2 for this example)
    assert abs(d.verified.multiplier - 0.5) <= 3 * 0.005
    # the offset on the section against the transported prediction z*/τ: within 5 % (first
    # order again: relative error O(z_d/(1 − λ_d)) ≈ 1 %)
    assert 0.95 <= d.verified.offset / d.predicted_section_offset <= 1.05


def test_a_design_is_verified_at_the_first_read_of_verified(problem_a, design_a):
    """``design_corner_controller(...).verified`` is the shot cycle at once (it was ``None``
    until verify_corner_design was called): the same shooting from the same start gives the
    same cycle, to the last bit."""
    from nscontrol.design.limit_cycle_switching import design_corner_controller

    plant, cyc, sec = problem_a
    fresh = design_corner_controller(plant, cyc, b=[1.0, 0.0], target_multiplier=0.5,
                                     target_offset=0.005, anchor=[1.0, 0.0], axis=[1.0, 0.0],
                                     section=sec)     # ch12.design_a's arguments
    assert fresh.status.startswith("predicted only")
    cc = fresh.verified
    assert cc is not None and fresh.verified is cc                 # shot once, then kept
    assert fresh.status.startswith("verified: cycle at section offset")
    assert cc.offset == design_a.verified.offset
    assert cc.multiplier == design_a.verified.multiplier
    assert verify_corner_design(fresh).verified.offset == cc.offset


def test_local_corner_map_converges_to_the_corner_gain():
    g = ch12.zdm_convergence(1.01, -0.62, xis=(1e-3, 5e-4))
    e1, e2 = (p["error"] for p in g["points"])
    # leading order in the offset ξ: relative error O(ξ) — ≤ 0.5 % at ξ = 1e-3 and halving
    # with ξ (first order; the integration's 1e-11/ξ is negligible)
    assert e1 <= 0.005
    assert 1.6 <= e1 / e2 <= 2.6


def test_sliding_variant_funnels_through_the_corner():
    (res,) = ch12.sliding_cycles(rhos=(1.01,))
    for p in res["per_k"]:
        assert p["status"] == "attracting_sliding"       # the crossing condition fails on H_in
        assert p["events"] == ("sliding starts on H_in", "sliding ends at the corner")
        # the saltation at sliding entry is singular: the monodromy is exactly rank one up
        # to the sliding field's differenced Jacobian (ε^(2/3) ≈ 4e-11)
        assert p["trivial_error"] <= 1e-7
        assert p["nontrivial"] <= 1e-8
    # the cycle is the plant's orbit of the corner whatever k: both runs end on the same
    # F1 flow from c, so they agree to the integration error K·RTOL·|x| ≈ 1e-9
    assert res["spread"] <= 1e-9
    assert res["to_corner_orbit"] <= 1e-9


def test_wedge_events_skip_the_lines_off_the_wedge(design_a):
    cyc = design_a.verified.cycle
    tr = simulate(design_a.system, cyc.x0, (0.0, cyc.period))
    assert len(tr.events) == 4                    # both lines cross the cycle twice
    assert wedge_events(design_a.system, tr) == ("enters through H_in", "leaves through H_out")


@pytest.mark.slow
@pytest.mark.parametrize("rho,k", [(1.01, 0.3), (1.2, -0.62), (1.2, 0.3)])
def test_local_corner_map_other_corners(rho, k):
    g = ch12.zdm_convergence(rho, k, xis=(1e-3, 5e-4))
    e1, e2 = (p["error"] for p in g["points"])
    assert e1 <= 0.005 and 1.6 <= e1 / e2 <= 2.6      # as above: first order in ξ


@pytest.mark.slow
@pytest.mark.parametrize("example,lam_d,offsets", [
    ("A", 0.5, (0.01, 0.005, 0.0025)),
    ("B", 0.2, (-0.01, -0.005, -0.0025)),
    ("B", 0.9, (0.01, 0.005, 0.0025)),
])
def test_design_converges_at_first_order(problem_a, problem_b, example, lam_d, offsets):
    make = ((lambda z: ch12.design_a(z, lam_d, problem_a)) if example == "A"
            else (lambda z: ch12.design_b(lam_d, z, problem_b)))
    designs = [make(z) for z in offsets]
    errors = [abs(d.verified.multiplier - lam_d) for d in designs]
    for z, e in zip(offsets, errors, strict=True):
        assert e <= 3 * abs(z)                     # first order, coefficient ≤ 3
    for e1, e2 in zip(errors, errors[1:], strict=False):
        assert 1.6 <= e1 / e2 <= 2.6               # halving z_d halves the error
    # amplitude at the smallest offsets the acceptance asks for (5 %; the error grows like
    # |z_d|/(1 − λ_d), so λ_d = 0.9 needs the smallest)
    d = designs[2] if lam_d == 0.9 else designs[1]
    assert 0.95 <= d.verified.offset / d.predicted_section_offset <= 1.05
    for d in designs:
        assert d.verified.trivial_error <= 1e-7


@pytest.mark.slow
def test_stabilisation(design_a):
    res = ch12.stabilisation(design_a)
    # contraction 0.51 per return: 30 returns shrink 1e-2 to 2e-11; the brute-force runs'
    # tolerance 1e-9 bounds the distance to the shot cycle
    assert max(res["to_cycle"]) <= 1e-6
    # from r = 0.99 the orbit spirals to the stable origin (0.6 per turn once small)
    assert res["inner_radius"] <= 1e-3


@pytest.mark.slow
def test_sliding_variant_second_corner():
    (res,) = ch12.sliding_cycles(rhos=(1.02,))
    assert all(p["events"] == ("sliding starts on H_in", "sliding ends at the corner")
               for p in res["per_k"])
    assert res["spread"] <= 1e-9 and res["to_corner_orbit"] <= 1e-9


@pytest.mark.slow
def test_corner_diagram_tends_to_q(design_a):
    dia = ch12.diagram(design_a, (0.001, 0.002, 0.004))
    err = np.abs(dia.offset_sigma / dia.mu / dia.q - 1.0)
    # leading order in μ_c: the error is O(μ_c) (≈ 6.5·μ_c measured), ≤ 5 % and decreasing
    assert np.all(err <= 0.05) and np.all(np.diff(err) > 0)
    assert not dia.errors


@pytest.mark.slow
def test_corner_diagram_same_on_processes(design_a):
    fam = CornerFamily(design_a.site, design_a.system.b, design_a.k)
    serial = corner_diagram(fam, [0.002, 0.004])
    pool = corner_diagram(fam, [0.002, 0.004], executor=None)
    # the same computation in another process: identical floating-point results
    assert np.array_equal(serial.offset, pool.offset)


@pytest.mark.slow
def test_suppression():
    design = ch12.design_a(0.005)
    for res in ch12.suppression(design):
        # stable origin: 80 returns take any r ≤ 1.3 below 1e-6 (0.6 per turn near 0)
        assert max(res["inner_radii"]) <= 1e-6
        assert res["cycles_near_1"] == 0
        # one outer stable cycle, moved inward by the wedge it crosses; 30 returns at the
        # outer multiplier (≈ 0.05) leave the starts within the tolerance 1e-9 of each other
        assert res["outer_spread"] <= 1e-6
        assert res["outer_radius"] < 2.0 and abs(res["outer_multiplier"]) < 1.0


def test_section_returns_refuses_short_runs(design_a):
    site = design_a.site
    from nscontrol.errors import ModelError

    with pytest.raises(ModelError, match="n_returns"):
        section_returns(design_a.system, site.section_point, site.section, 0,
                        period=site.period)


def test_verify_refuses_a_cycle_that_is_not_there(design_a):
    import dataclasses

    from nscontrol.errors import InfeasibleDesignError

    # the corner inside the unstable cycle: no controlled cycle near the prediction
    bad = dataclasses.replace(design_a, system=CornerFamily(design_a.site, design_a.system.b,
                                                            design_a.k)(-0.005))
    with pytest.raises(InfeasibleDesignError, match="design"):
        verify_corner_design(bad)
