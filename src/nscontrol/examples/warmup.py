"""Compile the numba kernels ahead of a first run (``nscontrol warmup``, ``make demo``).

Each kernel compiles on its first call and is cached on disk (``cache=True``), so one short
run of every integrator path that reaches a kernel is enough: the LCP solvers, the exact
event loop (impacts and guards), Moreau–Jean (linear and nonlinear forces), implicit Euler on
Lur'e systems (closed-form and LCP steps), the switching integrator, and the compiled loops of
closed loops with compiled blocks and models. :data:`COMPILES`
names the kernel modules each step reaches; a test holds it equal to the ``_*_kernel*.py``
modules of the package, so a new kernel module cannot be forgotten here.
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
    # forces="explicit" takes the Python path (as M(q) or nonlinear forces do), whose
    # matrices come from the linearised-forces kernel
    simulate(ball.system(), ball.x0, (0.0, 0.2), method="moreau_jean", h=1e-3,
             forces="explicit", progress=False)


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
    _lure_lcp()


def _lure_lcp() -> None:
    """A two-component relay coupled through ``H G`` (no triangular order): the one-step
    inclusion is an LCP, solved by the compiled LCP step loop."""
    import numpy as np

    from ..laws.set_valued import Relay
    from ..simulate import simulate
    from ..systems.lure import LureSystem

    coupled = LureSystem(-np.eye(2), np.eye(2), [[1.0, 0.5], [0.5, 1.0]], Relay([1.0, 1.0]))
    simulate(coupled, [1.0, -1.0], (0.0, 0.1), h=1e-2, progress=False)


def _zad_buck() -> None:
    """The ZAD buck's map, Jacobian, orbit search and loop, both duty variants."""
    from ..design.converter_regulation import ZADController
    from ..systems.buck import BuckConverter

    for variant in ("pl", "exact"):
        loop = ZADController(BuckConverter.normalized(0.35), 5.0, 0.18, 0.8, variant).loop()
        loop.run(loop.fixed_point().states[0], 2, n_transient=2)
        loop.duties([[0.8, 0.0]])


def _frictional_contacts() -> None:
    """Planar and spatial frictional contacts: the one-step solver and Moreau-Jean's
    compiled frictional step."""
    import numpy as np

    from ..numerics.friction_contact import solve_friction_contact
    from ..simulate import simulate
    from ..systems.frictional_bodies import inclined_block, rolling_sphere

    solve_friction_contact(np.eye(3), [-1.0, 1.0, 0.0], 0.5, dim=3)
    solve_friction_contact(np.eye(2), [-1.0, 1.0], 0.5, dim=2, method="nsgs")
    simulate(inclined_block(0.5, 0.6), [0.0] * 4, (0.0, 0.01), h=1e-3, progress=False)
    simulate(rolling_sphere(0.3), [0, 0, 0.1, 0, 0, 0, 1.0, 0, 0, 0, 0, 0], (0.0, 0.01),
             h=1e-3, progress=False)


def _sliding_mode() -> None:
    """The sampled sliding-mode loop (first order and super-twisting, both discretizations)."""
    from ..design.sliding_mode import FirstOrderSMC, SuperTwistingController
    from ..simulate import simulate
    from ..simulate.closed_loop import closed_loop
    from ..systems.sliding_mode import SlidingModePlant

    plant = SlidingModePlant.double_integrator()
    for disc in ("implicit", "explicit"):
        for ctrl in (FirstOrderSMC(plant, 1.0, 1e-2, disc),
                     SuperTwistingController(plant, 1.8, 1.65, 1e-2, disc)):
            for compiled in (True, False):      # the compiled loop, and the blocks' methods
                simulate(closed_loop(plant, ctrl, compiled=compiled), [1.0, 0.0], (0.0, 0.1),
                         method="sampled_zoh", progress=False)


