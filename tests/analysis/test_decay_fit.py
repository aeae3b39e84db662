"""Class 6: decay-rate fits leave out the error's numerical floor.

The measured error ``E x`` of a closed-loop run bottoms out near its roundoff level
``u ||E|| ||x||``; the fit must stop there. Every rate is compared with the *exact* one: the
error propagated alone (``dz`` with a zero plant part, normalised at every impact so it never
underflows) through the run's own impacts with ``expm`` and the jump matrices, fitted over the
same impacts.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy.linalg import expm

from nscontrol.analysis.observability import ROUNDOFF_MARGIN, impact_decay_rate
from nscontrol.errors import ModelError

U = np.finfo(float).eps
#: The measured norm's rounding, relative to u ||E|| ||x||: the propagation accumulates it
#: over the steps between impacts; <= 25 on chapter 2's runs (stated factor, with margin 2).
C_ROUND = 50.0


def chapter2_run(m3: float, k33: float, eps: float):
    """The chapter-2 observer run (exact event-driven) on a plant with these m3, k33."""
    from nscontrol.examples import ch02_impact_observer as ch
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    bodies = ImpactingBodies.from_springs([1.0, 1.0], [m3], {(0, 0): 4.0, (0, 1): 6.0},
                                          {(0, 0): k33}, restitution=1.0)
    run = ch.run_observer(bodies, eps)
    u = ch.input_generator()
    xp0 = np.concatenate([ch.X0_PLANT, u.w0])
    # the error alone: the same run minus one whose observer starts at the true state
    dz0 = run.design.initial_state(xp0, np.zeros(6)) - \
        run.design.initial_state(xp0, np.array(ch.X0_PLANT))
    return run, dz0


def exact_log_norms(run, dz0) -> np.ndarray:
    loop, E = run.loop, run.loop.outputs["error"]
    dz, t_prev, log_scale, out = dz0.copy(), 0.0, 0.0, []
    for ev in run.trajectory.events_of("jump"):
        dz = expm(loop.A * (ev.time - t_prev)) @ dz
        s = np.linalg.norm(dz)
        log_scale, dz = log_scale + np.log(s), dz / s
        out.append(log_scale + np.log(np.linalg.norm(E @ dz)))
        dz, t_prev = loop.jump_matrices[ev.index] @ dz, ev.time
    return np.array(out)


def slope_error_bound(fit) -> float:
    """|fitted - exact| <= sum_i |w_i| delta_i: the least-squares slope is sum_i w_i ln n_i with
    w_i = (t_i - mean t) / sum (t_j - mean t)^2, and each ln n_i is off by at most
    delta_i = C_ROUND u ||E|| ||x_i|| / n_i (measured rounding) + 100 u (expm and 10 jumps of
    norm <= 4 in the exact propagation)."""
    t = fit.times
    w = (t - t.mean()) / np.sum((t - t.mean()) ** 2)
    delta = C_ROUND * fit.roundoff[: t.size] / fit.norms + 100 * U
    return float(np.sum(np.abs(w) * delta))


CASES = {   # (m3, k33, eps): floor reached early, reached late, never; the main example's plant
    "floor_after_3_impacts": (1.0, 0.08, 0.025),
    "floor_after_1_impact": (1.0, 0.08, 0.0125),
    "no_floor_slow_decay": (0.7, 0.08, 0.025),
    "main_plant_eps_0.25": (1.0, 4.0, 0.25),
}


@functools.cache
def computed(name: str):
    run, dz0 = chapter2_run(*CASES[name])
    return name, run, exact_log_norms(run, dz0)


@pytest.fixture(params=list(CASES))
def case(request):
    return computed(request.param)


def test_fit_matches_exact_rate_or_refuses(case):
    name, run, exact = case
    E = run.loop.outputs["error"]
    t = run.trajectory.event_times("jump")
    try:
        fit = impact_decay_rate(run.trajectory, E)
    except ModelError as err:
        assert name == "floor_after_1_impact", err
        msg = str(err)
        assert msg.startswith("trajectory:") and "through_floor=True" in msg
        lower = impact_decay_rate(run.trajectory, E, through_floor=True)
        # the first norm under the floor is the floor, above the true error: a lower bound
        k = lower.n_points
        exact_rate = -np.polyfit(t[:k], exact[:k], 1)[0]
        assert lower.rate <= exact_rate
        return
    k = fit.n_points
    assert k == fit.times.size >= 2 and fit.n_points + fit.n_floor == t.size
    exact_rate = -np.polyfit(t[:k], exact[:k], 1)[0]
    assert abs(fit.rate - exact_rate) <= slope_error_bound(fit), (fit.rate, exact_rate)
    # every point used lies above the margin; every point left out under floor or margin
    assert np.all(fit.norms > ROUNDOFF_MARGIN * fit.roundoff[:k])


def test_floor_is_detected_where_a_fixed_threshold_is_not():
    """The fit through every norm above the fixed 1e-10 floor (the old behaviour) is far from
    the exact rate when the roundoff floor is higher; the new fit leaves those out."""
    _, run, exact = computed("floor_after_1_impact")
    E = run.loop.outputs["error"]
    old = impact_decay_rate(run.trajectory, E, roundoff_margin=0.0)
    t = run.trajectory.event_times("jump")
    exact_rate = -np.polyfit(t[: old.n_points], exact[: old.n_points], 1)[0]
    assert old.n_points == t.size and old.rate < exact_rate / 10   # 0.34 vs 12.9
    with pytest.raises(ModelError):
        impact_decay_rate(run.trajectory, E)


@pytest.mark.parametrize(("kwargs", "name"), [({"floor": "1e-10"}, "floor"),
                                              ({"roundoff_margin": -1.0}, "roundoff_margin"),
                                              ({"skip": 1.5}, "skip")])
def test_fit_arguments_validated(case, kwargs, name):
    _, run, _ = case
    with pytest.raises(ModelError, match=f"^{name}:"):
        impact_decay_rate(run.trajectory, run.loop.outputs["error"], **kwargs)
