"""Orbits and bifurcations of the ZAD-controlled buck converter against the surface slope
``k_s``: brute-force diagrams of the duty (on :func:`~nscontrol.analysis.bifurcation_diagram`,
hence on :mod:`nscontrol.sweep`), the flip read off them, the multipliers of the 1T orbit
along ``k_s`` and the regulation error against the sampling period.

The map is the closed-form :class:`~nscontrol.design.ZADLoopMap` (compiled), so a diagram
point of 40 000 periods costs milliseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector
from ..design.converter_regulation import ZADController, ZADLoopMap
from ..systems.buck import BuckConverter
from .bifurcation import BifurcationDiagram, bifurcation_diagram

__all__ = ["ZADFamily", "DutyDiagram", "duty_diagram", "duty_period", "brute_force_flip",
           "multiplier_branch", "mean_error_against_period"]

#: A 2T orbit is declared when the recorded duty ratios spread more than this (those of a
#: converged 1T orbit agree to rounding, ~1e-16).
SPREAD_2T = 1e-6


@dataclass(frozen=True)
class ZADFamily:
    """``k_s -> ZADLoopMap``: a picklable factory for diagrams on process or Dask executors.

    Parameters
    ----------
    model : BuckConverter
        The controller's model.
    T : float
        Sampling period.
    x_ref : float
        Reference.
    variant : {"pl", "exact"}
        ZAD variant.
    plant : BuckConverter, optional
        The converter controlled (default: the model).
    """

    model: BuckConverter
    T: float
    x_ref: float
    variant: Literal["pl", "exact"] = "pl"
    plant: BuckConverter | None = None

    def __call__(self, ks: float) -> ZADLoopMap:
        """The loop at slope ``ks``."""
        return ZADController(self.model, float(ks), self.T, self.x_ref, self.variant).loop(
            self.plant)


@dataclass(frozen=True)
class DutyDiagram:
    """A brute-force diagram of the duty ratio against ``k_s``.

    Attributes
    ----------
    diagram
        The underlying :class:`~nscontrol.analysis.BifurcationDiagram` (sampled states).
    duty_ratios
        ``(N, n_record)`` the recorded ``d_k/T`` per ``k_s`` (NaN where a point failed).
    period
        ``(N,)`` the period of the duty sequence (``0``: none up to 64).
    """

    diagram: BifurcationDiagram
    duty_ratios: FloatArray
    period: np.ndarray

    @property
    def ks(self) -> FloatArray:
        """The ``k_s`` grid (increasing)."""
        return self.diagram.values

    @property
    def saturated(self) -> np.ndarray:
        """``(N, n_record)``: periods with ``d = 0`` or ``d = T`` (no switching)."""
        D = np.nan_to_num(self.duty_ratios, nan=0.5)
        return (D <= 0.0) | (D >= 1.0)

    @property
    def spread(self) -> FloatArray:
        """``max - min`` of the recorded duty ratios per ``k_s``."""
        return np.nanmax(self.duty_ratios, axis=1) - np.nanmin(self.duty_ratios, axis=1)


def duty_period(duties: ArrayLike, *, tol: float = 1e-8, max_p: int = 64) -> int:
    """The smallest ``p <= max_p`` with ``|d_{k+p} - d_k| <= tol`` over the record.

    Parameters
    ----------
    duties : array_like
        A recorded duty sequence (at least ``2 max_p`` long to see period ``max_p``).
    tol : float
        Recurrence tolerance (absolute, in the units of ``duties``).
    max_p : int
        Largest period tried.

    Returns
    -------
    int
        ``0`` when no period up to ``max_p`` recurs (irregular motion, or a transient).

    Examples
    --------
    >>> duty_period([0.2, 0.5, 0.2, 0.5, 0.2, 0.5]), duty_period([0.3, 0.3, 0.3])
    (2, 1)
    """
    d = np.asarray(duties, float)
    for p in range(1, min(max_p, d.size - 1) + 1):
        if float(np.max(np.abs(d[p:] - d[:-p]))) <= tol:
            return p
    return 0


def duty_diagram(model: BuckConverter, ks_values: ArrayLike, *, T: float, x_ref: float,
                 variant: Literal["pl", "exact"] = "pl", plant: BuckConverter | None = None,
                 n_transient: int = 40_000, n_record: int = 128, chunk_size: int = 50,
                 executor: Any = "serial", progress: bool | None = False) -> DutyDiagram:
    """Brute-force diagram of the duty against ``k_s``, every point started ``1e-6`` off the
    1T orbit (so the flip shows where the orbit stops attracting, not a hysteresis branch).

    Parameters
    ----------
    model : BuckConverter
        The controller's model.
    ks_values : array_like
        The slopes.
    T, x_ref : float
        Sampling period and reference.
    variant : {"pl", "exact"}
        ZAD variant.
    plant : BuckConverter, optional
        The converter controlled (default: the model).
    n_transient, n_record : int
        Periods discarded and recorded per point.
    chunk_size : int
        Points per task of :mod:`nscontrol.sweep`.
    executor
        As :func:`nscontrol.sweep.run` (``"serial"``, ``None``: local processes, a Dask
        ``Client`` or address).
    progress : bool, optional
        Progress bar.

    Returns
    -------
    DutyDiagram
    """
    fam = ZADFamily(model, T, x_ref, variant, plant)
    bd = bifurcation_diagram(fam, ks_values, n_transient=n_transient, n_sample=n_record,
                             directions=("down",), chunk_size=chunk_size, executor=executor,
                             progress=progress, parameter_name="k_s", warm_start=False,
                             state_names=model.state_names)
    D = np.full(bd.points.shape[1:3], np.nan)
    for i, ks in enumerate(bd.values):
        X = bd.points[0, i]
        if np.all(np.isfinite(X)):
            D[i] = fam(ks).duties(X) / T
    period = np.array([duty_period(row) if np.all(np.isfinite(row)) else -1 for row in D])
    return DutyDiagram(bd, D, period)


def brute_force_flip(diagram: DutyDiagram, *, spread: float = SPREAD_2T) -> float:
    """The ``k_s`` where the 1T orbit stops attracting, read off a diagram: the midpoint
    between the largest ``k_s`` whose duty ratios spread more than ``spread`` and the next
    grid value above it.

    Parameters
    ----------
    diagram : DutyDiagram
        A diagram over a grid crossing the flip.
    spread : float
        Spread of the duty ratio that declares a 2T orbit.

    Returns
    -------
    float
        ``nan`` when no point of the grid shows a 2T orbit, or all do.
    """
    ks = diagram.ks
    split = diagram.spread > spread
    if not split.any() or split.all():
        return float("nan")
    i = int(np.max(np.nonzero(split)[0]))
    if i + 1 >= ks.size:
        return float("nan")
    return 0.5 * float(ks[i] + ks[i + 1])


def multiplier_branch(model: BuckConverter, ks_values: ArrayLike, *, T: float, x_ref: float,
                      variant: Literal["pl", "exact"] = "pl",
                      plant: BuckConverter | None = None) -> tuple[FloatArray, FloatArray]:
    """The Floquet multipliers of the 1T orbit along ``k_s`` (natural-parameter continuation:
    each Newton starts from the previous orbit).

    Parameters
    ----------
    model : BuckConverter
        The controller's model.
    ks_values : array_like
        The slopes, in the order walked.
    T, x_ref : float
        Sampling period and reference.
    variant : {"pl", "exact"}
        ZAD variant.
    plant : BuckConverter, optional
        The converter controlled.

    Returns
    -------
    multipliers : ndarray, shape (N, 2), complex
        Sorted by real part.
    duty_ratios : ndarray, shape (N,)
        ``D*`` of the orbit.
    """
    ks = as_vector("ks_values", ks_values)
    lam = np.empty((ks.size, 2), complex)
    D = np.empty(ks.size)
    x = None
    fam = ZADFamily(model, T, x_ref, variant, plant)
    for i, k in enumerate(ks):
        orbit = fam(k).fixed_point(x)
        x = orbit.states[0]
        lam[i] = np.sort_complex(orbit.multipliers)
        D[i] = orbit.duties[0] / T
    return lam, D


def mean_error_against_period(model: BuckConverter, ks: float, T_values: ArrayLike, *,
                              x_ref: float, variant: Literal["pl", "exact"] = "pl",
                              plant: BuckConverter | None = None) -> FloatArray:
    """``mean(x1) - x_ref`` on the 1T orbit for each sampling period.

    Parameters
    ----------
    model : BuckConverter
        The controller's model.
    ks : float
        Surface slope.
    T_values : array_like
        Sampling periods.
    x_ref : float
        Reference.
    variant : {"pl", "exact"}
        ZAD variant.
    plant : BuckConverter, optional
        The converter controlled.

    Returns
    -------
    ndarray
    """
    return np.array([ZADFamily(model, float(T), x_ref, variant, plant)(ks).fixed_point()
                     .mean_x1 - x_ref for T in as_vector("T_values", T_values)])
