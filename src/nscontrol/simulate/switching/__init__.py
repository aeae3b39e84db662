"""Event-driven integration of switched systems (``method="switching"``).

Accepted systems:

* :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` — between crossings the flow is affine
  with an exosystem input, propagated exactly by the shared
  :class:`~nscontrol.numerics.lti.LTIFlow` of the augmented system ``[x; ω; 1]``; crossings are
  located by :func:`nscontrol.numerics.lti.first_event` (machine precision, grazing detected).
  With an input that is an arbitrary function of time, each piece is integrated by DOP853 with
  one direction-aware event per facet and a grazing event per facet. With a ``domain``, an
  ``x0`` outside it is refused and leaving it stops the run (``status = 1``).
* :class:`~nscontrol.systems.switched.FilippovSystem` — smooth fields on the sides of switching
  surfaces ``h_j(x) = 0``; DOP853 with event location and grazing detection; attracting
  sliding by the Filippov (equivalent) vector field with exit detection, the state projected
  back onto the surface; repelling sliding raises ``ModelError``. A ``from_pwa`` system whose
  two fields differ by a constant (a relay on a linear plant; no input) runs exactly in the
  PWA path's compiled loop instead, the sliding motion a mode of its own (``_affine_filippov``).
* :class:`~nscontrol.systems.nonlinear.NonlinearSystem` — a smooth field ``f(t, x[, u])``:
  the Filippov path with no surface (one DOP853 piece; with ``sensitivity=True`` the
  variational equation gives the state transition).
* :class:`~nscontrol.systems.switched.SwitchedAffineSystem` with a PWM controller — the
  switching instants ``t_k + o_j`` follow from the state sampled at the exact ``t_k = t0 + kT``
  in closed form, and each sub-interval is propagated exactly by the mode's ``LTIFlow``.

Event kinds: ``"crossing"``, ``"sliding_start"``, ``"sliding_exit"``, ``"two_sliding_start"``,
``"two_sliding_exit"`` (second-order sliding of a Filippov system, see
``_filippov``), ``"grazing"``,
``"domain_exit"`` (PWA with a domain) and ``"switch"`` (PWM instants), each with ``mode_from``
/ ``mode_to`` and the surface/facet (or domain row) in ``index``.

Options
-------
u : Exosystem or callable, optional
    Input (PWA and nonlinear systems), overriding the system's default.
t_eval : array_like, optional
    Sample times (event instants are always added). Default: ``n_samples`` equally spaced.
n_samples : int
    Number of regular samples when ``t_eval`` is not given (1001; at least 2).
sensitivity : bool
    Also compute ``stats["state_transition"]`` (``∂x(tf)/∂x(t0)``, from the flows' exponentials
    or variational equations and the saltation matrices) and ``stats["saltation_matrices"]``
    (array ``(k, n, n)``, one per crossing / sliding start / sliding exit, in event order).
rtol, atol : float
    Tolerances of DOP853 where an ODE solver is used (1e-11, 1e-13; both > 0).
max_events : int
    Event budget: more events than this raises :class:`~nscontrol.errors.BudgetExceededError`
    (``budget="max_events"``, 1e6) with the computed part. Every DOP853 piece ends at an
    event, so this also bounds the number of pieces.
max_steps : int
    Step budget (1e6): the accepted DOP853 steps of the whole run (Filippov, nonlinear, PWA
    with an input function) plus the periods of a PWM run; spending it raises
    :class:`~nscontrol.errors.BudgetExceededError` (``budget="max_steps"``).
min_rel_step : float
    Smallest DOP853 step as a fraction of the span ``tf - t0`` (1e-12, in ``(0, 1)``; the last
    step, cut at ``tf``, is exempt): a field that blows up or loses its smoothness makes the
    steps shrink, and a step below this raises ``BudgetExceededError``
    (``budget="min_rel_step"``) instead of creeping on. The tests' smallest step is 3e-8 of
    the span.
progress : bool, optional
A failure during the run (``ZenoError``, ``SolverError``: DOP853 failed, and its subclass
``BudgetExceededError``: a budget spent — ``max_events``, ``max_steps``, ``min_rel_step``)
raises with the partial trajectory, every sample computed before it, in ``err.trajectory``
(``simulate(..., on_failure="return")`` returns it
with ``status = -1``); errors in the model or its initial state are always raised.
``stats["steps"]`` counts the steps spent on ``max_steps``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from ..._validation import as_vector
from ...errors import ModelError
from ..loop import drive
from ..trajectory import Trajectory
from ._run import SwitchingDrive, SwitchingOptions, SwitchingRun, saltation_matrix

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ...systems.nonlinear import NonlinearSystem
    from ...systems.pwa import PiecewiseAffineSystem
    from ...systems.switched import FilippovSystem, SwitchedAffineSystem

__all__ = ["integrate", "saltation_matrix", "SwitchingOptions"]


def integrate(system: PiecewiseAffineSystem | FilippovSystem | SwitchedAffineSystem
              | NonlinearSystem, x0: ArrayLike, t_span: tuple[float, float],
              **options: Any) -> Trajectory:
    """Integrate a PWA, Filippov or PWM-switched system with every switching located (or a
    smooth nonlinear system, which has none).

    Parameters
    ----------
    system : PiecewiseAffineSystem or FilippovSystem or SwitchedAffineSystem or NonlinearSystem
    x0 : array_like, shape (n,)
    t_span : (float, float)
    **options
        See the module docstring (``max_steps``: the budget of accepted DOP853 steps plus
        PWM periods, default 1e6, about a minute for a small model; ``min_rel_step``: the
        smallest DOP853 step as a fraction of ``tf - t0``, default 1e-12). They are checked
        once into a :class:`SwitchingOptions`.

    Returns
    -------
    Trajectory
        Samples at ``t_eval`` and at every event; the event table; ``stats`` with event
        counts and, with ``sensitivity=True``, ``state_transition`` and
        ``saltation_matrices``. ``status = 1`` when a PWA trajectory left its ``domain``.

    Raises
    ------
    ModelError
        Unsupported system, unknown or invalid option, repelling sliding, a non-finite PWM
        duty, or (PWA) a sliding motion on a facet of a discontinuous PWA system (use
        ``FilippovSystem.from_pwa``).
    InadmissibleStateError
        ``x0`` outside a PWA system's domain or in no region.
    ZenoError
        Accumulation of events; ``err.trajectory`` holds the computed part.
    BudgetExceededError
        ``max_steps`` spent, or a step below ``min_rel_step`` (``err.budget`` names which);
        ``err.trajectory`` holds every sample computed before.
    SolverError
        DOP853 failed (e.g. a field that blows up); ``err.trajectory`` holds the computed part.

    Examples
    --------
    >>> from nscontrol.testing.setvalued_problems import relay_feedback
    >>> p = relay_feedback(T=2.0)
    >>> tr = integrate(p.switched, p.x0, p.t_span, sensitivity=True)
    >>> [e.kind for e in tr.events], tr.stats["saltation_matrices"].shape
    (['sliding_start'], (1, 2, 2))
    """
    stepper_for = _stepper_for(system)   # an unsupported system is refused first
    opts = SwitchingOptions.parse(options)
    x0 = as_vector("x0", x0, system.n_states)
    run = SwitchingRun(system, x0, t_span, opts)
    return drive(SwitchingDrive(stepper_for, system, x0, run), t_span, desc="switching",
                 progress=opts.progress)


def _stepper_for(system: Any) -> Any:
    """The stepper of ``system``'s class, ``stepper(system, x0, run) -> SwitchingStepper``."""
    from ...systems.nonlinear import NonlinearSystem
    from ...systems.pwa import PiecewiseAffineSystem
    from ...systems.switched import FilippovSystem, SwitchedAffineSystem

    if isinstance(system, PiecewiseAffineSystem):
        from ._pwa import pwa_stepper
        return pwa_stepper
    if isinstance(system, FilippovSystem):
        from ._affine_filippov import affine_sides
        pwa = affine_sides(system)
        if pwa is not None:     # the compiled loop of the PWA path
            from ._affine_filippov import AffineFilippovStepper
            return lambda system, x0, run: AffineFilippovStepper(system, x0, run, pwa)
        from ._filippov import FilippovStepper
        return FilippovStepper
    if isinstance(system, SwitchedAffineSystem):
        from ._pwm import PwmStepper
        return PwmStepper
    if isinstance(system, NonlinearSystem):
        from ._filippov import smooth_stepper
        return smooth_stepper
    raise ModelError(f"switching: expected a PiecewiseAffineSystem, FilippovSystem, "
                     f"SwitchedAffineSystem or NonlinearSystem, got "
                     f"{type(system).__name__}; Lur'e systems use method='implicit_euler'")
