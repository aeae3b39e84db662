"""Cost per step of Moreau–Jean's Python path (``M(q)``, nonlinear forces), in one run.

1. the two-link arm of ch03 §4.1 falling onto the ground (h = 1e-3, T = 1.5, one impact):
   implicit forces with the analytic ``force_jacobian``, implicit with central differences
   (the same arm without it), explicit forces; reference: the explicit scheme (the Python
   path's only scheme before implicit forces), ``ratio`` = our steps/s over its steps/s;
2. a ball on a spring-damper bouncing on the ground (h = 1e-3, T = 10), the spring-damper
   given as a ``force`` callable (Python path, implicit) against the same linear system on
   the compiled path (reference); ``accuracy`` holds the largest state difference;
3. orders of convergence without contact (pendulum with its analytic Jacobian, a forced
   damped Duffing oscillator by central differences): the slope of the error in ``q(T)``,
   T = 2, against DOP853 at rtol 1e-12, h = 0.02 halved 4 times, for θ = 1 and θ = ½; speed
   of the smallest h, the explicit scheme's as reference; and ``m(q) = 1 + q²`` at θ = ½
   with ``M`` at ``q_k`` (first order) and at the predicted ``q_k + θ h v_k`` (second).

Run: ``nscontrol bench mj_python --json``. With an older nscontrol on ``PYTHONPATH`` (no
``forces`` option), only the explicit arm runs: its figure is the cost before implicit forces.
With ``MJ_BEFORE=/path/to/old/simulate/moreau_jean.py`` set, that older integrator is loaded
beside the current one and the arm is timed with both, alternately, in the same run
(``arm-now-vs-before``: ``ratio`` = our steps/s, implicit forces, over the old one's; the
explicit scheme's ratio in ``accuracy``).
"""

import importlib.util
import inspect
import os
import sys
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import time_per_call
from scipy.integrate import solve_ivp

from nscontrol.simulate import moreau_jean, simulate
from nscontrol.systems.lagrangian import LagrangianSystem

H = 1e-3
HAS_FORCES = "forces" in inspect.signature(moreau_jean.integrate).parameters


def _rate(system: Any, x0: list, t_end: float, budget: float, h: float = H,
          **kw: Any) -> tuple[float, Any]:
    out = {}

    def call() -> None:
        out["r"] = simulate(system, x0, (0.0, t_end), method="moreau_jean", h=h,
                            progress=False, signals=(), record_every=10**9, **kw)

    s = time_per_call(call, budget=budget, min_calls=2)
    return out["r"].stats["steps"] / s, out["r"]


def _record(scenario: str, ours: float, reference: str | None, ref: float | None,
            accuracy: dict) -> dict:
    return {"scenario": scenario, "size": "steps", "ours_steps_per_s": ours,
            "ours_us_per_step": 1e6 / ours, "reference": reference,
            "reference_steps_per_s": ref, "ratio": ours / ref if ref else None,
            "accuracy": accuracy}


def run(quick: bool = False) -> Iterator[dict]:
    budget = 0.5 if quick else 2.0
    arm = LagrangianSystem.two_link_arm()
    x0 = [0.8, -1.2, 0.0, 0.0]
    if not HAS_FORCES:
        rate, traj = _rate(arm, x0, 1.5, budget)
        yield _record("arm-explicit (before implicit forces)", rate, None, None,
                      {"impacts": len(traj.events_of("impact"))})
        return
    explicit, _ = _rate(arm, x0, 1.5, budget, forces="explicit")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        arm_fd = LagrangianSystem(arm.mass, force=arm.force, gap=arm.gap,
                                  jacobian=arm.jacobian, names=arm.names)
    yield _record("arm-explicit", explicit, "explicit", explicit, {})
    for name, system in (("arm-implicit-analytic", arm), ("arm-implicit-central-diff", arm_fd)):
        rate, traj = _rate(system, x0, 1.5, budget)
        yield _record(name, rate, "explicit", explicit,
                      {"force_jacobian": traj.stats["force_jacobian"],
                       "impacts": len(traj.events_of("impact"))})
    k, c, g = 50.0, 0.5, 9.81
    common = dict(constant_force=[-g], gap_matrix=[[1.0]], gap_offset=[0.1], restitution=0.7)
    linear = LagrangianSystem(np.eye(1), stiffness=[[k]], damping=[[c]], **common)
    python = LagrangianSystem(np.eye(1), force=lambda t, q, v: -k * q - c * v,
                              force_jacobian=lambda t, q, v: (np.array([[-k]]),
                                                              np.array([[-c]])), **common)
    ref, _ = _rate(linear, [1.0, 0.0], 10.0, budget)
    rate, _ = _rate(python, [1.0, 0.0], 10.0, budget)
    python_fd = LagrangianSystem(np.eye(1), force=lambda t, q, v: -k * q - c * v, **common)
    a, b, d = (simulate(sys_, [1.0, 0.0], (0.0, 10.0), method="moreau_jean", h=H,
                        progress=False) for sys_ in (linear, python, python_fd))
    yield _record("ball-spring-python-vs-compiled", rate, "compiled tridiagonal path", ref,
                  {"max_state_difference": float(np.max(np.abs(a.x - b.x))),
                   "max_state_difference_central_differences": float(np.max(np.abs(
                       a.x - d.x))),
                   "max_abs_state": float(np.max(np.abs(a.x))), "steps": b.stats["steps"]})
    yield from _orders(budget)
    if os.environ.get("MJ_BEFORE"):
        yield _before(arm, x0, budget, os.environ["MJ_BEFORE"])


