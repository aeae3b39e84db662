"""Chapter 12: feedback control of limit cycles by a corner (wedge) switching controller.

A constant input ``k·b`` acts only inside a wedge whose corner sits at offset ``μ_c`` from a
limit cycle ``Γ``. The corner collision makes the return map piecewise linear: the cycle
keeps its multiplier ``λ`` on the side that misses the wedge and gets ``λ(1 + a)`` on the
side that crosses it, so a new cycle appears at ``z* = −λaμ_c/(1 − λ(1 + a))``.

* Example A, ``r' = −σr(r² − 1)(r² − 4)``, ``θ' = ω`` (σ = 0.02, ω = 1): the unstable cycle
  ``r = 1`` (``λ = exp(12πσ/ω)``) gets a stable neighbour of multiplier 0.5 next to it, so
  orbits starting just outside it no longer run to ``r = 2``; with the corner inside, the
  oscillation near ``r = 1`` is suppressed. Wedge: corner ``(1 + μ_c, 0)``, half-angle 45°,
  opening along ``+x``, ``b = (1, 0)``; section the ray ``θ = −π/3``.
* Example B, Van der Pol ``x'' − ε(1 − x²)x' + x = 0`` (ε = 0.1), input on the force
  equation ``b = (0, 1)``: the stable cycle's multiplier is set to 0.2 (shrinking it) or 0.9
  (growing it). Corner on the positive ``v`` axis, wedge opening along ``+v``; section the
  line ``x = −0.5`` (``v > 0``).

The chapter's own example is not known to us: both examples, the wedge form of the
controller and the design formulas are our choices, checked here numerically.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from . import Example, ExampleResult, check, verdict_from
from ._figures import new_figure, save_figure
from .sweeps import SweepSpec

__all__ = ["EXAMPLES", "SIGMA", "OMEGA", "EPS", "example_a", "example_b", "design_a",
           "design_b", "design_point", "multiplier_point", "SWEEPS", "DESIGN_TARGETS",
           "zdm_convergence",
           "sliding_cycles", "stabilisation", "suppression", "diagram", "fd_slope", "run"]

SIGMA, OMEGA, EPS = 0.02, 1.0, 0.1
#: DOP853 tolerance of the switching method (its default).
RTOL = 1e-11
#: Tolerance of the long brute-force runs that only decide where an orbit goes.
RTOL_BRUTE = 1e-9
#: Corner offsets of the diagram (figure) and those its check is made at.
DIAGRAM_MUS = (0.0005, 0.001, 0.002, 0.004, 0.008)
CHECKED_MUS = (0.001, 0.002, 0.004)


def example_a() -> tuple[Any, Any, Any]:
    """Example A's plant, its cycle ``r = 1`` (shot) and the section ``θ = −π/3``."""
    from ..analysis.corner_maps import Section
    from ..analysis.orbits import find_cycle
    from ..testing.cycle_problems import polar_normal_form

    s = SIGMA
    plant, _ = polar_normal_form((-4 * s, 0.0, 5 * s, 0.0, -s), omega=OMEGA)
    cyc = find_cycle(plant, [1.0, 0.0], 2 * np.pi / OMEGA, normal=[0.0, 1.0])
    th = -np.pi / 3
    return plant, cyc, Section([-np.sin(th), np.cos(th)], 0.0, [np.cos(th), np.sin(th)])


def example_b() -> tuple[Any, Any, Any]:
    """Example B's plant (Van der Pol), its cycle and the section ``x = −0.5``."""
    from ..analysis.corner_maps import Section
    from ..analysis.orbits import find_cycle
    from ..testing.cycle_problems import van_der_pol

    plant = van_der_pol(EPS)
    cyc = find_cycle(plant, [2.0, 0.0], 2 * np.pi, normal=[0.0, 1.0])
    return plant, cyc, Section([1.0, 0.0], -0.5, [0.0, 1.0])


def design_a(z_d: float, lam_d: float = 0.5, problem: Any = None) -> Any:
    """Example A's verified design for ``(λ_d, z_d)``."""
    from ..analysis.corner_maps import verify_corner_design
    from ..design.limit_cycle_switching import design_corner_controller

    plant, cyc, sec = problem or example_a()
    return verify_corner_design(design_corner_controller(
        plant, cyc, b=[1.0, 0.0], target_multiplier=lam_d, target_offset=z_d,
        anchor=[1.0, 0.0], axis=[1.0, 0.0], section=sec))


def design_b(lam_d: float, z_d: float, problem: Any = None) -> Any:
    """Example B's verified design for ``(λ_d, z_d)``."""
    from ..analysis.corner_maps import verify_corner_design
    from ..design.limit_cycle_switching import design_corner_controller

    plant, cyc, sec = problem or example_b()
    return verify_corner_design(design_corner_controller(
        plant, cyc, b=[0.0, 1.0], target_multiplier=lam_d, target_offset=z_d,
        anchor=[0.0, 2.0], axis=[0.0, 1.0], section=sec))


