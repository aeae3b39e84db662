"""The closed loop's import path in the simulation layer (kept for existing code).

:func:`closed_loop` and :class:`ClosedLoop` are plain data defined in
:mod:`nscontrol.systems.closed_loop`; how :func:`nscontrol.simulate` runs a loop is in
:mod:`nscontrol.simulate.lowering`.
"""

from __future__ import annotations

from ..systems.closed_loop import ClosedLoop, closed_loop

__all__ = ["closed_loop", "ClosedLoop"]
