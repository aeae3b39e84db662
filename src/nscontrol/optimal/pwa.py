r"""Trajectory optimisation of a :class:`~nscontrol.systems.PiecewiseAffineSystem` (a
Filippov system on a polyhedral partition) by the FESD transcription of :mod:`.stewart`.

The partition ``Λ_i = {x : H_i x <= h_i}`` is written in Stewart's form: the switching
functions are the distinct hyperplanes of all the regions' rows, ``c_j(x) = a_jᵀ x - β_j``
(normalised, ``|a_j| = 1``, a hyperplane and its opposite counted once), and each region
becomes the cells of the hyperplane arrangement it contains: on a hyperplane that does not
cut the region (a linear program bounds ``c_j`` over it) the region has one sign, on one
that cuts it both. Each cell carries its region's field ``A_i x + b_i + E u``. A sign vector
that the products list but no point realises (two hyperplanes crossing outside the region)
is a field that never becomes active away from a lower-dimensional set.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from .._validation import check_type
from ..errors import ModelError
from ..systems.pwa import PiecewiseAffineSystem
from ._casadi import require_casadi
from .stewart import FesdProblem, StewartSystem

__all__ = ["stewart_form", "pwa_problem"]

#: Relative tolerance deciding that a hyperplane does not cut a region (and that two rows are
#: the same hyperplane).
SIDE_TOL = 1e-9


def _hyperplanes(system: PiecewiseAffineSystem) -> tuple[np.ndarray, np.ndarray]:
    """The distinct hyperplanes ``a_jᵀ x = β_j`` of the regions' rows (``|a_j| = 1``, the
    first nonzero entry of ``a_j`` positive)."""
    rows: list[np.ndarray] = []
    for H, h in system.regions:
        for a, beta in zip(H, h, strict=True):
            norm = float(np.linalg.norm(a))
            if norm == 0.0:
                continue
            v = np.append(a, beta) / norm
            if v[np.flatnonzero(np.abs(v[:-1]) > SIDE_TOL)[0]] < 0:
                v = -v
            if not any(np.allclose(v, w, rtol=0.0, atol=SIDE_TOL * (1.0 + abs(w[-1])))
                       for w in rows):
                rows.append(v)
    arr = np.array(rows).reshape(-1, system.n_states + 1)
    return arr[:, :-1], arr[:, -1]


def _sides(H: np.ndarray, h: np.ndarray, a: np.ndarray, beta: float, box: float
           ) -> tuple[float, ...]:
    """The signs ``aᵀx - β`` takes on ``{H x <= h}`` (within the box): one or both."""
    from scipy.optimize import linprog

    out = []
    for sign in (1.0, -1.0):   # min then max of aᵀx
        res = linprog(sign * a, A_ub=H, b_ub=h, bounds=[(-box, box)] * a.size, method="highs")
        if res.status != 0:
            raise ModelError(f"system: a region's linear program failed ({res.message})")
        out.append(sign * res.fun - beta)
    lo, hi = out
    tol = SIDE_TOL * (1.0 + abs(beta))
    if hi <= tol:
        return (-1.0,)
    if lo >= -tol:
        return (1.0,)
    return (-1.0, 1.0)


def stewart_form(system: PiecewiseAffineSystem) -> StewartSystem:
    """The piecewise-affine system as one layer of Stewart's form (the module docstring).

    Parameters
    ----------
    system : PiecewiseAffineSystem
        The system (its input matrix ``E`` gives the inputs; no ``domain``).

    Returns
    -------
    StewartSystem
        Switching functions ``c(x) = A_c x - β`` and one field per cell.

    Raises
    ------
    ModelError
        A system with a ``domain`` (its boundary is not a switching surface: constrain the
        states instead), or two regions claiming one cell.
    """
    check_type("system", system, PiecewiseAffineSystem)
    if system.domain is not None:
        raise ModelError("system: a PiecewiseAffineSystem with a domain is not transcribed "
                         "(its boundary is no switching surface); drop the domain and bound "
                         "the states with x_min/x_max")
    ca = require_casadi()
    Ac, beta = _hyperplanes(system)
    scale = 1.0 + max(float(np.abs(h).max(initial=0.0)) for _, h in system.regions)
    box = 1e6 * scale
    signs: list[tuple[float, ...]] = []
    owner: list[int] = []
    for i, (H, h) in enumerate(system.regions):
        options = [_sides(H, h, Ac[j], beta[j], box) for j in range(Ac.shape[0])]
        for cell in itertools.product(*options):
            if cell in signs:
                raise ModelError(f"system: regions {owner[signs.index(cell)]} and {i} both "
                                 f"hold the cell of signs {cell}")
            signs.append(cell)
            owner.append(i)
    E = None if system.E is None else ca.DM(system.E)

    def field(i: int) -> Any:
        A, b = ca.DM(system.A[i]), ca.DM(system.b[i])
        if E is None:
            return lambda x, u: ca.mtimes(A, x) + b
        return lambda x, u: ca.mtimes(A, x) + b + ca.mtimes(E, u)

    Acd, bd = ca.DM(Ac), ca.DM(beta)
    return StewartSystem(fields=[field(i) for i in owner],
                         switching=lambda x: ca.mtimes(Acd, x) - bd, signs=np.array(signs))


def pwa_problem(system: PiecewiseAffineSystem, x0: Any, T: float, stages: int,
                **options: Any) -> FesdProblem:
    """A :class:`~nscontrol.optimal.stewart.FesdProblem` of a piecewise-affine system.

    Parameters
    ----------
    system : PiecewiseAffineSystem
        The system; its inputs are ``E``'s columns.
    x0 : array_like (n,)
        Initial state.
    T : float
        Horizon.
    stages : int
        Control stages.
    **options
        The other parameters of :class:`~nscontrol.optimal.stewart.FesdProblem`
        (``elements``, ``x_final``, ``stage_cost``, bounds...; not ``inputs``).

    Returns
    -------
    FesdProblem

    Raises
    ------
    ModelError
        As :func:`stewart_form`, or ``inputs`` given.
    """
    if "inputs" in options:
        raise ModelError("inputs: fixed by the system's input matrix E; do not pass it")
    layer = stewart_form(system)
    p = 0 if system.E is None else int(system.E.shape[1])
    return FesdProblem(layer, x0, T, stages, inputs=p, **options)
