"""Mechanics examples: the bouncing ball (event-driven vs Moreau–Jean, Zeno accumulation)
and Newton's cradle (velocity exchange, momentum and energy per impact).

The checks are the conformance claims of the mechanics integrators (issue 3): exact impact
times and accumulation point event-driven, impact capture within 2h per flight and bounded
penetration with Moreau–Jean, conservation at every impact of the cradle.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Example, ExampleResult, check, verdict_from

H = 1e-3


def run_bouncing_ball(out_dir: Path | None) -> ExampleResult:
    from ..simulate import simulate
    from ..testing.mechanics_problems import BouncingBall
    from ._figures import new_figure, save_figure

    ball = BouncingBall(restitution=0.9, height=1.0, g=9.81)
    ed = simulate(ball.system(), ball.x0, (0.0, 10.0), method="event_driven", dt=1e-3)
    mj = simulate(ball.system(), ball.x0, (0.0, 10.0), method="moreau_jean", h=H)
    ted, tmj = ed.event_times("impact"), mj.event_times("impact")
    exact = ball.impact_times(20)
    err_ed = float(np.max(np.abs(ted[:20] - exact)))
    err_mj = tmj[:20] - exact
    t_acc = float(ed.event_times("accumulation")[0])
    after = ed.t > t_acc
    rest = mj.t > ball.accumulation_time + 0.2
    result = ExampleResult("bouncing-ball", summary=(
        f"20 impact times to {err_ed:.1e} s event-driven, accumulation at {t_acc:.6f} s "
        f"(analytic {ball.accumulation_time:.6f}); Moreau-Jean h={H:g}: "
        f"{tmj.size} impacts, penetration {mj.stats['max_penetration']:.2e}"))
    result.metrics.update(
        impacts_event_driven=int(ted.size), impacts_moreau_jean=int(tmj.size),
        accumulation_time=t_acc, max_impact_time_error_event_driven=err_ed,
        max_impact_time_error_moreau_jean=float(np.max(np.abs(err_mj))),
        penetration_moreau_jean=mj.stats["max_penetration"])
    result.checks += [
        check("event-driven impact times (first 20) error [s]", err_ed, 1e-12),
        check("accumulation time error [s]", abs(t_acc - 8.57895), 5e-6),
        check("at rest after the accumulation (event-driven) max|x|",
              float(np.max(np.abs(ed.x[after]))), 1e-12),
        check("Moreau-Jean first impact error / h", float(abs(err_mj[0]) / H), 2.0),
        check("Moreau-Jean flight-interval error / h", float(np.max(np.abs(np.diff(err_mj))) / H),
              2.0),
        check("Moreau-Jean penetration / (h v_max)",
              mj.stats["max_penetration"] / (H * ball.impact_velocity(0)), 1.0),
        check("Moreau-Jean at rest at the end |v|", float(np.max(np.abs(mj.x[rest, 1]))), 1e-12),
    ]
    fig, axes = new_figure(3, 1, sharex=True, figsize=(8, 7))
    axes[0].plot(ed.t, ed.x[:, 0], label="event-driven (exact)")
    axes[0].plot(mj.t, mj.x[:, 0], "--", label=f"Moreau-Jean h={H:g}")
    axes[0].plot(ted, np.zeros_like(ted), "k|", ms=8, label="impacts")
    axes[0].axvline(t_acc, color="r", lw=0.8, label=f"accumulation {t_acc:.4f} s")
    axes[0].set_ylabel("height q [m]")
    axes[0].legend(fontsize="small")
    axes[1].plot(ed.t, ed.x[:, 1], label="event-driven")
    axes[1].plot(mj.t, mj.x[:, 1], "--", label="Moreau-Jean")
    axes[1].set_ylabel("velocity v [m/s]")
    axes[2].plot(ed.t, ed.signals["energy"], label="event-driven")
    axes[2].plot(mj.t, mj.signals["energy"], "--", label="Moreau-Jean")
    axes[2].set_ylabel("energy [J]")
    axes[2].set_xlabel("t [s]")
    axes[2].legend(fontsize="small")
    save_figure(fig, out_dir, "bouncing_ball", result.figures)
    return result


def run_newtons_cradle(out_dir: Path | None) -> ExampleResult:
    from ..simulate import simulate
    from ..testing.mechanics_problems import NewtonsCradle
    from ._figures import new_figure, save_figure

    cradle = NewtonsCradle(n=5, spacing=0.01, velocity=1.0)
    n = cradle.n
    t_end = cradle.final_time + 0.02
    ed = simulate(cradle.system(), cradle.x0, (0.0, t_end), dt=1e-4)
    mj = simulate(cradle.system(), cradle.x0, (0.0, t_end), method="moreau_jean", h=1e-4)
    momentum_err = max(abs(float(np.sum(x[n:])) - 1.0) for ev in ed.events_of("impact")
                       for x in (ev.pre, ev.post))
    energy_err = max(abs(0.5 * float(np.sum(x[n:] ** 2)) - 0.5)
                     for ev in ed.events_of("impact") for x in (ev.pre, ev.post))
    v_mj = mj.x[:, n:]
    result = ExampleResult("newtons-cradle", summary=(
        f"{n} beads: velocity handed bead to bead in {len(ed.events_of('impact'))} impacts; "
        f"momentum/energy kept to {max(momentum_err, energy_err):.1e}"))
    result.metrics.update(impacts=len(ed.events_of("impact")),
                          momentum_error_event_driven=momentum_err,
                          energy_error_event_driven=energy_err)
    result.checks += [
        check("event-driven momentum error per impact", momentum_err, 1e-12),
        check("event-driven energy error per impact", energy_err, 1e-12),
        check("impact times error [s]", float(np.max(np.abs(
            ed.event_times("impact") - cradle.impact_times()))), 1e-12),
        check("last bead leaves with the striker's velocity",
              float(abs(ed.x[-1, 2 * n - 1] - 1.0)), 1e-12),
        check("Moreau-Jean momentum error", float(np.max(np.abs(v_mj.sum(axis=1) - 1.0))), 1e-12),
        check("Moreau-Jean energy error",
              float(np.max(np.abs(0.5 * (v_mj**2).sum(axis=1) - 0.5))), 1e-12),
    ]
    fig, axes = new_figure(2, 1, sharex=True, figsize=(8, 6))
    for i in range(n):
        axes[0].plot(ed.t, ed.x[:, i], label=f"bead {i}")
        axes[1].plot(ed.t, ed.x[:, n + i])
    for te in ed.event_times("impact"):
        for a in axes:
            a.axvline(te, color="0.8", lw=0.6, zorder=0)
    axes[0].set_ylabel("position [m]")
    axes[0].legend(fontsize="small", ncol=n)
    axes[1].set_ylabel("velocity [m/s]")
    axes[1].set_xlabel("t [s]")
    save_figure(fig, out_dir, "newtons_cradle", result.figures)
    return result


EXAMPLES = [
    Example(
        "bouncing-ball", "Bouncing ball: exact event-driven vs Moreau-Jean, Zeno "
        "accumulation then rest", "mechanics", run_bouncing_ball,
        claim="A ball bouncing with restitution 0.9 makes infinitely many impacts that "
              "accumulate at a finite time (8.5789 s), after which it rests. The event-driven "
              "integrator finds every impact time exactly and passes the accumulation point; "
              "Moreau-Jean time-stepping captures each impact within a step or two.",
        verdict=verdict_from(("event-driven impact times", "impact times exact to"),
                             ("accumulation time", "accumulation time error")),
        captions={"bouncing_ball": "Height, velocity and energy of the ball against time: "
                  "the event-driven (exact) and Moreau-Jean curves lie on top of each other; "
                  "the bounces shrink geometrically and stop at the accumulation time."}),
    Example(
        "newtons-cradle", "Newton's cradle: velocity exchange, momentum and energy per "
        "impact", "mechanics", run_newtons_cradle,
        claim="In Newton's cradle a striker's velocity passes from bead to bead at elastic "
              "impacts. Momentum and energy are conserved at every impact to rounding error, "
              "and the last bead leaves with the striker's velocity.",
        verdict=verdict_from(("event-driven momentum", "momentum error per impact"),
                             ("event-driven energy", "energy error per impact")),
        captions={"newtons_cradle": "Positions and velocities of the beads: each impact hands "
                  "the whole velocity to the next bead, so one bead moves at a time."}),
]
