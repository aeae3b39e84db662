"""The integrator family and the driver behind :func:`nscontrol.simulate`.

An integrator is a subclass of :class:`Integrator`; :data:`METHODS` maps the built-in names to
theirs, and ``simulate(method=...)`` takes a name or a class (as SciPy's ``solve_ivp`` does),
so a user can plug in an integrator of their own.

The contract an integrator keeps (the numbered list the driver relies on):

1. ``name`` (str), ``capabilities`` (a frozenset drawn from :data:`CAPABILITIES`) and
   ``options`` (the names of its own options, beside the common ones the driver owns:
   :data:`COMMON_OPTIONS`).
2. :meth:`Integrator.supports` says whether it integrates a system; the driver refuses the
   others with one :class:`~nscontrol.errors.ModelError` naming the method and the system.
3. :meth:`Integrator.integrate` validates its own options and ``x0`` and returns a
   :class:`~nscontrol.simulate.trajectory.Trajectory` built by a
   :class:`~nscontrol.simulate.trajectory.Recorder` (status 0 at the end of the span, 1 on a
   terminal event). It may raise any error mid-run: the driver attaches the trajectory
   computed so far (the samples in its recorder) to every exception that reaches the caller
   — the library's errors, a user callback's own exception, ``KeyboardInterrupt`` — as
   ``err.trajectory``.
4. Options it does not know never reach it: the driver checks every option name first and
   raises one :class:`~nscontrol.errors.ModelError` listing the accepted ones.

What the driver owns for every method:

* sampling: ``record_every`` (every k-th sample) and ``t_eval`` (sample times; methods
  without the ``"t_eval"`` capability are resampled after the run, see
  :meth:`Trajectory.resample`);
* the failure policy ``on_failure`` (``"raise"``, ``"return"`` or ``"warn"``);
* ``listeners`` (called during the run by methods with the ``"listeners"`` capability, from
  the event table after the run otherwise);
* ``progress`` (the bar on stderr: ``True``, ``False`` or ``None``), ``sensitivity``
  (``True``/``False``, refused by methods without it) — a string such as ``"no"`` is refused
  (:func:`check_run` makes the same checks ahead of a sweep);
* composite systems (a :func:`nscontrol.closed_loop`, impacting bodies): lowered to what the
  method integrates by the registered lowerings (:mod:`nscontrol.simulate.lowering`), and
  the result (a partial one too) mapped back, their named signals added. A closed loop is
  always lowered: an integrator receives a model and, for blocks run as code, the loop's
  block runner as the internal option ``blocks=`` (the one way feedback reaches it).
"""

from __future__ import annotations

import importlib
import math
import sys
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any, ClassVar

import numpy as np

from .._validation import check_bool
from ..errors import ModelError, NscontrolError, NscontrolWarning, SolverError, ZenoError
from ._run_context import RunContext, attach_partial, current_run, run_context
from .lowering.base import Lowered, invert_all, lower, lowers, needs_lowering
from .trajectory import Trajectory

__all__ = ["Integrator", "METHODS", "CAPABILITIES", "COMMON_OPTIONS", "Lowered",
           "integrator_for", "register_method", "current_run", "check_run"]

#: What an integrator may declare it can do.
CAPABILITIES: Mapping[str, str] = {
    "events": "locates events (impacts, crossings, switchings) in time",
    "exact_flow": "exact between events when the flow is linear (matrix exponentials)",
    "time_stepping": "fixed step h; events captured within a step",
    "sensitivity": "stats['state_transition'] and saltation matrices (sensitivity=True)",
    "t_eval": "samples exactly at requested times",
    "listeners": "calls listeners at every jump during the run",
    "multipliers": "records the contact multipliers (impulses or forces)",
}

#: Options the driver handles for every method (an integrator never sees these).
COMMON_OPTIONS: frozenset[str] = frozenset(
    {"t_eval", "record_every", "signals", "on_failure", "listeners", "progress",
     "sensitivity"})


class Integrator:
    """Base class of the integrators behind :func:`nscontrol.simulate`.

    Subclasses set the class attributes and implement :meth:`integrate`; see the module
    docstring for the contract. ``pass_through`` names the common options the method handles
    itself (the driver hands them on instead of emulating them).
    """

    name: ClassVar[str] = ""
    capabilities: ClassVar[frozenset[str]] = frozenset()
    options: ClassVar[frozenset[str]] = frozenset()
    pass_through: ClassVar[frozenset[str]] = frozenset({"record_every", "signals", "progress"})

    @classmethod
    def supports(cls, system: Any) -> bool:
        """Whether this method integrates ``system`` (default: every system)."""
        return True

    @classmethod
    def systems(cls) -> str:
        """The systems it integrates, in words (for error messages)."""
        return "see its documentation"

    def integrate(self, system: Any, x0: Any, t_span: tuple[float, float],
                  **options: Any) -> Trajectory:  # pragma: no cover - abstract
        """Run from ``x0`` over ``t_span`` with the method's own ``options``."""
        raise NotImplementedError


