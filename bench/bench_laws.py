"""Nonsmooth laws: cost of one resolvent, of one Lur'e step inclusion and of one impact.

Scenarios (no external reference exists for single law evaluations; where two of our paths
compute the same thing, the slower general one is the reference):

* ``relay_step_diagonal``: ``z = M w + q``, ``w in -c Sign(z)`` with diagonal ``M`` (m = 10,
  100): closed-form resolvent vs the LCP encoding solved by Lemke (the reference);
* ``relay_step_coupled``: the same with a dense positive definite ``M`` (LCP path only);
* ``stribeck_resolvent``: the scalar-root resolvent of a Stribeck law (m = 10, 100);
* ``chain_impact``: Newton impact on a chain of N unit masses (N = 10, 100), one Delassus LCP.

``ratio`` = reference seconds / ours (> 1: the closed form is faster). ``accuracy`` holds the
graph residuals and ``max |z_closed - z_lcp|``.

Run: ``nscontrol bench laws --json`` (``--quick`` for a smoke run).
"""

# ruff: noqa: B023  (the timed lambdas run before the loop variables change)
# No `from __future__ import annotations`: the CLI loads this file without registering it.
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import time_per_call

from nscontrol.laws.friction import Stribeck
from nscontrol.laws.impact import NewtonImpactLaw
from nscontrol.laws.inclusion import solve_inclusion
from nscontrol.laws.relay import Relay


def _record(scenario: str, size: int, ours: float, ref: float | None = None,
            reference: str | None = None, **accuracy: Any) -> dict:
    return {"scenario": scenario, "size": size, "ours_s_per_solve": ours,
            "reference": reference, "reference_s_per_solve": ref,
            "ratio": None if ref is None else ref / ours, "accuracy": accuracy}


def run(quick: bool = False) -> Iterator[dict]:
    rng = np.random.default_rng(0)
    budget = 0.05 if quick else 0.5
    for m in (10,) if quick else (10, 100):
        law = Relay(rng.uniform(0.5, 2.0, m))
        M = np.diag(rng.uniform(0.5, 2.0, m))
        q = rng.uniform(-3.0, 3.0, m)
        closed = solve_inclusion(law, M, q)
        lcp = solve_inclusion(law, M, q, method="lcp")
        yield _record("relay_step_diagonal", m,
                      time_per_call(lambda: solve_inclusion(law, M, q), budget=budget),
                      time_per_call(lambda: solve_inclusion(law, M, q, method="lcp"),
                                    budget=budget),
                      "nscontrol-lcp-path", residual_closed=closed.residual,
                      residual_lcp=lcp.residual,
                      max_z_difference=float(np.max(np.abs(closed.z - lcp.z))))
        A = rng.normal(size=(m, m)) / np.sqrt(m)
        Mc = A @ A.T + np.eye(m)
        sol = solve_inclusion(law, Mc, q)
        yield _record("relay_step_coupled", m,
                      time_per_call(lambda: solve_inclusion(law, Mc, q), budget=budget),
                      residual=sol.residual, lcp_iterations=sol.iterations)
        fric = Stribeck(0.3, 0.1, 1.0, viscous=0.01, dim=m)
        x = rng.uniform(-2.0, 2.0, m)
        z = fric.resolvent(x, 0.5)
        yield _record("stribeck_resolvent", m,
                      time_per_call(lambda: fric.resolvent(x, 0.5), budget=budget),
                      residual=fric.graph_residual(z, (x - z) / 0.5))
    for n in (10,) if quick else (10, 100):
        W = np.zeros((n, n - 1))
        W[np.arange(n - 1), np.arange(n - 1)] = -1.0
        W[np.arange(1, n), np.arange(n - 1)] = 1.0
        v = np.zeros(n)
        v[0] = 1.0
        law = NewtonImpactLaw(1.0)
        res = law.apply(np.eye(n), W, v)
        yield _record("chain_impact", n,
                      time_per_call(lambda: law.apply(np.eye(n), W, v), budget=budget),
                      momentum_error=abs(float(res.v_plus.sum()) - 1.0),
                      energy_error=abs(float(res.v_plus @ res.v_plus) - 1.0))