def _before(arm: Any, x0: list, budget: float, path: str) -> dict:
    """The arm with the integrator at ``path`` (loaded as a sibling module) and ours."""
    spec = importlib.util.spec_from_file_location("nscontrol.simulate._mj_before", path)
    assert spec and spec.loader
    old = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = old  # its dataclasses look their module up
    spec.loader.exec_module(old)
    rates: dict[str, list[float]] = {"now": [], "now_explicit": [], "before": []}
    runs = (("now", moreau_jean.integrate, {}),
            ("now_explicit", moreau_jean.integrate, {"forces": "explicit"}),
            ("before", old.integrate, {}))
    for _ in range(3):  # alternate, so that all see the same machine load
        for key, integrate, kw in runs:
            out: dict = {}

            def call(integrate: Any = integrate, out: dict = out, kw: dict = kw) -> None:
                out["r"] = integrate(arm, x0, (0.0, 1.5), h=H, progress=False, signals=(),
                                     record_every=10**9, **kw)

            seconds = time_per_call(call, budget=budget / 3, min_calls=2)
            rates[key].append(out["r"].stats["steps"] / seconds)
    now, before = float(np.median(rates["now"])), float(np.median(rates["before"]))
    explicit = float(np.median(rates["now_explicit"]))
    return _record("arm-now-vs-before", now, f"moreau_jean at {path}", before,
                   {"explicit_now_over_before": explicit / before,
                    **{f"steps_per_s_{k}": v for k, v in rates.items()}})


def _orders(budget: float) -> Iterator[dict]:
    w2 = 9.81
    far = dict(gap_matrix=[[1.0]], gap_offset=[1e6])
    pendulum = LagrangianSystem(
        np.eye(1), force=lambda t, q, v: -w2 * np.sin(q),
        force_jacobian=lambda t, q, v: (np.array([[-w2 * np.cos(q[0])]]), np.zeros((1, 1))),
        **far)

    def duffing_force(t: float, q: Any, v: Any) -> Any:
        return 0.5 * np.cos(1.2 * t) - q - q**3 - 0.2 * v

    duffing = LagrangianSystem(np.eye(1), force=duffing_force, **far)
    problems = {"pendulum-order": (pendulum, lambda t, x: [x[1], -w2 * np.sin(x[0])],
                                   [1.0, 0.0]),
                "duffing-order (central differences)": (
                    duffing, lambda t, x: [x[1], duffing_force(t, x[0], x[1])], [1.0, 0.5])}
    k = 4.0  # m(q) = 1 + q², V = k q²/2: m q'' = -q q'² - k q
    mass_q = LagrangianSystem(
        lambda q: np.array([[1.0 + q[0] ** 2]]), force=lambda t, q, v: -q * v**2 - k * q,
        force_jacobian=lambda t, q, v: (np.array([[-v[0] ** 2 - k]]),
                                        np.array([[-2 * q[0] * v[0]]])), names=("x",), **far)
    problems["mass-q-order"] = (
        mass_q, lambda t, x: [x[1], (-x[0] * x[1] ** 2 - k * x[0]) / (1 + x[0] ** 2)],
        [1.0, 0.0])
    hs = 0.02 / 2.0 ** np.arange(5)
    for name, (system, rhs, x0) in problems.items():
        ref = solve_ivp(rhs, (0.0, 2.0), x0, method="DOP853", rtol=1e-12, atol=1e-14).y[0, -1]
        acc = {}
        variants = ({"theta": 1.0}, {"theta": 0.5})
        if name.startswith("mass-q"):
            variants = ({"theta": 0.5}, {"theta": 0.5, "mass_at": "predicted"})
        for kw in variants:
            errs = [abs(simulate(system, x0, (0.0, 2.0), method="moreau_jean", h=h,
                                 signals=(), progress=False, **kw).x[-1, 0] - ref)
                    for h in hs]
            tag = "_".join(f"{key}_{val:g}" if isinstance(val, float) else f"{key}_{val}"
                           for key, val in kw.items())
            acc[f"slope_{tag}"] = float(np.polyfit(np.log(hs), np.log(errs), 1)[0])
            acc[f"error_{tag}_h_{hs[-1]:g}"] = float(errs[-1])
        rate, _ = _rate(system, x0, 2.0, budget, h=hs[-1])
        explicit, _ = _rate(system, x0, 2.0, budget, h=hs[-1], forces="explicit")
        yield _record(name, rate, "explicit", explicit, acc)
