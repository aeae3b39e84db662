"""Orbits, cycles, continuation, bifurcation diagrams and their command: bad input is refused
before anything runs, naming the argument and the valid choices; every iterative loop has a
budget option whose exhaustion raises :class:`BudgetExceededError` with the partial result
(or, where the contract is a result with a reason, names the budget in it).

Tolerances: the closed-form orbits of the impact oscillator are met by shooting to its
residual tolerance (``tol = 1e-11`` relative) times the condition of ``I - M`` (below 10 for
these stable or mildly unstable orbits): ``1e-9`` leaves a factor 10 of margin.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from nscontrol.analysis.bifurcation import bifurcation_diagram
from nscontrol.analysis.continuation import Branch, continue_orbit
from nscontrol.analysis.equilibria import continue_equilibrium
from nscontrol.analysis.impact_oscillator import ImpactOscillator, OscillatorFamily
from nscontrol.analysis.orbits import (
    Autonomous,
    Forced,
    find_cycle,
    find_orbit,
    hyperplane_map,
)
from nscontrol.analysis.periodic import period_multiplicity, periodic_steady_state
from nscontrol.cli import main
from nscontrol.errors import (
    BudgetExceededError,
    DimensionError,
    InadmissibleStateError,
    ModelError,
    SolverError,
)
from nscontrol.testing.cycle_problems import hopf_normal_form

BASE = ImpactOscillator(omega=2.5, stop=0.1)
FAM = OscillatorFamily(BASE, "forcing")
FG = BASE.grazing_forcing()
SHOOTING = 1e-9          # see the module docstring


def _impacting(F):
    return BASE.with_(forcing=F).admissible_orbit().x0


# -- silent: refused now, before anything is computed ------------------------------------

def test_a_cycle_is_not_found_at_an_equilibrium():
    system, _ = hopf_normal_form(0.25, 2.0)             # equilibrium at 0, cycle r = 1/2
    with pytest.raises(SolverError, match=r"x0: Newton iterate 0 is an equilibrium"):
        find_cycle(system, [0.0, 0.0], np.pi, normal=[0.0, 1.0])
    cyc = find_cycle(system, [0.5, 0.0], np.pi, normal=[0.0, 1.0])      # the cycle itself
    assert cyc.period == pytest.approx(np.pi, rel=1e-9)


CONT = dict(step=0.05, step_max=0.2, max_steps=2)


@pytest.mark.parametrize("cont", [continue_orbit, continue_equilibrium],
                         ids=["orbits", "equilibria"])
@pytest.mark.parametrize("bad, match", [
    (dict(p_range=(2.0, 1.0)), r"p_range: expected finite lo < hi, got \(2.0, 1.0\); "
                               r"write \(1, 2\)"),
    (dict(p_range="02"), r"p_range: expected a pair of numbers"),
    (dict(p_range=(1.0, 2.0)), r"p0: expected a value in p_range \[1, 2\], got 0.5"),
    (dict(step_min=0.5), r"step_min: expected step_min <= step_max, got step_min = 0.5 > "
                         r"step_max = 0.2"),
    (dict(detect=("flp",)), r"detect: unknown name\(s\) 'flp'; valid names: 'fold', "),
    (dict(detect="fold"), r"detect: expected a collection of names, got the string 'fold'"),
    (dict(stop_at=("grazin",)), r"stop_at: unknown name\(s\) 'grazin'; valid names: "),
    (dict(corrector_max_iter=0), r"corrector_max_iter: expected an integer >= 1"),
    (dict(locate_max_iter=2.5), r"locate_max_iter: expected an integer >= 1"),
])
def test_continuation_options_are_refused_before_anything_runs(cont, bad, match):
    calls = []

    def factory(p):
        calls.append(p)
        return FAM(p) if cont is continue_orbit else (lambda x: p - x**2)

    kw = {"p_range": (0.0, 3.0), **CONT, **bad}
    with pytest.raises(ModelError, match=match):
        cont(factory, 0.5, [0.0] * (2 if cont is continue_orbit else 1), **kw)
    assert calls == []                                  # refused before the first model


def test_the_valid_kinds_are_listed():
    with pytest.raises(ModelError) as err:
        continue_orbit(FAM, 0.5, [0.0, 0.0], p_range=(0.0, 3.0), stop_at=("slidng",))
    for kind in ("fold", "flip", "neimark_sacker", "grazing", "sliding"):
        assert repr(kind) in str(err.value)


@pytest.mark.parametrize("rtol", [-1e-6, 0.0, 1.0, np.nan, "1e-6"])
def test_bifurcation_diagram_refuses_a_bad_rtol(rtol):
    with pytest.raises(ModelError, match=r"^rtol: expected a"):
        bifurcation_diagram(FAM, [0.3], rtol=rtol, n_transient=2, n_sample=2, progress=False)
    with pytest.raises(ModelError, match=r"^rtol: expected a"):
        period_multiplicity(np.zeros((4, 2)), rtol=rtol)


# -- raw crashes: a named ModelError or a usage error --------------------------------------

@pytest.mark.parametrize("normal", [[0.0, 0.0], [0, 0]])
def test_a_zero_normal_is_refused(normal):
    system, _ = hopf_normal_form(0.25, 2.0)
    with pytest.raises(ModelError, match=r"^normal: expected a nonzero normal"):
        find_cycle(system, [0.5, 0.0], np.pi, normal=normal)
    with pytest.raises(ModelError, match=r"^normal: expected a nonzero normal"):
        Autonomous(system, np.pi, normal=normal)
    with pytest.raises(ModelError, match=r"^normal: expected a nonzero normal"):
        hyperplane_map(system, [0.5, 0.0], normal=normal, offset=0.0, t_max=4.0)


def _bifurcation(*args):
    return CliRunner().invoke(main, ["bifurcation", "impact-oscillator-bifurcation", *args])


def test_cli_names_the_valid_parameters(tmp_path):
    res = _bifurcation("--param", "nosuch=1:2:2", "--out", str(tmp_path))
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)   # no traceback
    assert "--param: 'nosuch' is no parameter" in res.output
    for name in ("forcing", "omega", "stop", "restitution"):
        assert repr(name) in res.output
    assert not list(tmp_path.iterdir())


def test_cli_names_the_valid_schedulers(tmp_path):
    res = _bifurcation("--param", "forcing=1:2:2", "--scheduler", "seriall",
                       "--out", str(tmp_path))
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    assert "--scheduler: 'seriall' is neither 'serial', 'auto' nor a Dask scheduler" \
        in res.output and "did you mean 'serial'?" in res.output
    assert not list(tmp_path.iterdir())


def test_wrong_object_types_are_named():
    with pytest.raises(ModelError, match=r"^forced: expected a Forced"):
        find_orbit(BASE, [0.0, 0.0])                    # the model, not its Forced
    with pytest.raises(ModelError, match=r"^factory: expected a Forced .* got ImpactOscillator"):
        continue_orbit(lambda p: BASE.with_(forcing=p), 0.5, [0.0, 0.0], p_range=(0.0, 1.0))
    with pytest.raises(ModelError, match=r"^factory: expected a callable"):
        continue_orbit(FAM(0.5), 0.5, [0.0, 0.0], p_range=(0.0, 1.0))
    with pytest.raises(ModelError, match=r"^system: expected a model with n_states"):
        find_cycle("hopf", [0.5, 0.0], np.pi, normal=[0.0, 1.0])
    with pytest.raises(ModelError, match=r"^system: expected a model with n_states"):
        Forced(BASE, None, 1.0)                  # the closed form, not a simulable model
    with pytest.raises(ModelError, match=r"^x0: expected a real numeric array, got strings"):
        continue_orbit(FAM, 0.5, [["0", "0"]], p_range=(0.0, 1.0))
    with pytest.raises(ModelError, match=r"^x0: expected a real numeric array, got strings"):
        find_orbit(FAM(0.5), [["0", "0"]])


def test_switch_at_flip_and_bifurcation_diagram_name_wrong_objects():
    from nscontrol.analysis.continuation import SpecialPoint, switch_at_flip

    with pytest.raises(ModelError, match=r"^branch: expected the Branch"):
        switch_at_flip(FAM, "branch", p_range=(1.0, 3.0))
    b = continue_orbit(FAM, 2.0, _impacting(2.0), p_range=(1.5, 3.0), max_steps=1)
    fold = SpecialPoint("fold", 2.0, 0, b.nodes[0], b.multipliers[0], 0.0)
    with pytest.raises(ModelError, match=r"^point: expected a flip of the branch .* got a "
                                         r"'fold' point"):
        switch_at_flip(FAM, b, fold, p_range=(1.0, 3.0))
    with pytest.raises(ModelError, match=r"^factory: expected a callable"):
        bifurcation_diagram(FAM(0.5), [0.3], progress=False)
    with pytest.raises(DimensionError, match=r"^x0: expected a vector of length 2"):
        bifurcation_diagram(FAM, [0.3], x0=[0.0, 0.0, 0.0], progress=False)


# -- vague: the message says what happened where --------------------------------------------

def test_an_inadmissible_newton_iterate_is_named_with_its_start():
    # from x0 = (0.05, 1.0) the first Newton step, and every damped one, leaves the
    # admissible set q <= 0.1: the message names the iterate and the user's x0, which is
    # admissible (before, it blamed x0 with the iterate's gap -18.6)
    with pytest.raises(InadmissibleStateError) as err:
        find_orbit(FAM(0.5), [0.05, 1.0])
    msg = str(err.value)
    assert msg.startswith("x0: Newton iterate 1 of the shooting from x0 = [0.05 1.  ] left the "
                          "admissible set")
    assert "start closer to the orbit" in msg and "contact 0 is penetrated" in msg


def test_a_penetrating_trial_step_is_damped_not_fatal():
    # from x0 = (0.09, 0) the full Newton step penetrates the stop; halving it stays
    # admissible and reaches the non-impacting orbit (F = 0.5 < F_g) in closed form
    orbit = find_orbit(FAM(0.5), [0.09, 0.0])
    assert np.allclose(orbit.x0, BASE.with_(forcing=0.5).non_impacting_state(0.0),
                       atol=SHOOTING)


def test_a_penetrating_predictor_halves_the_continuation_step():
    # near resonance (ω = 0.9) the non-impacting orbit's nodes move fast with F: a long
    # first step predicts nodes beyond the stop. That is a failed correction (the step is
    # halved), not the user's x0 being inadmissible; both step sizes end at the closed-form
    # grazing (location tolerance as in tests/analysis/test_continuation.py)
    osc = ImpactOscillator(omega=0.9, stop=0.1)
    fam, fg = OscillatorFamily(osc, "forcing"), osc.grazing_forcing()
    for step in (0.05, 0.3):
        b = continue_orbit(fam, 0.5 * fg, [0.0, 0.0], p_range=(0.0, 4 * fg), step=step,
                           step_max=1.0, max_steps=40)
        (g,) = b.points
        assert g.kind == "grazing" and g.parameter == pytest.approx(fg, rel=1e-9)
    with pytest.raises(InadmissibleStateError, match=r"^x0: contact 0 is penetrated"):
        continue_orbit(fam, 0.5 * fg, [0.2, 0.0], p_range=(0.0, 4 * fg))   # the user's x0


@pytest.mark.parametrize("tol", [-1e-11, 0.0, np.nan, "1e-11"])
def test_a_bad_tolerance_is_refused_upfront(tol):
    with pytest.raises(ModelError, match=r"^tol: expected a (finite number > 0|real number)"):
        find_orbit(FAM(0.5), [0.0, 0.0], tol=tol)
    system, _ = hopf_normal_form(0.25, 2.0)
    with pytest.raises(ModelError, match=r"^tol: expected a (finite number > 0|real number)"):
        find_cycle(system, [0.5, 0.0], np.pi, normal=[0.0, 1.0], tol=tol)


# -- budgets ---------------------------------------------------------------------------------

def test_find_orbit_budget_keeps_the_last_iterate():
    forced, start = FAM(1.0), [-0.5, 0.0]
    with pytest.raises(BudgetExceededError, match=r"^max_iter: shooting did not converge in "
                                                  r"2 Newton iterations") as err:
        find_orbit(forced, start, max_iter=2)
    e = err.value
    assert (e.budget, e.limit, e.used, e.status) == ("max_iter", 2, 2, "budget")
    assert e.partial.shape == (1, 2)
    # the partial iterate is where Newton was: resuming from it reaches the orbit that a run
    # from scratch reaches, two iterations fewer (Newton is deterministic)
    full = find_orbit(forced, start)
    resumed = find_orbit(forced, e.partial)
    assert resumed.iterations == full.iterations - 2
    assert np.allclose(resumed.x0, _impacting(1.0), atol=SHOOTING)
    assert np.allclose(full.x0, _impacting(1.0), atol=SHOOTING)


def test_find_cycle_budget_keeps_the_last_iterate():
    system, _ = hopf_normal_form(0.25, 2.0)
    with pytest.raises(BudgetExceededError, match=r"^max_iter: cycle shooting") as err:
        find_cycle(system, [0.6, 0.0], 1.1 * np.pi, normal=[0.0, 1.0], max_iter=1)
    e = err.value
    assert e.budget == "max_iter" and e.limit == 1 and e.partial.shape == (3,)
    # the partial (x0, T) is Newton's iterate: resuming from it takes one iteration fewer
    # than a run from scratch, and both end on the cycle r = 1/2, T = π (Newton's tolerance
    # 1e-9 times the bordered Jacobian's condition, ~10)
    full = find_cycle(system, [0.6, 0.0], 1.1 * np.pi, normal=[0.0, 1.0])
    resumed = find_cycle(system, e.partial[:2], e.partial[2], normal=[0.0, 1.0])
    assert resumed.iterations == full.iterations - 1
    for cyc in (full, resumed):
        assert np.allclose(cyc.x0, [0.5, 0.0], atol=1e-8)
        assert cyc.period == pytest.approx(np.pi, rel=1e-8)


def test_hyperplane_map_budget():
    system, _ = hopf_normal_form(0.25, 2.0)
    sec = dict(normal=[0.0, 1.0], offset=0.0, t_max=4.0)
    with pytest.raises(BudgetExceededError, match=r"^max_iter: the crossing time") as err:
        hyperplane_map(system, [0.6, 0.0], max_iter=1, samples=8, **sec)
    assert err.value.budget == "max_iter" and 0.0 < err.value.partial < 4.0
    # with the default budget the return time is the period π (θ' = 2)
    assert hyperplane_map(system, [0.6, 0.0], samples=8, **sec).time == \
        pytest.approx(np.pi, rel=1e-9)


def test_continuation_corrector_budget_at_the_start():
    with pytest.raises(BudgetExceededError, match=r"^corrector_max_iter: the corrector did not "
                                                  r"converge in 1 iterations") as err:
        continue_orbit(FAM, 2.0, [-0.5, 0.0], p_range=(1.5, 3.0), corrector_max_iter=1)
    e = err.value
    assert e.budget == "corrector_max_iter" and e.limit == 1
    assert e.partial.shape == (3,) and e.partial[-1] == 2.0      # (nodes, p), p pinned


def test_continuation_step_halving_stops_at_step_min_and_names_the_budgets():
    b = continue_orbit(FAM, 2.0, _impacting(2.0), p_range=(1.5, 3.0), step=0.2, step_min=0.1,
                       step_max=0.2, corrector_max_iter=1, parameter_name="F")
    assert isinstance(b, Branch) and len(b) == 1
    assert b.stop_reason.startswith("step_min: the corrector failed at p ≈ 2 with every step "
                                    "down to 0.1 < 2·step_min = 0.2: corrector_max_iter: ")


def test_continuation_max_steps_is_named_in_the_stop_reason():
    b = continue_orbit(FAM, 2.0, _impacting(2.0), p_range=(1.5, 3.0), step=0.05, max_steps=2)
    assert b.stop_reason.startswith("max_steps (2) reached at p = ")
    assert b.stop_reason.endswith("raise max_steps to go on") and b.n_steps == 2


def test_continuation_locate_budget_keeps_the_branch_so_far():
    F_flip = BASE.flip_forcing((1.1 * FG, 4 * FG))
    with pytest.raises(BudgetExceededError, match=r"^locate_max_iter: the zero was not located "
                                                  r"in 1 corrected trial") as err:
        continue_orbit(FAM, 1.5, _impacting(1.5), p_range=(0.0, 3.0), step=0.05, step_max=0.2,
                       direction=-1, locate_max_iter=1, parameter_name="F")
    e = err.value
    b = e.partial
    assert e.budget == "locate_max_iter" and isinstance(b, Branch)
    assert len(b) >= 2 and np.all(b.p > F_flip) and b.stop_reason.startswith("locate_max_iter")
    # every point of the partial branch is the closed-form orbit
    for p, x in zip(b.p, b.x0, strict=True):
        assert np.allclose(x, _impacting(p), atol=SHOOTING)


def test_equilibrium_continuation_locate_budget():
    with pytest.raises(BudgetExceededError, match=r"^locate_max_iter") as err:
        continue_equilibrium(lambda p: (lambda x: p - x**2), 1.0, [1.0], p_range=(-1.0, 2.0),
                             direction=-1, step=0.1, max_steps=60, locate_max_iter=1)
    b = err.value.partial
    assert isinstance(b, Branch) and np.allclose(b.x0[:, 0], np.sqrt(b.p), atol=1e-10)


def test_periodic_steady_state_budget():
    from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    from nscontrol.numerics.lti import Exosystem

    with pytest.raises(BudgetExceededError, match=r"^max_iter: no T-periodic solution") as err:
        periodic_steady_state(one_sided_oscillator(0.1), 2 * np.pi / 2.9,
                              u=Exosystem.sinusoid(1.0, 2.9), max_iter=1, fallback=False)
    assert err.value.budget == "max_iter" and err.value.partial.shape == (2,)
    with pytest.raises(ModelError, match=r"^max_periods: expected an integer >= 1"):
        periodic_steady_state(one_sided_oscillator(0.1), 1.0, max_periods=0)
