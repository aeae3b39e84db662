"""Normal cones of boxes and of the nonnegative orthant (complementarity)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray
from ..errors import InadmissibleStateError, ModelError
from .base import ComplementarityForm, SetValuedLaw, broadcast_parameter, check_dim

__all__ = ["NormalConeBox", "NormalConeInterval", "Complementarity"]


def box_normal_cone_distance(z: FloatArray, v: FloatArray, lo: FloatArray,
                             hi: FloatArray) -> FloatArray:
    """Per-component distance of ``(z_i, v_i)`` from the graph of ``N_[lo_i, hi_i]``.

    The graph is the horizontal segment ``[lo, hi] x {0}``, the half-line ``{lo} x (-inf, 0]``
    and the half-line ``{hi} x [0, inf)`` (absent when the bound is infinite).
    """
    outside = np.maximum(np.maximum(lo - z, z - hi), 0.0)
    to_segment = np.hypot(outside, v)
    with np.errstate(invalid="ignore"):
        to_lower = np.where(np.isfinite(lo), np.hypot(z - lo, np.maximum(v, 0.0)), np.inf)
        to_upper = np.where(np.isfinite(hi), np.hypot(z - hi, np.minimum(v, 0.0)), np.inf)
    return np.minimum(to_segment, np.minimum(to_lower, to_upper))


@dataclass(frozen=True, eq=False)
class NormalConeBox(SetValuedLaw):
    """Normal cone of the box ``[lower, upper]``: ``phi(z) = N_[lower, upper](z)``.

    Componentwise: ``phi(z)_i = (-inf, 0]`` at ``z_i = lower_i``, ``[0, inf)`` at
    ``z_i = upper_i``, ``{0}`` inside, empty outside (``R`` when ``lower_i = upper_i``).
    In a Lur'e system ``w in -phi(z)`` keeps ``z`` in the box: ``w_i >= 0`` pushes up at the
    lower face, ``w_i <= 0`` down at the upper face.

    Parameters
    ----------
    lower, upper
        Bounds, scalars (repeated over ``dim``) or vectors; ``-inf``/``inf`` allowed for
        half-lines. ``lower <= upper`` componentwise.
    dim
        Number of components when both bounds are scalars (default 1).

    Notes
    -----
    Resolvent: the projection ``z = clip(x, lower, upper)`` (independent of ``gamma``).

    Complementarity form, per component, with ``w = a - b``::

        0 <= a ⟂ z - lower >= 0,     0 <= b ⟂ upper - z >= 0

    (a row is dropped when its bound is infinite; ``w = 0`` when both are). For ``z = M w + q``
    the LCP matrix ``[[M, -M], [-M, M]]`` is positive semidefinite whenever ``M`` is.
    """

    lower: Any = 0.0
    upper: Any = np.inf
    dim: int = field(default=None)  # type: ignore[assignment]  # None: set in __post_init__
    monotone = True
    componentwise = True

    def __post_init__(self) -> None:
        dim = self.dim
        if dim is None and np.ndim(self.lower) == 0 and np.ndim(self.upper) == 0:
            dim = 1
        if dim is None:
            dim = int(np.size(self.lower) if np.ndim(self.lower) else np.size(self.upper))
        dim = check_dim(dim)
        lo = broadcast_parameter("lower", self.lower, dim)
        hi = broadcast_parameter("upper", self.upper, dim)
        if np.any(lo > hi):
            i = int(np.argmax(lo > hi))
            raise ModelError(f"lower, upper: expected lower <= upper componentwise, got "
                             f"lower[{i}] = {lo[i]} > upper[{i}] = {hi[i]}")
        if np.any(lo == np.inf) or np.any(hi == -np.inf):
            raise ModelError("lower, upper: the box is empty (lower = +inf or upper = -inf)")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        object.__setattr__(self, "dim", dim)

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        return np.clip(x, self.lower, self.upper)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        return float(np.linalg.norm(box_normal_cone_distance(z, v, self.lower, self.upper)))

    def _in_domain(self, z: FloatArray, tol: float) -> bool:
        return bool(np.all((z >= self.lower - tol) & (z <= self.upper + tol)))

    def _select(self, z: FloatArray) -> FloatArray:
        bad = (z < self.lower) | (z > self.upper)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise InadmissibleStateError(
                f"z: the normal cone is empty outside the box; z[{i}] = {z[i]} is not in "
                f"[{self.lower[i]}, {self.upper[i]}]. Project z first (resolvent)")
        return np.zeros(self.dim)

    def complementarity_form(self) -> ComplementarityForm:
        """``w = a - b``, ``0 <= a ⟂ z - lower >= 0``, ``0 <= b ⟂ upper - z >= 0`` (Notes)."""
        m = self.dim
        low_rows = [i for i in range(m) if np.isfinite(self.lower[i])]
        up_rows = [i for i in range(m) if np.isfinite(self.upper[i])]
        k = len(low_rows) + len(up_rows)
        E, Nz, r = np.zeros((m, k)), np.zeros((k, m)), np.zeros(k)
        for j, i in enumerate(low_rows):          # a_i: w_i += a_i, eta = z_i - lower_i
            E[i, j], Nz[j, i], r[j] = 1.0, 1.0, -self.lower[i]
        for j, i in enumerate(up_rows, start=len(low_rows)):   # b_i: w_i -= b_i, eta = upper - z
            E[i, j], Nz[j, i], r[j] = -1.0, -1.0, self.upper[i]
        return ComplementarityForm(
            w0=np.zeros(m), E=E, Nz=Nz, Nxi=np.zeros((k, k)), r=r,
            description="normal cone of a box: w = a - b, 0 <= a ⟂ z - lower >= 0, "
                        "0 <= b ⟂ upper - z >= 0")

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(lower={self.lower.tolist()}, "
                f"upper={self.upper.tolist()})")


@dataclass(frozen=True, eq=False, repr=False)
class NormalConeInterval(NormalConeBox):
    """Normal cone of one interval ``[lower, upper]`` (scalars), repeated over ``dim`` components.

    The same map as :class:`NormalConeBox`; this name reads better for scalar constraints.

    Parameters
    ----------
    lower, upper : float
        The interval's bounds, ``lower <= upper`` (either may be infinite).
    dim : int, optional
        Number of components (default 1).
    """

    def __post_init__(self) -> None:
        if np.ndim(self.lower) or np.ndim(self.upper):
            raise ModelError(f"lower, upper: NormalConeInterval takes scalar bounds, got shapes "
                             f"{np.shape(self.lower)} and {np.shape(self.upper)}; use "
                             "NormalConeBox for per-component bounds")
        super().__post_init__()


@dataclass(frozen=True, eq=False, init=False, repr=False)
class Complementarity(NormalConeBox):
    """Normal cone of the nonnegative orthant: in Lur'e form ``0 <= z ⟂ w >= 0``.

    ``phi(z) = N_{R+^dim}(z)``; its complementarity form is the LCP itself
    (``xi = w``, ``eta = z``), and its resolvent the projection ``max(x, 0)``.

    Parameters
    ----------
    dim
        Number of complementarity pairs.

    Examples
    --------
    >>> law = Complementarity(2)
    >>> law.resolvent([-1.0, 2.0]).tolist(), law.contains([0.0, 3.0], [-4.0, 0.0])
    ([0.0, 2.0], True)
    """

    def __init__(self, dim: int = 1) -> None:
        object.__setattr__(self, "lower", 0.0)
        object.__setattr__(self, "upper", np.inf)
        object.__setattr__(self, "dim", check_dim(dim))
        self.__post_init__()

    def __repr__(self) -> str:
        return f"Complementarity(dim={self.dim})"
