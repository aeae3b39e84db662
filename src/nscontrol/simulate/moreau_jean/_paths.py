"""Which step loop runs a Moreau–Jean system (the system's structure alone decides it; see
the module docstring of :mod:`nscontrol.simulate.moreau_jean`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ._options import MoreauJeanOptions
from ._python_runner import PythonRunner
from ._runners import DenseRunner, PairwiseRunner, Runner, kept

__all__ = ["choose_runner"]


def choose_runner(system: Any, opts: MoreauJeanOptions, S: FloatArray | None) -> Runner:
    """The fastest correct step loop for this system (see the module docstring of
    :mod:`nscontrol.simulate.moreau_jean`)."""
    path = kept(system, ("path", opts.forces), lambda: _path(system, opts.forces))
    if path == "tridiagonal":
        return PairwiseRunner(system, opts, S, system.pairwise_contacts())
    return DenseRunner(system, opts, S) if path == "dense" else PythonRunner(system, opts, S)


def _path(system: Any, forces: str) -> str:
    """The path of :func:`choose_runner` (the system's structure alone decides it)."""
    if system.is_linear and forces == "implicit":
        K = system.stiffness
        D = system.damping
        diag = system.mass_diagonal
        offdiag = [X for X in (K, D) if X is not None and np.count_nonzero(X - np.diag(np.diag(X)))]
        pairs = system.pairwise_contacts()
        if diag is not None and not offdiag and pairs is not None and _neighbour_only(pairs):
            return "tridiagonal"
        return "dense"
    return "python"


def _neighbour_only(pairs: tuple[np.ndarray, ...]) -> bool:
    """Contacts share coordinates only with their neighbours: the Delassus matrix is
    tridiagonal."""
    ia, ib, _, _ = pairs
    owner: dict[int, list[int]] = {}
    for j, (a, b) in enumerate(zip(ia, ib, strict=True)):
        for d in (a, b):
            if d >= 0:
                owner.setdefault(int(d), []).append(j)
    return all(max(js) - min(js) <= 1 for js in owner.values())
