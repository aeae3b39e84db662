"""Chapter 5: robustness of the switching passivity-based tracking controller of chapter 3.

The two-link task of :mod:`.ch03_two_link_tracking` (current configuration, ``h = 2e-3``, two
cycles per point) is swept with :func:`nscontrol.sweep.run` over

* restitution ``e`` of the ground x model scale ``ŝ`` (the controller's ``M, C, g`` are the
  plant's times ``ŝ``), a map;
* delay ``k`` (steps) in detecting the impact and the persistent contact x standard deviation
  ``σ`` (rad) of the noise on the measured joint angles, a map;
* the step ``h`` of the Moreau–Jean scheme, a curve;
* the height ``c`` of the real ground while the controller believes ``y = 0``, a curve;
* the contact-force sensor the force loop reads, ``λ̂ = a P/h + b + n`` (scale ``a``, bias
  ``b``, noise ``n``), curves.

Each point gives cycles completed, worst tracking error at the transition start, largest growth
of ``V(τ0ᵏ)`` from cycle to cycle, penetration, the weak-stability verdict and the contact-phase
quantities (:func:`~.ch03_two_link_tracking.robustness_point`). The checks compare the results
with the analysis of ``docs/ch05.md``: the critical model scale ``ŝ* = 1 + γ1 γ2 d_max / g_n``,
the ultimate bound ``√κ(M) ‖Δ‖ / (γ1 γ2)`` of the free-phase error under model error, the
``h²`` floor of ``V`` and the ``O(h u⁻)`` penetration of the scheme, the landing speed and the
contact-force offset ``γ1 γ2 c / (1 + K_f)`` of a misplaced ground, and the steady force
``(1 + K_f) λ_d / (1 + a K_f)`` (stable for ``a K_f < 1``) of a miscalibrated sensor.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from . import Check, Example, ExampleResult, check, verdict_from

__all__ = ["RESTITUTIONS", "MODEL_SCALES", "DELAYS", "NOISES", "STEPS", "GROUND_OFFSETS",
           "FORCE_SCALES", "FORCE_BIASES", "FORCE_NOISE", "grids", "robustness_maps",
           "critical_model_scale", "hover_height", "model_error_bound", "crossing_speed",
           "ground_force_offset", "sensor_force_ratio", "robustness_checks", "step_checks",
           "ground_checks", "sensor_checks", "EXAMPLES"]

#: Restitution coefficients of the first map (0: plastic; 0.7: the nominal ground).
RESTITUTIONS = (0.0, 0.7, 0.95)
#: Model scales of the first map; 1.3 lies beyond the predicted critical scale (about 1.29).
MODEL_SCALES = (0.8, 1.0, 1.2, 1.3)
#: Detection delays (steps of h) of the second map.
DELAYS = (0, 5)
#: Noise standard deviations (rad) on the measured joint angles, second map.
NOISES = (0.0, 1e-3)
#: Steps (s) of the step-size curve.
STEPS = (1e-3, 2e-3, 4e-3, 8e-3)
#: Heights (m) of the real ground; the controller believes 0. -0.06 lies below the deepest dive.
GROUND_OFFSETS = (-0.06, -0.003, 0.0, 0.003, 0.006)
#: Scales of the force sensor; 2.5 K_f > 1 makes the one-step-delayed force loop unstable.
FORCE_SCALES = (0.5, 1.0, 1.5, 2.5)
#: Biases (N) of the force sensor.
FORCE_BIASES = (0.0, 1.0)
#: Standard deviation (N) of the force sensor's white noise (one point).
FORCE_NOISE = 1.0
#: The map values, as returned by ``robustness_point``.
FIELDS = ("cycles_completed", "worst_tau0_error", "worst_V_growth", "penetration",
          "weakly_stable", "gap_before_first_takeoff", "first_impact_speed", "contact_gap",
          "contact_lost_steps", "takeoff_shift", "contact_held", "force_error", "force_ratio")
#: Step and cycles of every point but the step-size curve's (about 27 points of 10 000 steps;
#: at h = 1e-3 the maps give the same verdicts for twice the run time).
H, CYCLES = 2e-3, 2


def grids() -> dict[str, list[dict[str, Any]]]:
    """The grids as lists of ``robustness_point`` arguments, row-major.

    Returns
    -------
    dict
        ``"restitution-model"`` (rows: ``e``, columns: ``ŝ``), ``"delay-noise"`` (rows:
        delay, columns: ``σ``), and the curves ``"step"`` (:data:`STEPS`), ``"ground"``
        (:data:`GROUND_OFFSETS`), ``"force-scale"`` (:data:`FORCE_SCALES`) and
        ``"force-bias"`` (:data:`FORCE_BIASES`, then one point with noise
        :data:`FORCE_NOISE`). Points equal to the nominal one are written identically, so
        :func:`run` computes them once.
    """
    base = {"h": H, "cycles": CYCLES}
    return {
        "restitution-model": [{**base, "restitution": e, "model_scale": s}
                              for e in RESTITUTIONS for s in MODEL_SCALES],
        "delay-noise": [{**base, "detection_delay": k, "position_noise": sg}
                        for k in DELAYS for sg in NOISES],
        "step": [{**base, "h": h} for h in STEPS],
        "ground": [{**base, "ground_offset": c} for c in GROUND_OFFSETS],
        "force-scale": [{**base, "force_scale": a} for a in FORCE_SCALES],
        "force-bias": [{**base, "force_bias": b} for b in FORCE_BIASES]
                      + [{**base, "force_noise": FORCE_NOISE}],
    }


def _nominal_key(point: dict[str, Any]) -> tuple:
    """A point without its default-valued keys: equal keys, equal runs."""
    defaults = {"restitution": 0.7, "model_scale": 1.0, "detection_delay": 0,
                "position_noise": 0.0, "ground_offset": 0.0, "force_scale": 1.0,
                "force_bias": 0.0, "force_noise": 0.0}
    return tuple(sorted((k, v) for k, v in point.items() if defaults.get(k, None) != v))


def robustness_maps(result: Any, shape: tuple[int, ...]) -> dict[str, Any]:
    """Arrays of the per-point values of a sweep; a failed point is NaN (``False`` for the
    verdict) and its error is kept.

    Parameters
    ----------
    result : SweepResult
        Outcome of ``sweep.run(robustness_point, grid)`` on a row-major grid.
    shape : tuple of int
        ``(rows, columns)`` of a map, ``(points,)`` of a curve.

    Returns
    -------
    dict
        One ``shape`` array per name of :data:`FIELDS`, ``"most_impacts"`` (most impact events
        in a cycle), ``"errors"``: the failed points as ``{"index", "point", "error"}``, and
        ``"records"``: the points' full records (``None`` where a point failed).
    """
    maps: dict[str, Any] = {f: np.full(shape, np.nan) for f in FIELDS}
    maps["weakly_stable"] = np.zeros(shape, dtype=bool)
    maps["most_impacts"] = np.full(shape, np.nan)
    errors = []
    for i, (point, value, err) in enumerate(zip(result.grid, result.values, result.errors,
                                                strict=True)):
        idx = np.unravel_index(i, shape)
        if err is not None:
            errors.append({"index": i, "point": point, "error": f"{err.type}: {err.message}"})
            continue
        for f in FIELDS:
            maps[f][idx] = value.get(f, np.nan)
        maps["most_impacts"][idx] = max(value.get("impacts_per_cycle") or [np.nan])
    maps["errors"] = errors
    maps["records"] = list(result.values)
    return maps


def critical_model_scale(depth_max: float = 0.05) -> float:
    """``ŝ* = 1 + γ1 γ2 d_max / g_n``: above it the controller's surplus weight compensation
    ``(ŝ - 1) g_n`` lifts the arm more than the largest pressing force ``γ1 γ2 d_max`` pushes
    it down, so the normal equilibrium of the transition lies above the ground.

    Parameters
    ----------
    depth_max : float
        Largest depth of the virtual dive (m).
    """
    from .ch03_two_link_tracking import CONFIGS

    g1, g2, _ = CONFIGS["siconos-current"].gains
    return 1.0 + g1 * g2 * depth_max / _normal_weight()


def hover_height(scale: float, depth_max: float = 0.05) -> float:
    """Height of the rest equilibrium of the transition, ``(ŝ - 1) g_n / (γ1 γ2) - d_max``
    (positive above the critical scale: the arm hovers above the ground).

    At rest ``s = γ2 q̃`` and ``C(q, 0) = 0``, so the controller's force is ``ŝ g - γ1 γ2 q̃``
    and the plant rests where ``γ1 γ2 q̃ = (ŝ - 1) g``, ``q̃1 = q1 + d_max``.

    Parameters
    ----------
    scale : float
        The controller's model scale ``ŝ``.
    depth_max : float
        Depth of the dive (m), at its clip.
    """
    from .ch03_two_link_tracking import CONFIGS

    g1, g2, _ = CONFIGS["siconos-current"].gains
    return (scale - 1.0) * _normal_weight() / (g1 * g2) - depth_max


def _normal_weight() -> float:
    """``g_n``: normal component of the weight in task coordinates at the landing point."""
    from ..design.complementarity_tracking import CircleTask
    from ..systems.two_link import TwoLinkArm

    arm, task = TwoLinkArm(), CircleTask()
    x_land = task.nominal(task.tau0(0))[0][1]
    theta = arm.inverse(np.array([0.0, x_land]))
    return float(arm.task_model(theta, np.zeros(2))[4][0])


def model_error_bound(scale: float, samples: int = 200) -> float:
    """``√κ(M_q) max ‖Δ‖ / (γ1 γ2)`` over the nominal free path, ``Δ = (ŝ - 1)(M q̈_d + C q̇_d
    + g)``: the ultimate bound of the tracking error in free motion under model error.

    From ``M ṡ + (C + γ1) s = Δ`` and skew ``Ṁ - 2C``, ``½ sᵀ M s`` decreases while
    ``‖s‖ > ‖Δ‖/γ1``, so ultimately ``‖s‖ ≤ √κ(M) ‖Δ‖/γ1``; the filter ``q̃' + γ2 q̃ = s`` divides
    by ``γ2``.

    Parameters
    ----------
    scale : float
        The controller's model scale ``ŝ``.
    samples : int
        Points on the upper half-circle.
    """
    from ..design.complementarity_tracking import CircleTask
    from ..systems.two_link import TwoLinkArm
    from .ch03_two_link_tracking import CONFIGS

    arm, task = TwoLinkArm(), CircleTask()
    g1, g2, _ = CONFIGS["siconos-current"].gains
    worst = 0.0
    for t in np.linspace(0.0, task.period / 2, samples):
        q, dq, ddq = task.nominal(float(t))
        theta = arm.inverse(q)
        dtheta = np.asarray(np.linalg.solve(arm.jacobian(theta), dq), float)
        Mq, Cq, gq, _ = arm.task_dynamics(theta, dtheta)
        delta = abs(scale - 1.0) * float(np.linalg.norm(Mq @ ddq + Cq @ dq + gq))
        worst = max(worst, math.sqrt(float(np.linalg.cond(Mq))) * delta / (g1 * g2))
    return worst


def _gains() -> tuple[float, float, float]:
    from .ch03_two_link_tracking import CONFIGS

    return CONFIGS["siconos-current"].gains


def crossing_speed(ground: float, depth: float = 0.05, samples: int = 60) -> float:
    """Speed of the virtual dive where it crosses the real ground ``y = c`` (m/s; NaN when it
    does not reach it): the landing speed when the dive is tracked closely.

    The dive of cycle ``k`` goes from ``q10 = y_thr`` to ``-d_k`` along
    ``q10 - (q10 + d)(3θ² - 2θ³)`` over ``Δ``; it crosses ``c`` where
    ``3θ² - 2θ³ = (q10 - c)/(q10 + d)`` at the speed ``6 (q10 + d) θ (1 - θ)/Δ``.

    Parameters
    ----------
    ground : float
        Height ``c`` of the real ground (m).
    depth : float
        ``d_k`` (m); cycle 0 starts with a large error and dives to the clip ``d_max``.
    samples : int
        Bisection steps.
    """
    from ..design.complementarity_tracking import CircleTask, TransitionDesign

    task, tr = CircleTask(), TransitionDesign()
    q10 = float(task.nominal(task.tau0(0))[0][0])
    a = q10 + depth
    target = (q10 - ground) / a
    if not 0.0 <= target <= 1.0:
        return math.nan
    lo, hi = 0.0, 1.0
    for _ in range(samples):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if 3 * mid**2 - 2 * mid**3 < target else (lo, mid)
    th = 0.5 * (lo + hi)
    return 6 * a * th * (1 - th) / tr.Delta


def ground_force_offset(ground: float) -> float:
    """``γ1 γ2 c / (1 + K_f)``: the shift of the contact force ``λ - λ_d`` when the arm slides on
    a ground at ``y = c`` while the controller tracks ``y = 0``.

    On the ground ``q̃1 = c`` and ``q̃1' = 0``, so ``s1 = γ2 c`` and the law adds ``-γ1 γ2 c``
    along the normal; the force loop ``λ = λ_d + K_f (λ_d - λ) + ...`` shares it as
    ``γ1 γ2 c / (1 + K_f)`` (more force on a higher ground, less on a lower one).

    Parameters
    ----------
    ground : float
        Height ``c`` of the real ground (m).
    """
    g1, g2, kf = _gains()
    return g1 * g2 * ground / (1.0 + kf)


def sensor_force_ratio(scale: float) -> float:
    """``λ/λ_d = (1 + K_f)/(1 + a K_f)``: the steady contact force under a sensor of scale
    ``a`` (NaN when ``a K_f >= 1``, where the one-step-delayed loop
    ``λ_{k+1} = (1 + K_f) λ_d - a K_f λ_k`` diverges).

    Parameters
    ----------
    scale : float
        Sensor scale ``a``.
    """
    kf = _gains()[2]
    return (1.0 + kf) / (1.0 + scale * kf) if scale * kf < 1.0 else math.nan


def _records(m: dict[str, Any]) -> list[dict[str, Any]]:
    return [r if r is not None else {} for r in m["records"]]


def step_checks(m: dict[str, Any]) -> list[Check]:
    """Checks on the step-size curve (``m``: :func:`robustness_maps` over :data:`STEPS`).

    Parameters
    ----------
    m : dict
        Output of :func:`robustness_maps` with shape ``(len(STEPS),)``.
    """
    recs = _records(m)
    V_last = np.array([r.get("V_tau0", [np.nan])[-1] for r in recs])
    slopes = np.diff(np.log(V_last)) / np.diff(np.log(STEPS))
    pen_ratio = max(float(r["penetration"]) / (h * float(r["first_impact_speed"])
                                               * (1 - 0.7 / 2))
                    for h, r in zip(STEPS, recs, strict=True) if r)
    return [
        check("Every step size completes both cycles, weakly stable (points failing)",
              int(np.sum(~m["weakly_stable"])), 0, "==", key="step_stable"),
        check("Order of the V(tau0) floor in h: worst |slope - 2| of log V(tau0 of cycle 1) "
              "against log h", float(np.max(np.abs(slopes - 2.0))), 0.25,
              note="first-order tracking error, V quadratic in it: V ~ h²; the next term is "
                   "O(h gamma2) = 0.06 at h = 8e-3, times a factor 4",
              key="step_V_floor_h2"),
        check("Penetration over its bound h |u-| (1 - e/2) (worst ratio over h)", pen_ratio,
              1.0, note="impact when gap + h u/2 <= 0 (gap >= -h|u|/2), then the step moves by "
                        "h (1 - e) u/2: at most h |u-| (1 - e/2), u- the landing speed",
              key="step_penetration_bound"),
    ]


def ground_checks(m: dict[str, Any]) -> list[Check]:
    """Checks on the ground-offset curve (``m``: :func:`robustness_maps` over
    :data:`GROUND_OFFSETS`).

    Parameters
    ----------
    m : dict
        Output of :func:`robustness_maps` with shape ``(len(GROUND_OFFSETS),)``.
    """
    from ..design.complementarity_tracking import TransitionDesign

    d_max = TransitionDesign().depth_max
    c_lam = 1.0 + _gains()[2]      # the ramp rate of λ_d that two_link_tracking sets
    recs = _records(m)
    nom = recs[GROUND_OFFSETS.index(0.0)]
    below = [i for i, c in enumerate(GROUND_OFFSETS) if c < -d_max]
    within = [i for i, c in enumerate(GROUND_OFFSETS) if -d_max < c and c != 0.0]
    hover_err = max(abs(float(recs[i]["gap_before_first_takeoff"])
                        - (-GROUND_OFFSETS[i] - d_max)) for i in below)
    speed_err = max(abs(float(recs[i]["first_impact_speeds"][0])
                        / crossing_speed(GROUND_OFFSETS[i]) - 1) for i in within)
    force_err = max(abs((float(recs[i]["force_error"]) - float(nom["force_error"]))
                        / ground_force_offset(GROUND_OFFSETS[i]) - 1) for i in within)
    early = [i for i in within if ground_force_offset(GROUND_OFFSETS[i]) < 0]
    late = [i for i in within if ground_force_offset(GROUND_OFFSETS[i]) > 0]
    lift_err = max(abs(float(recs[i]["takeoff_shift"]) - float(nom["takeoff_shift"])
                       - ground_force_offset(GROUND_OFFSETS[i]) / c_lam) for i in early)
    return [
        check("Ground below the deepest dive (c < -d_max): cycles that reach contact",
              int(np.nansum(m["cycles_completed"][below])), 0, "==",
              note="the dive stops at -d_k >= -d_max above the ground", key="ground_below_dive"),
        check("Ground below the deepest dive: hover gap minus the predicted |c| - d_max "
              "(worst, m)", hover_err, 1e-3,
              note="at rest the exact-model loop holds q1 = -d_max; the residual is the "
                   "decaying tracking error, 1e-4 m at the transition start, times 10",
              key="ground_hover_gap"),
        check("Ground within reach (-d_max < c < y_thr): points not weakly stable",
              int(np.sum(~m["weakly_stable"][within])), 0, "==", key="ground_stable"),
        check("Landing speed over the dive's speed where it crosses y = c (worst relative "
              "error, cycle 0)", speed_err, 0.05,
              note="the dive is tracked to O(h): the same 5 % as the nominal landing check",
              key="ground_landing_speed"),
        check("Contact force offset lambda - lambda_d against g1 g2 c / (1 + K_f), relative to "
              "the nominal run (worst relative error)", force_err, _sliding_coriolis_bound(),
              note="the analysis drops C q_r' = -g2 c C_11 while sliding: relative size "
                   "|C_11|/g1 at the largest sliding speed", key="ground_force_offset"),
        check("Lower ground: take-off advance against offset / c_lambda, relative to the "
              "nominal run (worst error, s)", lift_err, 0.03,
              note="lambda reaches 0 when lambda_d = -offset; the gap then needs ~26 ms to open "
                   "by 1 um (nominal run), allowed once more", key="ground_early_liftoff"),
        check("Higher ground: take-off no earlier than nominal (smallest shift, s)",
              min(float(recs[i]["takeoff_shift"]) - float(nom["takeoff_shift"])
                  for i in late), 0.0, ">=",
              note="the offset adds force; the arm leaves when the lift-off reference passes "
                   "c", key="ground_late_takeoff"),
    ]


def _sliding_coriolis_bound(min_duration: float = 3.5) -> float:
    """``max |C_q,11| / γ1`` on the ground at the fastest tangential speed of the sliding
    phase: the relative size of the term ``C q̇_r`` that :func:`ground_force_offset` drops.

    The slide is a rest-to-rest cubic from the landing point to the take-off point over at
    least ``min_duration`` seconds, so its speed is at most ``1.5 Δx / min_duration``;
    ``C`` is linear in the velocity.

    Parameters
    ----------
    min_duration : float
        Shortest sliding phase (s): the planned take-off minus the latest start of contact.
    """
    from ..design.complementarity_tracking import CircleTask
    from ..systems.two_link import TwoLinkArm

    arm, task = TwoLinkArm(), CircleTask()
    x0 = float(task.nominal(task.tau0(0))[0][1])
    x1 = float(task.nominal(task.t_detach(0))[0][1])
    speed = 1.5 * abs(x1 - x0) / min_duration
    worst = 0.0
    for x in np.linspace(min(x0, x1), max(x0, x1), 21):
        theta = arm.inverse(np.array([0.0, x]))
        dtheta = np.linalg.solve(arm.jacobian(theta), np.array([0.0, speed]))
        worst = max(worst, abs(float(arm.task_dynamics(theta, dtheta)[1][0, 0])))
    return worst / _gains()[0]


def sensor_checks(ms: dict[str, Any], mb: dict[str, Any]) -> list[Check]:
    """Checks on the force-sensor curves (``ms``: scales, ``mb``: biases then the noisy
    point).

    Parameters
    ----------
    ms, mb : dict
        Outputs of :func:`robustness_maps` over :data:`FORCE_SCALES` and over
        :data:`FORCE_BIASES` plus the noisy point.
    """
    g1, g2, kf = _gains()
    c_lam = 1.0 + kf
    rs, rb = _records(ms), _records(mb)
    stable = [i for i, a in enumerate(FORCE_SCALES) if a * kf < 1.0]
    unstable = [i for i, a in enumerate(FORCE_SCALES) if a * kf > 1.0]
    ratio_err = max(abs(float(rs[i]["force_ratio"]) / sensor_force_ratio(FORCE_SCALES[i]) - 1)
                    for i in stable)
    nom = rb[FORCE_BIASES.index(0.0)]
    biased = [i for i, b in enumerate(FORCE_BIASES) if b != 0.0]
    offset_err = max(abs(float(rb[i]["force_error"]) - float(nom["force_error"])
                         + kf * FORCE_BIASES[i] / (1 + kf)) for i in biased)
    lift_err = max(abs(float(rb[i]["takeoff_shift"]) - float(nom["takeoff_shift"])
                       + kf * FORCE_BIASES[i] / ((1 + kf) * c_lam)) for i in biased
                   if FORCE_BIASES[i] > 0)
    noisy = rb[-1]
    lam_std = kf * FORCE_NOISE / math.sqrt(1 - kf**2)
    return [
        check("Sensor scales with a K_f < 1: force ratio lambda/lambda_d against "
              "(1 + K_f)/(1 + a K_f) (worst relative error)", ratio_err, 0.01,
              note="the loop lags the ramp by one step: c_lambda h / lambda_d <= 3e-3 for "
                   "lambda_d >= 1 N, times 3", key="sensor_scale_ratio"),
        check("Sensor scale with a K_f > 1: longest contact held in the first constrained "
              "phase (s)", max(float(rs[i]["contact_held"]) for i in unstable), 0.5,
              note="the force error grows by a K_f per step (1.25): from 0.01 N to several N "
                   "in about 30 steps = 0.06 s; the gap opens and the impulsive reading "
                   "throws the arm off again", key="sensor_scale_unstable"),
        check("Every sensor point completes both cycles (points failing)",
              int(np.sum(ms["cycles_completed"] < CYCLES) + np.sum(mb["cycles_completed"]
                                                                   < CYCLES)), 0, "==",
              note="the force loop acts only on the ground; the landing does not use it",
              key="sensor_cycles_complete"),
        check("Sensor bias b: contact force offset against -K_f b/(1 + K_f), relative to the "
              "exact sensor (worst error, N)", offset_err, 0.01,
              note="the same one-step lag as the scale check", key="sensor_bias_offset"),
        check("Sensor bias b > 0: take-off advance against K_f b/((1 + K_f) c_lambda), "
              "relative to the exact sensor (worst error, s)", lift_err, 0.03,
              note="as for the lower ground", key="sensor_bias_liftoff"),
        check("Sensor noise: the gap opens no earlier than where lambda_d = 4 std(lambda) "
              "(take-off shift minus the bound, s)",
              float(noisy["takeoff_shift"]) - float(nom["takeoff_shift"])
              + 4 * lam_std / c_lam, 0.0, ">=",
              note=f"lambda_(k+1) = (1 + K_f) lambda_d - K_f (lambda_k + n_k): std(lambda) = "
                   f"K_f sigma / sqrt(1 - K_f²) = {lam_std:.3f} N; a 4-std excursion has "
                   "probability 3e-5 per step", key="sensor_noise_contact"),
    ]


def robustness_checks(m1: dict[str, Any], m2: dict[str, Any]) -> list[Check]:
    """The checks on the two maps (``m1``: restitution x model, ``m2``: delay x noise).

    Parameters
    ----------
    m1, m2 : dict
        Outputs of :func:`robustness_maps`.
    """
    s_crit = critical_model_scale()
    e_idx = {e: i for i, e in enumerate(RESTITUTIONS)}
    s_idx = {s: j for j, s in enumerate(MODEL_SCALES)}
    nominal = (e_idx[0.7], s_idx[1.0])
    inside = [j for j, s in enumerate(MODEL_SCALES) if s < s_crit]
    outside = [j for j, s in enumerate(MODEL_SCALES) if s > s_crit]
    checks = [
        check("The nominal point (e = 0.7, exact model) is weakly stable",
              bool(m1["weakly_stable"][nominal]), True, "==", key="nominal_stable"),
        check("Points with model scale below the predicted critical scale that are not "
              "weakly stable", int(np.sum(~m1["weakly_stable"][:, inside])), 0, "==",
              note=f"critical scale 1 + g1 g2 d_max / g_n = {s_crit:.3f}",
              key="stable_below_critical_scale"),
        check("Points with model scale above the critical scale that complete a cycle",
              int(np.sum(m1["cycles_completed"][:, outside] > 0)), 0, "==",
              note="predicted failure: the normal equilibrium lies above the ground, so "
                   "contact never persists", key="fails_above_critical_scale"),
        check("Failing points hover above the ground before the planned take-off "
              "(smallest gap over the last second, m)",
              float(np.min(m1["gap_before_first_takeoff"][:, outside])), 0.0, ">",
              note="the predicted reason; the rest equilibrium gamma1 gamma2 (q1 + d_max) = "
                   "(s - 1) g_n puts q1 at "
                   + ", ".join(f"{hover_height(MODEL_SCALES[j]) * 1e3:.2f} mm"
                               for j in outside), key="failure_is_hovering"),
        check("Plastic ground (e = 0): completed cycles over all model scales below the "
              "critical one", float(np.nanmin(m1["cycles_completed"][e_idx[0.0], inside])),
              CYCLES, ">=", key="plastic_completes"),
    ]
    impacts = m1["most_impacts"][:, s_idx[1.0]]
    checks.append(check("Plastic ground (e = 0), exact model: most impact events in a cycle",
                        float(impacts[e_idx[0.0]]), 1, "==",
                        note="e = 0 stops the normal velocity at the first impact",
                        key="plastic_single_impact"))
    checks.append(check("Impact events per cycle grow with e (exact model; smallest "
                        "increase from one e to the next)", float(np.min(np.diff(impacts))),
                        0, ">", note="flight times shrink by about e per rebound: about "
                                     "log(eps)/log(e) rebounds", key="impacts_grow_with_e"))
    bounds = {s: model_error_bound(s) for s in MODEL_SCALES if s != 1.0 and s < s_crit}
    ratio = max(float(m1["worst_tau0_error"][i, j]) / bounds[s]
                for i in range(len(RESTITUTIONS)) for j, s in enumerate(MODEL_SCALES)
                if s in bounds)
    checks.append(check("Free-phase error at the transition start over the model-error "
                        "bound sqrt(cond M) |Delta| / (g1 g2) (worst ratio)", ratio, 1.0,
                        note="ultimate bound of the smooth-phase analysis; the runs start at "
                             "rest on the path and have 4.7 s (> 30 time constants 1/g2) to "
                             "settle", key="model_error_within_bound"))
    checks.append(check("Delay x noise points that are not weakly stable",
                        int(np.sum(~m2["weakly_stable"])), 0, "==",
                        note="delayed detection keeps the dive (hence the pressing force) a "
                             "few steps longer; zero-mean noise does not bias it",
                        key="delay_noise_stable"))
    n_err = float(np.nanmax(m2["worst_tau0_error"]))
    base_err = float(m2["worst_tau0_error"][0, 0])
    # |J|_2 <= |J|_F = sqrt((l1 + l2)² + l2²) = 1.12 m/rad for any joint angles
    jmax = math.hypot(1.0, 0.5)
    checks.append(check("Free-phase error at the transition start with delay and noise "
                        "(worst, m)", n_err, base_err + 3 * jmax * max(NOISES),
                        note="the loop tracks the measured position with unit gain at low "
                             "frequency and filters the white noise: nominal O(h) error plus "
                             "3 sigma |J|", key="noise_error_bounded"))
    pen = max(float(np.nanmax(np.where(m["cycles_completed"] > 0, m["penetration"], 0.0)))
              for m in (m1, m2))
    checks.append(check("Penetration over every map point that reached contact (worst, m)",
                        pen, H * 0.1,
                        note="a landing penetrates at most h |u-|, and |u-| <= 0.1 m/s on the "
                             "maps (the dive to d_max crosses the ground at 0.07 m/s)",
                        key="penetration"))
    checks.append(check("Sweep points lost to an error", len(m1["errors"]) + len(m2["errors"]),
                        0, "==", note="a failed point would be NaN in its map, its error "
                                      "listed in the metrics", key="no_failed_points"))
    return checks


def run(out_dir: Path | None) -> ExampleResult:
    """Every grid in one sweep (each distinct point once), the checks, two maps and three
    curves."""
    from .. import sweep
    from ..sweep import SweepResult
    from .ch03_two_link_tracking import robustness_point

    g = grids()
    unique: dict[tuple, dict[str, Any]] = {}
    for points in g.values():
        for p in points:
            unique.setdefault(_nominal_key(p), p)
    # the finest step first: the longest point should not be the last one started
    order = sorted(unique, key=lambda k: unique[k].get("h", H))
    res = sweep.run(robustness_point, [unique[k] for k in order], executor="auto",
                    desc="chapter 5 robustness")
    by_key = {k: (v, e) for k, v, e in zip(order, res.values, res.errors, strict=True)}

    def part(name: str) -> SweepResult:
        pts = g[name]
        vals = [by_key[_nominal_key(p)] for p in pts]
        return SweepResult(grid=tuple(pts), values=tuple(v for v, _ in vals),
                           errors=tuple(e for _, e in vals))

    m1 = robustness_maps(part("restitution-model"), (len(RESTITUTIONS), len(MODEL_SCALES)))
    m2 = robustness_maps(part("delay-noise"), (len(DELAYS), len(NOISES)))
    mh = robustness_maps(part("step"), (len(STEPS),))
    mc = robustness_maps(part("ground"), (len(GROUND_OFFSETS),))
    ms = robustness_maps(part("force-scale"), (len(FORCE_SCALES),))
    mb = robustness_maps(part("force-bias"), (len(FORCE_BIASES) + 1,))
    checks = (robustness_checks(m1, m2) + step_checks(mh) + ground_checks(mc)
              + sensor_checks(ms, mb))
    figures: list[Path] = []
    _map_figure(m1, [f"{s:g}" for s in MODEL_SCALES], [f"{e:g}" for e in RESTITUTIONS],
                "controller model scale s (M, C, g) [-]", "restitution e [-]",
                "Restitution x model error", out_dir, "ch05_map_restitution_model", figures,
                critical_x=float(np.interp(critical_model_scale(), MODEL_SCALES,
                                           range(len(MODEL_SCALES)))))
    _map_figure(m2, [f"{s:g}" for s in NOISES], [f"{k}" for k in DELAYS],
                "joint-angle noise sigma [rad]", f"detection delay [steps of {H * 1e3:g} ms]",
                "Detection delay x measurement noise", out_dir, "ch05_map_delay_noise",
                figures, field="worst_V_growth",
                colour_label="largest V(tau0) growth per cycle [-]")
    _step_figure(mh, out_dir, figures)
    _ground_figure(mc, out_dir, figures)
    _sensor_figure(ms, mb, out_dir, figures)
    all_errors = [e for m in (m1, m2, mh, mc, ms, mb) for e in m["errors"]]
    metrics = {"h": H, "cycles": CYCLES, "points": len(res),
               "critical_model_scale": critical_model_scale(),
               "restitution_model": _json_map(m1, RESTITUTIONS, MODEL_SCALES),
               "delay_noise": _json_map(m2, DELAYS, NOISES),
               "step": _json_curve(mh, STEPS),
               "ground_offset": _json_curve(mc, GROUND_OFFSETS),
               "force_scale": _json_curve(ms, FORCE_SCALES),
               "force_bias_noise": _json_curve(mb, (*FORCE_BIASES, f"noise {FORCE_NOISE} N")),
               "failed_points": all_errors}
    n_stable = sum(int(np.sum(m["weakly_stable"])) for m in (m1, m2, mh, mc, ms, mb))
    n_all = sum(m["weakly_stable"].size for m in (m1, m2, mh, mc, ms, mb))
    return ExampleResult("ch05-robustness", metrics=metrics, checks=checks, figures=figures,
                         summary=f"{n_stable} of {n_all} grid entries weakly stable "
                                 f"({len(res)} distinct points); predicted critical model "
                                 f"scale {metrics['critical_model_scale']:.3f}")


def _json_map(m: dict[str, Any], rows: tuple, cols: tuple) -> dict[str, Any]:
    return {"rows": list(rows), "columns": list(cols),
            **{f: np.asarray(m[f]).tolist() for f in (*FIELDS, "most_impacts")}}


def _json_curve(m: dict[str, Any], values: tuple) -> dict[str, Any]:
    recs = _records(m)
    return {"values": list(values),
            **{f: np.asarray(m[f]).tolist() for f in (*FIELDS, "most_impacts")},
            "V_tau0": [r.get("V_tau0") for r in recs], "depths": [r.get("depths") for r in recs]}


def _map_figure(m: dict[str, Any], xticks: list[str], yticks: list[str], xlabel: str,
                ylabel: str, title: str, out_dir: Path | None, name: str,
                figures: list[Path], critical_x: float | None = None,
                field: str = "worst_tau0_error",
                colour_label: str = "worst tracking error at transition start [m]") -> None:
    """One value per point (``field``) on a log colour scale, weakly stable points ringed,
    points that never reach persistent contact crossed."""
    from matplotlib.colors import LogNorm

    from ._figures import new_figure, save_figure

    err = np.asarray(m[field], float)
    fig, ax = new_figure(figsize=(6, 4))
    pos = err[np.isfinite(err) & (err > 0)]
    norm = LogNorm(vmin=pos.min(), vmax=pos.max()) if pos.size else None
    im = ax.imshow(np.where(err > 0, err, np.nan), origin="lower", aspect="auto", norm=norm,
                   cmap="viridis")
    fig.colorbar(im, ax=ax, label=colour_label)
    rows, cols = np.nonzero(m["weakly_stable"])
    ax.plot(cols, rows, "o", mfc="none", mec="w", mew=2, ms=14, label="weakly stable")
    rows, cols = np.nonzero(~(m["cycles_completed"] > 0))
    if rows.size:
        ax.plot(cols, rows, "x", color="r", mew=2, ms=12, label="never slides on the ground")
    ax.set_xticks(range(len(xticks)), xticks)
    ax.set_yticks(range(len(yticks)), yticks)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    if critical_x is not None:
        ax.axvline(critical_x, color="w", ls="--", lw=2, label="predicted critical scale")
    # grey background: the white rings must stay visible in the legend
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3, fontsize="small",
              facecolor="0.6")
    save_figure(fig, out_dir, name, figures)


def _step_figure(m: dict[str, Any], out_dir: Path | None, figures: list[Path]) -> None:
    """V(τ0) of cycle 1 and the penetration against h, with the h² and h |u-| predictions."""
    from ._figures import new_figure, save_figure

    recs = _records(m)
    h = np.array(STEPS)
    V = np.array([r.get("V_tau0", [np.nan])[-1] for r in recs])
    fig, (a1, a2) = new_figure(1, 2, figsize=(9, 3.8))
    a1.loglog(h, V, "o-", label="measured V(tau0), cycle 1")
    ref = STEPS.index(H)
    a1.loglog(h, V[ref] * (h / H) ** 2, "k--", label="h² through the example's step")
    a1.set_xlabel("step h [s]")
    a1.set_ylabel("V at the transition start [J]")
    a1.legend(fontsize="small")
    a1.set_title("Floor of V: second order in h")
    pen = np.asarray(m["penetration"], float)
    bound = h * np.asarray(m["first_impact_speed"], float) * (1 - 0.7 / 2)
    a2.loglog(h, pen, "o-", label="measured penetration")
    a2.loglog(h, bound, "k--", label="bound h |u-| (1 - e/2)")
    a2.set_xlabel("step h [s]")
    a2.set_ylabel("largest penetration [m]")
    a2.legend(fontsize="small")
    a2.set_title("Penetration: O(h u-)")
    for ax in (a1, a2):
        ax.minorticks_off()
        ax.set_xticks(STEPS, [f"{x * 1e3:g} ms" for x in STEPS])
    save_figure(fig, out_dir, "ch05_curve_step_size", figures)


def _ground_figure(m: dict[str, Any], out_dir: Path | None, figures: list[Path]) -> None:
    """Landing speed, contact-force offset and take-off shift against the ground height."""
    from ._figures import new_figure, save_figure

    recs = _records(m)
    c = np.array(GROUND_OFFSETS)
    nom = recs[GROUND_OFFSETS.index(0.0)]
    from ..design.complementarity_tracking import TransitionDesign

    fine = np.linspace(c.min(), c.max(), 200)
    reach = fine[fine > -TransitionDesign().depth_max]     # where contact is possible
    fig, (a1, a2, a3) = new_figure(1, 3, figsize=(11, 4.4))
    u0 = [r["first_impact_speeds"][0] if r.get("first_impact_speeds") else np.nan
          for r in recs]
    a1.plot(c * 1e3, u0, "o", label="measured, cycle 0")
    a1.plot(fine * 1e3, [crossing_speed(x) for x in fine], "k--",
            label="dive speed where it crosses y = c")
    missed = [x for x, u in zip(c, u0, strict=True) if not np.isfinite(u)]
    if missed:
        a1.plot(np.array(missed) * 1e3, np.zeros(len(missed)), "x", color="C3", mew=2,
                label="no contact (ground below the deepest dive)")
    a1.set_xlabel("ground height c [mm] (controller believes 0)")
    a1.set_ylabel("landing speed |u-| [m/s]")
    a1.set_title("Landing (none below -d_max)")
    a1.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize="small")
    df = np.asarray(m["force_error"], float) - float(nom["force_error"])
    a2.plot(c * 1e3, df, "o", label="measured (minus nominal)")
    a2.plot(reach * 1e3, [ground_force_offset(x) for x in reach], "k--",
            label="g1 g2 c / (1 + K_f)")
    a2.set_xlabel("ground height c [mm]")
    a2.set_ylabel("contact force offset lambda - lambda_d [N]")
    a2.set_title("Force on the ground")
    a2.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize="small")
    ds = np.asarray(m["takeoff_shift"], float) - float(nom["takeoff_shift"])
    c_lam = 1.0 + _gains()[2]
    a3.plot(c * 1e3, ds, "o", label="measured (minus nominal)")
    low = reach[reach < 0]
    a3.plot(low * 1e3, [ground_force_offset(x) / c_lam for x in low], "k--",
            label="offset / c_lambda (lower ground)")
    a3.axhline(0.0, color="0.6", lw=1)
    a3.set_xlabel("ground height c [mm]")
    a3.set_ylabel("take-off shift [s] (< 0: early)")
    a3.set_title("Take-off")
    a3.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), fontsize="small")
    save_figure(fig, out_dir, "ch05_curve_ground_offset", figures)


def _sensor_figure(ms: dict[str, Any], mb: dict[str, Any], out_dir: Path | None,
                   figures: list[Path]) -> None:
    """Force ratio against the sensor scale, take-off shift against the bias."""
    from ._figures import new_figure, save_figure

    kf = _gains()[2]
    c_lam = 1.0 + kf
    a = np.array(FORCE_SCALES)
    fig, (a1, a2) = new_figure(1, 2, figsize=(9, 3.8))
    a1.plot(a, ms["force_ratio"], "o", label="measured (while contact holds)")
    fine = np.linspace(a.min(), a.max(), 200)
    a1.plot(fine, [sensor_force_ratio(x) for x in fine], "k--",
            label="(1 + K_f)/(1 + a K_f)")
    a1.axvspan(1 / kf, a.max() + 0.1, color="#f4a6a6", label="a K_f > 1: loop unstable")
    a1.set_xlabel("sensor scale a [-]")
    a1.set_ylabel("contact force ratio lambda / lambda_d [-]")
    a1.set_title("Sensor scale")
    a1.legend(fontsize="small")
    recs = _records(mb)
    nom = recs[FORCE_BIASES.index(0.0)]
    b = np.array(FORCE_BIASES)
    shift = np.array([float(r["takeoff_shift"]) - float(nom["takeoff_shift"])
                      for r in recs])
    a2.plot(b, shift[:len(b)], "o", label="bias, measured (minus exact sensor)")
    fine_b = np.linspace(0.0, b.max(), 50)
    a2.plot(fine_b, -kf * fine_b / ((1 + kf) * c_lam), "k--",
            label="-K_f b / ((1 + K_f) c_lambda)")
    a2.plot([0.0], [shift[-1]], "s", color="C3",
            label=f"noise {FORCE_NOISE:g} N (no bias)")
    a2.axhline(0.0, color="0.6", lw=1)
    a2.set_xlabel("sensor bias b [N]")
    a2.set_ylabel("take-off shift [s] (< 0: early)")
    a2.set_title("Sensor bias and noise")
    a2.legend(fontsize="small")
    save_figure(fig, out_dir, "ch05_curve_force_sensor", figures)


EXAMPLES = [Example(
    "ch05-robustness",
    "Robustness of the tracking controller: restitution, model error, detection delay, "
    "measurement noise, step size, ground location, force sensor",
    "ch05", run,
    claim="The switching passivity-based controller of chapter 3 stays weakly stable over "
          "every restitution coefficient below 1, a model error of up to 20 %, a delay of up "
          "to five steps in detecting the impacts and joint-angle noise of up to 1 mrad; it "
          "fails where the analysis says it must, when the controller over-compensates the "
          "arm's weight by more than the largest pressing force of the virtual dive, and "
          "then for the predicted reason: after a graze the arm comes to rest hovering a few "
          "millimetres above the ground instead of sliding on it. The step size sets a "
          "floor of V that grows as h² and a penetration below h |u-|; a ground a few "
          "millimetres off the modelled one shifts the landing speed and the contact force "
          "as predicted, and a ground below the deepest dive is never reached; a biased or "
          "miscalibrated force sensor shifts the contact force as the force loop predicts, "
          "and a sensor that over-reads by more than 1/K_f destabilises it.",
    verdict=verdict_from(("nominal_stable", "the nominal tracking loop is weakly stable "
                                            "({value})"),
                         ("stable_below_critical_scale", "below the predicted critical model "
                                                         "scale, {value} points lose it"),
                         ("fails_above_critical_scale", "above it {value} points complete a "
                                                        "cycle, because the arm hovers "
                                                        "instead of sliding"),
                         ("failure_is_hovering", "at least {value} m above the ground"),
                         ("step_V_floor_h2", "the step size sets V's floor as h², slope off "
                                             "2 by {value}"),
                         ("ground_force_offset", "a shifted ground moves the contact force as "
                                                 "predicted, to a relative {value}"),
                         ("sensor_scale_ratio", "and a miscalibrated force sensor to "
                                                "{value}")),
    key_figure="ch05_map_restitution_model",
    captions={
        "ch05_map_restitution_model":
            "Restitution e against the controller's model scale s: colour is the worst "
            "tracking error at the transition start (log scale); rings mark weakly stable "
            "points, crosses points where the arm never slides on the ground, the dashed "
            "line the predicted critical scale. The error grows "
            "with |s - 1| and does not depend on e; s = 1.3 is beyond the predicted critical "
            "scale of about 1.29, and there the arm hovers above the ground.",
        "ch05_map_delay_noise":
            "Detection delay against joint-angle noise: colour is the largest ratio "
            "V(tau0 of cycle k+1) / V(tau0 of cycle k) (log scale; weak stability needs at "
            "most 1.1 above the step's floor of V), rings mark weakly stable points. Every "
            "point is weakly stable and the delay changes nothing; with noise the V(tau0) "
            "are snapshots of a noise floor (1e-6) below the scheme's floor allowance, so "
            "their ratio is not a growth.",
        "ch05_curve_step_size":
            "Step size h: V at the transition start of cycle 1 (left) follows the h² line; "
            "the largest penetration (right) stays below h |u-| (1 - e/2), u- the landing "
            "speed.",
        "ch05_curve_ground_offset":
            "Real ground at y = c while the controller believes y = 0: landing speed against "
            "the dive's speed where it crosses c (no landing for c below -d_max), contact "
            "force offset against g1 g2 c / (1 + K_f), take-off shift (a lower ground lets "
            "the arm lift off early by offset / c_lambda).",
        "ch05_curve_force_sensor":
            "Force sensor read by the force loop: the contact force ratio follows "
            "(1 + K_f)/(1 + a K_f) while a K_f < 1 (shaded: unstable loop, the contact is "
            "lost); a positive bias makes the arm lift off early by K_f b/((1 + K_f) "
            "c_lambda); noise only near the end of the contact phase.",
    })]
