"""Coulomb friction at contacts: the known answers of frictional Moreau–Jean.

Every scenario here has a closed-form answer from elementary mechanics (the slope at which a
block starts to slide and its acceleration, the stopping time of a pushed block, the time at
which a disk or a sphere thrown with backspin starts rolling), except the brick stack, whose
answer is rest. The scenarios and parameters are ours.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from . import Check, Example, ExampleResult, check, verdict_from
from ._figures import new_figure, save_figure

__all__ = ["PARAMETERS", "EXAMPLES"]

#: Step, gravity, friction coefficient, and the scenarios' data.
PARAMETERS: dict[str, float] = {
    "h": 1e-3, "g": 9.81, "mu": 0.5, "T_plane": 0.5, "v0_push": 2.0,
    "disk_R": 0.1, "disk_mu": 0.2, "disk_v0": 1.0, "disk_w0": 5.0,
    "sphere_mu": 0.3, "sphere_v0": 2.0, "sphere_w0": 10.0,
    "stack_n": 10, "stack_angle": 0.1, "stack_T": 10.0, "ball_e": 0.9, "ball_T": 3.0,
}
_EPS = float(np.finfo(float).eps)


def _simulate(system: Any, x0: Any, T: float, **kw: Any) -> Any:
    from ..simulate import simulate

    return simulate(system, x0, (0.0, T), method="moreau_jean", h=PARAMETERS["h"],
                    progress=False, **kw)


def _plane_checks(ctx: dict[str, Any]) -> None:
    from ..systems.frictional_bodies import inclined_block

    p = PARAMETERS
    mu, g, T, h = p["mu"], p["g"], p["T_plane"], p["h"]
    ratios = np.linspace(0.3, 0.7, 9)
    measured, predicted, runs = [], [], {}
    for ratio in ratios:
        angle = float(np.arctan(ratio))
        traj = _simulate(inclined_block(mu, angle), [0.0] * 4, T)
        measured.append(traj.x[-1, 2] / T)
        predicted.append(max(0.0, g * (np.sin(angle) - mu * np.cos(angle))))
        runs[float(ratio)] = traj
    measured_a, predicted_a = np.array(measured), np.array(predicted)
    stuck = ratios <= mu
    n = int(round(T / h))
    ctx["plane"] = (ratios, measured_a, predicted_a, runs)
    ctx["checks"] += [
        check("largest speed of a block on a slope below the friction angle [m/s]",
              float(np.max(np.abs(measured_a[stuck]))) * T, 4 * n * _EPS * g * h,
              note="the stick impulse cancels h g sin(theta) to a few ulps a step",
              key="check_1"),
        check("largest relative error of the sliding acceleration g (sin - mu cos)",
              float(np.max(np.abs(measured_a[~stuck] - predicted_a[~stuck])
                           / predicted_a[~stuck])), 4 * n * _EPS * 10,
              note="v_k = k h a exactly; round-off of n additions, relative to a / (10 g)",
              key="check_2")]
    ctx["metrics"]["plane_friction_ratio_threshold"] = mu


def _push_checks(ctx: dict[str, Any]) -> None:
    from ..systems.frictional_bodies import inclined_block

    p = PARAMETERS
    mu, g, h, v0 = p["mu"], p["g"], p["h"], p["v0_push"]
    traj = _simulate(inclined_block(mu), [0.0, 0.0, v0, 0.0], 0.6)
    k = int(np.argmax(traj.x[:, 2] == 0.0))
    t_stop, d_stop = v0 / (mu * g), v0**2 / (2 * mu * g)
    ctx["push"] = traj
    ctx["checks"] += [
        check("pushed block: stopping time minus v0 / (mu g) [s]", float(traj.t[k] - t_stop),
              h, "<", note="v is set to zero in the step that contains the stopping time",
              key="check_3"),
        check("pushed block: stopping distance error [m]",
              float(abs(traj.x[-1, 0] - d_stop)), mu * g * h * h / 2,
              note="trapezoidal positions are exact except in the last step (mu g h^2 / 2)",
              key="check_4")]


def _rolling_checks(ctx: dict[str, Any]) -> None:
    from ..systems.frictional_bodies import rolling_disk, rolling_sphere

    p = PARAMETERS
    g, h, R = p["g"], p["h"], p["disk_R"]
    mu, v0, w0 = p["disk_mu"], p["disk_v0"], p["disk_w0"]
    disk = _simulate(rolling_disk(mu, radius=R), [0.0, R, 0.0, v0, 0.0, w0], 0.5)
    s0 = v0 + R * w0
    slip = disk.x[:, 3] + R * disk.x[:, 5]
    k = int(np.argmax(np.abs(slip) <= 1e-12 * s0))
    t_disk = s0 / (3 * mu * g)
    mu_s, v0_s, w0_s = p["sphere_mu"], p["sphere_v0"], p["sphere_w0"]
    x0 = [0.0, 0.0, R, 0.0, 0.0, 0.0, v0_s, 0.0, 0.0, 0.0, w0_s, 0.0]
    sphere = _simulate(rolling_sphere(mu_s, radius=R), x0, 0.3)
    s0_s = v0_s - R * w0_s
    slip_s = sphere.x[:, 6] - R * sphere.x[:, 10]
    ks = int(np.argmax(np.abs(slip_s) <= 1e-12 * v0_s))
    t_sphere, v_sphere = 2 * s0_s / (7 * mu_s * g), v0_s - 2 * s0_s / 7
    E = sphere.signals["energy"]
    work = sphere.signals["friction_work"] + sphere.signals["normal_work"]
    ctx["rolling"] = (disk, slip, t_disk, sphere, slip_s, t_sphere)
    n = sphere.t.size - 1
    ctx["checks"] += [
        check("planar disk with backspin: rolling starts after s0 / (3 mu g), delay [s]",
              float(disk.t[k] - t_disk), h, "<", key="check_5"),
        check("sphere with backspin (spatial contact): rolling starts after 2 s0 / (7 mu g),"
              " delay [s]", float(sphere.t[ks] - t_sphere), h, "<", key="check_6"),
        check("sphere: rolling speed error against v0 - 2 s0 / 7 [m/s]",
              float(abs(sphere.x[-1, 6] - v_sphere)), 4 * n * _EPS * v0_s,
              note="angular momentum about the contact point is conserved by every step",
              key="check_7"),
        check("sphere: energy change minus the work of the contact impulses [J]",
              float(np.max(np.abs(E - E[0] - work))), 4 * n * _EPS * float(np.max(np.abs(E))),
              note="exact balance of the theta = 1/2 step on linear forces", key="check_8")]
    ctx["metrics"]["sphere_friction_dissipation_J"] = float(-sphere.signals["friction_work"][-1])


def _stack_checks(ctx: dict[str, Any]) -> None:
    from ..systems.frictional_bodies import brick_stack, brick_stack_rest_state

    p = PARAMETERS
    n, mu, angle, T, h, g = (int(p["stack_n"]), p["mu"], p["stack_angle"], p["stack_T"],
                             p["h"], p["g"])
    x0 = brick_stack_rest_state(n)
    start = time.perf_counter()
    traj = _simulate(brick_stack(n, mu, angle=angle), x0, T, record_every=10)
    elapsed = time.perf_counter() - start
    steps = traj.stats["steps"]
    pn, pt = traj.signals["impulse"][1:], traj.signals["friction_impulse"][1:]
    ratio = float(np.max(np.abs(pt) / np.maximum(mu * pn, np.finfo(float).tiny)))
    drift = float(np.max(np.abs(traj.x - x0)))
    bound = steps * (h * 10 * 1e-12 * h * g * np.sqrt(2 * n) + 4 * _EPS)
    ctx["stack"] = traj
    ctx["checks"] += [
        check(f"stack of {n} bricks on a slope tan = {np.tan(angle):.3g} < mu: largest drift "
              f"over {steps} steps [m or rad]", drift, bound,
              note="contact solves at relative residual 1e-12 and position round-off",
              key="check_9"),
        check("stack: largest |P_t| / (mu P_n) over all contacts and steps", ratio,
              1.0 + 1e-12, note="friction impulses in the Coulomb cone", key="check_10"),
        check("stack: share of contact-steps in stick", float(np.mean(
            traj.signals["contact_state"][1:] == 1)), 1.0, "==", key="check_11")]
    ctx["metrics"].update(stack_steps_per_second=steps / elapsed,
                          stack_max_contact_residual=traj.stats["max_contact_residual"],
                          stack_nsgs_sweeps_per_step=traj.stats["contact_sweeps"] / steps)


def _projection_checks(ctx: dict[str, Any]) -> None:
    from ..systems.lagrangian import LagrangianSystem

    p = PARAMETERS
    ball = LagrangianSystem.bouncing_ball(p["ball_e"])
    plain = _simulate(ball, [1.0, 0.0], p["ball_T"])
    proj = _simulate(ball, [1.0, 0.0], p["ball_T"], projection=True)
    t_plain, t_proj = plain.event_times("impact"), proj.event_times("impact")
    n = min(t_plain.size, t_proj.size)
    shift = np.abs(t_proj[:n] - t_plain[:n]) / p["h"]
    ctx["ball"] = (plain, proj)
    ctx["checks"] += [
        check("bouncing ball with projection: largest penetration [m]",
              proj.stats["max_penetration"], 1e-12, key="check_12"),
        check("bouncing ball with projection: same number of impacts as without",
              int(t_proj.size), int(t_plain.size), "==", key="check_13"),
        check("impact-time shift by the projection, in steps h",
              float(np.max(shift)), 1.0,
              note="each projection lifts the ball by at most h|u|/2 and takes the lift's "
                   "energy from the velocity: the next flight is the plain one advanced by "
                   "at most h/2, so impacts stay within a step and do not drift",
              key="check_14"),
        check("bouncing ball with projection: energy added by the projections [J]",
              abs(proj.stats["projection_energy"]), 1e-12,
              note=f"the lifts alone would add {proj.stats['projection_lift_energy']:.3g} J",
              key="check_15")]
    ctx["metrics"].update(
        ball_penetration_without_projection_m=plain.stats["max_penetration"],
        ball_projection_energy_J=proj.stats["projection_energy"],
        ball_projection_lift_energy_J=proj.stats["projection_lift_energy"])


def _figures(ctx: dict[str, Any], out_dir: Path | None, figures: list[Path]) -> None:
    p = PARAMETERS
    mu = p["mu"]
    fig, ax = new_figure(figsize=(6.5, 4.5))
    stack = ctx["stack"]
    pn, pt = stack.signals["impulse"][1:].ravel(), stack.signals["friction_impulse"][1:].ravel()
    ax.plot(pn, pt, "C0.", ms=3, label=f"brick stack contacts (stick, tan = "
            f"{np.tan(p['stack_angle']):.2f})")
    ratios, _, _, runs = ctx["plane"]
    for ratio, style in ((0.6, "C3s"), (0.7, "C1^")):
        tr = runs[min(runs, key=lambda r: abs(r - ratio))]
        ax.plot(tr.signals["impulse"][1:, 0], tr.signals["friction_impulse"][1:, 0], style,
                ms=6, label=f"sliding block, tan = {ratio:.1f} (on the edge)")
    top = 1.05 * float(np.max(pn))
    ax.plot([0, top], [0, mu * top], "k-", lw=1, label=f"cone edges |P_t| = {mu} P_n")
    ax.plot([0, top], [0, -mu * top], "k-", lw=1)
    ax.set_xlabel("normal impulse per step P_n [N s]")
    ax.set_ylabel("tangential impulse per step P_t [N s]")
    ax.set_title("Contact impulses in the Coulomb cone")
    ax.legend(fontsize=8)
    save_figure(fig, out_dir, "contacts_cone", figures)

    disk, slip, t_disk, sphere, slip_s, t_sphere = ctx["rolling"]
    fig, (a1, a2) = new_figure(2, 1, figsize=(7, 6), sharex=True)
    a1.plot(disk.t, slip, label="planar disk: slip x' + R theta'")
    a1.plot(sphere.t, slip_s, label="sphere: slip x' - R omega_y")
    a1.axvline(t_disk, color="C0", ls=":", label="closed-form rolling time, disk")
    a1.axvline(t_sphere, color="C1", ls=":", label="closed-form rolling time, sphere")
    a1.set_ylabel("slip velocity [m/s]")
    a1.set_title("Thrown with backspin: slip, then rolling")
    a1.legend(fontsize=8)
    a2.step(disk.t, disk.signals["contact_state"][:, 0], where="post", label="disk")
    a2.step(sphere.t, sphere.signals["contact_state"][:, 0] + 0.05, where="post",
            label="sphere (offset 0.05)")
    a2.set_yticks([0, 1, 2], ["open", "stick", "slip"])
    a2.set_ylabel("contact state")
    a2.set_xlabel("time t [s]")
    a2.legend(fontsize=8)
    save_figure(fig, out_dir, "contacts_stick_slip", figures)

    plain, proj = ctx["ball"]
    fig, ax = new_figure(figsize=(7, 4.5))
    ax.plot(plain.t, plain.signals["gap"][:, 0], label="plain Moreau-Jean")
    ax.plot(proj.t, proj.signals["gap"][:, 0], "--", label="with projection")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_ylim(-4e-3, 4e-3)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("ball height (gap) [m], zoom on the ground")
    ax.set_title(f"Penetration at h = {p['h']:g}: "
                 f"{plain.stats['max_penetration']:.2g} m without, "
                 f"{proj.stats['max_penetration']:.2g} m with projection")
    ax.legend(fontsize=8)
    save_figure(fig, out_dir, "contacts_penetration", figures)

    ratios, measured, predicted, _ = ctx["plane"]
    fig, ax = new_figure(figsize=(6.5, 4.5))
    fine = np.linspace(ratios[0], ratios[-1], 200)
    ang = np.arctan(fine)
    ax.plot(fine, np.maximum(0, p["g"] * (np.sin(ang) - mu * np.cos(ang))), "k-", lw=1,
            label="g (sin - mu cos), zero below tan = mu")
    ax.plot(ratios, measured, "C0o", label="Moreau-Jean: final speed / time")
    ax.axvline(mu, color="grey", ls=":", label=f"friction coefficient mu = {mu}")
    ax.set_xlabel("slope tan(theta)")
    ax.set_ylabel("block acceleration [m/s^2]")
    ax.set_title("Inclined plane: stick below the friction angle, Coulomb sliding above")
    ax.legend(fontsize=8)
    save_figure(fig, out_dir, "contacts_inclined_plane", figures)


def run(out_dir: Path | None = None) -> ExampleResult:
    """Every check of the frictional contacts, with the figures."""
    ctx: dict[str, Any] = {"checks": [], "metrics": {}}
    _plane_checks(ctx)
    _push_checks(ctx)
    _rolling_checks(ctx)
    _stack_checks(ctx)
    _projection_checks(ctx)
    figures: list[Path] = []
    _figures(ctx, out_dir, figures)
    checks: list[Check] = ctx["checks"]
    return ExampleResult(
        "frictional-contacts", metrics=ctx["metrics"], checks=checks, figures=figures,
        summary="Coulomb friction at planar and spatial contacts in Moreau-Jean "
                "time-stepping (one frictional contact problem a step, non-smooth Gauss-Seidel "
                "with exact local solvers), and the position projection that removes "
                "penetration. Scenarios and parameters are ours; the answers are closed-form.")


EXAMPLES = [Example(
    name="frictional-contacts", chapter="contacts",
    title="Coulomb friction at contacts and penetration-free time-stepping", run=run,
    claim="With Coulomb's law at every contact, Moreau-Jean time-stepping reproduces the "
          "closed-form answers of elementary mechanics: a block sticks below the friction "
          "angle and slides with acceleration g (sin - mu cos) above it, a disk or sphere "
          "thrown with backspin rolls after the predicted time, a brick stack stays at rest "
          "with its impulses in the cone. Projecting positions after each step removes the "
          "penetration without changing the impacts.",
    verdict=verdict_from(("check_6", "a sphere with backspin starts rolling at the closed-form "
                                     "time, {value} s late (less than a step)"),
                         ("check_12", "with projection a bouncing ball penetrates the floor by "
                                      "{value} m")),
    key_figure="contacts_stick_slip",
    captions={
        "contacts_cone": "Every contact impulse of the tilted brick stack lies inside the "
        "cone (lines); the sliding blocks' impulses lie on its edge.",
        "contacts_stick_slip": "Slip velocity of the disk and the sphere against time: it "
        "decreases linearly and vanishes at the closed-form times (dotted), then the contact "
        "sticks (lower panel).",
        "contacts_penetration": "Ball height near the ground: plain Moreau-Jean dips below "
        "zero at every landing, the projected run does not; the impacts stay aligned.",
        "contacts_inclined_plane": "Measured acceleration against the slope: zero below "
        "tan = mu, on the Coulomb line above."})]