def design_point(target: tuple[str, float, float]) -> dict[str, float]:
    """One verified design, ``(example, λ_d, z_d)`` -> measured multiplier and offset ratio
    (module level: a task for :func:`nscontrol.sweep.run` on processes or Dask)."""
    example, lam_d, z_d = target
    d = design_a(z_d, lam_d) if example == "A" else design_b(lam_d, z_d)
    return {"k": d.k, "mu_c": d.mu_c, "multiplier": d.verified.multiplier,
            "offset_ratio": d.verified.offset / d.predicted_section_offset}


def multiplier_point(lam_d: float) -> tuple[float, float, float]:
    """Van der Pol (example B) with a wedge designed for the multiplier ``lam_d`` at offset
    ``±0.005`` (the side on which a controlled cycle crosses the wedge: ``+`` for targets
    above the corner's threshold, ``−`` below, as in :data:`DESIGN_TARGETS`): ``(gain k,
    measured multiplier, offset measured/predicted)`` (module level: ``nscontrol sweep``)."""
    from ..errors import InfeasibleDesignError

    try:
        d = design_point(("B", float(lam_d), 0.005))
    except InfeasibleDesignError as exc:
        if "change the sign of target_offset" not in str(exc):
            raise
        d = design_point(("B", float(lam_d), -0.005))
    return d["k"], d["multiplier"], d["offset_ratio"]


#: ``nscontrol sweep ch12-corner-control --param lambda_d=0.1:0.9:9``
SWEEPS = {"lambda_d": SweepSpec(multiplier_point, ("gain k", "measured multiplier",
                                                   "offset ratio (measured/predicted)"),
                                "designed multiplier λ_d of Van der Pol's cycle")}


#: The designs of the convergence study: ``(example, λ_d, z_d)``.
DESIGN_TARGETS = tuple([("A", 0.5, z) for z in (0.01, 0.005, 0.0025)]
                       + [("B", 0.2, z) for z in (-0.01, -0.005, -0.0025)]
                       + [("B", 0.9, z) for z in (0.01, 0.005, 0.0025)])


def fd_slope(design: Any, h: float = 1e-7) -> float:
    """The return map's slope at the verified cycle by central differences (step ``h``)."""
    from ..analysis.corner_maps import section_returns

    site, z = design.site, design.verified.offset
    ends = [site.section_offset(section_returns(design.system, site.section_state(z + s),
                                                site.section, 1, period=site.period)[0])
            for s in (h, -h)]
    return (ends[0] - ends[1]) / (2 * h)


def _radial_transport(plant: Any, r0: float, dtheta: float) -> tuple[float, float]:
    """Radius after turning ``dtheta`` from ``(r0, angle 0)`` and ``∂r_end/∂r0`` (the
    polar plant: ``θ' = ω`` exactly, so the turn takes ``dtheta/ω``)."""
    from ..simulate import simulate

    t = abs(dtheta) / OMEGA
    if dtheta >= 0:
        tr = simulate(plant, [r0, 0.0], (0.0, t), t_eval=np.array([0.0, t]), sensitivity=True)
        Phi = tr.stats["state_transition"]
        end = tr.x[-1]
        r1 = float(np.hypot(*end))
        return r1, float(end @ Phi @ np.array([1.0, 0.0])) / r1
    # backward: the time-reversed polar field is the same family with -g, -ω; use rotation
    # symmetry instead: find r_start with forward image r0 by Newton
    r = r0
    for _ in range(30):
        r1, d = _radial_transport(plant, r, -dtheta)
        step = (r1 - r0) / d
        r -= step
        if abs(step) <= 1e-15:
            break
    return r, _radial_transport(plant, r, -dtheta)[1]


def zdm_convergence(rho: float, k: float, xis: tuple[float, ...] = (1e-3, 5e-4)
                    ) -> dict[str, Any]:
    """The local test of the corner map on Example A: the measured slope change between the
    rays ``θ = ∓π/6`` against :func:`~nscontrol.analysis.corner_maps.corner_gain`."""
    from ..analysis.corner_maps import Section, corner_gain, section_returns
    from ..systems.wedge import Wedge, WedgeSwitchedSystem

    plant, _, _ = example_a()
    c = np.array([rho, 0.0])
    f1 = plant.rhs(0.0, c)
    wedge = Wedge.symmetric(c, [1.0, 0.0], np.pi / 4, flow=f1)
    system = WedgeSwitchedSystem(plant, wedge, [1.0, 0.0], k)
    a = corner_gain(f1, f1 + k * np.array([1.0, 0.0]), wedge.n_in, wedge.n_out, [1.0, 0.0])
    th = np.pi / 6
    r_up, tau_up = _radial_transport(plant, rho, -th)        # ray −π/6 -> Σ_c
    r_dn, tau_dn = _radial_transport(plant, rho, th)         # Σ_c -> ray +π/6
    down = Section([-np.sin(th), np.cos(th)], 0.0, [np.cos(th), np.sin(th)])
    out = []
    for xi in xis:
        r0 = r_up + xi / tau_up
        x0 = r0 * np.array([np.cos(-th), np.sin(-th)])
        r_ctrl = float(np.hypot(*section_returns(system, x0, down, 1, period=2 * np.pi)[0]))
        r_free = float(np.hypot(*section_returns(plant, x0, down, 1, period=2 * np.pi)[0]))
        measured = (r_ctrl - r_free) / (xi * tau_dn)
        out.append({"xi": xi, "measured": measured, "error": abs(measured / a - 1.0)})
    return {"rho": rho, "k": k, "a": a, "closed_form": 2 * k / (OMEGA * rho - k),
            "points": out}


