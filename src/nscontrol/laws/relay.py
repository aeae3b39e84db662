"""Relay (signum) law with componentwise bounds: ``phi(z) = diag(c) Sign(z)``."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import ModelError
from .base import ComplementarityForm, SetValuedLaw, broadcast_parameter, check_dim

__all__ = ["Relay"]


def relay_distance(z: FloatArray, v: FloatArray, c: FloatArray) -> FloatArray:
    """Per-component distance of ``(z_i, v_i)`` from the graph of ``c_i Sign``.

    The graph is the vertical segment ``{0} x [-c, c]`` plus the two horizontal half-lines
    ``v = +-c`` on the side of ``z``; the distance is the smaller of the two candidates.
    """
    to_segment = np.hypot(z, np.maximum(np.abs(v) - c, 0.0))
    with np.errstate(invalid="ignore"):
        to_branch = np.where(z != 0.0, np.abs(v - c * np.sign(z)), np.inf)
    return np.minimum(to_segment, to_branch)


@dataclass(frozen=True, eq=False)
class Relay(SetValuedLaw):
    """Relay law ``phi(z)_i = c_i Sign(z_i)`` with ``Sign(0) = [-1, 1]``.

    In a Lur'e system ``w in -phi(z)``: ``w_i = -c_i sign(z_i)`` for ``z_i != 0`` and
    ``w_i in [-c_i, c_i]`` at ``z_i = 0``.

    Parameters
    ----------
    bound
        The bounds ``c >= 0``: a scalar (repeated over ``dim`` components) or a vector.
    dim
        Number of components when ``bound`` is a scalar (default 1).

    Notes
    -----
    Resolvent (soft thresholding): ``z = sign(x) max(|x| - gamma c, 0)``.

    Complementarity form (box-MCP in ``w``, split into an LCP): with ``w = -c + s``,
    ``s in [0, 2c]``::

        0 <= s ⟂ z + b >= 0,     0 <= b ⟂ 2c - s >= 0

    (``b`` is the negative part of ``z`` when ``w = c``). For ``z = M w + q`` the LCP matrix
    ``[[M, I], [-I, 0]]`` is positive semidefinite whenever ``M`` is.

    Examples
    --------
    >>> Relay(2.0).resolvent([3.0], gamma=1.0)
    array([1.])
    """

    bound: Any = 1.0
    dim: int = field(default=None)  # type: ignore[assignment]  # None: set in __post_init__
    monotone = True
    componentwise = True

    def __post_init__(self) -> None:
        dim = None if self.dim is None else check_dim(self.dim)
        c = broadcast_parameter("bound", self.bound, dim)
        if np.any(~np.isfinite(c)):
            raise ModelError(f"bound: expected finite relay bounds, got {c}")
        if np.any(c < 0.0):
            raise ModelError(f"bound: expected relay bounds c >= 0, got min(c) = {c.min():.3g}; "
                             "the sign of the feedback belongs in the linear part (w in -phi(z))")
        object.__setattr__(self, "bound", c)
        object.__setattr__(self, "dim", int(c.shape[0]))

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        return np.sign(x) * np.maximum(np.abs(x) - gamma * self.bound, 0.0)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        return float(np.linalg.norm(relay_distance(z, v, self.bound)))

    def _select(self, z: FloatArray) -> FloatArray:
        return self.bound * np.sign(z)

    def complementarity_form(self) -> ComplementarityForm:
        """``w = -c + s``, ``0 <= s ⟂ z + b >= 0``, ``0 <= b ⟂ 2c - s >= 0`` (Notes)."""
        m = self.dim
        eye, zero = np.eye(m), np.zeros((m, m))
        return ComplementarityForm(
            w0=-self.bound.copy(), E=np.hstack([eye, zero]), Nz=np.vstack([eye, zero]),
            Nxi=np.block([[zero, eye], [-eye, zero]]),
            r=np.concatenate([np.zeros(m), 2.0 * self.bound]),
            description="relay: w = -c + s, 0 <= s ⟂ z + b >= 0, 0 <= b ⟂ 2c - s >= 0")

    def __repr__(self) -> str:
        return f"Relay(bound={self.bound.tolist()})"
