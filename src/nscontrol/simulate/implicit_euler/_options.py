"""The options of ``method="implicit_euler"``, checked once into a frozen record."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..._validation import check_bool, check_in_interval, check_integer, check_positive
from ...errors import ModelError
from .._block_runner import BlockRunner
from ..trajectory import _signal_names

__all__ = ["ImplicitEulerOptions", "SIGNALS"]

#: The signals the method records.
SIGNALS = ("z", "w", "y")


@dataclass(frozen=True)
class ImplicitEulerOptions:
    """The options of ``method="implicit_euler"``, validated once (their meaning: the
    package docstring). Build it with :meth:`parse` from the keyword options of
    ``simulate``.

    ``blocks`` is internal: the :class:`~nscontrol.simulate._block_runner.BlockRunner` of a
    closed loop of blocks around a Lur'e plant, set by the ``python_blocks`` lowering of
    ``simulate(closed_loop(plant, block), ...)``.
    """

    h: float
    theta: float = 1.0
    u: Any = None
    record_every: int = 1
    signals: frozenset[str] | None = None
    progress: bool | None = None
    sensitivity: bool = False
    blocks: BlockRunner | None = None

    @classmethod
    def parse(cls, options: Mapping[str, Any]) -> ImplicitEulerOptions:
        """The checked options: unknown names and bad values raise ``ModelError``.

        Parameters
        ----------
        options : mapping
            The method's options as given to :func:`nscontrol.simulate` (``h`` required).

        Returns
        -------
        ImplicitEulerOptions
            The validated record.
        """
        unknown = set(options) - _OPTIONS
        if unknown:
            raise ModelError(f"implicit_euler: unknown option(s) {sorted(unknown)}; "
                             f"accepted: {sorted(_OPTIONS - {'blocks'})}")
        if "h" not in options:
            raise ModelError("h: implicit_euler needs a step, e.g. simulate(sys, x0, t_span, "
                             "method='implicit_euler', h=1e-3)")
        get = options.get
        blocks = _check_blocks(get("blocks"), get("u"))
        sensitivity = check_bool("sensitivity", get("sensitivity", False))
        if sensitivity and blocks is not None:
            raise ModelError("sensitivity: not available for a closed loop of blocks (the "
                             "Jacobian of the discrete map would miss the feedback's "
                             "derivative)")
        signals = get("signals")
        return cls(h=check_positive("h", options["h"]),
                   theta=check_in_interval("theta", get("theta", 1.0), 0.5, 1.0),
                   u=get("u"), record_every=check_integer("record_every",
                                                          get("record_every", 1), minimum=1),
                   signals=None if signals is None else frozenset(
                       _signal_names(signals, SIGNALS)),
                   progress=check_bool("progress", get("progress"), allow_none=True),
                   sensitivity=sensitivity, blocks=blocks)


_OPTIONS = frozenset(ImplicitEulerOptions.__dataclass_fields__)


def _check_blocks(blocks: Any, u: Any) -> BlockRunner | None:
    """The ``blocks`` option (``None`` when absent): a closed loop's block runner, not given
    with ``u`` (the controller's output is the plant's input)."""
    if blocks is None:
        return None
    if not isinstance(blocks, BlockRunner):
        raise ModelError(f"blocks: expected the BlockRunner of a closed loop (set by "
                         f"simulate(closed_loop(plant, block), ...)), got "
                         f"{type(blocks).__name__}")
    if u is not None:
        raise ModelError("u: the plant of a closed loop takes its input from the loop's "
                         "controller; give the reference to the controller instead")
    return blocks
