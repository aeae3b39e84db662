"""Issue 33, example (4): a ball juggled by a vibrating paddle. The period-1 gait is found as a
periodic optimal control problem (least paddle amplitude with a stability margin,
:mod:`nscontrol.optimal.periodic`), replayed through Moreau–Jean, and the planned paddle's
orbit is found and its Floquet multipliers computed by the library's orbit tools
(event-driven, saltation matrices), against the closed forms.

Needs the ``optimal`` extra (CasADi); imported only when the example runs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import Example, ExampleResult, check, verdict_from

STEPS = (100, 200)


def run_juggler(out_dir: Path | None) -> ExampleResult:
    from ..analysis.orbits import Forced, find_orbit
    from ..optimal import VibratingTable, ZeroOrderHold
    from ..simulate import simulate
    from ._figures import new_figure, save_figure

    table = VibratingTable()
    A, psi = table.optimum()
    plans = {n: table.problem(n).solve() for n in STEPS}
    jp, n = plans[STEPS[-1]], STEPS[-1]
    p = jp.plan
    u = ZeroOrderHold(0.0, p.h, np.vstack([p.u, p.u]))
    run = simulate(table.system(), p.x[2], (2 * p.h, (n + 2) * p.h), method="moreau_jean",
                   h=p.h, u=u)
    replay = float(np.max(np.abs(run.x - np.vstack([p.x[2:], p.x[1:3]]))))
    k = n // 2
    forced = Forced(table.system(), table.paddle(jp.amplitude, jp.phase + table.omega * k * p.h),
                    table.period, method="event_driven")
    orb = find_orbit(forced, p.x[k], tol=1e-12)
    mu_closed = table.multipliers(jp.amplitude)
    mu_err = float(np.max(np.abs(np.sort_complex(orb.multipliers)
                                 - np.sort_complex(mu_closed))))
    err = {m: abs(plans[m].amplitude - A) for m in STEPS}
    ratio = err[STEPS[0]] / err[STEPS[1]]
    result = ExampleResult("juggler", summary=(
        f"least paddle amplitude {jp.amplitude:.6f} m (closed form {A:.6f}, N={n}); "
        f"replay {replay:.1e}; multipliers {np.abs(orb.multipliers[0]):.4f}∠ by the orbit "
        f"tools vs closed form to {mu_err:.1e}"))
    result.metrics.update(
        amplitude_closed_form=A, phase_closed_form=psi,
        amplitude_planned={str(m): plans[m].amplitude for m in STEPS},
        phase_planned={str(m): plans[m].phase for m in STEPS},
        multipliers_library=orb.multipliers, multipliers_closed_form=mu_closed,
        multipliers_at_optimum=table.multipliers(A), replay_error=replay,
        solve_time_s={str(m): plans[m].plan.stats["solve_time"] for m in STEPS})
    h = table.period / STEPS[0]
    result.checks += [
        check("amplitude error ratio N=100 / N=200 (first order: 2)", ratio, 1.8, op=">="),
        check("amplitude error ratio N=100 / N=200, upper", ratio, 2.2),
        check("Richardson amplitude error [m]",
              abs(2 * plans[STEPS[1]].amplitude - plans[STEPS[0]].amplitude - A),
              table.omega ** 2 * A * h ** 2),
        check("plan replayed through Moreau-Jean, max state error", replay, n * 1e-10),
        check("multipliers: orbit tools vs closed form", mu_err, 1e-9),
        check("|det monodromy| - e^2", abs(abs(np.prod(orb.multipliers))
                                           - table.restitution ** 2), 1e-9),
        check("planned gait stable (max |multiplier|)", float(np.abs(orb.multipliers[0])),
              1.0, op="<"),
        check("complementarity residual", p.residual, 1e-8),
    ]
    fig, axes = new_figure(3, 1, figsize=(8, 8))
    t = np.linspace(0.0, table.period, 400)
    exact = table.state(A, t)
    axes[0].plot(t, exact[:, 0], label="closed-form gait (A*)")
    axes[0].plot(p.t, p.x[:, 0], ".", ms=3, label=f"plan, Moreau-Jean N={n}")
    axes[0].plot(run.t, run.x[:, 0], "--", lw=0.8, label="replay through simulate")
    axes[0].set_ylabel("height above paddle z [m]")
    axes[0].set_xlabel("t [s]")
    axes[0].legend(fontsize="small")
    axes[1].step(p.t[:-1], p.u[:, 0], where="post", label="planned -s''(t)")
    axes[1].plot(t, A * table.omega ** 2 * np.sin(table.omega * t + psi), "--",
                 label="closed-form optimum")
    axes[1].set_ylabel("paddle input u = -s'' [m/s²]")
    axes[1].set_xlabel("t [s]")
    axes[1].legend(fontsize="small")
    circle = np.exp(1j * np.linspace(0, 2 * np.pi, 200))
    axes[2].plot(circle.real, circle.imag, "k", lw=0.6)
    axes[2].plot(orb.multipliers.real, orb.multipliers.imag, "o", label="orbit tools")
    axes[2].plot(mu_closed.real, mu_closed.imag, "x", ms=10, label="closed form")
    axes[2].set_aspect("equal")
    axes[2].set_xlabel("Re μ")
    axes[2].set_ylabel("Im μ")
    axes[2].legend(fontsize="small")
    save_figure(fig, out_dir, "juggler", result.figures)
    return result


EXAMPLES = [
    Example(
        "juggler", "Juggler: a periodic gait as a periodic optimal control problem, its "
        "Floquet multipliers by the orbit tools", "optimal", run_juggler,
        claim="The least vibration of a paddle that keeps a ball bouncing once per period, "
              "with the paddle decelerating at the impact, has a closed form, and so do the "
              "gait's Floquet multipliers. The periodic Moreau-Jean transcription finds it "
              "to first order in h, its plan replays through simulate, and the library's "
              "orbit tools find the planned paddle's orbit and multipliers exactly.",
        verdict=verdict_from(("multipliers: orbit tools", "multipliers match the closed "
                              "form to {value} (bound {bound})"),
                             ("replayed", "replay error {value}"),
                             ("Richardson", "extrapolated amplitude error {value} m")),
        captions={"juggler": "Top: the ball's height above the paddle over one period, the "
                  "closed form, the plan and its Moreau-Jean replay on top of each other. "
                  "Middle: the planned paddle input against the optimal sinusoid. Bottom: "
                  "the Floquet multipliers inside the unit circle, library and closed form "
                  "coinciding."}),
]
