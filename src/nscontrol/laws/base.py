"""The abstract set-valued law, its complementarity encoding and the monotonicity gate.

Sign convention (Lur'e, everywhere in nscontrol): a law ``phi`` enters a system as
``w in -phi(z)``. The methods of a law speak about the law's *own* graph ``v in phi(z)``:
``select(z)`` is the minimum-norm ``v``, ``graph_residual(z, v)`` the distance of ``(z, v)`` from
``graph(phi)``. A Lur'e multiplier ``w`` is therefore checked with ``graph_residual(z, -w)``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_float_array,
    as_matrix,
    as_vector,
    check_integer,
    check_positive,
)
from ..errors import DimensionError, ModelError

__all__ = [
    "SetValuedLaw",
    "ComplementarityForm",
    "LoopTransformation",
    "require_monotone",
]


def as_gamma(gamma: ArrayLike, dim: int) -> FloatArray:
    """``gamma`` as a length-``dim`` vector of finite positive step weights."""
    if isinstance(gamma, (float, int, np.floating)) and 0.0 < gamma < np.inf:
        return np.full(dim, float(gamma))         # fast path: the common scalar step
    g = as_vector("gamma", gamma)
    if g.shape[0] == 1 and dim != 1:
        g = np.full(dim, g[0])
    if g.shape[0] != dim:
        raise DimensionError(f"gamma: expected a scalar or a vector of length {dim}, got length "
                             f"{g.shape[0]}")
    if np.any(g <= 0.0):
        raise ModelError(f"gamma: expected positive weights (the resolvent (I + gamma phi)^-1 "
                         f"needs gamma > 0), got min(gamma) = {g.min():.3g}")
    return g


def broadcast_parameter(name: str, value: Any, dim: int | None) -> FloatArray:
    """A law parameter (scalar or vector) as a vector of length ``dim`` (or its own length).

    Infinite entries are allowed (half-line bounds); NaN is not.
    """
    arr = np.atleast_1d(as_float_array(name, value, finite=False))
    if arr.ndim != 1:
        raise DimensionError(f"{name}: expected a scalar or a vector, got shape {arr.shape}")
    if np.any(np.isnan(arr)):
        raise ModelError(f"{name}: expected real entries, got NaN")
    if dim is not None:
        if arr.shape[0] == 1:
            arr = np.full(dim, arr[0])
        elif arr.shape[0] != dim:
            raise DimensionError(f"{name}: expected a scalar or a vector of length dim={dim}, "
                                 f"got length {arr.shape[0]}")
    if arr.shape[0] == 0:
        raise DimensionError(f"{name}: expected at least one component, got an empty vector")
    return arr


def check_dim(dim: Any) -> int:
    """A positive integer dimension (``DimensionError`` naming ``dim`` otherwise)."""
    return check_integer("dim", dim, minimum=1, error=DimensionError)


@dataclass(frozen=True, eq=False)
class ComplementarityForm:
    """Linear complementarity encoding of a law, independent of the system it is used in.

    The Lur'e relation ``w in -phi(z)`` holds exactly when there are ``xi`` (``k`` entries) with::

        w   = w0 + E xi                       (m entries)
        eta = Nz z + Nxi xi + r               (k entries)
        0 <= xi  ⟂  eta >= 0

    For a linear step ``z = M w + q`` this is the LCP ``0 <= xi ⟂ A xi + b >= 0`` with
    ``A = Nz M E + Nxi`` and ``b = Nz (M w0 + q) + r`` (see :meth:`lcp`), after which
    ``w`` and ``z`` follow from :meth:`recover`. When ``M`` is positive (semi)definite, ``A``
    is positive semidefinite for every law here, so Lemke's method solves it.

    Attributes
    ----------
    w0, E, Nz, Nxi, r
        The encoding above; shapes ``(m,)``, ``(m, k)``, ``(k, m)``, ``(k, k)``, ``(k,)``.
    description
        One line per component type, saying which splitting is used.
    """

    w0: FloatArray
    E: FloatArray
    Nz: FloatArray
    Nxi: FloatArray
    r: FloatArray
    description: str

    @property
    def dim(self) -> int:
        """Number of components ``m`` of ``z`` and ``w``."""
        return int(self.w0.shape[0])

    @property
    def n_complementarity(self) -> int:
        """Number ``k`` of complementarity pairs (the LCP size)."""
        return int(self.r.shape[0])

    def lcp(self, M: ArrayLike, q: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """LCP data ``(A, b)`` for the linear step ``z = M w + q``."""
        M = as_matrix("M", M, self.dim, self.dim)
        q = as_vector("q", q, self.dim)
        A = self.Nz @ M @ self.E + self.Nxi
        b = self.Nz @ (M @ self.w0 + q) + self.r
        return A, b

    def recover(self, xi: FloatArray, M: FloatArray, q: FloatArray) -> tuple[FloatArray,
                                                                             FloatArray]:
        """``(z, w)`` from an LCP solution ``xi`` of :meth:`lcp`."""
        w = self.w0 + self.E @ xi
        return M @ w + q, w

    @staticmethod
    def block_diagonal(forms: list[ComplementarityForm]) -> ComplementarityForm:
        """The encoding of a product law: the parts' encodings side by side."""
        m = sum(f.dim for f in forms)
        k = sum(f.n_complementarity for f in forms)
        E, Nz, Nxi = np.zeros((m, k)), np.zeros((k, m)), np.zeros((k, k))
        i = j = 0
        for f in forms:
            rows, cols = slice(i, i + f.dim), slice(j, j + f.n_complementarity)
            E[rows, cols], Nz[cols, rows], Nxi[cols, cols] = f.E, f.Nz, f.Nxi
            i, j = i + f.dim, j + f.n_complementarity
        return ComplementarityForm(
            w0=np.concatenate([f.w0 for f in forms]), E=E, Nz=Nz, Nxi=Nxi,
            r=np.concatenate([f.r for f in forms]),
            description="; ".join(f.description for f in forms))