def _closed_form_error(plant: Any, rho: float, k: float) -> float:
    """Relative distance of :func:`corner_gain` (true field at the corner ``(ρ, 0)``) to the
    symmetric wedge's closed form ``2k tanα/(ωρ − k tanα)`` (α = 45°)."""
    from ..design.limit_cycle_switching import corner_gain

    f1 = plant.rhs(0.0, np.array([rho, 0.0]))
    s = np.sqrt(0.5)
    a = corner_gain(f1, f1 + np.array([k, 0.0]), [s, s], [s, -s], [1.0, 0.0])
    return abs(a / (2 * k / (OMEGA * rho - k)) - 1.0)


def sliding_cycles(rhos: tuple[float, ...] = (1.01, 1.02), ks: tuple[float, ...] = (-1.5, -3.0)
                   ) -> list[dict[str, Any]]:
    """The sliding variant on Example A: for each corner, the cycle for each gain and the
    plant's orbit of the corner to the section."""
    from ..analysis.corner_maps import CornerFamily, controlled_cycle, section_returns
    from ..design.limit_cycle_switching import corner_site

    plant, cyc, sec = example_a()
    site = corner_site(plant, cyc, b=[1.0, 0.0], anchor=[1.0, 0.0], axis=[1.0, 0.0],
                       section=sec)
    out = []
    for rho in rhos:
        corner_orbit = section_returns(plant, [rho, 0.0], sec, 1, period=site.period)[0]
        guess = site.section_offset(corner_orbit)
        per_k = []
        for k in ks:
            system = CornerFamily(site, np.array([1.0, 0.0]), k)(rho - 1.0)
            cc = controlled_cycle(system, site, guess)
            mults = np.abs(np.linalg.eigvals(cc.cycle.monodromy))
            per_k.append({"k": k, "status": system.face_status(system.wedge.corner, "in"),
                          "events": cc.events, "x0": cc.cycle.x0,
                          "trivial_error": cc.trivial_error,
                          "nontrivial": float(np.min(mults)), "cycle": cc})
        spread = float(np.linalg.norm(per_k[0]["x0"] - per_k[1]["x0"]))
        to_orbit = max(float(np.linalg.norm(p["x0"] - corner_orbit)) for p in per_k)
        out.append({"rho": rho, "per_k": per_k, "spread": spread, "to_corner_orbit": to_orbit})
    return out


def stabilisation(design: Any, n_returns: int = 30) -> dict[str, Any]:
    """Example A: orbits from the section at ``r = 1 + z_d/2``, ``1 + 2z_d`` (to the
    controlled cycle) and ``r = 0.99`` (to the origin)."""
    from ..analysis.corner_maps import section_returns

    site, z_d = design.site, design.predicted_offset
    z_star = design.verified.offset
    out: dict[str, Any] = {"to_cycle": [], "paths": {}}
    for z0 in (0.5 * z_d, 2.0 * z_d):
        pts = section_returns(design.system, site.section_state(z0), site.section, n_returns,
                              period=site.period, rtol=RTOL_BRUTE, atol=1e-12)
        z = np.array([site.section_offset(p) for p in pts])
        out["to_cycle"].append(abs(z[-1] - z_star))
        out["paths"][f"from r0 = 1 + {z0:g}: distance to the controlled cycle"] = \
            np.abs(z - z_star)
    pts = section_returns(design.system, site.section_state(-0.01), site.section, n_returns,
                          period=site.period, rtol=RTOL_BRUTE, atol=1e-12)
    out["inner_radius"] = float(np.hypot(*pts[-1]))
    out["paths"]["from r0 = 0.99: radius (to the origin)"] = np.hypot(pts[:, 0], pts[:, 1])
    return out


