"""Chapter 8, LMI synthesis: spec §6 checks 1 (post-conditions), 2 (infeasibility), 3 (rates),
and bad input to the design functions."""

import numpy as np
import pytest

from nscontrol.design.lure_observer import (
    design_lure_observer,
    lure_observer_lmi,
    max_observer_decay_rate,
    observer_from_gains,
    recheck_lure_certificate,
    structural_infeasibility,
)
from nscontrol.errors import DimensionError, InfeasibleDesignError, ModelError
from nscontrol.examples import ch08_lure_observer as ex

pytestmark = pytest.mark.sensitive   # rerun under other rounding (tests/README.md)


def _postconditions(design):
    cert = design.certificate
    scale = max(1.0, np.linalg.norm(design.H))
    assert cert.equality_residual <= 1e-7 * scale
    # independent recomputation, not the stored numbers
    A_L = design.A - design.L @ design.C
    lyap = A_L.T @ design.P + design.P @ A_L
    assert np.linalg.eigvalsh(0.5 * (lyap + lyap.T) + 2 * design.alpha * design.P)[-1] < 0
    assert np.linalg.eigvalsh(design.P)[0] > 0
    assert np.max(np.linalg.eigvals(A_L).real) < 0
    assert np.linalg.norm(design.G.T @ design.P - (design.H - design.K @ design.C)) \
        <= 1e-7 * scale


FEASIBLE = [
    (ex.coulomb_oscillator(0.0), "extended", 20.0),
    (ex.coulomb_oscillator(0.1), "basic", None),
    (ex.diode_circuit(), "basic", 100.0),
    (ex.diode_circuit(), "extended", 100.0),
    (ex.relay_relative_degree_one("z"), "basic", None),
    (ex.relay_relative_degree_one("x1"), "extended", 100.0),
    (ex.rotor_standin("alpha"), "extended", 1000.0),
]


@pytest.mark.parametrize(("scenario", "variant", "kappa"), FEASIBLE,
                         ids=[f"{s.name}-{v}" for s, v, _ in FEASIBLE])
def test_check1_postconditions_at_half_alpha_max(scenario, variant, kappa):
    best = max_observer_decay_rate(**scenario.matrices, variant=variant, kappa=kappa, tol=1e-2)
    assert best.alpha_max > 0
    design = lure_observer_lmi(**scenario.matrices, variant=variant, kappa=kappa,
                               alpha=0.5 * best.alpha_max)
    _postconditions(design)
    if kappa is not None:
        assert np.linalg.norm(design.P @ design.L, 2) <= kappa * (1 + 1e-6)
    if variant == "basic":
        assert not np.any(design.K)


def test_check1_siconos_certificate_is_exact():
    s = ex.siconos_observer_lcs()
    d = observer_from_gains(**s.matrices, L=ex.SICONOS_L, P=np.eye(2), alpha=1.0)
    assert d.certificate.equality_residual == 0.0
    assert d.certificate.lmi_max_eig == pytest.approx(0.0, abs=1e-14)  # Q = 2I exactly
    with pytest.raises(InfeasibleDesignError):
        observer_from_gains(**s.matrices, L=ex.SICONOS_L, P=np.eye(2), alpha=1.01)


def test_check2_not_passifiable_structural_reason_without_solver(monkeypatch):
    s = ex.not_passifiable()
    import nscontrol.design.lure_observer as lo

    def no_solver(*a, **k):
        raise AssertionError("the structural check must not build or call the SDP")

    monkeypatch.setattr(lo, "_ObserverLMI", no_solver)
    for variant in ("basic", "extended"):
        reason = structural_infeasibility(s.A, s.G, s.H, s.C, variant=variant)
        assert reason is not None and "H G" in reason
        with pytest.raises(InfeasibleDesignError) as err:
            lure_observer_lmi(**s.matrices, variant=variant)
        assert err.value.status == "structural" and "passifiable" in str(err.value)


@pytest.mark.parametrize("variant", ["basic", "extended"])
def test_check2_solver_agrees_when_precheck_is_skipped(variant):
    s = ex.not_passifiable()
    with pytest.raises(InfeasibleDesignError) as err:
        lure_observer_lmi(**s.matrices, variant=variant, precheck=False)
    assert "infeasible" in err.value.status or "failed" in err.value.status


