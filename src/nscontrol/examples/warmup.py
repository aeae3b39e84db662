"""Compile the numba kernels ahead of a first run (``nscontrol warmup``, ``make demo``).

Each kernel compiles on its first call and is cached on disk (``cache=True``), so one short
run of every integrator path that reaches a kernel is enough: the LCP solvers, the exact
event loop (impacts and guards), Moreau–Jean, implicit Euler on Lur'e systems and the
switching integrator.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def _lcp() -> None:
    from ..numerics.lcp import solve_lcp
    from ..testing.lcp_problems import canonical_lcps, stack_delassus

    for p in [*canonical_lcps(), stack_delassus(8)]:
        for method in ("auto", "lemke", "pgs", "banded"):
            try:
                solve_lcp(p.M, p.q, method=method)
            except Exception:  # noqa: BLE001 - a method that refuses a matrix has compiled
                pass


def _mechanics() -> None:
    from ..simulate import simulate
    from ..testing.mechanics_problems import BouncingBall, RestingStack, impact_oscillator

    ball = BouncingBall()
    simulate(ball.system(), ball.x0, (0.0, 1.0), method="event_driven", progress=False)
    simulate(ball.system(), ball.x0, (0.0, 1.0), method="moreau_jean", h=1e-3, progress=False)
    stack = RestingStack(n=3)
    simulate(stack.system(), stack.x0, (0.0, 0.01), method="moreau_jean", h=1e-3,
             progress=False)
    simulate(impact_oscillator(), [0.0, 0.0], (0.0, 2.0), progress=False)


def _impacting_bodies() -> None:
    from .ch02_impact_observer import EPS_LIST, bodies_n1, run_observer

    run_observer(bodies_n1(), EPS_LIST[0], t_end=2.0)


def _setvalued() -> None:
    from ..simulate import simulate
    from ..testing import setvalued_problems as sp

    for make in (sp.relay_feedback, sp.diode_circuit, sp.coulomb_oscillator, sp.relay_scalar):
        p = make()
        t_end = p.t_span[0] + min(1.0, p.t_span[1] - p.t_span[0])
        simulate(p.system, p.x0, (p.t_span[0], t_end), h=1e-3, progress=False)
        if p.switched is not None:
            simulate(p.switched, p.x0, (p.t_span[0], t_end), progress=False)
    p = sp.bimodal_oscillator()
    simulate(p.system, p.x0, (0.0, 2.0), sensitivity=True, progress=False)


#: (what, how): one step of the warm-up each.
STEPS: list[tuple[str, Callable[[], Any]]] = [
    ("LCP solvers", _lcp),
    ("event-driven and Moreau-Jean mechanics", _mechanics),
    ("impacting bodies with an observer", _impacting_bodies),
    ("Lur'e systems (implicit Euler) and switching", _setvalued),
]


def warm_up(report: Callable[[str], None] = lambda _: None) -> list[str]:
    """Run every step (``report(what)`` before each); returns the steps that failed, as
    ``"what: error"`` (a failing step only leaves its kernels to compile on first use)."""
    failed = []
    for what, step in STEPS:
        report(what)
        try:
            step()
        except Exception as exc:  # noqa: BLE001 - warm-up is best effort, said in the output
            failed.append(f"{what}: {type(exc).__name__}: {exc}")
    return failed
