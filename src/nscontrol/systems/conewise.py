"""Continuous conewise linear control systems: :class:`ConewiseLinearSystem`.

::

    x' = A_i x + B u,      x ∈ C_i = {x : E_i x >= 0},   i = 0..N-1

The cones form a *fan*: closed polyhedral cones with non-empty interiors, pairwise disjoint
interiors, covering ``R^n``. The field is continuous: across a facet with normal ``c`` the
modes differ by a rank-one term, ``A_i - A_j = e cᵀ``. ``B`` (full column rank) is common to
all cones, so the field is continuous in ``(x, u)``.

The fan is checked by the partition machinery of
:class:`~nscontrol.systems.pwa.PiecewiseAffineSystem` (overlaps by LP, cover on both sides of
every facet, facets and neighbours); continuity is then checked *exactly* on every facet by
the rank-one test above, before any design sees the model.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_square, as_vector
from ..errors import DimensionError, ModelError
from .pwa import CONTINUITY_RTOL, PiecewiseAffineSystem

__all__ = ["ConewiseLinearSystem", "Facet", "orthant_cones"]


@dataclass(frozen=True)
class Facet:
    """A facet shared by two cones of a fan.

    Attributes
    ----------
    i, j
        The two cones (``i < j``).
    normal
        Unit normal ``c`` of the facet's hyperplane ``cᵀx = 0``, pointing into cone ``i``.
    """

    i: int
    j: int
    normal: FloatArray


@dataclass(frozen=True, eq=False)
class ConewiseLinearSystem:
    """A continuous conewise linear system ``x' = A_i x + B u`` on a fan of cones.

    Parameters
    ----------
    A : sequence of (n, n) array_like
        One matrix per cone.
    B : (n, m) or (n,) array_like
        Input matrix, common to all cones, full column rank (a vector is one input).
    cones : sequence of (k_i, n) array_like
        Cone ``i`` is ``{x : E_i x >= 0}`` (``cones[i] = E_i``).
    state_names : tuple of str, optional
        Names of the states.

    Attributes
    ----------
    facets
        The facets of the fan (:class:`Facet`), one per pair of adjacent cones.
    pwa
        The same model as a continuous :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem`
        (input matrix ``E = B``), whose partition machinery checks the fan and finds the
        facets (two opposite half-spaces need no search); simulate it for the open loop.

    Raises
    ------
    DimensionError
        Inconsistent shapes.
    ModelError
        ``B`` without full column rank; cones that overlap or leave a gap (message from the
        partition check, naming the regions and a witness point); modes discontinuous on a
        facet: the message names the two cones, the facet's normal and the residual
        ``‖(A_i − A_j)(I − ccᵀ)‖ / max(‖A_i‖, ‖A_j‖)`` (tolerance ``CONTINUITY_RTOL``).

    Examples
    --------
    A one-sided spring: stiffness 4 for ``x_1 >= 0``, 1 otherwise.

    >>> s = ConewiseLinearSystem.bimodal([[0, 1], [-4, -0.1]], [[0, 1], [-1, -0.1]],
    ...                                  [0, 1], [1, 0])
    >>> s.n_modes, s.mode([1.0, 0.0]), s.mode([-1.0, 0.0]), len(s.facets)
    (2, 0, 1, 1)
    """

    A: tuple[FloatArray, ...]
    B: FloatArray
    cones: tuple[FloatArray, ...]
    state_names: tuple[str, ...] = ()
    facets: tuple[Facet, ...] = field(default=(), init=False)
    _pwa: PiecewiseAffineSystem | None = field(default=None, init=False, repr=False)

    if TYPE_CHECKING:
        def __init__(self, A: Sequence[ArrayLike], B: ArrayLike, cones: Sequence[ArrayLike],
                     state_names: Sequence[str] = ()) -> None: ...

    def __post_init__(self) -> None:
        if len(self.A) == 0:
            raise DimensionError("A: expected one matrix per cone, got none")
        As = tuple(as_square(f"A[{i}]", a) for i, a in enumerate(self.A))
        n = As[0].shape[0]
        As = tuple(as_square(f"A[{i}]", a, n) for i, a in enumerate(As))
        B = _input_matrix(self.B, n)
        if len(self.cones) != len(As):
            raise DimensionError(f"cones: expected {len(As)} cones (one per matrix in A), got "
                                 f"{len(self.cones)}")
        cones = tuple(as_matrix(f"cones[{i}]", E, cols=n) for i, E in enumerate(self.cones))
        for i, E in enumerate(cones):
            if np.any(np.linalg.norm(E, axis=1) == 0.0):
                raise ModelError(f"cones[{i}]: a row is zero; every row E_i[r] must be a "
                                 f"nonzero normal")
        if self.state_names and len(self.state_names) != n:
            raise DimensionError(f"state_names: expected {n} names, got "
                                 f"{len(self.state_names)}")
        pwa = None
        if _is_half_space_pair(cones):   # two half-spaces: a fan, one facet, nothing to search
            facets: tuple[Facet, ...] = (Facet(0, 1, cones[0][0] / np.linalg.norm(cones[0][0])),)
        else:
            # the partition (overlaps, cover, neighbours) is PiecewiseAffineSystem's; the
            # continuity is tested below exactly, so that the message names facet and residual
            pwa = PiecewiseAffineSystem.conewise(As, [-E for E in cones], E=B,
                                                 continuous=False,
                                                 state_names=tuple(self.state_names))
            facets = _facets(pwa, cones)
        for fac in facets:
            _check_facet_continuity(As, fac)
        if pwa is not None:
            # the exact test above is stronger than the sampled one continuous=True would
            # repeat (with its LPs): record its outcome on the partition already built
            object.__setattr__(pwa, "continuous", True)
        for key, value in (("A", As), ("B", B), ("cones", cones), ("facets", facets),
                           ("state_names", tuple(self.state_names)), ("_pwa", pwa)):
            object.__setattr__(self, key, value)

    # -- construction helpers -----------------------------------------------------------
    @classmethod
    def bimodal(cls, A1: ArrayLike, A2: ArrayLike, B: ArrayLike, c: ArrayLike, *,
                state_names: Sequence[str] = ()) -> ConewiseLinearSystem:
        """Two modes split by the hyperplane ``cᵀx = 0``: ``A1`` on ``cᵀx >= 0`` (cone 0),
        ``A2`` on ``cᵀx <= 0`` (cone 1).

        Parameters
        ----------
        A1, A2 : (n, n) array_like
            The two modes; continuity needs ``A1 - A2 = e cᵀ``.
        B : (n, m) or (n,) array_like
            Input matrix.
        c : (n,) array_like
            Normal of the switching hyperplane (nonzero).
        state_names : sequence of str, optional
            Names of the states.

        Returns
        -------
        ConewiseLinearSystem
        """
        c = as_vector("c", c)
        if not np.any(c):
            raise ModelError("c: expected a nonzero normal vector, got zeros")
        return cls(A=(A1, A2), B=B, cones=(c[None, :], -c[None, :]),
                   state_names=tuple(state_names))

    # -- queries --------------------------------------------------------------------------
    @property
    def pwa(self) -> PiecewiseAffineSystem:
        """The same model as a continuous :class:`~nscontrol.systems.pwa.PiecewiseAffineSystem`
        (regions ``{-E_i x <= 0}``, input matrix ``E = B``); built on first use for a
        bimodal fan."""
        if self._pwa is None:
            object.__setattr__(self, "_pwa", PiecewiseAffineSystem.conewise(
                self.A, [-E for E in self.cones], E=self.B, continuous=True,
                state_names=self.state_names))
        assert self._pwa is not None
        return self._pwa

    @property
    def n_states(self) -> int:
        """Dimension ``n`` of the state."""
        return int(self.A[0].shape[0])

    @property
    def n_inputs(self) -> int:
        """Number ``m`` of inputs."""
        return int(self.B.shape[1])

    @property
    def n_modes(self) -> int:
        """Number ``N`` of cones."""
        return len(self.A)

    def contains(self, i: int, x: ArrayLike, tol: float = 1e-9) -> bool:
        """Whether a state lies in cone ``i`` (``E_i x >= -tol |E_i| |x|``).

        Parameters
        ----------
        i : int
            Cone index.
        x : (n,) array_like
            State.
        tol : float, optional
            Relative tolerance.

        Returns
        -------
        bool
        """
        x = np.asarray(x, float)
        E = self.cones[i]
        return bool(np.all(E @ x >= -tol * (np.abs(E) @ np.abs(x))))

    def mode(self, x: ArrayLike, tol: float = 1e-9) -> int:
        """The cone of a state (the lowest index on a shared face).

        Parameters
        ----------
        x : (n,) array_like
            State.
        tol : float, optional
            Relative tolerance (see :meth:`contains`).

        Returns
        -------
        int
        """
        for i in range(self.n_modes):
            if self.contains(i, x, tol):
                return i
        return -1   # unreachable for a validated fan (kept for a non-finite x)

    def f(self, x: ArrayLike, u: ArrayLike | None = None) -> FloatArray:
        """The field ``A_i x + B u`` at one state.

        Parameters
        ----------
        x : (n,) array_like
            State.
        u : (m,) array_like, optional
            Input (default zero).

        Returns
        -------
        ndarray, shape (n,)
        """
        x = np.asarray(x, float)
        out = self.A[self.mode(x)] @ x
        return out if u is None else out + self.B @ np.atleast_1d(np.asarray(u, float))


def orthant_cones(n: int) -> list[FloatArray]:
    """The ``2^n`` closed orthants of ``R^n`` as cones ``{x : E x >= 0}``.

    Parameters
    ----------
    n : int
        Dimension.

    Returns
    -------
    list of (n, n) ndarray
        ``E = diag(s)`` for the sign patterns ``s`` in the order of
        ``itertools.product((1, -1), repeat=n)``: the first cone is the non-negative orthant.

    Examples
    --------
    >>> [E.diagonal().tolist() for E in orthant_cones(2)]
    [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]]
    """
    return [np.diag(np.array(s, float)) for s in itertools.product((1, -1), repeat=n)]


def _input_matrix(B: Any, n: int) -> FloatArray:
    Bm = as_vector("B", B, n)[:, None] if np.ndim(B) == 1 else as_matrix("B", B, rows=n)
    s = np.linalg.svd(Bm, compute_uv=False)
    if Bm.shape[1] == 0 or Bm.shape[1] > n or s[-1] <= n * np.finfo(float).eps * s[0]:
        raise ModelError(f"B: expected full column rank (independent inputs), got shape "
                         f"{Bm.shape} with singular values {np.array2string(s, precision=3)}; "
                         f"drop the dependent columns")
    return Bm


def _is_half_space_pair(cones: tuple[FloatArray, ...]) -> bool:
    return (len(cones) == 2 and cones[0].shape[0] == 1 and cones[1].shape[0] == 1 and
            bool(np.allclose(cones[0][0] / np.linalg.norm(cones[0][0]),
                             -cones[1][0] / np.linalg.norm(cones[1][0]), rtol=0.0, atol=1e-15)))


def _facets(pwa: PiecewiseAffineSystem, cones: tuple[FloatArray, ...]) -> tuple[Facet, ...]:
    """One facet per adjacent pair, from the neighbour table of the partition check."""
    seen: dict[tuple[int, int], Facet] = {}
    for i, row, j in pwa.neighbours:
        a, b = min(i, j), max(i, j)
        if (a, b) in seen:
            continue
        c = cones[i][row] / np.linalg.norm(cones[i][row])
        seen[(a, b)] = Facet(a, b, c if a == i else -c)
    return tuple(seen[k] for k in sorted(seen))


def _check_facet_continuity(As: tuple[FloatArray, ...], fac: Facet) -> None:
    """``A_i x = A_j x`` on the facet's hyperplane: ``(A_i - A_j)(I - ccᵀ) = 0``."""
    c = fac.normal
    D = As[fac.i] - As[fac.j]
    residual = float(np.linalg.norm(D - np.outer(D @ c, c), 2))
    scale = max(float(np.linalg.norm(As[fac.i], 2)), float(np.linalg.norm(As[fac.j], 2)),
                1e-300)
    if residual > CONTINUITY_RTOL * scale:
        raise ModelError(
            f"A: modes {fac.i} and {fac.j} are discontinuous on their shared facet (the "
            f"hyperplane cᵀx = 0 with c = {np.array2string(c, precision=6)}): residual "
            f"‖(A_{fac.i} − A_{fac.j})(I − ccᵀ)‖ = {residual:.3g}, relative "
            f"{residual / scale:.3g} > {CONTINUITY_RTOL:g}. A continuous conewise linear "
            f"system needs A_{fac.i} − A_{fac.j} = e cᵀ for some vector e; fix the matrices")