class _ModuleIntegrator(Integrator):
    """A built-in method whose work is a module's ``integrate`` function."""

    module: ClassVar[str] = ""

    def integrate(self, system: Any, x0: Any, t_span: tuple[float, float],
                  **options: Any) -> Trajectory:
        module = sys.modules.get(self.module) or importlib.import_module(self.module)
        return module.integrate(system, x0, t_span, **options)


# -- the registry: names -> classes, resolved lazily (import nscontrol stays fast) ----------
class _Registry(Mapping[str, type[Integrator]]):
    def __init__(self, entries: Mapping[str, str]) -> None:
        self._paths = dict(entries)
        self._classes: dict[str, type[Integrator]] = {}

    def __getitem__(self, name: str) -> type[Integrator]:
        if name not in self._classes:
            module, _, attr = self._paths[name].partition(":")
            self._classes[name] = getattr(importlib.import_module(module), attr)
        return self._classes[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._paths)

    def __len__(self) -> int:
        return len(self._paths)

    def add(self, cls: type[Integrator]) -> None:
        self._paths[cls.name] = f"{cls.__module__}:{cls.__qualname__}"
        self._classes[cls.name] = cls


#: Method name -> integrator class (imported on first use).
METHODS = _Registry({
    "event_driven": "nscontrol.simulate.methods:EventDriven",
    "moreau_jean": "nscontrol.simulate.methods:MoreauJean",
    "implicit_euler": "nscontrol.simulate.methods:ImplicitEuler",
    "switching": "nscontrol.simulate.methods:Switching",
    "sampled_zoh": "nscontrol.simulate.methods:SampledZOH",
})


def register_method(cls: type[Integrator]) -> type[Integrator]:
    """Register a user integrator under ``cls.name`` (usable as a class decorator).

    Raises
    ------
    ModelError
        ``cls`` is not an :class:`Integrator` subclass, has no ``name``, or declares an
        unknown capability.
    """
    _check_class(cls)
    if not cls.name:
        raise ModelError(f"register_method: {cls.__name__}.name is empty; set name = '...'")
    METHODS.add(cls)
    return cls


def _check_class(cls: Any) -> type[Integrator]:
    if not (isinstance(cls, type) and issubclass(cls, Integrator)):
        raise ModelError(f"method: expected a method name or an Integrator subclass, got "
                         f"{cls!r}")
    unknown = sorted(set(cls.capabilities) - set(CAPABILITIES))
    if unknown:
        raise ModelError(f"method: {cls.__name__}.capabilities has unknown entries {unknown}; "
                         f"known: {sorted(CAPABILITIES)}")
    return cls


# -- the driver ---------------------------------------------------------------------------------
def integrator_for(system: Any, method: Any = None) -> type[Integrator]:
    """The integrator class ``simulate`` would use for ``system`` and ``method``.

    Parameters
    ----------
    system
        The model (or composite system).
    method : str or Integrator subclass, optional
        Default: the system's ``default_method``.

    Raises
    ------
    ModelError
        Unknown method name, not an integrator class, no default method.
    """
    if method is None:
        method = getattr(system, "default_method", None)
        if method is None:
            raise ModelError(f"simulate: {type(system).__name__} has no default_method; pass "
                             f"method= one of {sorted(METHODS)} (or an Integrator subclass)")
    if isinstance(method, str):
        if method not in METHODS:
            raise ModelError(f"method: expected one of {sorted(METHODS)} or an Integrator "
                             f"subclass, got {method!r}")
        return METHODS[method]
    return _check_class(method)


def run(system: Any, x0: Any, t_span: tuple[float, float], method: Any,
        options: dict[str, Any]) -> Trajectory:
    """The body of :func:`nscontrol.simulate` (validated ``t_span``)."""
    cls = integrator_for(system, method)
    _refuse_blocks(options)
    applied: list[Any] = []
    if needs_lowering(system, cls):   # a closed loop, impacting bodies: lowered for it
        if not lowers(system, cls):
            raise ModelError(_unsupported(cls, system))
        system, x0, options, applied = lower(system, cls, x0, options)
    common, own = _split_options(cls, options)
    if "time_stepping" in cls.capabilities and own.get("h") is not None:
        own["h"] = _check_step(own["h"], t_span)
    try:
        with run_context(RunContext(cls.name)) as ctx:
            traj = _run_guarded(cls, ctx, system, x0, t_span, common, own)
    except BaseException as err:   # the partial run in the terms of the system given too
        partial = getattr(err, "trajectory", None)
        if applied and isinstance(partial, Trajectory):
            err.trajectory = invert_all(partial, applied)  # type: ignore[attr-defined]
        raise
    return invert_all(traj, applied) if applied else traj


