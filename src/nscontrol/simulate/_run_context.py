"""The run in progress: what the driver knows of a :func:`~nscontrol.simulate` call.

Integrators never need it. Every :class:`~nscontrol.simulate.trajectory.Recorder` registers
itself with the run in progress, so that the driver can attach the samples computed so far to
any exception that ends the run (a user callback's own error, ``KeyboardInterrupt``).
"""

from __future__ import annotations

import contextvars
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["RunContext", "current_run", "run_context", "register_recorder",
           "attach_partial"]


class PartialRecord(Protocol):
    """What the run needs of a recorder (:class:`~nscontrol.simulate.trajectory.Recorder`):
    its sample count and a snapshot of it as a trajectory. A protocol, so that this module
    does not import the recorder's (which registers with it)."""

    def __len__(self) -> int: ...

    def snapshot(self, *, status: int = -1, message: str | None = None,
                 method: str = "") -> Any: ...


@dataclass
class RunContext:
    """One :func:`simulate` call in progress (nested calls stack).

    Attributes
    ----------
    method
        The integrator's name.
    recorders
        Every recorder created during the run, the run's own record first.
    partial_transform
        Maps a partial trajectory to the caller's convention (e.g. the state order of
        :class:`~nscontrol.systems.ImpactingBodies`); set by the integrator that needs it.
    """

    method: str
    recorders: list[PartialRecord] = field(default_factory=list)
    partial_transform: Callable[[Any], Any] | None = None

    def has_samples(self) -> bool:
        """Whether the run's record holds at least one sample."""
        return bool(self.recorders) and len(self.recorders[0]) > 0

    def partial(self, message: str) -> Any:
        """The trajectory recorded so far (a :class:`~nscontrol.simulate.trajectory.Trajectory`,
        ``None`` before any recorder), with ``status = -1`` and ``message``."""
        if not self.recorders:
            return None
        traj = self.recorders[0].snapshot(status=-1, message=message, method=self.method)
        return self.partial_transform(traj) if self.partial_transform else traj


_CURRENT: contextvars.ContextVar[RunContext | None] = contextvars.ContextVar(
    "nscontrol_run", default=None)


def current_run() -> RunContext | None:
    """The innermost run in progress, if any."""
    return _CURRENT.get()


@contextmanager
def run_context(ctx: RunContext) -> Iterator[RunContext]:
    """Make ``ctx`` the run in progress for the duration of the block."""
    token = _CURRENT.set(ctx)
    try:
        yield ctx
    finally:
        _CURRENT.reset(token)


def register_recorder(rec: PartialRecord) -> None:
    """Called by every recorder at construction."""
    ctx = _CURRENT.get()
    if ctx is not None:
        ctx.recorders.append(rec)


def attach_partial(err: BaseException, traj: Any, *, note: bool) -> None:
    """Attach the partial trajectory ``traj`` to ``err`` as ``err.trajectory``; with
    ``note``, also a note saying so (an exception that is not the library's, whose message
    does not mention it)."""
    try:
        err.trajectory = traj  # type: ignore[attr-defined]  # on any exception
        if note:
            err.add_note(f"nscontrol: the run so far ({len(traj.t)} samples up to "
                         f"t = {traj.t[-1]:.6g}) is in err.trajectory")
    except (AttributeError, TypeError):  # pragma: no cover - exotic exceptions
        pass
