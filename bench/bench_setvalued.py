"""Set-valued and switched integrators against their references, in one run.

1. relay Lur'e system ``x' = Ax + Bλ, y = Cx, λ ∈ -Sign(y)``, ``A = [[0, 1], [0, 0]]``,
   ``B = [0, 1]ᵀ``, ``C = [1, 1]``, ``x0 = (1, 0)``, ``h = 1e-3``, ``T = 10``: our implicit Euler
   (compiled closed-form resolvent) vs Siconos ``EulerMoreauOSI(1) + Relay`` (θ = 1 both);
   accuracy: reaching step vs ``√3 - 1``, largest ``|y|`` after reaching, final states vs the
   exact solution.
2. PWA one-sided-spring oscillator (ch11 example A, ``a = 1``, ``ω = 2.9``) over 1000 forcing
   periods: our exact switching integrator vs ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10,
   atol 1e-12, a terminal event on the facet, restarted at every crossing); accuracy: number of
   crossings and final-state difference between the two.

3. Filippov relay (the fields of 1. as a Filippov system, sliding from ``√3 - 1``, ``T = 2``):
   ``simulate`` of the library's example ``relay_feedback().switched`` (given as data: the
   compiled loop, exact pieces and sliding mode) and of the same fields as Python callables
   (``two_sided`` of lambdas: the DOP853 path) vs a
   hand-written ``solve_ivp`` loop (DOP853 and RK45 at rtol 1e-11, atol 1e-13: a terminal
   event at the surface, then the Filippov field with its two exit events); 1001 samples
   (``t_eval``) and 2; accuracy: the largest error against the closed form at the samples and
   of the reaching time. ``ratio``: the loop's time over ours (compiled path, DOP853 loop,
   1001 samples), the other pairs beside it.

Run: ``nscontrol bench setvalued --json`` (``--quick``: 100 periods, shorter budgets).
"""

import time
from collections.abc import Iterator

import numpy as np
from harness import run_siconos, siconos_available, siconos_version, time_per_call

from nscontrol.simulate import simulate
from nscontrol.testing import setvalued_problems as sp

H, T_RELAY = 1e-3, 10.0


def _relay(quick: bool) -> dict:
    p = sp.relay_feedback(T=T_RELAY)
    steps = round(T_RELAY / H)

    def ours() -> object:
        return simulate(p.system, p.x0, p.t_span, h=H, progress=False)

    sec = time_per_call(ours, budget=0.5 if quick else 2.0, min_calls=3)
    tr = ours()
    z = tr.signal("z")[:, 0]
    k = int(np.argmax(z == 0.0))
    exact_final = p.facts["exact"](T_RELAY)[0]
    acc = {"ours_reaching_time": float(tr.t[k]), "exact_reaching_time": p.facts["reaching_time"],
           "ours_max_abs_y_after": float(np.max(np.abs(tr.signal("y")[k:]))),
           "ours_final_error": float(np.max(np.abs(tr.x[-1] - exact_final)))}
    rec = {"scenario": "relay-lure-h1e-3-T10", "size": 2, "ours_steps_per_s": steps / sec,
           "reference": None, "reference_steps_per_s": None, "ratio": None, "unit": "steps",
           "accuracy": acc}
    ok, why = siconos_available()
    if not ok:
        rec["note"] = f"Siconos skipped: {why}"
        return rec
    payload = {"A": [[0.0, 1.0], [0.0, 0.0]], "B": [[0.0], [1.0]], "C": [[1.0, 1.0]],
               "x0": [1.0, 0.0], "h": H, "T": T_RELAY, "theta": 1.0,
               "repeats": 2 if quick else 5}
    (ref,) = run_siconos("setvalued.py", payload, timeout=200)
    ref_rate = ref["steps"] / ref["seconds"]
    acc.update({"siconos_reaching_time": ref["reaching_time"],
                "siconos_max_abs_y_after": ref["max_abs_y_after"],
                "siconos_final_error": float(np.max(np.abs(np.array(ref["final"])
                                                          - exact_final))),
                "ours_vs_siconos_final": float(np.max(np.abs(np.array(ref["final"])
                                                            - tr.x[-1])))})
    rec.update(reference=siconos_version(), reference_steps_per_s=ref_rate,
               ratio=(steps / sec) / ref_rate)
    return rec


def _scipy_pwa(p: sp.SetValuedProblem, t_end: float) -> tuple[np.ndarray, int]:
    from scipy.integrate import solve_ivp

    rhs = p.facts["rhs"]
    t, x, n_cross = 0.0, p.x0.copy(), 0

    def facet(t: float, x: np.ndarray) -> float:
        return x[0]
    facet.terminal = True  # type: ignore[attr-defined]
    while t < t_end:
        sol = solve_ivp(rhs, (t, t_end), x, method="DOP853", rtol=1e-10, atol=1e-12,
                        events=facet)
        t, x = float(sol.t[-1]), sol.y[:, -1].copy()
        if sol.status != 1:
            break
        n_cross += 1
        # step off the facet so the restarted run does not stop at once
        x = x + 1e-12 * rhs(t, x)
        t = t + 1e-12
    return x, n_cross


