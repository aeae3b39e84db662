"""Checks of a PWL feedback linearization (chapter 9): is ``T`` a homeomorphism, is the closed
loop well posed, do the closed-loop solutions map onto the linear ones?

* :func:`coherent_orientation` — the signs of ``det T_i`` (necessary for a PWL
  homeomorphism; sufficient for the ``T`` of the single-input construction);
* :func:`preimage_counts` — how many points ``x`` map to each sample ``z`` (exactly one for a
  homeomorphism); :func:`homeomorphism_report` combines both with the continuity of ``T``;
* :func:`crossing_ratios` — on every facet, the ratio of the normal components of the
  closed-loop fields on its two sides (positive: crossings; negative: sliding or
  non-uniqueness);
* :func:`linear_reference`, :func:`conjugacy_error` — ``z(t)`` of the linear target (matrix
  exponential of the target with the input generator) against ``T(x(t))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import expm

from .._validation import FloatArray, as_matrix, check_integer
from ..design.pwl_linearization import PWLLinearization, input_generator

__all__ = ["coherent_orientation", "preimage_counts", "HomeomorphismReport",
           "homeomorphism_report", "CrossingRatios", "crossing_ratios", "linear_reference",
           "conjugacy_error"]


def coherent_orientation(T_modes: Any) -> tuple[bool, FloatArray]:
    """Whether all pieces ``T_i`` have determinants of one strict sign.

    Parameters
    ----------
    T_modes : sequence of (n, n) array_like
        The pieces of a conewise linear map.

    Returns
    -------
    coherent : bool
    dets : ndarray
        ``det T_i``.

    Examples
    --------
    >>> coherent_orientation([np.eye(2), np.diag([1.0, -1.0])])[0]
    False
    """
    dets = np.array([np.linalg.det(np.asarray(T, float)) for T in T_modes])
    return bool(np.all(dets > 0) or np.all(dets < 0)), dets


def preimage_counts(lin: PWLLinearization, z: ArrayLike, tol: float = 1e-9) -> np.ndarray:
    """The number of distinct preimages of each point under ``T``.

    For every cone ``i`` the candidate ``x = T_i⁻¹ z`` is a preimage when it lies in ``C_i``;
    candidates equal to ``tol`` (relative) are one point (a shared face).

    Parameters
    ----------
    lin : PWLLinearization
        The map ``T`` (its pieces and its system's cones).
    z : (k, n) array_like
        Points.
    tol : float, optional
        Relative tolerance of the cone test and of the identification of candidates.

    Returns
    -------
    ndarray of int, shape (k,)
    """
    Z = as_matrix("z", np.atleast_2d(np.asarray(z, float)), cols=lin.system.n_states)
    inverses = [np.linalg.inv(T) for T in lin.T_modes]
    counts = np.zeros(Z.shape[0], dtype=int)
    for k, zk in enumerate(Z):
        found: list[FloatArray] = []
        for i, Ti_inv in enumerate(inverses):
            x = Ti_inv @ zk
            if lin.system.contains(i, x, tol) and not any(
                    np.linalg.norm(x - y) <= tol * (1.0 + np.linalg.norm(x)) for y in found):
                found.append(x)
        counts[k] = len(found)
    return counts


@dataclass(frozen=True)
class HomeomorphismReport:
    """Is ``T`` a PWL homeomorphism?

    Attributes
    ----------
    homeomorphism
        Continuous, coherently oriented and every sample with exactly one preimage.
    continuity_residual
        Largest ``‖(T_i − T_j)(I − ccᵀ)‖`` over the facets, relative to ``max ‖T_i‖``.
    coherent
        Whether ``det T_i`` has one sign.
    dets
        ``det T_i``.
    counts
        Number of samples with 0, 1, 2, … preimages (index = count).
    reasons
        What fails, in words.
    """

    homeomorphism: bool
    continuity_residual: float
    coherent: bool
    dets: FloatArray
    counts: np.ndarray
    reasons: tuple[str, ...]


def homeomorphism_report(lin: PWLLinearization, n_samples: int = 2000, seed: int = 0,
                         tol: float = 1e-9) -> HomeomorphismReport:
    """Continuity on the facets, coherent orientation and preimage counts of ``T``.

    Parameters
    ----------
    lin : PWLLinearization
        The map.
    n_samples : int, optional
        Random points ``z`` (standard normal) whose preimages are counted.
    seed : int, optional
        Seed of the samples.
    tol : float, optional
        Relative tolerance (continuity and the cone tests).

    Returns
    -------
    HomeomorphismReport
    """
    n_samples = check_integer("n_samples", n_samples, minimum=1)
    scale = max(float(np.linalg.norm(T, 2)) for T in lin.T_modes)
    cont = 0.0
    for fac in lin.system.facets:
        D = lin.T_modes[fac.i] - lin.T_modes[fac.j]
        c = fac.normal
        cont = max(cont, float(np.linalg.norm(D - np.outer(D @ c, c), 2)) / scale)
    coherent, dets = coherent_orientation(lin.T_modes)
    z = np.random.default_rng(seed).standard_normal((n_samples, lin.system.n_states))
    counts = np.bincount(preimage_counts(lin, z, tol))
    reasons = []
    if cont > tol:
        reasons.append(f"T is discontinuous on a facet (relative residual {cont:.3g})")
    if not coherent:
        reasons.append(f"det T_i change sign ({np.array2string(dets, precision=4)})")
    bad = n_samples - (int(counts[1]) if counts.size > 1 else 0)
    if bad:
        reasons.append(f"{bad} of {n_samples} samples do not have exactly one preimage "
                       f"(counts by number of preimages: {counts.tolist()})")
    return HomeomorphismReport(not reasons, cont, coherent, dets, counts, tuple(reasons))


@dataclass(frozen=True)
class CrossingRatios:
    """Normal components of the closed-loop field on the two sides of every facet.

    Attributes
    ----------
    ratios
        Per facet ``(i, j)``: the measured ratios ``cᵀẋ_j / cᵀẋ_i`` at the sample points.
    predicted
        Per facet: ``γ_i / γ_j`` (the ratio the construction predicts).
    well_posed
        All ratios positive: every trajectory reaching a facet crosses it (no sliding, no
        branching).
    """

    ratios: dict[tuple[int, int], FloatArray]
    predicted: dict[tuple[int, int], float]
    well_posed: bool


def crossing_ratios(lin: PWLLinearization, n_samples: int = 200, seed: int = 0
                    ) -> CrossingRatios:
    """The ratios of the normal velocities across each facet under the feedback.

    Random states on each facet (projections of normal samples onto the facet's hyperplane,
    kept when they lie in both cones) and random new inputs ``v``; the closed-loop fields of
    the two cones are ``(A_k + B K_k) x + B G_k v``.

    Parameters
    ----------
    lin : PWLLinearization
        The feedback.
    n_samples : int, optional
        Samples drawn per facet (fewer are kept on a facet narrower than its hyperplane).
    seed : int, optional
        Seed.

    Returns
    -------
    CrossingRatios
    """
    n_samples = check_integer("n_samples", n_samples, minimum=1)
    rng = np.random.default_rng(seed)
    s = lin.system
    ratios, predicted = {}, {}
    ok = True
    for fac in s.facets:
        c = fac.normal
        X = rng.standard_normal((n_samples, s.n_states))
        X -= np.outer(X @ c, c)
        X = np.array([x for x in X if s.contains(fac.i, x) and s.contains(fac.j, x)])
        V = rng.standard_normal((len(X), s.n_inputs))
        vel = []
        for k in (fac.i, fac.j):
            F = s.A[k] + s.B @ lin.K_modes[k]
            vel.append(X @ F.T @ c + V @ (s.B @ lin.G_modes[k]).T @ c if len(X) else
                       np.zeros(0))
        r = vel[1] / vel[0]
        ratios[(fac.i, fac.j)] = r
        predicted[(fac.i, fac.j)] = float(lin.gammas[fac.i] / lin.gammas[fac.j])
        ok = ok and bool(np.all(r > 0))
    return CrossingRatios(ratios, predicted, ok)


def linear_reference(lin: PWLLinearization, z0: ArrayLike, t: ArrayLike, v: Any = None,
                     outer: ArrayLike | None = None) -> FloatArray:
    """``z(t)`` of the linear target ``z' = (Ā − B̄κ) z + B̄ v`` by the matrix exponential.

    Parameters
    ----------
    lin : PWLLinearization
        The target ``(Ā, B̄)``.
    z0 : (n,) array_like
        Initial point.
    t : (k,) array_like
        Increasing times, from 0 (the exosystem's time origin).
    v : Exosystem or float, optional
        The new input (as given to :meth:`PWLLinearization.closed_loop`).
    outer : (m, n) or (n,) array_like, optional
        The outer gain ``κ``.

    Returns
    -------
    ndarray, shape (k, n)
    """
    n, m = lin.system.n_states, lin.system.n_inputs
    exo = input_generator(v, m)
    q = exo.S.shape[0]
    kappa = np.zeros((m, n)) if outer is None else np.atleast_2d(np.asarray(outer, float))
    M = np.block([[lin.A_target - lin.B_target @ kappa, lin.B_target @ exo.Cu],
                  [np.zeros((q, n)), exo.S]])
    xi = np.concatenate([np.asarray(z0, float), exo.w0])
    # step by step from t = 0, one exponential per distinct step (a uniform grid needs one):
    # k steps add about k roundoffs relative to the size of the solution
    steps: dict[float, FloatArray] = {}
    out, t_prev = [], 0.0
    for tk in np.asarray(t, float):
        h = float(tk - t_prev)
        key = round(h, 12)
        if key not in steps:
            steps[key] = expm(M * h)
        xi = steps[key] @ xi
        out.append(xi[:n])
        t_prev = float(tk)
    return np.array(out)


def conjugacy_error(lin: PWLLinearization, trajectory: Any, v: Any = None,
                    outer: ArrayLike | None = None) -> float:
    """``max_t ‖T(x(t)) − z(t)‖`` along a closed-loop run of :meth:`PWLLinearization.closed_loop`.

    Parameters
    ----------
    lin : PWLLinearization
        The transformation.
    trajectory : Trajectory
        The run (state ``[x; ω]``, started at time 0).
    v, outer
        As given to :meth:`PWLLinearization.closed_loop`.

    Returns
    -------
    float
    """
    n = lin.system.n_states
    x = np.asarray(trajectory.x)[:, :n]
    z = linear_reference(lin, lin.T(x[0]), trajectory.t, v, outer)
    return float(np.max(np.linalg.norm(lin.T(x) - z, axis=1)))