def test_check2_relative_degree_three_infeasible():
    s = ex.relay_relative_degree_three()
    assert "H G" in structural_infeasibility(s.A, s.G, s.H, s.C)
    with pytest.raises(InfeasibleDesignError):
        lure_observer_lmi(**s.matrices, precheck=False)


def test_check2_undamped_coulomb_basic_infeasible_extended_feasible():
    s = ex.coulomb_oscillator(0.0)
    reason = structural_infeasibility(s.A, s.G, s.H, s.C, variant="basic")
    assert reason is not None and "sym(H A G)" in reason
    with pytest.raises(InfeasibleDesignError):
        lure_observer_lmi(**s.matrices, variant="basic", precheck=False)
    assert structural_infeasibility(s.A, s.G, s.H, s.C, variant="extended") is None
    d = max_observer_decay_rate(**s.matrices, variant="extended", kappa=20.0)
    assert 2.2 < d.alpha_max < 2.8  # spec: about 2.5 with ||Y|| <= 20


def test_check3_rate_of_damped_coulomb_basic_is_c_over_m():
    d = max_observer_decay_rate(**ex.coulomb_oscillator(0.1).matrices, variant="basic")
    assert abs(d.alpha_max - 0.1) <= 0.02 * 0.1


@pytest.mark.parametrize("variant", ["basic", "extended"])
def test_check3_relay_zero_limits_rate_to_two(variant):
    d = max_observer_decay_rate(**ex.relay_relative_degree_one("z").matrices, variant=variant)
    assert abs(d.alpha_max - 2.0) <= 0.02 * 2.0


def test_extended_rate_grows_with_kappa():
    s = ex.coulomb_oscillator(0.0)
    rates = [max_observer_decay_rate(**s.matrices, kappa=k, tol=1e-2).alpha_max
             for k in (5.0, 20.0)]
    assert rates[0] < rates[1]


# -- bad input --------------------------------------------------------------------------------
def test_bad_shapes_name_the_argument():
    s = ex.coulomb_oscillator(0.1)
    with pytest.raises(DimensionError, match="H"):
        lure_observer_lmi(s.A, s.G, np.ones((1, 3)), s.C)
    with pytest.raises(DimensionError, match="G"):
        lure_observer_lmi(s.A, np.ones((3, 1)), s.H, s.C)
    with pytest.raises(DimensionError, match="C"):
        lure_observer_lmi(s.A, s.G, s.H, np.ones(2))


def test_feedthrough_not_psd_is_refused():
    s = ex.siconos_observer_lcs()
    with pytest.raises(ModelError, match="D \\+ D\\^T"):
        lure_observer_lmi(s.A, s.G, s.H, s.C, D=[[-0.5]])


@pytest.mark.parametrize("kappa", [-1.0, 0.0, float("nan")])
def test_bad_kappa_is_refused(kappa):
    with pytest.raises(ModelError, match="kappa"):
        max_observer_decay_rate(**ex.coulomb_oscillator(0.0).matrices, kappa=kappa)


def test_bad_variant_and_alpha():
    m = ex.coulomb_oscillator(0.1).matrices
    with pytest.raises(ModelError, match="variant"):
        lure_observer_lmi(**m, variant="full")
    with pytest.raises(ModelError, match="alpha"):
        lure_observer_lmi(**m, alpha=-1.0)


def test_infeasible_rate_says_what_to_do():
    with pytest.raises(InfeasibleDesignError, match="lower alpha"):
        lure_observer_lmi(**ex.coulomb_oscillator(0.1).matrices, variant="basic", alpha=0.2)


def test_recheck_detects_a_wrong_certificate():
    s = ex.siconos_observer_lcs()
    cert = recheck_lure_certificate(s.A, s.G, s.H, s.C, 2 * np.eye(2), ex.SICONOS_L,
                                    np.zeros((1, 1)), 1.0)
    assert cert.equality_residual == pytest.approx(np.sqrt(2))


