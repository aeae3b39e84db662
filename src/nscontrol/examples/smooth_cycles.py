"""Limit cycles of smooth autonomous flows, found by shooting with the variational equation.

Known answers (:mod:`nscontrol.testing.cycle_problems`): the polar normal form
``r' = r(1 - r)(2 - r)``, ``θ' = ω`` has the cycles ``r = 1`` (multiplier ``exp(-2π/ω)``)
and ``r = 2`` (``exp(4π/ω)``), period ``2π/ω``; Van der Pol's cycle for small ``ε`` has
``ln μ = -2πε - (π/4)ε³ + O(ε⁵)`` (averaging: ``exp(-2πε)``), period
``2π(1 + ε²/16 - 5ε⁴/3072 + O(ε⁶))`` and amplitude ``2 + ε²/96 + O(ε⁴)``; the Hopf normal
form ``r' = r(μ - r²)`` has the cycle ``r = √μ`` with multiplier ``exp(-4πμ/ω)``, which
continuation in ``μ`` must follow.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import Example, ExampleResult, check, verdict_from
from ._figures import new_figure, save_figure

__all__ = ["EXAMPLES", "polar_errors", "van_der_pol_errors", "hopf_branches", "run"]

#: DOP853 tolerance of the switching method (its default) and the factor K of the global
#: error bound K·rtol over one period (tens to hundreds of steps; see the tests).
RTOL, K = 1e-11, 100


def polar_errors(omega: float = 4.0) -> list[dict[str, float]]:
    """Both cycles of ``r' = r(1 - r)(2 - r)``: errors of radius, period and multiplier
    (relative), and the trivial multiplier's distance to 1."""
    from ..analysis.orbits import find_cycle
    from ..testing.cycle_problems import polar_normal_form

    system, cycles = polar_normal_form(omega=omega)
    out = []
    for known in cycles:
        r = float(known.x0[0])
        guess = known.x0 * (1.0 + (0.01 if r < 1.5 else -0.01))
        cyc = find_cycle(system, guess, 1.02 * known.period, normal=known.normal,
                         tol=10 * RTOL)
        out.append({"radius": r, "multiplier": known.multiplier,
                    "radius_error": abs(float(np.hypot(*cyc.x0)) - r),
                    "period_error": abs(cyc.period - known.period) / known.period,
                    "multiplier_error": abs(complex(cyc.nontrivial[0]) - known.multiplier)
                    / known.multiplier,
                    "trivial_error": abs(complex(cyc.multipliers[cyc.trivial_index]) - 1.0),
                    "stable": cyc.stable})
    return out


def van_der_pol_errors(eps: float) -> dict[str, Any]:
    """Van der Pol's cycle at ``ε`` against the Poincaré–Lindstedt series, with the cycle's
    samples for a figure."""
    from ..analysis.orbits import find_cycle
    from ..simulate import simulate
    from ..testing.cycle_problems import van_der_pol, van_der_pol_series

    series = van_der_pol_series(eps)
    system = van_der_pol(eps)
    cyc = find_cycle(system, [series["amplitude"], 0.0], series["period"], normal=[0.0, 1.0],
                     offset=0.0, tol=10 * RTOL)
    mu = float(cyc.nontrivial[0].real)
    t = np.linspace(0.0, cyc.period, 400)
    tr = simulate(system, cyc.x0, (0.0, cyc.period), t_eval=t)
    return {"eps": eps, "period": cyc.period, "amplitude": float(cyc.x0[0]), "multiplier": mu,
            "period_error": abs(cyc.period - series["period"]),
            "amplitude_error": abs(float(cyc.x0[0]) - series["amplitude"]),
            "log_multiplier_error": abs(np.log(mu) - series["log_multiplier"]),
            "averaging_error": float(np.log(mu / series["averaging_multiplier"])),
            "x": tr.x}


def hopf_branches(omega: float = 2.0) -> list[Any]:
    """The Hopf normal form's cycle continued in ``μ`` from 0.25 up and down over
    ``[0.1, 1]`` (each branch ends with its first point outside)."""
    from ..analysis.continuation import continue_orbit

    return [continue_orbit(_HopfFamily(omega), 0.25, [0.51, 0.0], p_range=(0.1, 1.0), step=0.05,
                           step_max=0.2, direction=d, parameter_name="μ") for d in (1, -1)]


class _HopfFamily:
    """``μ -> Autonomous`` (picklable): the cycle's phase condition is ``y = 0``."""

    def __init__(self, omega: float) -> None:
        self.omega = omega

    def __call__(self, mu: float) -> Any:
        from ..analysis.orbits import Autonomous
        from ..testing.cycle_problems import hopf_normal_form

        system, _ = hopf_normal_form(mu, self.omega)
        return Autonomous(system, 1.01 * 2 * np.pi / self.omega, normal=[0.0, 1.0], offset=0.0)