def _compiled_blocks() -> None:
    """Chapter 7's compiled blocks around its Lur'e plant (implicit Euler's compiled loop),
    the two-link arm's and the foot + body's compiled models in Moreau–Jean's."""
    from ..design.friction_compensation import PDLaw, simulate_friction_loop
    from ..simulate import simulate
    from ..simulate.closed_loop import closed_loop
    from ..systems import OneLinkRobot, StateFeedback, TwoLinkArm
    from .ch04_posture_regulation import foot_body_setup, initial_state
    from .ch07_friction_compensation import reference_friction

    robot = OneLinkRobot(0.05, reference_friction())
    simulate_friction_loop(robot, PDLaw(2.0, 0.3, 0.05), l=150.0, kappa=1.0, h=1e-4, T=1e-2)
    pd = StateFeedback([[-30.0, 0.0, -8.0, 0.0], [0.0, -30.0, 0.0, -8.0]], period=1e-3)
    simulate(closed_loop(TwoLinkArm().system(), pd), [0.8, -0.6, 0.0, 0.0], (0.0, 0.05),
             method="moreau_jean", h=1e-3, progress=False)
    model, reg, plant = foot_body_setup()
    simulate(reg.folded(plant), initial_state(model, reg.design.q_star, -1.0), (0.0, 0.05),
             method="moreau_jean", h=1e-3, progress=False)
    from ..design.complementarity_tracking import CircleTask, SwitchingTrackingController

    arm = TwoLinkArm()
    simulate(closed_loop(arm.system(), SwitchingTrackingController(arm, CircleTask())),
             [0.9, -1.6, 0.0, 0.0], (0.0, 0.05), method="moreau_jean", h=1e-3,
             progress=False)
    _block_stepper()


def _block_stepper() -> None:
    """The block stepper on its own (the loops above load it inside their cached code)."""
    import warnings

    import numpy as np
    from numba.core.errors import NumbaExperimentalFeatureWarning

    from ..simulate._block_kernels import reset_blocks, step_blocks
    from ..systems._feedback_kernels import empty_output, keep_state, static_update

    e, fns, rs = np.zeros(0), (empty_output, static_update), (keep_state,)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NumbaExperimentalFeatureWarning)
        step_blocks(0.0, e, e, e, False, fns, e, -1.0, e, e, False, fns, e, -1.0, e, e, e, e,
                    e, e, np.full(3, np.nan))
        reset_blocks(0.0, e, e, e, False, rs, e, e, False, rs, e, e)


#: (what, how): one step of the warm-up each. In this order: run side by side, the LCP solvers
#: (the longest, and called by the contact steps) go first, beside the steps that need no
#: LCP kernel; the steps that call them come after, so that they mostly find them cached
#: rather than compile them a second time in another process.
STEPS: list[tuple[str, Callable[[], Any]]] = [
    ("LCP solvers", _lcp),
    ("ZAD-controlled buck converter", _zad_buck),
    ("sampled sliding-mode control", _sliding_mode),
    ("impacting bodies with an observer", _impacting_bodies),
    ("Lur'e systems (implicit Euler) and switching", _setvalued),
    ("event-driven and Moreau-Jean mechanics", _mechanics),
    ("frictional contacts", _frictional_contacts),
    ("compiled controllers, observers and models", _compiled_blocks),
]