def suppression(design: Any, mus: tuple[float, ...] = (-0.002, -0.005),
                inner: tuple[float, ...] = (1.0, 1.003, 1.02, 1.3),
                outer: tuple[float, ...] = (1.9, 2.0, 2.1), n_inner: int = 80,
                n_outer: int = 30) -> list[dict[str, Any]]:
    """Example A with the corner inside the unstable cycle (same gain): where orbits from the
    section go, and the outer cycle."""
    from ..analysis.corner_maps import CornerFamily, controlled_cycle, section_returns

    site = design.site
    fam = CornerFamily(site, design.system.b, design.k)
    out = []
    for mu in mus:
        system = fam(mu)
        radii, paths = [], {}
        for r0 in inner:
            pts = section_returns(system, site.section_state(r0 - 1.0), site.section, n_inner,
                                  period=site.period, rtol=RTOL_BRUTE, atol=1e-14)
            rr = np.hypot(pts[:, 0], pts[:, 1])
            radii.append(float(rr[-1]))
            paths[r0] = rr
        ends = []
        for r0 in outer:
            pts = section_returns(system, site.section_state(r0 - 1.0), site.section, n_outer,
                                  period=site.period, rtol=RTOL_BRUTE, atol=1e-12)
            ends.append(float(np.hypot(*pts[-1])))
        outer_cycle = controlled_cycle(system, site, float(np.mean(ends)) - 1.0)
        near = _cycles_near_unit(system, site)
        out.append({"mu": mu, "inner_radii": radii, "outer_ends": ends,
                    "outer_spread": float(np.ptp(ends)),
                    "outer_radius": 1.0 + outer_cycle.offset,
                    "outer_multiplier": outer_cycle.multiplier, "paths": paths,
                    "cycles_near_1": near})
    return out


def _cycles_near_unit(system: Any, site: Any) -> int:
    """Sign changes of ``P(z) − z`` on the section over offsets ``[−0.05, 0.05]``: the
    number of cycles near ``r = 1`` (one return per offset)."""
    from ..analysis.corner_maps import section_returns

    zs = np.linspace(-0.05, 0.05, 11)
    g = [site.section_offset(section_returns(system, site.section_state(z), site.section, 1,
                                             period=site.period)[0]) - z for z in zs]
    return int(np.sum(np.diff(np.sign(g)) != 0))


def diagram(design: Any, mus: tuple[float, ...] = (0.001, 0.002, 0.004), *,
            executor: Any = "serial", n_record: int = 0) -> Any:
    """The controlled cycle against the corner offset at the design's gain (check 9)."""
    from ..analysis.corner_maps import CornerFamily, corner_diagram

    fam = CornerFamily(design.site, design.system.b, design.k)
    return corner_diagram(fam, mus, executor=executor, n_transient=20 if n_record else 0,
                          n_record=n_record)


def _return_map_points(design: Any, n: int = 9) -> tuple[Any, Any]:
    """One return from ``n`` section offsets around the corner's, and the prediction."""
    from ..analysis.corner_maps import section_returns

    site = design.site
    zs = np.linspace(-1.0, 4.0, n) * design.mu_c / site.tau
    nxt = np.array([site.section_offset(section_returns(design.system, site.section_state(z),
                                                        site.section, 1,
                                                        period=site.period)[0]) for z in zs])
    return zs, nxt


def _cycle_points(system: Any, x0: Any, period: float) -> Any:
    from ..simulate import simulate

    return simulate(system, x0, (0.0, period), n_samples=600).x


