"""Class 6: decay-rate fits leave out the error's numerical floor; the rate over a whole run
comes from the error propagated alone along its impacts.

The measured error ``E x`` of a closed-loop run bottoms out near its rounding level
``u ||E|| ||x||``; the fit must stop there, wherever that floor lies on this machine. Every
figure is compared with an independent reference written here from the chapter's equations,
in the original coordinates: the error flow ``x~_a' = (A_a - G_eps C_a) x~_a`` through its
eigendecomposition, the free mass's ``x~_b`` in closed form (cos, sin), and the observer's
jump rules at the run's impacts (``q~_1 -> 0``, ``q~_n -> q~_{n-1}``, velocities times ``M``),
rescaled after every interval so that it never underflows. The library works on the stacked
closed loop (scaled observer coordinates, ``expm``, the loop's jump matrices) instead.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from nscontrol.analysis.observability import (
    MAX_RELATIVE_ROUNDING,
    ROUNDING_PER_STATE,
    impact_decay_rate,
    impact_error_contraction,
)
from nscontrol.errors import DimensionError, ModelError

U = np.finfo(float).eps


def chapter2_run(m3: float, k33: float, eps: float):
    """The chapter-2 observer run (exact event-driven) on a plant with these m3, k33, and the
    error as a closed-loop state."""
    from nscontrol.examples import ch02_impact_observer as ch
    from nscontrol.systems.impacting_bodies import ImpactingBodies

    bodies = ImpactingBodies.from_springs([1.0, 1.0], [m3], {(0, 0): 4.0, (0, 1): 6.0},
                                          {(0, 0): k33}, restitution=1.0)
    run = ch.run_observer(bodies, eps)
    xp0 = np.concatenate([ch.X0_PLANT, ch.input_generator().w0])
    return run, run.design.error_state(xp0, np.zeros(6))


def reference_log_norms(run, x_err0) -> tuple[np.ndarray, float]:
    """``ln ||x~(t_i-)||`` at the run's impacts from the chapter's equations, and a bound on
    its error: each interval's ``V diag(e^{lambda dt}) V^-1 x`` is relative to the rescaled
    error accurate to ``cond(V) u`` times the length 4 of the products (factor 10 for both
    products and the norm), and the intervals add up."""
    d = run.design
    p = d.plant
    na = p.n_a
    lam, V = np.linalg.eig(p.A_a - np.outer(d.G_eps, p.C_a))
    V_inv = np.linalg.inv(V)
    w = np.sqrt(-p.A_b[1, 0])                   # the free mass: q'' = -w^2 q

    def flow(x, dt):
        xa = (V @ (np.exp(lam * dt) * (V_inv @ x[:2 * na]))).real
        c, s = np.cos(w * dt), np.sin(w * dt)
        q, v = x[2 * na:]
        return np.concatenate([xa, [c * q + s / w * v, -w * s * q + c * v]])

    def jump(x):                                # (7c)-(7g) on the error, q_n = q_{n-1}
        out = x.copy()
        out[0] = 0.0                            # q^_1 <- y
        out[2 * na] = x[na - 1]                 # q^_n <- q^_{n-1}
        out[[2 * na - 1, 2 * na + 1]] = p.M @ x[[2 * na - 1, 2 * na + 1]]
        return out

    x, t_prev, log_scale, out = x_err0 / np.linalg.norm(x_err0), 0.0, 0.0, []
    log_scale = np.log(np.linalg.norm(x_err0))
    events = run.trajectory.events_of("jump")
    for ev in events:
        x = flow(x, ev.time - t_prev)
        s = np.linalg.norm(x)
        log_scale, x = log_scale + np.log(s), x / s
        out.append(log_scale)
        x, t_prev = jump(x), ev.time
    return np.array(out), 10 * 4 * np.linalg.cond(V) * U * len(events)


def ls_rate(t: np.ndarray, log_n: np.ndarray) -> float:
    return -float(np.polyfit(t, log_n, 1)[0])


CASES = {   # (m3, k33, eps): floor reached early, reached late, never; the main example's plant
    "floor_after_3_impacts": (1.0, 0.08, 0.025),
    "floor_after_1_impact": (1.0, 0.08, 0.0125),
    "no_floor_slow_decay": (0.7, 0.08, 0.025),
    "main_plant_eps_0.25": (1.0, 4.0, 0.25),
    "issue_plant_eps_0.05": (1.0, 3.0, 0.05),
}


@functools.cache
def computed(name: str):
    run, dz0 = chapter2_run(*CASES[name])
    ref, ref_error = reference_log_norms(run, run.loop.outputs["error"] @ dz0)
    return name, run, dz0, ref, ref_error


@pytest.fixture(params=list(CASES))
def case(request):
    return computed(request.param)


def measured_norms(run) -> tuple[np.ndarray, np.ndarray]:
    """The simulated ||x~(t_i-)|| and their rounding levels u ||E|| ||x(t_i-)||."""
    E = run.loop.outputs["error"]
    evs = run.trajectory.events_of("jump")
    norms = np.array([np.linalg.norm(E @ ev.pre) for ev in evs])
    level = U * np.linalg.norm(E, 2) * np.array([np.linalg.norm(ev.pre) for ev in evs])
    return norms, level


def test_rounding_estimate_bounds_every_measured_norm(case):
    """The estimate the floor rests on: |simulated - exact| <= ROUNDING_PER_STATE n u ||E|| ||x||
    at every impact, at the floor too (there the simulated norm is all rounding)."""
    _, run, _, ref, ref_error = case
    norms, level = measured_norms(run)
    kappa = ROUNDING_PER_STATE * run.loop.n_states
    exact = np.exp(ref)
    # the reference's own error (ref_error in the log) is added to the estimate
    assert np.all(np.abs(norms - exact) <= kappa * level + 2 * ref_error * exact)


def test_fit_matches_exact_rate_within_its_rounding_bound_or_refuses(case):
    name, run, _, ref, ref_error = case
    E = run.loop.outputs["error"]
    t = run.trajectory.event_times("jump")
    try:
        fit = impact_decay_rate(run.trajectory, E)
    except ModelError as err:
        assert name == "floor_after_1_impact", err
        msg = str(err)
        assert msg.startswith("trajectory:") and "through_floor=True" in msg
        assert "impact_error_contraction" in msg
        lower = impact_decay_rate(run.trajectory, E, through_floor=True)
        # the first norm under the floor is the floor, above the true error: a lower bound
        k = lower.n_points
        assert lower.rate <= ls_rate(t[:k], ref[:k]) and lower.rate_error == np.inf
        return
    k = fit.n_points
    assert k == fit.times.size >= 2 and fit.n_points + fit.n_floor == t.size
    # the same least-squares fit through the reference at the same impacts; the fit's
    # rate_error bounds the effect of the simulated norms' rounding, the reference's own
    # error moves the slope by at most sum |w_i| ref_error
    tt = t[:k] - t[:k].mean()
    ref_slope_error = ref_error * np.sum(np.abs(tt)) / np.sum(tt * tt)
    assert abs(fit.rate - ls_rate(t[:k], ref[:k])) <= fit.rate_error + ref_slope_error
    # every norm used lies within MAX_RELATIVE_ROUNDING of the exact error
    assert np.all(np.abs(fit.norms - np.exp(ref[:k])) <= MAX_RELATIVE_ROUNDING * fit.norms)


@pytest.mark.parametrize("name", ["floor_after_3_impacts", "floor_after_1_impact",
                                  "issue_plant_eps_0.05"])
def test_floor_is_detected_from_the_rounding_estimate(name):
    """Runs that reach their floor: the norms past it are rounding (the exact error is orders
    below them) and the fit uses none of them, whatever the level the floor settles at on
    this machine; a fixed threshold relative to ||x~(t0)|| cannot promise that."""
    _, run, _, ref, _ = computed(name)
    norms, level = measured_norms(run)
    exact = np.exp(ref)
    at_floor = exact < 1e-3 * norms          # the simulated norm is (almost) all rounding
    assert at_floor.sum() >= 3
    try:
        used = impact_decay_rate(run.trajectory, run.loop.outputs["error"]).n_points
    except ModelError:
        used = 1
    assert not np.any(at_floor[:used])
    # what the floor decides: every norm left out is within the margin of its level
    margin = ROUNDING_PER_STATE * run.loop.n_states / MAX_RELATIVE_ROUNDING
    assert norms[used] <= margin * level[used]


def test_error_contraction_matches_an_independent_integrator(case):
    """impact_error_contraction (expm of the stacked loop, its jump matrices) against the
    chapter's equations at every impact; it has no floor: it follows the error far below the
    simulated one's."""
    _, run, dz0, ref, ref_error = case
    c = impact_error_contraction(run.loop, run.trajectory, dz0, run.loop.outputs["error"])
    assert np.array_equal(c.times, run.trajectory.event_times("jump"))
    # the library's own rounding (expm, ~ n u ||A dt|| per interval on the rescaled state,
    # summed) is below the reference's bound ref_error: the two together, 2 ref_error
    tol = 2 * ref_error
    assert np.max(np.abs(c.log_norms - ref)) <= tol
    assert np.allclose(np.log(c.factors), np.diff(ref), rtol=0.0, atol=2 * tol)
    t = c.times
    assert c.rate == pytest.approx((ref[0] - ref[-1]) / (t[-1] - t[0]),
                                   abs=2 * tol / (t[-1] - t[0]))
    assert c.rate_over(t[:4]) == pytest.approx(ls_rate(t[:4], ref[:4]),
                                               abs=2 * tol / np.ptp(t[:4]))