def check_run(system: Any, method: Any, options: Mapping[str, Any]) -> type[Integrator]:
    """What :func:`nscontrol.simulate` checks before it runs, for a caller that will run many
    simulations (a sweep) and must refuse a bad call once, up front: the method, that it
    integrates ``system`` (a closed loop is checked when it is lowered, at run time), the
    option names and the common options' values.

    Parameters
    ----------
    system
        The model.
    method : str or Integrator subclass or None
        As in :func:`nscontrol.simulate`.
    options : mapping
        The options the caller will pass to :func:`nscontrol.simulate`.

    Returns
    -------
    type[Integrator]
        The integrator that will run.

    Raises
    ------
    ModelError
        Unknown method or option, a method that does not integrate ``system``, a bad common
        option (``on_failure``, ``listeners``, ``progress``, ``sensitivity`` ...).
    """
    cls = integrator_for(system, method)
    _refuse_blocks(options)
    if not lowers(system, cls):
        raise ModelError(_unsupported(cls, system))
    _split_options(cls, dict(options))
    return cls


def _refuse_blocks(options: Mapping[str, Any]) -> None:
    """``blocks=`` is set by the lowering of a closed loop, never by a caller: the one way
    feedback reaches an integrator is ``simulate(closed_loop(plant, block), ...)``."""
    if "blocks" in options:
        raise ModelError(f"blocks: expected the BlockRunner of a closed loop (set by "
                         f"simulate(closed_loop(plant, block), ...) when it lowers the loop), "
                         f"got {type(options['blocks']).__name__} given to simulate; close "
                         f"the loop with nscontrol.closed_loop instead")


def _unsupported(cls: type[Integrator], system: Any) -> str:
    """The message for a method that does not integrate ``system``, naming those that do."""
    able = [name for name in METHODS if lowers(system, METHODS[name])]
    todo = (f"use method={able[0]!r}" + (f" (or one of {able[1:]})" if able[1:] else "")
            if able else "no built-in method integrates it, and no registered lowering turns "
            "it into a system one does (see nscontrol.simulate.register_lowering)")
    return f"{cls.name}: integrates {cls.systems()}, got {type(system).__name__}; {todo}"


#: What ``simulate(..., controller=...)`` is told: feedback is a closed loop, a system too.
FEEDBACK_IS_A_CLOSED_LOOP = (
    "controller: unknown option of simulate; feedback is a closed loop, a system of its own: "
    "write simulate(closed_loop(plant, block), x0, t_span, ...) with the block a "
    "StateFeedback(K) (u = K x + k), a StaticLaw subclass for a law written in Python, or "
    "any Controller (see nscontrol.systems.feedback); a PWM controller is part of its model: "
    "SwitchedAffineSystem(modes, controller=PWMController(period, duty))")


def _split_options(cls: type[Integrator], options: dict[str, Any]
                   ) -> tuple[dict[str, Any], dict[str, Any]]:
    unknown = sorted(set(options) - COMMON_OPTIONS - set(cls.options))
    if "controller" in unknown:
        raise ModelError(FEEDBACK_IS_A_CLOSED_LOOP)
    if unknown:
        accepted = set(cls.options) | COMMON_OPTIONS
        if "sensitivity" not in cls.capabilities:
            accepted.discard("sensitivity")
        raise ModelError(f"{cls.name}: unknown option(s) {unknown}; accepted: "
                         f"{sorted(accepted)}")
    common = {k: v for k, v in options.items() if k in COMMON_OPTIONS}
    own = {k: v for k, v in options.items() if k not in COMMON_OPTIONS}
    if "progress" in common:      # one check for every method (a str would be truthy)
        common["progress"] = check_bool("progress", common["progress"], allow_none=True)
    if "sensitivity" in common:
        common["sensitivity"] = check_bool("sensitivity", common["sensitivity"])
    on_failure = common.get("on_failure", "raise")
    if on_failure not in ("raise", "return", "warn"):
        raise ModelError(f"on_failure: expected 'raise', 'return' or 'warn', got "
                         f"{on_failure!r}")
    if common.get("sensitivity") and "sensitivity" not in cls.capabilities:
        raise ModelError(f"sensitivity: method {cls.name!r} does not compute sensitivities; "
                         f"use one of {sorted(_with_capability('sensitivity'))}")
    listeners = common.get("listeners", ())
    if callable(listeners) or isinstance(listeners, str | bytes):
        raise ModelError("listeners: expected a sequence of callables, got a single "
                         f"{type(listeners).__name__}; write listeners=[fn]")
    for i, fn in enumerate(listeners):
        if not callable(fn):
            raise ModelError(f"listeners[{i}]: expected a callable (t, x_minus, x_plus, "
                             f"contacts, impulse), got {type(fn).__name__}")
    if common.get("t_eval") is not None and "t_eval" not in cls.capabilities:
        common["t_eval"] = _check_t_eval(common["t_eval"])
    for name in ("record_every", "signals", "progress", "listeners", "sensitivity", "t_eval"):
        if name in common and (name in cls.pass_through or
                               (name == "listeners" and "listeners" in cls.capabilities) or
                               (name == "sensitivity" and "sensitivity" in cls.capabilities) or
                               (name == "t_eval" and "t_eval" in cls.capabilities)):
            own[name] = common[name]
    return common, own