def run(out_dir: Path | None) -> ExampleResult:
    """Examples A and B: designs, their verification, the sliding variant, the diagram in
    the corner position and the suppression of the oscillation."""
    t_start = time.perf_counter()
    prob_a, prob_b = example_a(), example_b()
    plant_a, cyc_a, _ = prob_a
    plant_b, cyc_b, _ = prob_b
    lam_a = float(np.real(cyc_a.nontrivial[0]))
    lam_a_exact = float(np.exp(12 * np.pi * SIGMA / OMEGA))
    # check 2: the uncontrolled references
    from ..simulate import simulate

    grid = np.linspace(0.0, cyc_b.period, 4097)
    xs = simulate(plant_b, cyc_b.x0, (0.0, cyc_b.period), t_eval=grid).x[:, 0]
    # trapezoid rule on a periodic integrand: spectrally accurate
    liouville = float(np.exp(np.sum(EPS * (1.0 - xs[:-1] ** 2)) * (grid[1] - grid[0])))
    lam_b = float(np.real(cyc_b.nontrivial[0]))
    # checks 4, 5 and 1: designs for decreasing offsets
    t0 = time.perf_counter()
    series = {"A, λ_d = 0.5": [design_a(z, 0.5, prob_a) for z in (0.01, 0.005, 0.0025)],
              "B, λ_d = 0.2": [design_b(0.2, z, prob_b) for z in (-0.01, -0.005, -0.0025)],
              "B, λ_d = 0.9": [design_b(0.9, z, prob_b) for z in (0.01, 0.005, 0.0025)]}
    design_seconds = (time.perf_counter() - t0) / 9
    conv: dict[str, dict[str, Any]] = {}
    for name, ds in series.items():
        err = [abs(d.verified.multiplier - d.predicted_multiplier) for d in ds]
        conv[name] = {"z_d": [d.predicted_offset for d in ds], "error": err,
                      "bound_ratio": max(e / (3 * abs(d.predicted_offset))
                                         for e, d in zip(err, ds, strict=True)),
                      "halving": [err[i] / err[i + 1] for i in range(len(err) - 1)]}
    ampl = {"A, λ_d = 0.5, z_d = 0.005": series["A, λ_d = 0.5"][1],
            "B, λ_d = 0.2, z_d = −0.005": series["B, λ_d = 0.2"][1],
            "B, λ_d = 0.9, z_d = 0.0025": series["B, λ_d = 0.9"][2]}
    ratios = {k: d.verified.offset / d.predicted_section_offset for k, d in ampl.items()}
    crossing = [d for ds in series.values() for d in ds]
    trivial = max(d.verified.trivial_error for d in crossing)
    main = series["A, λ_d = 0.5"][1]
    fd = {"A": (fd_slope(main), main.verified.multiplier),
          "B 0.2": (fd_slope(series["B, λ_d = 0.2"][1]),
                    series["B, λ_d = 0.2"][1].verified.multiplier),
          "B 0.9": (fd_slope(series["B, λ_d = 0.9"][2]),
                    series["B, λ_d = 0.9"][2].verified.multiplier)}
    fd_err = max(abs(a - b) for a, b in fd.values())
    # check 3: corner gain against the closed form, and the local map test
    gains = [zdm_convergence(rho, k, xis=(1e-3, 5e-4))
             for rho, k in ((1.01, -0.62), (1.01, 0.3), (1.2, -0.62), (1.2, 0.3))]
    closed = max(_closed_form_error(plant_a, 1.01, k) for k in (-0.62, -0.3, 0.3))
    zdm_err = max(g["points"][0]["error"] for g in gains)
    zdm_halving = min(g["points"][0]["error"] / g["points"][1]["error"] for g in gains)
    # check 6
    stab = stabilisation(main)
    # check 7
    slide = sliding_cycles()
    slide_events_ok = all(p["events"] == ("sliding starts on H_in", "sliding ends at the corner")
                          for s_ in slide for p in s_["per_k"])
    slide_status_ok = all(p["status"] == "attracting_sliding" for s_ in slide
                          for p in s_["per_k"])
    slide_trivial = max(p["trivial_error"] for s_ in slide for p in s_["per_k"])
    slide_mult = max(p["nontrivial"] for s_ in slide for p in s_["per_k"])
    slide_spread = max(s_["spread"] for s_ in slide)
    slide_orbit = max(s_["to_corner_orbit"] for s_ in slide)
    # check 8
    from ..design.limit_cycle_switching import design_corner_controller
    from ..errors import InfeasibleDesignError
    refused, switched = 0, 0
    for lam_d in (-0.5, -0.1, 0.0):
        try:
            design_corner_controller(plant_a, cyc_a, b=[1.0, 0.0], target_multiplier=lam_d,
                                     target_offset=0.005, anchor=[1.0, 0.0])
        except InfeasibleDesignError:
            refused += 1
        d8 = design_corner_controller(plant_a, cyc_a, b=[1.0, 0.0], target_multiplier=lam_d,
                                      target_offset=0.005, anchor=[1.0, 0.0],
                                      allow_sliding=True)
        switched += d8.regime == "sliding"
    # check 9
    t0 = time.perf_counter()
    dia = diagram(main, DIAGRAM_MUS)
    diagram_seconds = time.perf_counter() - t0
    at = np.isin(dia.mu, CHECKED_MUS)         # the acceptance check's corner offsets
    q_err = np.abs(dia.offset_sigma / dia.mu / dia.q - 1.0)[at]
    # check 10
    supp = suppression(main)
    inner_max = max(max(s_["inner_radii"]) for s_ in supp)
    outer_spread = max(s_["outer_spread"] for s_ in supp)
    outer_shift = max(s_["outer_radius"] - 2.0 for s_ in supp)
    near = max(s_["cycles_near_1"] for s_ in supp)

    checks = [
        check("Controlled cycles: largest distance of the trivial multiplier to 1",
              max(trivial, slide_trivial), 1e-7, key="check_1",
              note="monodromy through the saltation matrices of the face crossings"),
        check("Controlled cycles: multiplier minus the return map's central-difference "
              "slope (step 1e-7)", fd_err, 1e-4, key="check_1_slope"),
        check("Unstable cycle r = 1: multiplier error against exp(12πσ/ω)",
              abs(lam_a - lam_a_exact), 1e-6, key="check_2"),
        check("Van der Pol: multiplier minus exp of the divergence integral along the cycle",
              abs(lam_b - liouville), 1e-7, key="check_2_liouville"),
        check("Van der Pol: relative distance of the multiplier to exp(−2πε)",
              abs(lam_b / np.exp(-2 * np.pi * EPS) - 1.0), 0.01, key="check_2_averaging"),
        check("Corner gain against its closed form for the symmetric wedge (relative, "
              "corner at r = 1.01)", closed, 1e-3, key="check_3",
              note="the closed form neglects the field's radial part g(ρ)ρ ≈ 1.2e-3 at the "
                   "corner, relative to ωρ"),
        check("Corner map: measured slope change against the corner gain (relative, "
              "offset 1e-3)", zdm_err, 0.005, key="check_3_local"),
        check("Corner map: error reduction when the offset is halved (smallest)", zdm_halving,
              1.6, ">=", key="check_3_order"),
        check("Designs: largest multiplier error as a fraction of 3|z_d|",
              max(c["bound_ratio"] for c in conv.values()), 1.0, key="check_4"),
        check("Designs: smallest error reduction when the offset is halved",
              min(min(c["halving"]) for c in conv.values()), 1.6, ">=", key="check_4_order_lo"),
        check("Designs: largest error reduction when the offset is halved",
              max(max(c["halving"]) for c in conv.values()), 2.6, key="check_4_order_hi"),
        check("Designs: largest distance of the cycle's offset ratio (measured/predicted) "
              "to 1", max(abs(r - 1.0) for r in ratios.values()), 0.05, key="check_5"),
        check("Stabilisation: distance to the controlled cycle after 30 returns (largest)",
              max(stab["to_cycle"]), 1e-6, key="check_6"),
        check("Stabilisation: radius of the orbit started inside r = 1 after 30 returns",
              stab["inner_radius"], 1e-3, key="check_6_inner"),
        check("Sliding variant: every run slides on the entry face into the corner, once per "
              "period", int(slide_events_ok and slide_status_ok), 1, "==", key="check_7"),
        check("Sliding variant: largest non-trivial multiplier", slide_mult, 1e-8,
              key="check_7_multiplier"),
        check("Sliding variant: cycle point spread over the gains", slide_spread, 1e-9,
              key="check_7_gain_independence"),
        check("Sliding variant: distance to the plant's orbit of the corner", slide_orbit, 1e-9,
              key="check_7_corner_orbit"),
        check("Crossing-condition guard: non-positive target multipliers refused (of 3)",
              refused, 3, "==", key="check_8"),
        check("Crossing-condition guard: switched to the sliding design when allowed (of 3)",
              switched, 3, "==", key="check_8_sliding"),
        check("Corner position sweep: largest relative error of offset/μ_c against q",
              float(np.max(q_err)), 0.05, key="check_9"),
        check("Corner position sweep: the error decreases as the corner approaches the cycle",
              int(bool(np.all(np.diff(q_err) > 0))), 1, "==", key="check_9_trend"),
        check("Suppression: largest radius after 80 returns from r in [1, 1.3]", inner_max,
              1e-6, key="check_10"),
        check("Suppression: cycles near r = 1 (sign changes of P(z) − z)", near, 0, "==",
              key="check_10_no_cycle"),
        check("Suppression: spread of the outer orbits' radii after 30 returns", outer_spread,
              1e-6, key="check_10_outer"),
        check("Suppression: the outer cycle moves inward (radius minus 2)", outer_shift, 0.0,
              "<", key="check_10_shift"),
    ]
    metrics = {
        "lambda_A": lam_a, "lambda_B": lam_b, "liouville_B": liouville,
        "designs": {k: {"z_d": c["z_d"], "multiplier_error": c["error"],
                        "halving": c["halving"]} for k, c in conv.items()},
        "offset_ratios": ratios, "fd_slopes": {k: list(v) for k, v in fd.items()},
        "corner_gain": [{"rho": g["rho"], "k": g["k"], "a": g["a"],
                         "errors": [p["error"] for p in g["points"]]} for g in gains],
        "design_A": {"k": main.k, "mu_c": main.mu_c, "a": main.a, "tau": main.site.tau,
                     "multiplier": main.verified.multiplier},
        "sliding": [{"rho": s_["rho"], "spread": s_["spread"],
                     "to_corner_orbit": s_["to_corner_orbit"]} for s_ in slide],
        "diagram": {"mu": dia.mu.tolist(), "offset_over_mu": (dia.offset_sigma / dia.mu).tolist(),
                    "q": dia.q.tolist(), "seconds": diagram_seconds},
        "suppression": [{"mu": s_["mu"], "inner_radii": s_["inner_radii"],
                         "outer_radius": s_["outer_radius"]} for s_ in supp],
        "design_seconds": design_seconds,
        "seconds": time.perf_counter() - t_start,
    }
    figures: list[Path] = []
    _figure_portraits(out_dir, figures, main, series, plant_a, cyc_a, plant_b, cyc_b)
    _figure_return_map(out_dir, figures, main)
    _figure_convergence(out_dir, figures, conv)
    _figure_diagram(out_dir, figures, main, dia)
    _figure_suppression(out_dir, figures, supp, stab)
    return ExampleResult("ch12-corner-control", metrics, checks, figures,
                         summary="a switching wedge placed at a limit cycle sets the "
                                 "multiplier and amplitude of a new cycle next to it, as the "
                                 "piecewise-linear corner-collision map predicts")