@functools.cache
def contraction_rates(k33: float, eps_list: tuple[float, ...]) -> list[float]:
    out = []
    for eps in eps_list:
        run, dz0 = chapter2_run(1.0, k33, eps)
        E = run.loop.outputs["error"]
        ref, ref_error = reference_log_norms(run, E @ dz0)
        c = impact_error_contraction(run.loop, run.trajectory, dz0, E)
        t = c.times
        # the library's rate is the reference's mean contraction (to their errors)
        assert c.rate == pytest.approx((ref[0] - ref[-1]) / (t[-1] - t[0]),
                                       abs=4 * ref_error / (t[-1] - t[0]))
        out.append(c.rate)
    return out


@pytest.mark.parametrize(("k33", "eps_list"), [
    (3.0, (0.2, 0.1, 0.05, 0.025)),              # the loop of issue 29
    (4.0, (0.25, 0.125, 0.0625, 0.03125)),       # the chapter's worked example
])
def test_equal_mass_rate_at_least_doubles_as_eps_halves(k33, eps_list):
    """Theorem 3 (equal masses): the rate grows without bound as eps -> 0. Its proof bounds the
    observer's error flow by c eps^-p e^{-D delta / eps}, and with equal masses the jumps only
    exchange the two bodies' errors: -ln of the contraction over a pair of impacts is
    D delta / eps - p ln(1/eps) - ln c, so the rate grows like 1/eps -- x2 per halving as
    eps -> 0, the ln(1/eps) term holding it back more at larger eps (ratios above 2,
    approaching it). The impact times are the plant's, the same for every eps."""
    rates = contraction_rates(k33, eps_list)
    ratios = np.array(rates[1:]) / np.array(rates[:-1])
    # the rates are exact to ~1e-9 (ref_error / 40 s): no tolerance needed at this resolution
    assert np.all(ratios >= 2.0), ratios
    assert ratios[-1] <= ratios[0], ratios      # approaching 2 from above


