"""Chapter 5: robustness of the switching passivity-based tracking controller of chapter 3.

The two-link task of :mod:`.ch03_two_link_tracking` (current configuration, ``h = 1e-3``, two
cycles per point) is swept over two pairs of parameters with :func:`nscontrol.sweep.run`:

* restitution ``e`` of the ground x model scale ``ŝ`` (the controller's ``M, C, g`` are the
  plant's times ``ŝ``);
* delay ``k`` (steps) in detecting the impact and the persistent contact x standard deviation
  ``σ`` (rad) of the noise on the measured joint angles.

Each point gives cycles completed, worst tracking error at the transition start, largest growth
of ``V(τ0ᵏ)`` from cycle to cycle, penetration and the weak-stability verdict
(:func:`~.ch03_two_link_tracking.robustness_point`). The checks compare the maps with the
analysis of ``docs/ch05.md``: the critical model scale ``ŝ* = 1 + γ1 γ2 d_max / g_n`` above
which the pressing force cannot beat the over-compensated weight, and the ultimate bound
``√κ(M) ‖Δ‖ / (γ1 γ2)`` of the free-phase error under model error.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from . import Check, Example, ExampleResult, check, verdict_from

__all__ = ["RESTITUTIONS", "MODEL_SCALES", "DELAYS", "NOISES", "grids", "robustness_maps",
           "critical_model_scale", "hover_height", "model_error_bound", "robustness_checks",
           "EXAMPLES"]

#: Restitution coefficients of the first map (0: plastic; 0.7: the nominal ground).
RESTITUTIONS = (0.0, 0.7, 0.95)
#: Model scales of the first map; 1.3 lies beyond the predicted critical scale (about 1.29).
MODEL_SCALES = (0.8, 1.0, 1.2, 1.3)
#: Detection delays (steps of h = 1e-3) of the second map.
DELAYS = (0, 2, 5)
#: Noise standard deviations (rad) on the measured joint angles, second map.
NOISES = (0.0, 3e-4, 1e-3)
#: The map values, as returned by ``robustness_point``.
FIELDS = ("cycles_completed", "worst_tau0_error", "worst_V_growth", "penetration",
          "weakly_stable", "gap_before_first_takeoff")
#: Step and cycles of every point (the run time of the example is about 20 points x 5 s).
H, CYCLES = 1e-3, 2


def grids() -> dict[str, list[dict[str, Any]]]:
    """The two grids as lists of ``robustness_point`` arguments, row-major.

    Returns
    -------
    dict
        ``"restitution-model"`` (rows: ``e``, columns: ``ŝ``) and ``"delay-noise"`` (rows:
        delay, columns: ``σ``).
    """
    base = {"h": H, "cycles": CYCLES}
    return {
        "restitution-model": [{**base, "restitution": e, "model_scale": s}
                              for e in RESTITUTIONS for s in MODEL_SCALES],
        "delay-noise": [{**base, "detection_delay": k, "position_noise": sg}
                        for k in DELAYS for sg in NOISES],
    }


def robustness_maps(result: Any, shape: tuple[int, int]) -> dict[str, Any]:
    """Arrays of the per-point values of a sweep; a failed point is NaN (``False`` for the
    verdict) and its error is kept.

    Parameters
    ----------
    result : SweepResult
        Outcome of ``sweep.run(robustness_point, grid)`` on a row-major grid.
    shape : tuple of int
        ``(rows, columns)`` of the grid.

    Returns
    -------
    dict
        One ``shape`` array per name of :data:`FIELDS`, ``"most_impacts"`` (most impact events
        in a cycle) and ``"errors"``: the failed points as ``{"index", "point", "error"}``.
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
            maps[f][idx] = value[f]
        maps["most_impacts"][idx] = max(value.get("impacts_per_cycle") or [np.nan])
    maps["errors"] = errors
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
    ratio = max(float(m1["worst_tau0_error"][i, j]) / model_error_bound(s)
                for i in range(len(RESTITUTIONS)) for j, s in enumerate(MODEL_SCALES)
                if s != 1.0 and s < s_crit)
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
    checks.append(check("Penetration over every point that reached contact (worst, m)", pen,
                        1e-4, note="a landing penetrates at most h |u-| ~ 1e-3 x 0.05 m/s",
                        key="penetration"))
    checks.append(check("Sweep points lost to an error", len(m1["errors"]) + len(m2["errors"]),
                        0, "==", note="a failed point would be NaN in its map, its error "
                                      "listed in the metrics", key="no_failed_points"))
    return checks


