"""Balancing and scaling of badly scaled matrices: one balancing routine, one ``Scaling``.

Mechanical models mix units (stiffnesses ~1e5 next to unit masses), and the numbers that
decide a design -- LMI margins, rank tests, event searches -- are only meaningful on a
well-scaled copy. Two transformations leave those decisions unchanged:

* a **diagonal similarity** ``x̃ = D^{-1} x`` with ``D`` from ``scipy.linalg.matrix_balance``
  (powers of two, so applying it is exact in floating point) -- eigenvalues, Krylov spaces,
  (un)observable modes and the feasibility of Lyapunov inequalities are invariant;
* a **time scale** ``τ = ω t`` with ``ω = max_i ||D^{-1} A_i D||_2`` -- rates are divided by ``ω``.

:func:`balance` computes ``(d, ω)`` (the only balancing routine of the package: the LMI
designs, the observability tests and the event search all use it), and :class:`Scaling`
holds the coordinates a design is solved in, adding input and output units to the state and
time scaling.

References
----------
B. N. Parlett, C. Reinsch, "Balancing a matrix for calculation of eigenvalues and
eigenvectors", Numer. Math. 13, 1969 (the LAPACK ``gebal`` scaling); Boyd, El Ghaoui, Feron,
Balakrishnan, *Linear Matrix Inequalities in System and Control Theory*, SIAM 1994, on the
invariance of Lyapunov LMIs under congruence.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from .._validation import FloatArray, as_square, check_positive
from ..errors import ModelError

__all__ = ["balance", "balanced_unit_norm", "Scaling"]


def balance(As: Sequence[Any]) -> tuple[FloatArray, float]:
    """A common balancing similarity and time scale for the matrices ``As``.

    Parameters
    ----------
    As : sequence of (n, n) array_like
        One or more matrices of the same size (e.g. the modes of a PWA system).

    Returns
    -------
    d : ndarray (n,)
        Diagonal of ``D`` (powers of two): ``D^{-1} A_i D`` is balanced for every ``i``.
    omega : float
        ``max_i ||D^{-1} A_i D||_2``; 1 when every matrix is zero (no time scale to remove).

    Raises
    ------
    ModelError, DimensionError
        No matrix, or matrices that are not square, of different sizes or not finite.

    Notes
    -----
    ``D`` balances ``Σ|A_i|`` (no permutation): for a single matrix this is the balancing of
    ``A`` itself, since ``gebal`` looks only at the moduli of the entries.

    Examples
    --------
    >>> A = np.array([[0.0, 1.0], [-1e4, -1.0]])
    >>> d, omega = balance([A])
    >>> An = A / d[:, None] * d[None, :] / omega          # D^{-1} A D / omega
    >>> round(float(np.linalg.norm(An, 2)), 12), d.tolist()
    (1.0, [0.0078125, 1.0])
    """
    mats = [as_square(f"As[{i}]", A) for i, A in enumerate(As)]
    if not mats:
        raise ModelError("As: expected at least one matrix, got none")
    n = mats[0].shape[0]
    mats = [as_square(f"As[{i}]", A, n) for i, A in enumerate(mats)]
    if n == 0:
        return np.ones(0), 1.0
    _, (d, _) = scipy.linalg.matrix_balance(sum(np.abs(A) for A in mats), permute=False,
                                            separate=True)
    d = np.asarray(d, dtype=float)
    omega = max(float(np.linalg.norm(A / d[:, None] * d[None, :], 2)) for A in mats)
    if not np.isfinite(omega) or omega == 0.0:
        omega = 1.0
    return d, omega


def balanced_unit_norm(A: Any) -> tuple[FloatArray, FloatArray, float]:
    """``A = ω D A_n D^{-1}``: the balanced copy ``A_n`` of one matrix, of 2-norm 1.

    Parameters
    ----------
    A : (n, n) array_like

    Returns
    -------
    A_n : ndarray (n, n)
        ``D^{-1} A D / ω`` (the zero matrix for ``A = 0``).
    d, omega
        As returned by :func:`balance` for ``[A]``.

    Notes
    -----
    A diagonal similarity and a time rescaling change neither the Krylov spaces nor the
    (un)observable modes, only their numerical margins: rank decisions taken on ``A_n`` do
    not depend on the units of the model.

    Examples
    --------
    >>> An, d, omega = balanced_unit_norm([[0.0, 1.0], [-1e6, 0.0]])
    >>> round(float(np.linalg.norm(An, 2)), 12), omega
    (1.0, 1024.0)
    """
    A = as_square("A", A)
    d, omega = balance([A])
    return A / d[:, None] * d[None, :] / omega, d, omega


@dataclass(frozen=True)
class Scaling:
    """Coordinates in which a design is solved: ``x̃ = S x``, ``τ = ω t``, ``u = f ũ``,
    ``y = g ỹ``.

    Then ``Ã_i = S A_i S⁻¹/ω``, ``B̃ = S B f/ω``, ``C̃ = C S⁻¹/g``; gains map back as
    ``K = f K̃ S``, ``L = ω S⁻¹ L̃/g`` and quadratic certificates as ``P = Sᵀ P̃ S``. Decay
    rates scale as ``α = ω α̃``.

    Attributes
    ----------
    S
        State scaling (invertible).
    omega
        Time scale (1/time unit of the model).
    input_unit
        Input unit ``f`` (e.g. a reference stiffness for forces).
    output_unit
        Output unit ``g`` of the measured output (observer designs).

    Examples
    --------
    >>> sc = Scaling.balanced([[[0.0, 1.0], [-1e4, -1.0]]])
    >>> sc.matrix([[0.0, 1.0], [-1e4, -1.0]]).round(3).tolist()
    [[0.0, 1.0], [-0.61, -0.008]]
    >>> P = np.array([[2.0, 0.3], [0.3, 1.0]])
    >>> bool(np.array_equal(sc.quadratic_scaled(sc.quadratic_back(P)), P))
    True
    """

    S: FloatArray
    omega: float = 1.0
    input_unit: float = 1.0
    output_unit: float = 1.0
    _diagonal: FloatArray | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        S = as_square("Scaling.S", self.S)
        if abs(np.linalg.det(S)) == 0.0:
            raise ModelError("Scaling.S: expected an invertible matrix, got a singular one")
        object.__setattr__(self, "S", S)
        diagonal = np.diagonal(S).copy()
        is_diagonal = np.array_equal(S, np.diag(diagonal))
        object.__setattr__(self, "_diagonal", diagonal if is_diagonal else None)
        check_positive("Scaling.omega", self.omega)
        check_positive("Scaling.input_unit", self.input_unit)
        check_positive("Scaling.output_unit", self.output_unit)

    # -- constructors ----------------------------------------------------------------------
    @classmethod
    def identity(cls, n: int) -> Scaling:
        """No scaling."""
        return cls(np.eye(n))

    @classmethod
    def mechanical(cls, n_dof: int, omega_ref: float, input_unit: float = 1.0,
                   output_unit: float = 1.0) -> Scaling:
        """``x = (q, q')``: ``S = diag(I, I/ω_ref)``, ``τ = ω_ref t``, forces in ``input_unit``
        (e.g. the static stiffness at the actuator), measurements in ``output_unit``
        (ch11 §3.5, ch06 §2.4)."""
        omega_ref = check_positive("omega_ref", omega_ref)
        d = np.concatenate([np.ones(n_dof), np.full(n_dof, 1.0 / omega_ref)])
        return cls(np.diag(d), omega_ref, check_positive("input_unit", input_unit),
                   check_positive("output_unit", output_unit))

    @classmethod
    def balanced(cls, As: Sequence[Any]) -> Scaling:
        """``S = D⁻¹`` and ``ω`` of :func:`balance`: every ``Ã_i`` of norm at most 1."""
        d, omega = balance(As)
        return cls(np.diag(1.0 / d), omega)

    @classmethod
    def auto(cls, As: Sequence[Any], B: Any = None, C: Any = None) -> Scaling:
        """:meth:`balanced` plus an input unit making ``‖B̃‖ = 1`` and an output unit making
        ``‖C̃‖ = 1``: every block of the design LMIs is then O(1) (without the output unit a
        beam's ``C̃`` is ~4e-3 and its observer LMI fails the re-check)."""
        d, omega = balance(As)
        S = np.diag(1.0 / d)
        f = g = 1.0
        if B is not None and np.linalg.norm(B) > 0:
            f = omega / float(np.linalg.norm(S @ np.asarray(B, float), 2))
        if C is not None and np.linalg.norm(C) > 0:
            g = float(np.linalg.norm(np.asarray(C, float) @ np.diag(d), 2))
        return cls(S, omega, f, g)

    # -- maps --------------------------------------------------------------------------------
    def matrix(self, A: Any) -> FloatArray:
        """``Ã = S A S⁻¹ / ω`` (exact for a balancing ``S``: powers of two)."""
        A = np.asarray(A, dtype=float)
        if self._diagonal is not None:
            s = self._diagonal
            return A * s[:, None] / s[None, :] / self.omega
        return self.S @ A @ np.linalg.inv(self.S) / self.omega

    def quadratic_back(self, P_scaled: Any) -> FloatArray:
        """``P = Sᵀ P̃ S``, so that ``x̃ᵀ P̃ x̃ = xᵀ P x``."""
        P_scaled = np.asarray(P_scaled, dtype=float)
        if self._diagonal is not None:
            s = self._diagonal
            return P_scaled * s[:, None] * s[None, :]
        return self.S.T @ P_scaled @ self.S

    def quadratic_scaled(self, P: Any) -> FloatArray:
        """``P̃ = S⁻ᵀ P S⁻¹``, the inverse of :meth:`quadratic_back`."""
        P = np.asarray(P, dtype=float)
        if self._diagonal is not None:
            s = self._diagonal
            return P / s[:, None] / s[None, :]
        Sinv = np.linalg.inv(self.S)
        return Sinv.T @ P @ Sinv