def test_error_contraction_refuses_what_it_cannot_propagate():
    _, run, dz0, _, _ = computed("main_plant_eps_0.25")
    E = run.loop.outputs["error"]
    with_plant = dz0.copy()
    with_plant[4] += 0.1                        # moves body b: the gap changes
    with pytest.raises(ModelError, match="^error_state0: moves the guards"):
        impact_error_contraction(run.loop, run.trajectory, with_plant, E)
    with pytest.raises(DimensionError, match="^error_state0"):
        impact_error_contraction(run.loop, run.trajectory, dz0[:-1], E)
    with pytest.raises(ModelError, match="^skip:"):
        impact_error_contraction(run.loop, run.trajectory, dz0, E, skip=-1)
    with pytest.raises(ModelError, match="^trajectory: 22 impact"):
        impact_error_contraction(run.loop, run.trajectory, dz0, E, skip=21)
    c = impact_error_contraction(run.loop, run.trajectory, dz0, E, skip=1)
    assert c.times.size == 21 and c.factors.size == 20
    with pytest.raises(ModelError, match="^times:"):
        c.rate_over([c.times[0] + 0.1, c.times[3]])


@pytest.mark.parametrize(("kwargs", "name"), [({"floor": "1e-10"}, "floor"),
                                              ({"roundoff_margin": -1.0}, "roundoff_margin"),
                                              ({"skip": 1.5}, "skip")])
def test_fit_arguments_validated(kwargs, name):
    _, run, _, _, _ = computed("main_plant_eps_0.25")
    with pytest.raises(ModelError, match=f"^{name}:"):
        impact_decay_rate(run.trajectory, run.loop.outputs["error"], **kwargs)