def _wedge_outline(wedge: Any, length: float) -> Any:
    """The wedge's two faces as a polyline (corner in the middle)."""
    c = wedge.corner
    faces = []
    for n in (wedge.n_in, wedge.n_out):
        d = np.array([-n[1], n[0]])
        other = wedge.n_out if n is wedge.n_in else wedge.n_in
        if other @ d < 0:
            d = -d
        faces.append(c + length * d)
    return np.array([faces[0], c, faces[1]])


def _figure_portraits(out_dir: Path | None, figures: list[Path], main: Any,
                      series: dict[str, list[Any]], plant_a: Any, cyc_a: Any, plant_b: Any,
                      cyc_b: Any) -> None:
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(9.5, 4.4))
    th = np.linspace(0.0, 2 * np.pi, 400)
    ax1.plot(np.cos(th), np.sin(th), "--", color="C3", label="unstable cycle r = 1")
    ctrl = _cycle_points(main.system, main.verified.cycle.x0, main.verified.cycle.period)
    ax1.plot(ctrl[:, 0], ctrl[:, 1], color="C0", label="controlled cycle (λ = 0.51)")
    w = _wedge_outline(main.wedge, 0.25)
    ax1.plot(w[:, 0], w[:, 1], color="k", lw=1.5, label="wedge faces")
    ax1.set_xlim(0.85, 1.2)
    ax1.set_ylim(-0.2, 0.2)
    ax1.set_xlabel("x")
    ax1.set_ylabel("y")
    ax1.set_title("A: near the corner (z_d = 0.005)")
    ax1.legend(loc="lower left", fontsize="small")
    free = _cycle_points(plant_b, cyc_b.x0, cyc_b.period)
    ax2.plot(free[:, 0], free[:, 1], "--", color="0.4", label="Van der Pol cycle")
    for name, color in (("B, λ_d = 0.2", "C0"), ("B, λ_d = 0.9", "C1")):
        d = series[name][0]
        pts = _cycle_points(d.system, d.verified.cycle.x0, d.verified.cycle.period)
        ax2.plot(pts[:, 0], pts[:, 1], color=color,
                 label=f"controlled, λ_d = {name[-3:]}, z_d = {d.predicted_offset:g}")
        w = _wedge_outline(d.wedge, 0.15)
        ax2.plot(w[:, 0], w[:, 1], color=color, lw=1.0)
    ax2.set_xlim(-0.6, 0.6)
    ax2.set_ylim(1.8, 2.15)
    ax2.set_xlabel("x")
    ax2.set_ylabel("v = x'")
    ax2.set_title("B: top of the cycle, wedges in colour")
    ax2.legend(loc="lower center", fontsize="small")
    save_figure(fig, out_dir, "ch12_phase_portraits", figures)