def test_design_options_are_validated():
    from nscontrol.design.lure_observer import design_lure_observer

    plant = ex.coulomb_oscillator(0.1).plant()
    with pytest.raises(ModelError, match="alpha"):
        design_lure_observer(plant, alpha="fastest")
    with pytest.raises(ModelError, match="alpha_fraction"):
        design_lure_observer(plant, alpha_fraction=1.5)
    with pytest.raises(ModelError, match="LureSystem"):
        design_lure_observer(np.eye(2))


def test_structural_check_is_not_fooled_by_rank_deficient_G():
    # two identical multiplier channels: G has rank 1, H G = [[1, 1], [1, 1]] is only PSD;
    # nothing certain can be said, so the pre-check must stay silent
    A = [[0.0, 1.0], [-1.0, -1.0]]
    G = [[0.0, 0.0], [1.0, 1.0]]
    H = [[0.0, 1.0], [0.0, 1.0]]
    assert structural_infeasibility(A, G, H, [[1.0, 0.0]], variant="basic") is None


def test_unbounded_rate_without_kappa_warns_and_names_the_fix():
    from nscontrol.errors import InaccurateCertificateWarning

    with pytest.warns(InaccurateCertificateWarning, match="pass kappa"):
        d = max_observer_decay_rate(**ex.coulomb_oscillator(0.0).matrices, tol=1e-2)
    assert d.alpha_max >= 1e3 and d.certificate.gain_norm > 1e6  # huge gains: why kappa exists


# -- solver names and the Clarabel -> SCS fallback -------------------------------------------
def test_misspelt_solver_is_bad_input_not_an_infeasible_design():
    from nscontrol.design.lure_observer import design_lure_observer

    s = ex.coulomb_oscillator(0.1)
    calls = (lambda: lure_observer_lmi(**s.matrices, variant="basic", solver="BOGUS"),
             lambda: max_observer_decay_rate(**s.matrices, variant="basic", solver="BOGUS"),
             lambda: design_lure_observer(s.plant(), variant="basic", solver="BOGUS"),
             # found before the structural pre-check would report infeasibility
             lambda: lure_observer_lmi(**ex.not_passifiable().matrices, solver="BOGUS"))
    for call in calls:
        with pytest.raises(ModelError, match="solver: expected one of 'auto', 'CLARABEL', "
                                             "'SCS'.*got 'BOGUS'"):
            call()
    # a known SDP solver that is not installed is named as such
    import cvxpy as cp

    missing = [n for n in ("MOSEK", "COPT", "SDPA", "CVXOPT") if n not in cp.installed_solvers()]
    if missing:
        with pytest.raises(ModelError, match=f"solver: '{missing[0]}' .*not installed"):
            lure_observer_lmi(**s.matrices, variant="basic", solver=missing[0])
    # names are case-insensitive, "auto" is the default order
    d = lure_observer_lmi(**s.matrices, variant="basic", alpha=0.05, solver="scs")
    assert d.certificate.solver == "SCS"
    _postconditions(d)
    assert lure_observer_lmi(**s.matrices, variant="basic", alpha=0.05,
                             solver="auto").certificate.solver == "CLARABEL"


def test_clarabel_failure_falls_back_to_scs(clarabel_fails):
    attempts = clarabel_fails
    s = ex.coulomb_oscillator(0.1)
    d = lure_observer_lmi(**s.matrices, variant="basic", alpha=0.05)
    assert attempts == ["CLARABEL", "SCS"]
    assert d.certificate.solver == "SCS" and d.certificate.solver_status == "optimal"
    _postconditions(d)
    # asking for Clarabel alone: no fallback, and the solver error is the reported status
    with pytest.raises(InfeasibleDesignError, match="solver_error.*Clarabel made to fail"):
        lure_observer_lmi(**s.matrices, variant="basic", alpha=0.05, solver="CLARABEL")


