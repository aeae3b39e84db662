"""The constant matrices of one θ-method step (``Φ``, ``Γ``, ``G_h``, ``D_h``), with the
round-off of their solves below ``1e-14`` of the largest entry set to exact zeros."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray, check_in_interval, check_positive
from ...errors import ModelError

__all__ = ["StepMatrices", "step_matrices", "structural"]

#: Couplings of ``D_h`` below this fraction of ``max|D_h|`` are structural zeros.
_STRUCTURAL_ZERO = 1e-14


class StepMatrices:
    """The constant matrices of one θ-method step.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system.
    h : float
        Step.
    theta : float
        θ of the smooth part, in ``[1/2, 1]``.

    Attributes
    ----------
    Phi, Gam, Gh : ndarray
        ``Φ = W⁻¹(I + h(1-θ)A)``, ``Γ = hW⁻¹B``, ``G_h = hW⁻¹G`` with ``W = I - hθA``.
    HPhi, HGam : ndarray
        ``HΦ`` and ``HΓ``.
    Dh : ndarray
        The one-step matrix ``D_h = H G_h + D``.

    Notes
    -----
    Entries of ``Φ``, ``Γ``, ``G_h`` below ``1e-14`` times the largest are set to exact zeros:
    the round-off of the solve must not couple blocks that are uncoupled (a plant does not see
    its observer).

    Raises
    ------
    ModelError
        ``I - hθA`` is singular (condition number above ``1e14``).
    """

    def __init__(self, system: Any, h: float, theta: float) -> None:
        A, G, H = system.A, system.G, system.H
        n = A.shape[0]
        W = np.eye(n) - h * theta * A
        cond = np.linalg.cond(W)
        if not np.isfinite(cond) or cond > 1e14:
            raise ModelError(f"h: I - h·θ·A is singular for h = {h:g}, θ = {theta:g} "
                             f"(condition number {cond:.3g}); change the step h")
        B = system.B if system.B is not None else np.zeros((n, 0))
        self.Phi = structural(np.linalg.solve(W, np.eye(n) + h * (1.0 - theta) * A), False)
        self.Gam = structural(np.linalg.solve(W, h * B), False)
        self.Gh = structural(np.linalg.solve(W, h * G), False)
        self.HPhi = H @ self.Phi
        self.HGam = H @ self.Gam
        self.Dh = H @ self.Gh + system.D
        self.h, self.theta = h, theta


def step_matrices(system: Any, h: float, theta: float = 1.0) -> StepMatrices:
    """The step matrices of the θ-method for ``system`` and step ``h``.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system.
    h : float
        Step, ``> 0``.
    theta : float, optional
        θ in ``[1/2, 1]`` (default 1, backward Euler).

    Returns
    -------
    StepMatrices
        ``Φ, Γ, G_h, HΦ, HΓ, D_h`` (see the module docstring).

    Examples
    --------
    >>> from nscontrol.laws.relay import Relay
    >>> from nscontrol.systems.lure import LureSystem
    >>> m = step_matrices(LureSystem([[0.0]], [[1.0]], [[1.0]], Relay(1.0)), 0.1)
    >>> float(m.Phi[0, 0]), float(m.Dh[0, 0])
    (1.0, 0.1)
    """
    h = check_positive("h", h)
    theta = check_in_interval("theta", theta, 0.5, 1.0)
    return StepMatrices(system, h, theta)


def structural(M: FloatArray, keep_diagonal: bool = True) -> FloatArray:
    """``M`` with the round-off of a solve taken for exact zeros.

    Parameters
    ----------
    M : ndarray
        A computed matrix.
    keep_diagonal : bool, optional
        Keep a square matrix's diagonal as it is (default).

    Returns
    -------
    ndarray
        A copy of ``M`` with its entries below ``1e-14 max|M|`` set to ``0.0``.
    """
    D = np.array(M, dtype=float)
    tol = _STRUCTURAL_ZERO * float(np.max(np.abs(D), initial=0.0))
    off = np.abs(D) <= tol
    if keep_diagonal and D.ndim == 2 and D.shape[0] == D.shape[1]:
        np.fill_diagonal(off, False)
    D[off] = 0.0
    return D