def _figure_return_map(out_dir: Path | None, figures: list[Path], main: Any) -> None:
    zs, nxt = _return_map_points(main)
    tau = main.site.tau
    grid = np.linspace(zs[0], zs[-1], 200)
    pred = np.asarray(main.return_map(tau * grid)) / tau
    fig, ax = new_figure(figsize=(6.0, 4.4))
    ax.plot(grid * 1e3, pred * 1e3, color="0.6", lw=3, label="predicted PWL map (moved to "
                                                                "the section)")
    ax.plot(zs * 1e3, nxt * 1e3, "o", color="C0", label="measured returns")
    ax.plot(grid * 1e3, grid * 1e3, ":", color="k", label="diagonal")
    ax.axvline(main.mu_c / tau * 1e3, color="C3", lw=1, label="corner offset μ_c/τ")
    ax.set_xlabel("offset on the section z_n [10⁻³]")
    ax.set_ylabel("next offset z_(n+1) [10⁻³]")
    ax.set_title("Example A: return map near the corner")
    ax.legend(loc="upper left", fontsize="small")
    save_figure(fig, out_dir, "ch12_return_map", figures)


def _figure_convergence(out_dir: Path | None, figures: list[Path],
                        conv: dict[str, dict[str, Any]]) -> None:
    fig, ax = new_figure(figsize=(6.0, 4.4))
    for i, (name, c) in enumerate(conv.items()):
        z = np.abs(c["z_d"])
        ax.loglog(z, c["error"], "o-", color=f"C{i}", label=name)
    z = np.array([0.0025, 0.01])
    ax.loglog(z, 3 * z, "--", color="k", label="bound 3|z_d|")
    ax.set_xlabel("target offset |z_d|")
    ax.set_ylabel("|achieved − designed multiplier|")
    ax.set_title("First-order convergence of the design")
    ax.legend(loc="lower right", fontsize="small")
    save_figure(fig, out_dir, "ch12_multiplier_convergence", figures)


