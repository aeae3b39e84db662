"""The super-twisting law ``phi(z) = k1 |z|^{1/2} sign(z) + k2 Sign(z)``, with its exact resolvent.

It is the set-valued map whose one-step (implicit Euler) inclusion the super-twisting
controller and Levant's differentiator solve at every sample: eliminating the integral
state ``nu_{k+1} = nu_k - h k2 sigma_{k+1}`` from the implicit step leaves
``s + gamma (k1 |s|^{1/2} sign(s) + h k2 Sign(s)) ∋ p`` for the new sample ``s``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import FloatArray, as_float_array
from ..errors import DimensionError, ModelError
from .base import SetValuedLaw, broadcast_parameter, check_dim

__all__ = ["SuperTwistingLaw", "super_twisting_resolvent"]


def super_twisting_resolvent(x: Any, a: Any, b: Any) -> Any:
    """The solution ``z`` of ``z + a |z|^{1/2} sign(z) + b Sign(z) ∋ x`` (``a, b >= 0``).

    Parameters
    ----------
    x : float or ndarray
        The right-hand side.
    a : float or ndarray
        Weight of the square-root term (``gamma k1``).
    b : float or ndarray
        Weight of the sign graph (``gamma k2``).

    Returns
    -------
    float or ndarray
        ``z = 0`` when ``|x| <= b``; otherwise ``z = sign(x) r^2`` with ``r > 0`` the positive
        root of ``r^2 + a r - (|x| - b) = 0``, written ``r = 2c / (a + sqrt(a^2 + 4c))``
        (``c = |x| - b``) so that no cancellation occurs when ``a^2 >> c``.

    Examples
    --------
    >>> float(super_twisting_resolvent(3.0, 1.0, 1.0))   # r^2 + r - 2 = 0: r = 1
    1.0
    >>> float(super_twisting_resolvent(-0.5, 1.0, 1.0))  # inside the sign graph
    -0.0

    Raises
    ------
    ModelError
        Non-finite or non-numeric ``x``, ``a`` or ``b``, or a negative weight (the map is
        then not monotone and the formula's ``z`` solves nothing).
    DimensionError
        Shapes that do not broadcast together.
    """
    if type(x) is float and type(a) is float and type(b) is float and math.isfinite(x) \
            and 0.0 <= a < math.inf and 0.0 <= b < math.inf:   # valid scalars: no array checks
        return _resolvent(np.asarray(x), a, b)              # (implicit Euler, every step)
    x = as_float_array("x", x)
    weights = []
    for name, w in (("a", a), ("b", b)):
        w = as_float_array(name, w)
        if np.any(w < 0.0):
            raise ModelError(f"{name}: expected weights >= 0 (gamma times a gain of the "
                             f"monotone law), got {w.tolist()}; the feedback's sign belongs in "
                             f"the linear part")
        weights.append(w)
    try:
        np.broadcast_shapes(x.shape, weights[0].shape, weights[1].shape)
    except ValueError:
        raise DimensionError(f"x, a, b: shapes {x.shape}, {weights[0].shape}, "
                             f"{weights[1].shape} do not broadcast together; give scalars or "
                             f"arrays of x's shape") from None
    return _resolvent(x, weights[0], weights[1])


def _resolvent(x: FloatArray, a: Any, b: Any) -> Any:
    """:func:`super_twisting_resolvent` on checked arrays (the law's own, validated, path)."""
    c = np.maximum(np.abs(x) - b, 0.0)
    r = 2.0 * c / (a + np.sqrt(a * a + 4.0 * c) + (c == 0.0))   # c = 0: r = 0, no 0/0
    out = np.sign(x) * r * r
    return out if out.ndim else float(out)


@dataclass(frozen=True, eq=False)
class SuperTwistingLaw(SetValuedLaw):
    """``phi(z)_i = k1_i |z_i|^{1/2} sign(z_i) + k2_i Sign(z_i)`` with ``Sign(0) = [-1, 1]``.

    Maximal monotone (a continuous nondecreasing function plus a relay), componentwise.

    Parameters
    ----------
    k1
        Gains ``>= 0`` of the square-root term (scalar or one per component).
    k2
        Relay bounds ``>= 0`` (scalar or one per component).
    dim
        Number of components when both gains are scalars (default 1).

    Notes
    -----
    Resolvent in closed form (:func:`super_twisting_resolvent`): ``z + gamma phi(z) = x`` has
    ``z = 0`` when ``|x| <= gamma k2``, else ``z = sign(x) r^2`` with
    ``r^2 + gamma k1 r = |x| - gamma k2``, a quadratic in ``r = |z|^{1/2}``.

    ``graph_residual`` is the distance to the vertical segment ``{0} x [-k2, k2]`` or the
    vertical distance to the curve (an upper bound of the Euclidean distance that vanishes
    exactly on the graph). No complementarity form: the graph is curved.

    Examples
    --------
    >>> law = SuperTwistingLaw(k1=1.0, k2=1.0)
    >>> law.resolvent([3.0]).tolist(), law.resolvent([0.5]).tolist()
    ([1.0], [0.0])
    """

    k1: Any = 1.0
    k2: Any = 1.0
    dim: int = field(default=None)  # type: ignore[assignment]  # None: set in __post_init__
    monotone = True
    componentwise = True

    def __post_init__(self) -> None:
        dim = None if self.dim is None else check_dim(self.dim)
        k1 = broadcast_parameter("k1", self.k1, dim)
        k2 = broadcast_parameter("k2", self.k2, k1.shape[0] if dim is None else dim)
        if k1.shape[0] != k2.shape[0]:
            k1 = broadcast_parameter("k1", k1, k2.shape[0])
        for name, k in (("k1", k1), ("k2", k2)):
            if np.any(~np.isfinite(k)) or np.any(k < 0.0):
                raise ModelError(f"{name}: expected finite gains >= 0 (a monotone law), got "
                                 f"{k.tolist()}; the sign of the feedback belongs in the "
                                 f"linear part (w in -phi(z))")
        object.__setattr__(self, "k1", k1)
        object.__setattr__(self, "k2", k2)
        object.__setattr__(self, "dim", int(k1.shape[0]))

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        return np.asarray(_resolvent(x, gamma * self.k1, gamma * self.k2))

    def _curve(self, z: FloatArray) -> FloatArray:
        return self.k1 * np.sqrt(np.abs(z)) * np.sign(z) + self.k2 * np.sign(z)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        to_segment = np.hypot(z, np.maximum(np.abs(v) - self.k2, 0.0))
        to_curve = np.where(z != 0.0, np.abs(v - self._curve(z)), np.inf)
        return float(np.linalg.norm(np.minimum(to_segment, to_curve)))

    def _select(self, z: FloatArray) -> FloatArray:
        return self._curve(z)

    def __repr__(self) -> str:
        return f"SuperTwistingLaw(k1={self.k1.tolist()}, k2={self.k2.tolist()})"