def _pwa(quick: bool) -> dict:
    p = sp.bimodal_oscillator()
    periods = 100 if quick else 1000
    t_end = periods * p.facts["period"]
    simulate(p.system, p.x0, (0.0, 5 * p.facts["period"]), progress=False)  # warm-up
    start = time.perf_counter()
    tr = simulate(p.system, p.x0, (0.0, t_end), progress=False, n_samples=2)
    ours = time.perf_counter() - start
    start = time.perf_counter()
    x_ref, n_ref = _scipy_pwa(p, t_end)
    ref = time.perf_counter() - start
    n_ours = tr.event_times("crossing").size
    return {"scenario": f"pwa-oscillator-{periods}-periods", "size": periods,
            "ours_s_per_solve": ours, "reference": "scipy solve_ivp DOP853 + events",
            "reference_s_per_solve": ref, "ratio": ref / ours, "unit": "solves",
            "ours_steps_per_s": n_ours / ours, "reference_steps_per_s": n_ref / ref,
            "accuracy": {"ours_crossings": n_ours, "scipy_crossings": n_ref,
                         "final_state_difference": float(np.max(np.abs(x_ref - tr.x[-1])))}}


def _scipy_filippov(method: str, t_eval: np.ndarray | None) -> tuple[np.ndarray, float]:
    """The relay run as one would write it with ``solve_ivp``: until the surface, then the
    Filippov field ``(σ⁺F⁻ - σ⁻F⁺)/(σ⁺ - σ⁻)`` with its exits ``σ⁻ = 0``, ``σ⁺ = 0``.
    Returns the states at ``t_eval`` (or at the end) and the reaching time."""
    from scipy.integrate import solve_ivp

    A, g, c = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), np.array([1.0, 1.0])

    def f_minus(t: float, x: np.ndarray) -> np.ndarray:
        return A @ x + g

    def f_plus(t: float, x: np.ndarray) -> np.ndarray:
        return A @ x - g

    def f_s(t: float, x: np.ndarray) -> np.ndarray:
        fm, fp = f_minus(t, x), f_plus(t, x)
        sm, sp = c @ fm, c @ fp
        return (sp * fm - sm * fp) / (sp - sm)

    def surface(t: float, x: np.ndarray) -> float:
        return float(c @ x)
    surface.terminal = True  # type: ignore[attr-defined]

    def exit_minus(t: float, x: np.ndarray) -> float:
        return float(c @ f_minus(t, x))
    exit_minus.terminal = True  # type: ignore[attr-defined]

    def exit_plus(t: float, x: np.ndarray) -> float:
        return float(c @ f_plus(t, x))
    exit_plus.terminal = True  # type: ignore[attr-defined]

    opts = {"method": method, "rtol": 1e-11, "atol": 1e-13}
    a = solve_ivp(f_plus, (0.0, 2.0), np.array([1.0, 0.0]), events=surface, t_eval=t_eval,
                  **opts)
    t_r = float(a.t_events[0][0])
    rest = None if t_eval is None else t_eval[t_eval > t_r]
    b = solve_ivp(f_s, (t_r, 2.0), a.y_events[0][0], events=(exit_minus, exit_plus),
                  t_eval=rest, **opts)
    x = b.y[:, -1:].T if t_eval is None else np.vstack([a.y.T, b.y.T])
    return x, t_r


def _filippov_relay(quick: bool) -> dict:
    from nscontrol.systems.switched import FilippovSystem

    p = sp.relay_feedback(T=2.0)
    A, g, c = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([0.0, 1.0]), np.ones(2)
    python = FilippovSystem.two_sided(lambda t, x: A @ x + g, lambda t, x: A @ x - g,
                                      lambda x: float(c @ x), 2, gradient=lambda x: c)
    budget = 0.3 if quick else 1.5
    out: dict = {"scenario": "filippov-relay-T2", "size": 2, "unit": "solves",
                 "reference": "scipy solve_ivp loop (reaching event, then the Filippov field)"}
    acc: dict = {}
    for ns in (1001, 2):
        t_eval = np.linspace(0.0, 2.0, ns)
        exact = p.facts["exact"](t_eval if ns > 2 else t_eval[-1:])
        for name, system in (("compiled", p.switched), ("python", python)):
            def ours(system: object = system, ns: int = ns) -> object:
                return simulate(system, p.x0, p.t_span, n_samples=ns, progress=False)
            out[f"ours_{name}_s_per_solve_{ns}"] = time_per_call(ours, budget=budget)
            tr = ours()
            ev = tr.events[0].time
            keep = np.isin(tr.t, t_eval) if ns > 2 else slice(-1, None)
            acc[f"ours_{name}_error_{ns}"] = float(np.max(np.abs(tr.x[keep] - exact)))
            acc[f"ours_{name}_reaching_error"] = abs(ev - p.facts["reaching_time"])
            acc[f"ours_{name}_propagation"] = tr.stats["propagation"]
        for method in ("DOP853", "RK45"):
            te = t_eval if ns > 2 else None
            out[f"scipy_{method}_s_per_solve_{ns}"] = time_per_call(
                lambda method=method, te=te: _scipy_filippov(method, te), budget=budget)
            x, t_r = _scipy_filippov(method, te)
            acc[f"scipy_{method}_error_{ns}"] = float(np.max(np.abs(x - exact)))
            acc[f"scipy_{method}_reaching_error"] = abs(t_r - p.facts["reaching_time"])
        for name in ("compiled", "python"):
            for method in ("DOP853", "RK45"):
                out[f"ratio_{name}_vs_{method}_{ns}"] = (
                    out[f"scipy_{method}_s_per_solve_{ns}"] / out[f"ours_{name}_s_per_solve_{ns}"])
    out.update(ours_s_per_solve=out["ours_compiled_s_per_solve_1001"],
               reference_s_per_solve=out["scipy_DOP853_s_per_solve_1001"],
               ratio=out["ratio_compiled_vs_DOP853_1001"], accuracy=acc)
    return out


def run(quick: bool = False) -> Iterator[dict]:
    yield _filippov_relay(quick)
    yield _relay(quick)
    yield _pwa(quick)