def _figure_diagram(out_dir: Path | None, figures: list[Path], main: Any, dia: Any) -> None:
    fig, ax = new_figure(figsize=(6.0, 4.4))
    ax.plot(dia.mu * 1e3, dia.offset_sigma / dia.mu, "o", color="C0",
            label="shot cycle: offset on Σ_c / μ_c")
    ax.plot(dia.mu * 1e3, dia.q, "-", color="0.5", lw=2, label="prediction q")
    ax.set_xlabel("corner offset μ_c [10⁻³]")
    ax.set_ylabel("controlled cycle offset / μ_c")
    ax.set_title(f"Example A, k = {main.k:.4f} fixed")
    ax.legend(loc="best", fontsize="small")
    save_figure(fig, out_dir, "ch12_corner_diagram", figures)


def _figure_suppression(out_dir: Path | None, figures: list[Path], supp: list[dict[str, Any]],
                        stab: dict[str, Any]) -> None:
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(9.5, 4.2))
    for i, (name, rr) in enumerate(stab["paths"].items()):
        ax1.semilogy(np.arange(1, len(rr) + 1), rr + 1e-16, ".-", color=f"C{i}", label=name)
    ax1.set_xlabel("return n")
    ax1.set_ylabel("distance on the section")
    ax1.set_title("Corner outside: stabilised (μ_c > 0)")
    ax1.set_ylim(1e-12, 10.0)
    ax1.legend(loc="upper right", fontsize="small")
    s0 = supp[0]
    for i, (r0, rr) in enumerate(s0["paths"].items()):
        ax2.semilogy(np.arange(1, len(rr) + 1), rr, ".-", ms=3, color=f"C{i}",
                     label=f"r0 = {r0:g}")
    ax2.set_xlabel("return n")
    ax2.set_ylabel("radius on the section")
    ax2.set_title(f"Corner inside (μ_c = {s0['mu']:g}): suppressed")
    ax2.legend(loc="upper right", fontsize="small")
    save_figure(fig, out_dir, "ch12_suppression", figures)


EXAMPLES = [Example(
    "ch12-corner-control",
    "Feedback control of limit cycles by a switching wedge (corner collision)", "ch12", run,
    claim="A constant input switched on inside a wedge whose corner sits next to a limit "
          "cycle makes the cycle's return map piecewise linear. Placing the corner and "
          "choosing the gain from that map creates a cycle of chosen multiplier and "
          "amplitude: an unstable cycle gets a stable neighbour (multiplier 0.5), a stable "
          "one is made more or less stable; with the corner inside the cycle the oscillation "
          "is suppressed.",
    verdict=verdict_from(("check_4", "the wedge gives the controlled cycle the multiplier "
                                     "it was designed for, the largest error being {value} of "
                                     "its leading-order bound 3|z_d|"),
                         ("check_5", "the cycle's offset from the corner is the predicted one "
                                     "to a relative {value}"),
                         ("check_9", "moving the corner along the cycle changes the offset as "
                                     "the theory's factor q says, to a relative {value}")),
    key_figure="ch12_phase_portraits",
    captions={
        "ch12_phase_portraits": "Left: example A near the corner; the unstable cycle r = 1 "
        "(dashed) and the stable controlled cycle next to it that crosses the wedge. Right: "
        "Van der Pol's cycle (dashed) made smaller (multiplier 0.2) or larger (0.9) by a "
        "wedge at the top of the cycle.",
        "ch12_return_map": "Example A: one return from points of the section (dots) on the "
        "predicted piecewise-linear map: slope λ = 2.13 left of the corner, λ(1 + a) = 0.5 "
        "right of it; the fixed point on the right branch is the controlled cycle.",
        "ch12_multiplier_convergence": "Achieved minus designed multiplier against the target "
        "offset: first order (halving the offset halves the error) and under 3|z_d|.",
        "ch12_corner_diagram": "The controlled cycle's offset divided by the corner's, "
        "against the corner's offset at fixed gain: it tends to the predicted q.",
        "ch12_suppression": "Left: with the corner outside, orbits started next to r = 1 "
        "converge to the controlled cycle (0.51 per return), one started inside goes to the "
        "origin. Right: with the corner "
        "inside the cycle, every orbit from r in [1, 1.3] goes to the origin."})]