#: More steps than this is refused up front (it would run for hours and fill the memory).
MAX_STEPS = 10**9


def _check_step(h: Any, t_span: tuple[float, float]) -> float:
    """A step ``0 < h <= tf - t0`` that implies a feasible number of steps."""
    from .._validation import check_positive

    h = check_positive("h", h)
    span = t_span[1] - t_span[0]
    if h > span * (1 + 1e-12):
        raise ModelError(f"h: the step {h:.6g} is longer than the span {span:.6g}; use "
                         f"h <= {span:.6g} (a few hundred steps per time constant is typical)")
    steps = span / h
    if steps > MAX_STEPS:
        raise ModelError(f"h: {h:.3g} on a span of {span:.6g} means {steps:.3g} steps (more "
                         f"than {MAX_STEPS:.0e}); take a larger step or a shorter span")
    return h


def _with_capability(name: str) -> list[str]:
    out = []
    for key in METHODS:
        try:
            if name in METHODS[key].capabilities:
                out.append(key)
        except ImportError:  # pragma: no cover - a broken user registration
            continue
    return out


def _check_t_eval(t_eval: Any) -> np.ndarray:
    from .._validation import as_vector

    t = as_vector("t_eval", t_eval)
    if t.size == 0 or np.any(np.diff(t) < 0):
        raise ModelError("t_eval: expected non-decreasing sample times (at least one), sorted "
                         "in time")
    return t


def _run_guarded(cls: type[Integrator], ctx: RunContext, system: Any, x0: Any,
                 t_span: tuple[float, float], common: dict[str, Any],
                 own: dict[str, Any]) -> Trajectory:
    on_failure = common.get("on_failure", "raise")
    try:
        traj = cls().integrate(system, x0, t_span, **own)
    except NscontrolError as err:
        if err.trajectory is None and ctx.has_samples():
            err.trajectory = ctx.partial(str(err))
        if on_failure == "raise" or err.trajectory is None or not _is_run_failure(err):
            raise
        if on_failure == "warn":
            warnings.warn(f"{cls.name}: {err} (returning the partial trajectory)",
                          _warning_for(err), stacklevel=4)
        traj = err.trajectory
    except BaseException as err:  # user callbacks, KeyboardInterrupt: keep what was computed
        if ctx.has_samples() and getattr(err, "trajectory", None) is None:
            partial = ctx.partial(f"interrupted by {type(err).__name__}: {err}")
            if partial is None:  # pragma: no cover - has_samples() implies a recorder
                raise
            attach_partial(err, partial, note=True)
        raise
    traj = _stop_at_non_finite(traj, on_failure, system)
    return _post_process(cls, traj, common)


def _non_finite_source(system: Any, t: float, x: np.ndarray) -> str | None:
    """Which of the model's own functions returns a non-finite value at ``(t, x)``, if any
    (the input, the shift, the force): the error then names it instead of the dynamics."""
    probes: list[tuple[str, Callable[[], Any]]] = []
    if getattr(system, "has_input", False):
        probes.append(("the input u(t)", lambda: system.input_at(np.array([t]))))
    if getattr(system, "has_shift", False):
        probes.append(("the shift g(t)", lambda: system.shift_at(np.array([t]))))
    if getattr(system, "force", None) is not None and hasattr(system, "n_dof"):
        n = system.n_dof
        probes.append(("the force(t, q, v)", lambda: system.force(t, x[:n], x[n:2 * n])))
    u = getattr(system, "u", None)
    if callable(u) and not hasattr(system, "has_input"):
        probes.append(("the input u(t)", lambda: u(t)))
    for name, probe in probes:
        try:
            value = np.asarray(probe(), dtype=float)
        except Exception:  # noqa: BLE001 - a probe that fails says nothing about finiteness
            continue
        if not np.all(np.isfinite(value)):
            return name
    return None