def run(out_dir: Path | None) -> ExampleResult:
    """Both sweeps (about 20 points), their checks and one map per pair."""
    from .. import sweep
    from .ch03_two_link_tracking import robustness_point

    g = grids()
    r1 = sweep.run(robustness_point, g["restitution-model"], executor="auto",
                   desc="e x model scale")
    r2 = sweep.run(robustness_point, g["delay-noise"], executor="auto",
                   desc="delay x noise")
    m1 = robustness_maps(r1, (len(RESTITUTIONS), len(MODEL_SCALES)))
    m2 = robustness_maps(r2, (len(DELAYS), len(NOISES)))
    checks = robustness_checks(m1, m2)
    figures: list[Path] = []
    _map_figure(m1, [f"{s:g}" for s in MODEL_SCALES], [f"{e:g}" for e in RESTITUTIONS],
                "controller model scale s (M, C, g) [-]", "restitution e [-]",
                "Restitution x model error", out_dir, "ch05_map_restitution_model", figures,
                critical_x=float(np.interp(critical_model_scale(), MODEL_SCALES,
                                           range(len(MODEL_SCALES)))))
    _map_figure(m2, [f"{s:g}" for s in NOISES], [f"{k}" for k in DELAYS],
                "joint-angle noise sigma [rad]", "detection delay [steps of 1 ms]",
                "Detection delay x measurement noise", out_dir, "ch05_map_delay_noise",
                figures, field="worst_V_growth",
                colour_label="largest V(tau0) growth per cycle [-]")
    metrics = {"h": H, "cycles": CYCLES, "critical_model_scale": critical_model_scale(),
               "restitution_model": _json_map(m1, RESTITUTIONS, MODEL_SCALES),
               "delay_noise": _json_map(m2, DELAYS, NOISES),
               "failed_points": m1["errors"] + m2["errors"]}
    n_stable = int(m1["weakly_stable"].sum() + m2["weakly_stable"].sum())
    return ExampleResult("ch05-robustness", metrics=metrics, checks=checks, figures=figures,
                         summary=f"{n_stable} of {len(r1) + len(r2)} points weakly stable; "
                                 f"predicted critical model scale "
                                 f"{metrics['critical_model_scale']:.3f}")


def _json_map(m: dict[str, Any], rows: tuple, cols: tuple) -> dict[str, Any]:
    return {"rows": list(rows), "columns": list(cols),
            **{f: np.asarray(m[f]).tolist() for f in (*FIELDS, "most_impacts")}}


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


EXAMPLES = [Example(
    "ch05-robustness",
    "Robustness maps of the tracking controller: restitution, model error, detection delay, "
    "measurement noise",
    "ch05", run,
    claim="The switching passivity-based controller of chapter 3 stays weakly stable over "
          "every restitution coefficient below 1, a model error of up to 20 %, a delay of up "
          "to five steps in detecting the impacts and joint-angle noise of up to 1 mrad; it "
          "fails where the analysis says it must, when the controller over-compensates the "
          "arm's weight by more than the largest pressing force of the virtual dive, and "
          "then for the predicted reason: after a graze the arm comes to rest hovering a few "
          "millimetres above the ground instead of sliding on it.",
    verdict=verdict_from(("nominal_stable", "nominal point weakly stable"),
                         ("stable_below_critical_scale", "unstable points below the "
                                                         "critical scale"),
                         ("fails_above_critical_scale", "points above it completing a "
                                                        "cycle"),
                         ("failure_is_hovering", "their hover gap")),
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
            "most 1.1), rings mark weakly stable points. Every point is weakly stable: noise "
            "raises the ratio from 0.003 to about 0.05, the delay leaves it unchanged.",
    })]
