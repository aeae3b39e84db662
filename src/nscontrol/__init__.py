"""nscontrol — control and observer design for non-smooth systems.

Layers (a lower layer never imports a higher one)::

    errors, _validation, _progress, sweep -> numerics -> laws -> systems -> simulate
    -> design -> analysis -> testing -> examples -> cli, report, this package root

(``numerics`` sits below ``laws`` because the multi-contact impact law solves LCPs, while the
solvers only ever see matrices; ``tests/test_layers.py`` enforces the order.)

The public surface most users need is re-exported here lazily, so that ``import nscontrol``
stays fast (numba, cvxpy and matplotlib load only when a function needs them).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from . import _kernel_cache, _lazy, errors
from .errors import (
    BudgetExceededError,
    DimensionError,
    InadmissibleStateError,
    InfeasibleDesignError,
    ModelError,
    NscontrolError,
    SolverError,
    ZenoError,
)
from .simulate import Trajectory, simulate  # noqa: E402  (the verb shadows its subpackage)

# the kernels are cached per user, by content (a new virtual environment finds them); numba
# stamps a cached kernel with its own file only: drop the caches of kernels whose imported
# kernels changed since (an edit, an upgrade) before any kernel module loads
_kernel_cache.install()
_kernel_cache.refresh()

# what a lower layer calls in a higher one (imported at the first call): a corner design's
# `verified` is shot by the analysis layer's orbit engine
_lazy.provide("corner_verifier", "nscontrol.analysis.corner_maps:verify_corner_design")

if TYPE_CHECKING:   # the lazy names below, typed for type checkers (imported on first use)
    from .numerics.lcp import solve_lcp as solve_lcp
    from .systems.closed_loop import closed_loop as closed_loop

__version__ = "0.1.0"

_SUBPACKAGES = ("laws", "numerics", "systems", "design", "analysis", "testing",
                "examples", "sweep")
_LAZY = {"solve_lcp": ("nscontrol.numerics.lcp", "solve_lcp"),
         "closed_loop": ("nscontrol.systems.closed_loop", "closed_loop")}

__all__ = ["errors", "NscontrolError", "ModelError", "DimensionError", "InadmissibleStateError",
           "InfeasibleDesignError", "SolverError", "BudgetExceededError", "ZenoError",
           "simulate", "Trajectory", *_LAZY, *_SUBPACKAGES]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    if name in _SUBPACKAGES:
        return importlib.import_module(f"nscontrol.{name}")
    raise AttributeError(f"module 'nscontrol' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The public names, the lazily imported ones included (tab completion, ``dir()``)."""
    return sorted(set(globals()) | set(__all__))