@dataclass(frozen=True, eq=False)
class LoopTransformation:
    """``phi(z) = monotone_part(z) - diag(slope) z`` (ch08 §2.6).

    With ``w in -phi(z)`` this reads ``w = w_m + diag(slope) z``, ``w_m in -monotone_part(z)``:
    the linear term moves into the linear dynamics (see :meth:`transform_A`).

    Attributes
    ----------
    monotone_part
        The maximal monotone law ``phi + diag(slope) I``.
    slope
        The slopes ``sigma`` (one per component, zero for components that were monotone).
    """

    monotone_part: SetValuedLaw
    slope: FloatArray

    def transform_A(self, A: Any, G: Any, H: Any) -> FloatArray:
        """State matrix ``A + G diag(slope) H`` of the transformed Lur'e system.

        Valid for ``x' = A x + G w``, ``z = H x`` (no feedthrough ``D``; with ``D`` the
        transformation also changes ``D``, which is left to the caller).
        """
        A = as_matrix("A", A)
        n = A.shape[0]
        m = self.slope.shape[0]
        G = as_matrix("G", G, n, m)
        H = as_matrix("H", H, m, n)
        return A + G @ (self.slope[:, None] * H)


class SetValuedLaw(ABC):
    """A set-valued law ``phi: R^dim => R^dim`` (maximal monotone unless ``monotone`` is False).

    Contract for subclasses:

    1. set ``dim`` (int), ``monotone`` (bool) and ``componentwise`` (bool: ``phi`` acts on each
       component separately, so the resolvent accepts a vector ``gamma``);
    2. implement ``_resolvent(x, gamma)`` (validated inputs, ``gamma`` a vector),
       ``_graph_distance(z, v)`` and ``_select(z)``;
    3. implement :meth:`complementarity_form` when the graph is piecewise linear.

    Public methods validate their inputs once and call the protected ones.
    """

    dim: int
    monotone: bool
    componentwise: bool

    # -- public surface -------------------------------------------------------------------
    def resolvent(self, x: ArrayLike, gamma: ArrayLike = 1.0) -> FloatArray:
        """The resolvent ``z = (I + gamma phi)^{-1} x``, i.e. ``x in z + gamma phi(z)``.

        Parameters
        ----------
        x
            Point, length ``dim``.
        gamma
            Positive step weight; a vector of per-component weights for componentwise laws.

        Returns
        -------
        numpy.ndarray
            ``z``; the matching graph point is ``(z, (x - z) / gamma)``.
        """
        x = as_vector("x", x, self.dim)
        g = as_gamma(gamma, self.dim)
        if not self.componentwise and np.ptp(g) > 0.0:
            raise ModelError(f"gamma: {type(self).__name__} is not componentwise, so gamma must "
                             f"be a scalar, got per-component values {g}")
        return self._resolvent(x, g)

    def graph_residual(self, z: ArrayLike, v: ArrayLike) -> float:
        """Distance of ``(z, v)`` from ``graph(phi) = {(z, v): v in phi(z)}`` (Euclidean in R^2m).

        Exact for piecewise-linear laws; for curved laws (:class:`MonotoneFunction`,
        :class:`Stribeck`) an upper bound that vanishes exactly on the graph.
        A Lur'e pair ``w in -phi(z)`` is checked with ``graph_residual(z, -w)``.
        """
        z = as_vector("z", z, self.dim)
        v = as_vector("v", v, self.dim)
        return float(self._graph_distance(z, v))

    def contains(self, z: ArrayLike, v: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether ``v in phi(z)`` up to ``graph_residual(z, v) <= tol``."""
        return self.graph_residual(z, v) <= tol

    def in_domain(self, z: ArrayLike, tol: float = 0.0) -> bool:
        """Whether ``phi(z)`` is nonempty, allowing a violation of the domain by ``tol``."""
        return self._in_domain(as_vector("z", z, self.dim),
                               check_positive("tol", tol, allow_zero=True))

    def select(self, z: ArrayLike) -> FloatArray:
        """The minimum-norm element of ``phi(z)``.

        Raises
        ------
        InadmissibleStateError
            ``z`` is outside the domain of ``phi`` (``phi(z)`` is empty).
        """
        return self._select(as_vector("z", z, self.dim))

    def complementarity_form(self) -> ComplementarityForm:
        """The LCP encoding of ``w in -phi(z)`` (see :class:`ComplementarityForm`).

        Raises
        ------
        ModelError
            The graph is not piecewise linear, so no finite LCP encodes it.
        """
        raise ModelError(f"{type(self).__name__} has no complementarity (LCP) form: its graph is "
                         "not piecewise linear. Use its resolvent (closed form when the step "
                         "matrix is diagonal) instead")

    def loop_transformation(self, sigma: ArrayLike | None = None) -> LoopTransformation:
        """Split ``phi = phi_m - diag(sigma) I`` with ``phi_m`` maximal monotone (ch08 §2.6).

        A monotone law returns itself with zero slope.
        """
        if sigma is not None and np.any(broadcast_parameter("sigma", sigma, self.dim) != 0.0):
            raise ModelError(f"sigma: {type(self).__name__} is already monotone; it takes no loop "
                             f"transformation, got sigma = {sigma!r}")
        return LoopTransformation(monotone_part=self, slope=np.zeros(self.dim))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dim={self.dim})"

    # -- subclass hooks -------------------------------------------------------------------
    def _in_domain(self, z: FloatArray, tol: float) -> bool:
        return True    # full domain unless a subclass says otherwise

    @abstractmethod
    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray: ...

    @abstractmethod
    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float: ...

    @abstractmethod
    def _select(self, z: FloatArray) -> FloatArray: ...


def require_monotone(law: SetValuedLaw, *, who: str,
                     loop_transformation: LoopTransformation | None = None) -> SetValuedLaw:
    """Return a maximal monotone law for a method that needs one, or refuse clearly.

    Parameters
    ----------
    law
        The law of the model.
    who
        Name of the calling method, quoted in the error.
    loop_transformation
        For a non-monotone ``law``: the split ``law = monotone_part - diag(slope)``
        (from ``law.loop_transformation()``); the caller must also move ``slope`` into its
        linear part (``LoopTransformation.transform_A``).

    Returns
    -------
    SetValuedLaw
        ``law`` itself when monotone, else ``loop_transformation.monotone_part``.

    Raises
    ------
    ModelError
        ``law`` is not monotone and no (valid) loop transformation was given.
    """
    if not isinstance(law, SetValuedLaw):
        raise ModelError(f"{who}: expected a SetValuedLaw, got {type(law).__name__}")
    if law.monotone:
        return law
    if loop_transformation is None:
        raise ModelError(
            f"{who}: requires a maximal monotone law, got the non-monotone {law!r}. Way out: "
            f"split it with lt = law.loop_transformation() (phi = phi_m - sigma I, ch08 §2.6), "
            f"move sigma into the linear part (A -> lt.transform_A(A, G, H)) and pass "
            f"loop_transformation=lt")
    part = loop_transformation.monotone_part
    if not part.monotone or part.dim != law.dim:
        raise ModelError(f"{who}: loop_transformation.monotone_part must be a monotone law of "
                         f"dim {law.dim}, got {part!r} (monotone={part.monotone})")
    return part