#: Step name to the kernel modules (their dotted path in the package, as
#: :func:`nscontrol._progress.uncompiled_kernel_modules` names them) its runs compile.
COMPILES: dict[str, tuple[str, ...]] = {
    "LCP solvers": ("numerics._lcp_kernels", "numerics._lcp_dispatch_kernels"),
    "event-driven and Moreau-Jean mechanics": (
        "numerics._lti_kernels", "simulate._event_kernels", "simulate.moreau_jean._step_kernels",
        "simulate.moreau_jean._linearised_kernels"),
    "impacting bodies with an observer": ("numerics._lti_kernels", "simulate._event_kernels"),
    "Lur'e systems (implicit Euler) and switching": (
        "simulate.implicit_euler._lure_kernels", "simulate.implicit_euler._lure_lcp_kernels",
        "numerics._lti_kernels",
        "simulate.switching._pwa_kernels", "simulate.switching._filippov_kernels"),
    "ZAD-controlled buck converter": ("design._zad_kernels",),
    "frictional contacts": ("numerics._friction_kernels", "numerics._lcp_kernels",
                            "simulate.moreau_jean._frictional_kernels"),
    "sampled sliding-mode control": ("design._sliding_mode_kernels",
                                     "simulate.sampled_zoh._zoh_kernels", "simulate._block_kernels",
                                     "systems._feedback_kernels"),
    "compiled controllers, observers and models": (
        "systems._feedback_kernels", "systems._lagrangian_kernels", "systems._foot_body_kernels",
        "systems._two_link_kernels", "design._friction_compensation_kernels",
        "simulate._block_kernels", "simulate.implicit_euler._lure_kernels",
        "simulate.moreau_jean._model_kernels", "simulate.moreau_jean._step_kernels",
        "simulate.moreau_jean._linearised_kernels", "numerics._lcp_kernels",
        "design._complementarity_tracking_kernels"),
}


def warm_up(report: Callable[[str], None] = lambda _: None, jobs: int | None = 1) -> list[str]:
    """Run every step; returns the steps that failed, as ``"what: error"`` (a failing step
    only leaves its kernels to compile on first use).

    ``jobs=1`` runs the steps one after another here (``report(what)`` before each);
    more run them side by side, each in its own process (``None``: one per core), and
    ``report`` gets a line as each step finishes (``"what: done in 12 s (CPU 10 s)"``).
    The processes share the one kernel cache: each writes numba's cache index under the
    cache's lock (:func:`run_step`).
    """
    from .._processes import Outcome, check_jobs, run_each

    n_jobs = check_jobs(jobs)
    failed = []
    if n_jobs == 1:
        for what, _ in STEPS:
            report(what)
            error = _run_step_here(what)
            if error:
                failed.append(f"{what}: {error}")
        return failed
    names = [what for what, _ in STEPS]

    def done(index: int, outcome: Outcome) -> None:
        error = outcome.value if outcome.value is not None else _last_line(outcome.error)
        if error:
            failed.append(f"{names[index]}: {error}")
        report(f"{names[index]}: {'FAILED' if error else 'done'} in {outcome.seconds:.0f} s "
               f"(CPU {outcome.cpu:.0f} s)")

    run_each([(_run_step_here, (what,)) for what in names], n_jobs, on_done=done,
             shared=("numpy", "numba", "scipy.linalg", "nscontrol.simulate"))
    return failed


def run_step(what: str) -> None:
    """Run the step called ``what`` (a name of :data:`STEPS`), writing numba's cache index
    under the cache's lock (:func:`nscontrol._compile_background.cache_lock`, the one the
    background compiler takes): numba reads, extends and rewrites a module's index when it
    saves a kernel, so two processes saving kernels of one module at once could otherwise
    drop an entry, or give two kernels one data file. Compiling itself is not locked.
    """
    import numba.core.caching as caching

    from .._compile_background import cache_lock

    step = dict(STEPS)[what]
    save = caching.IndexDataCacheFile.save

    def locked_save(self: Any, key: Any, data: Any) -> None:
        with cache_lock():
            save(self, key, data)

    caching.IndexDataCacheFile.save = locked_save   # type: ignore[method-assign]
    try:
        step()
    finally:
        caching.IndexDataCacheFile.save = save      # type: ignore[method-assign]


def _run_step_here(what: str) -> str:
    """:func:`run_step`; the error as ``"Type: message"``, empty when it ran."""
    try:
        run_step(what)
    except Exception as exc:  # noqa: BLE001 - warm-up is best effort, said in the output
        return f"{type(exc).__name__}: {exc}"
    return ""


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else "failed"