def _stop_at_non_finite(traj: Trajectory, on_failure: str, system: Any = None) -> Trajectory:
    """A run whose state became infinite or NaN is a failure, not a success: cut it at the
    first non-finite sample and raise (or return it with ``status = -1``)."""
    from ..errors import NonFiniteStateError

    if math.isfinite(traj.x.sum()):   # one pass; a finite sum means every entry is finite
        return traj
    finite = np.isfinite(traj.x).all(axis=1)
    if finite.all():                  # the sum overflowed, the entries did not
        return traj
    i = int(np.argmin(finite))
    j = int(np.argmin(np.isfinite(traj.x[i])))
    name = traj.state_names[j] if j < len(traj.state_names) else f"x[{j}]"
    where = (f"at t = {traj.t[i]:.6g}" if i == 0 else
             f"between t = {traj.t[i - 1]:.6g} (last finite sample) and t = {traj.t[i]:.6g}")
    source = None
    if system is not None:
        t_probe = float(traj.t[i])
        source = (_non_finite_source(system, t_probe, traj.x[i - 1]) if i > 0 else
                  _non_finite_source(system, t_probe, traj.x[0]))
    if source is not None:
        cause = (f"{source} of the model returns a non-finite value at t = {traj.t[i]:.6g}; "
                 f"fix it there (the step size is not the cause)")
    else:
        cause = ("the model is unstable there, or a force, input or field returned a "
                 "non-finite value (evaluate them at the last finite state, "
                 "err.trajectory.x[-1])")
    message = (f"{traj.method or 'simulate'}: state {name} became {traj.x[i, j]} {where}; "
               f"{cause}")
    keep = np.arange(len(traj.t)) < i
    partial = replace(traj, t=traj.t[keep], x=traj.x[keep],
                      signals={k: np.asarray(v)[keep] for k, v in traj.signals.items()},
                      events=tuple(e for e in traj.events if e.time < traj.t[i]),
                      status=-1, message=message)
    if on_failure == "raise":
        raise NonFiniteStateError(message, time=float(traj.t[i]), state=name,
                                  trajectory=partial)
    if on_failure == "warn":
        warnings.warn(message, NscontrolWarning, stacklevel=4)
    return partial


def _is_run_failure(err: NscontrolError) -> bool:
    """Failures of the run itself (kept under on_failure='return'), not of the model."""
    return isinstance(err, SolverError | ZenoError)


def _warning_for(err: NscontrolError) -> type[Warning]:
    from ..errors import ZenoWarning

    return ZenoWarning if isinstance(err, ZenoError) else NscontrolWarning


def _post_process(cls: type[Integrator], traj: Trajectory, common: dict[str, Any]
                  ) -> Trajectory:
    listeners: Sequence[Callable[..., None]] = common.get("listeners", ())
    if listeners and "listeners" not in cls.capabilities:
        for ev in traj.events:  # replayed in time order: they observe, as during a run
            for fn in listeners:
                fn(ev.time, ev.pre, ev.post, np.array([ev.index]), None)
    every = common.get("record_every", 1)
    if every != 1 and "record_every" not in cls.pass_through:
        traj = _thin(traj, every)
    wanted = common.get("signals")
    if wanted is not None and "signals" not in cls.pass_through:
        traj = _select_signals(cls, traj, wanted)
    t_eval = common.get("t_eval")
    if t_eval is not None and "t_eval" not in cls.capabilities:
        traj = traj.resample(t_eval)
    return traj


def _thin(traj: Trajectory, every: Any) -> Trajectory:
    """Every ``every``-th sample and the last one (what a :class:`Recorder` keeps)."""
    from .._validation import check_integer

    k = check_integer("record_every", every, minimum=1)
    keep = np.zeros(len(traj.t), dtype=bool)
    keep[::k] = True
    keep[-1:] = True
    return replace(traj, t=traj.t[keep], x=traj.x[keep],
                   signals={n: np.asarray(v)[keep] for n, v in traj.signals.items()})


def _select_signals(cls: type[Integrator], traj: Trajectory, wanted: Any) -> Trajectory:
    from .trajectory import _signal_names

    names = _signal_names(wanted, tuple(traj.signals))
    return replace(traj, signals={n: v for n, v in traj.signals.items() if n in names})