# -- observer_from_gains: only strict certificates ---------------------------------------------
def test_observer_from_gains_refuses_a_non_converging_observer():
    # A = 0, L = 0: A - L C = 0 is not Hurwitz; P = I satisfies G^T P = H and the Lyapunov
    # matrix is 0 <= 0, but with alpha = 0 that only says V does not grow
    A, G, H, C = np.zeros((2, 2)), [[0.0], [1.0]], [[0.0, 1.0]], np.eye(2)
    with pytest.raises(InfeasibleDesignError) as err:
        observer_from_gains(A, G, H, C, L=np.zeros((2, 2)), P=np.eye(2), alpha=0.0)
    msg = str(err.value)
    assert err.value.status == "recheck_failed"
    assert "must be strict" in msg and "not Hurwitz" in msg
    # with alpha > 0 the same gains break the Lyapunov inequality outright
    with pytest.raises(InfeasibleDesignError, match="not negative semidefinite"):
        observer_from_gains(A, G, H, C, L=np.zeros((2, 2)), P=np.eye(2), alpha=0.1)
    # a strict certificate at alpha = 0 is accepted (Siconos example: A_L'P + PA_L = -2I)
    s = ex.siconos_observer_lcs()
    d = observer_from_gains(**s.matrices, L=ex.SICONOS_L, P=np.eye(2), alpha=0.0)
    assert d.certificate.lmi_max_eig == pytest.approx(-2.0, abs=1e-14)
    # P not positive definite and a broken equality are both listed
    with pytest.raises(InfeasibleDesignError) as err:
        observer_from_gains(**s.matrices, L=ex.SICONOS_L, P=-np.eye(2), alpha=1.0)
    assert "G^T P = H - K C fails" in str(err.value) and "positive definite" in str(err.value)


# -- the default rate rule: the largest certified rate whose gain stays moderate -------------
def _coulomb_oscillator():
    from nscontrol.laws.set_valued import Relay
    from nscontrol.systems.lure import LureSystem

    return LureSystem([[0, 1], [-1, -0.1]], [[0], [1]], [[0, 1]], Relay(1.0), C=[[1, 0]])


def test_default_extended_design_keeps_the_gain_within_the_rule():
    from nscontrol.design.lure_observer import GAIN_MULTIPLE

    plant = _coulomb_oscillator()
    d = design_lure_observer(plant, tol=1e-2)
    rule = GAIN_MULTIPLE * max(1.0, np.linalg.norm(plant.A, 2))
    assert d.gain_limit == pytest.approx(rule, rel=1e-12)
    # the rate search kept ||L|| within the bound at alpha_max; the design at half of it has
    # a smaller gain still, and a certified positive rate
    assert 0.0 < d.alpha == pytest.approx(d.alpha_max / 2, rel=1e-12)
    assert np.linalg.norm(d.L, 2) <= rule
    assert "|L|=" in repr(d) and "limit" in repr(d)
    # without the bound the rate runs to the cap (the gains of the 1.3e7)
    with pytest.warns(Warning, match="unbounded"):
        free = max_observer_decay_rate(plant.A, plant.G, plant.H, plant.C, tol=1e-1)
    assert free.alpha_max > 100 * d.alpha_max


def test_default_design_error_stays_within_its_certificate():
    # the theorem's bound |e(t)| <= sqrt(cond P) e^{-alpha t} |e(0)| measured on a run: the
    # default gains (cond P ~ 14) give no large transient (the unbounded design peaked at 700
    # for an initial error of 1)
    from nscontrol.simulate import simulate

    plant = _coulomb_oscillator()
    d = design_lure_observer(plant, tol=1e-2)
    h = 1e-3
    traj = simulate(d.closed_loop(plant), [1.0, 0.0, 0.0, 0.0], (0.0, 5.0), h=h,
                    progress=False)
    e = np.linalg.norm(traj.signal("e"), axis=1)
    # implicit Euler's discrete bound is V_k <= V_0/(1 + 2 alpha h)^k: compare with it
    bound = np.sqrt(d.certificate.P_cond) * e[0] * (1 + 2 * d.alpha * h) ** (
        -0.5 * np.arange(e.size))
    assert np.all(e <= bound * (1 + 1e-9) + 1e-12)
    assert e.max() <= np.sqrt(d.certificate.P_cond) * e[0] * (1 + 1e-9)


def test_a_given_rate_above_the_rule_warns_and_bad_bounds_are_refused():
    plant = _coulomb_oscillator()
    with pytest.warns(Warning, match="L: "):
        design_lure_observer(plant, alpha=20.0)
    with pytest.raises(ModelError, match="max_gain"):
        design_lure_observer(plant, max_gain="large")
    with pytest.raises(ModelError, match="max_gain"):
        design_lure_observer(plant, max_gain=-1.0)