def run(out_dir: Path | None) -> ExampleResult:
    """Polar normal form, Van der Pol (small and moderate ε) and the Hopf branch."""
    integration = K * RTOL
    polar = polar_errors()
    small = van_der_pol_errors(0.1)
    vdp = [small] + [van_der_pol_errors(e) for e in (1.0, 2.0)]
    branches = hopf_branches()
    omega, T = 2.0, np.pi
    mu = np.concatenate([b.p for b in branches])
    radius = np.concatenate([b.x0[:, 0] for b in branches])
    mult = np.concatenate([b.multipliers[:, 0].real for b in branches])
    ok = mu >= 0.1      # where the error bounds below hold (a branch's last point may not)
    hopf_radius = float(np.max(np.abs(radius - np.sqrt(mu))[ok]))
    hopf_mult = float(np.max(np.abs(mult / np.exp(-4 * np.pi * mu / omega) - 1.0)[ok]))
    checks = []
    for c in polar:
        tag = f"r = {c['radius']:g} cycle"
        checks += [
            check(f"{tag}: period error (relative)", c["period_error"], integration,
                  note="bound K·rtol: the phase's global integration error"),
            check(f"{tag}: multiplier error (relative to the exact {c['multiplier']:.4g})",
                  c["multiplier_error"], integration,
                  note="bound K·rtol: the variational equation's global error"),
            check(f"{tag}: trivial multiplier |μ - 1|", c["trivial_error"],
                  integration * max(1.0, c["multiplier"])),
        ]
    e = small["eps"]
    checks += [
        check("Van der Pol ε = 0.1: |ln μ - (-2πε - (π/4)ε³)|", small["log_multiplier_error"],
              e ** 5 + integration, note="series remainder O(ε⁵), coefficient taken <= 1"),
        check("Van der Pol ε = 0.1: |T - 2π(1 + ε²/16 - 5ε⁴/3072)|", small["period_error"],
              e ** 6 + integration * small["period"],
              note="series remainder O(ε⁶), coefficient taken <= 1"),
        check("Van der Pol ε = 0.1: |x_max - (2 + ε²/96)|", small["amplitude_error"],
              e ** 4 / 100 + integration, note="series remainder 1033ε⁴/552960 < ε⁴/100"),
        check("Hopf branch: max |r - √μ| along the continuation (μ >= 0.1)", hopf_radius,
              (1e-10 * T + integration) / 0.47,
              note="corrector residual 1e-10·T over min |1 - μ_mult|, ω√μ >= 0.47"),
        check("Hopf branch: max relative error of the multiplier exp(-4πμ/ω) (μ >= 0.1)",
              hopf_mult, integration + 6 * 1.1 * T * (1e-10 * T + integration) / 0.47,
              note="the radius error through ∂/∂r of the exponent ∮(μ - 3r²)dt, 6rT"),
        check("Hopf branch: continued from μ = 0.25 beyond both ends of [0.1, 1]",
              int(mu.min() < 0.1 and mu.max() > 1.0), 1, "=="),
    ]
    metrics = {"polar": [{k: v for k, v in c.items()} for c in polar],
               "van_der_pol": [{k: v for k, v in d.items() if k != "x"} for d in vdp],
               "hopf_points": int(mu.size), "hopf_steps": sum(b.n_steps for b in branches),
               "hopf_corrector_iterations": sum(b.corrector_iterations for b in branches),
               "hopf_radius_error": hopf_radius, "hopf_multiplier_error": hopf_mult}
    figures: list[Path] = []
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(9.0, 4.0))
    for k, d in enumerate(vdp):
        ax1.plot(d["x"][:, 0], d["x"][:, 1], color=f"C{k}",
                 label=f"ε = {d['eps']:g}: T = {d['period']:.4f}, μ = {d['multiplier']:.2g}")
    ax1.set_xlabel("x")
    ax1.set_ylabel("v = x'")
    ax1.set_ylim(-4.5, 6.5)        # room for the legend above the cycles
    ax1.set_title("Van der Pol limit cycles")
    ax1.legend(loc="upper left", fontsize="small")
    grid = np.linspace(0.0, 1.05, 200)
    ax2.plot(grid, np.sqrt(grid), color="0.6", lw=3, label="r = √μ (exact)")
    ax2.plot(mu, radius, "o", color="C3", label="continuation from μ = 0.25 (x on y = 0)")
    ax2.set_xlabel("μ")
    ax2.set_ylabel("cycle radius")
    ax2.set_title("Hopf normal form r' = r(μ - r²)")
    ax2.legend(loc="lower right", fontsize="small")
    save_figure(fig, out_dir, "smooth_cycles", figures)
    return ExampleResult("smooth-cycles", metrics, checks, figures,
                         summary="limit cycles of smooth flows by shooting on the DOP853 "
                                 "variational equation: exact polar cycles, Van der Pol "
                                 "against its series, the Hopf branch by continuation")


EXAMPLES = [Example(
    "smooth-cycles", "Limit cycles of smooth flows: polar normal forms, Van der Pol, Hopf",
    "orbits", run,
    claim="Shooting with the variational equation finds the limit cycles of smooth flows: "
          "the exact cycles of polar normal forms to the integrator's tolerance, Van der "
          "Pol's multiplier exp(-2πε - (π/4)ε³) for small ε, and the Hopf branch r = √μ "
          "by continuation.",
    verdict=verdict_from(("r = 1 cycle: multiplier", "multiplier error"),
                         ("ε = 0.1: |ln μ", "Van der Pol log-multiplier error")),
    captions={"smooth_cycles": "Left: Van der Pol limit cycles for ε = 0.1, 1 and 2 (the "
                               "near-circle of radius 2 turns into a relaxation oscillation). "
                               "Right: the Hopf normal form's cycle continued in μ lies on the "
                               "exact r = √μ."})]
