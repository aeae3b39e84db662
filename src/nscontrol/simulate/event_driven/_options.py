"""Options of :func:`integrate`, checked once, and the check of an input."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from ..._validation import check_bool, check_integer, check_positive
from ...errors import DimensionError, ModelError
from ...numerics.lti import Exosystem


def _check_input(system: Any, u: Any) -> Any:
    """``u`` must be an :class:`Exosystem` with one output per actuator column."""
    if u is None:
        return None
    if not isinstance(u, Exosystem):
        raise ModelError(f"u: event_driven needs the input as an Exosystem (constant, "
                         f"polynomial, sinusoid or a sum: exact flow), got "
                         f"{type(u).__name__}; for another function of time use "
                         f"method='moreau_jean', or write it as a time-dependent force")
    m = system.n_dof if system.actuation is None else system.actuation.shape[1]
    if u.n_inputs != m:
        raise DimensionError(f"u: expected an Exosystem with {m} input(s) (the actuation's "
                             f"columns), got {u.n_inputs}")
    return u


@dataclass(frozen=True, slots=True)
class _Options:
    """The options of one run, checked (names as the runners use them; the user's names in
    :func:`~nscontrol.simulate.event_driven.integrate`)."""

    t0: float
    dt: float
    max_events: int
    min_interval: float
    ratio_tol: float
    horizon: float  # < 0: relative criterion (``rel``)
    rel: float
    listeners: tuple[Callable[..., None], ...]
    rtol: float
    atol: float
    every: Any  # checked by the Recorder (``record_every``)
    signals: Sequence[str] | None
    progress: bool | None

    @classmethod
    def checked(cls, t0: float, tf: float, **options: Any) -> _Options:
        """The user's options (the keywords of :meth:`_check`), each checked; the result of
        the same options, without listeners, is reused (a sweep or a benchmark checks its
        options once, not at every run)."""
        key = None
        if not options["listeners"]:  # a cached listener would stay alive with its closure
            try:
                key = (t0, tf, *((type(v), v) for v in options.values()))
                hit = _CHECKED.get(key)
            except TypeError:  # an unhashable option (a list of signals): no reuse
                key = hit = None
            if hit is not None:
                return hit
        opts = cls._check(t0, tf, **options)
        if key is not None:
            if len(_CHECKED) >= 64:
                _CHECKED.clear()
            _CHECKED[key] = opts
        return opts

    @classmethod
    def _check(cls, t0: float, tf: float, *, dt: float | None, max_events: int,
               min_interval: float, zeno_ratio_tol: float, zeno_horizon: float | None,
               zeno_rel: float, listeners: Sequence[Callable[..., None]],
               rtol: float, atol: float, record_every: int, signals: Sequence[str] | None,
               progress: bool | None) -> _Options:
        for i, fn in enumerate(listeners):
            if not callable(fn):
                raise ModelError(f"listeners[{i}]: expected a callable (t, x_minus, x_plus, "
                                 f"contacts, impulse), got {type(fn).__name__}")
        return cls(t0=t0, dt=check_positive("dt", dt) if dt is not None else (tf - t0) / 1000,
                   max_events=check_integer("max_events", max_events, minimum=1),
                   min_interval=check_positive("min_interval", min_interval, allow_zero=True),
                   ratio_tol=check_positive("zeno_ratio_tol", zeno_ratio_tol),
                   horizon=(check_positive("zeno_horizon", zeno_horizon)
                            if zeno_horizon is not None else -1.0),
                   rel=check_positive("zeno_rel", zeno_rel),
                   listeners=tuple(listeners), rtol=check_positive("rtol", rtol),
                   atol=check_positive("atol", atol), every=record_every, signals=signals,
                   progress=check_bool("progress", progress, allow_none=True))


#: Checked options by ``(t0, tf, (type, value) of each option)``.
_CHECKED: dict[tuple[Any, ...], _Options] = {}
