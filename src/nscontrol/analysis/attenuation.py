"""Analysis of disturbance attenuation for the beam of chapter 6: the servo-damping
threshold of a common quadratic Lyapunov function by three equivalent tests
(:func:`min_velocity_gain`), and the attenuation figures of open-loop and closed-loop
frequency sweeps (:func:`attenuation_report`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .._validation import as_real_scalar, check_positive
from ..errors import DimensionError, ModelError

if TYPE_CHECKING:
    from ..systems.beam import MechanicalPWL
    from .periodic import FrequencyResponse

__all__ = ["VelocityGainThreshold", "min_velocity_gain", "response_amplitude",
           "local_maxima", "AttenuationReport", "attenuation_report", "AttenuationTradeoff",
           "attenuation_tradeoff"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class VelocityGainThreshold:
    """The smallest collocated servo-damping ``d*`` giving the beam a CQLF, by three tests.

    Attributes
    ----------
    kp
        The servo-stiffness it was computed for (N/m).
    cqlf
        ``d*`` by bisection on the CQLF LMI (N s/m).
    product
        ``d*`` by the ``A_1A_2`` eigenvalue test (no real negative eigenvalue).
    circle
        ``d*`` by the circle criterion (``1 + k Re G(iω) > 0``).
    rtol
        Relative width of the bisection brackets.
    """

    kp: float
    cqlf: float
    product: float
    circle: float
    rtol: float

    @property
    def spread(self) -> float:
        """Largest relative difference between the three values."""
        v = (self.cqlf, self.product, self.circle)
        return float((max(v) - min(v)) / self.cqlf)


def min_velocity_gain(plant: MechanicalPWL, *, kp: float = 0.0,
                      bracket: tuple[float, float] = (1.0, 1e5),
                      rtol: float = 1e-6) -> VelocityGainThreshold:
    """Smallest ``k_d`` of ``u = -k_p y_s - k_d y_s'`` with a CQLF, by bisection on three
    equivalent tests of a continuous bimodal system.

    Parameters
    ----------
    plant : MechanicalPWL
        The beam.
    kp : float
        Servo-stiffness (N/m), ``>= 0``.
    bracket : tuple of float
        ``(lo, hi)`` in N s/m: no CQLF at ``lo``, a CQLF at ``hi``.
    rtol : float
        Relative width of the final brackets.

    Returns
    -------
    VelocityGainThreshold

    Raises
    ------
    ModelError
        The bracket does not contain the threshold of a test.

    Notes
    -----
    For Hurwitz modes with a rank-one difference the CQLF LMI, the absence of real negative
    eigenvalues of ``A_1A_2`` and the circle criterion are equivalent (Shorten and Narendra);
    the three thresholds agree up to the bisection width and the LMI's margin tolerance.
    Each test is monotone in ``k_d`` here (more damping, same stiffness).

    References
    ----------
    R. Shorten, K.S. Narendra, IEEE TAC 48(4), 2003; R. Shorten, O. Mason, F. O'Cairbre,
    P. Curran, IJC 77(1), 2004; D5.3 chapters 6 and 11.

    Examples
    --------
    >>> from nscontrol.systems.beam import two_mode_beam
    >>> d = min_velocity_gain(two_mode_beam(), rtol=1e-4)
    >>> round(d.cqlf), d.spread < 1e-3
    (873, True)
    """
    import warnings

    from ..design.beam_attenuation import pd_gain
    from ..errors import InaccurateCertificateWarning
    from . import convergence as cv

    lo, hi = (as_real_scalar(f"bracket[{i}]", v) for i, v in enumerate(bracket))
    kp = check_positive("kp", kp, allow_zero=True)
    As = plant.to_pwa().A

    def pair(kd: float) -> tuple[FloatArray, FloatArray]:
        K = pd_gain(plant, kp, kd)
        return As[0] + plant.B @ K, As[1] + plant.B @ K

    tests = {"cqlf": lambda k: cv.quadratic_convergence(list(pair(k))).convergent,
             "product": lambda k: cv.product_test(*pair(k)),
             "circle": lambda k: cv.circle_test(*pair(k))}
    with warnings.catch_warnings():  # near d* the LMI is (rightly) on its edge
        warnings.simplefilter("ignore", InaccurateCertificateWarning)
        found = {name: cv.bisect_boundary(test, lo, hi, rtol=rtol) for name, test in tests.items()}
    return VelocityGainThreshold(kp, found["cqlf"], found["product"], found["circle"],
                                 float(rtol))


# -- attenuation figures ---------------------------------------------------------------------

def response_amplitude(response: FrequencyResponse) -> FloatArray:
    """``P(ω) = max_t|z̄(t)|`` per frequency: the gain times the input amplitude ``a(ω)``.

    Parameters
    ----------
    response : FrequencyResponse
        From :func:`~nscontrol.analysis.periodic.frequency_response` or
        :func:`~nscontrol.analysis.periodic.frequency_sweep`.
    """
    a = response.amplitudes if response.amplitudes.size else \
        np.full(response.omega.shape, response.amplitude)
    return np.asarray(response.gamma * a, float)


def local_maxima(values: Any) -> NDArray[np.int64]:
    """Indices of strict interior local maxima of a sampled curve (NaN entries are never
    maxima and break neighbourhoods).

    Parameters
    ----------
    values : (n,) array_like
        The samples.
    """
    v = np.asarray(values, float)
    if v.ndim != 1:
        raise DimensionError(f"values: expected a 1-d array, got shape {v.shape}")
    mid = v[1:-1]
    with np.errstate(invalid="ignore"):
        ok = (mid > v[:-2]) & (mid > v[2:]) & np.isfinite(mid)
    return np.flatnonzero(ok) + 1


@dataclass(frozen=True)
class AttenuationReport:
    """Open-loop against closed-loop steady-state amplitudes over a frequency band.

    Attributes
    ----------
    frequency
        The grid (Hz).
    open_loop
        ``P_OL(f)``: the largest response amplitude over the open-loop sweeps (up, down) at
        each frequency (m).
    closed_loop
        ``P_CL(f)`` (m).
    sup_ratio
        ``sup P_OL / sup P_CL`` over the band.
    ratios
        ``P_OL/P_CL`` at named frequencies: a window ``(lo, hi)`` gives the open loop's
        largest local maximum in it, a number the nearest grid frequency.
    at
        The grid frequency (Hz) each ratio was taken at.
    max_effort
        Largest control effort ``max|u|`` over the band (NaN without effort data).
    coexistence
        Frequency windows ``(lo, hi)`` (Hz) where the open-loop sweeps differ by more than
        ``coexistence_rtol`` relative: coexisting steady states.
    closed_loop_maxima
        Frequencies (Hz) of the local maxima of ``P_CL``.
    max_effort_rms
        Largest RMS control effort ``RMS(u)`` over the band (NaN without effort data).
    """

    frequency: FloatArray
    open_loop: FloatArray
    closed_loop: FloatArray
    sup_ratio: float
    ratios: dict[str, float]
    at: dict[str, float]
    max_effort: float
    coexistence: list[tuple[float, float]]
    closed_loop_maxima: FloatArray
    max_effort_rms: float = float("nan")


def _windows(mask: NDArray[np.bool_], f: FloatArray) -> list[tuple[float, float]]:
    """Runs of True in ``mask`` as ``(f_first, f_last)``."""
    out, start = [], None
    for i, m in enumerate(mask):
        if m and start is None:
            start = i
        if not m and start is not None:
            out.append((float(f[start]), float(f[i - 1])))
            start = None
    if start is not None:
        out.append((float(f[start]), float(f[-1])))
    return out


def attenuation_report(open_loop: Sequence[FrequencyResponse], closed_loop: FrequencyResponse,
                       *, points: Mapping[str, float | tuple[float, float]] | None = None,
                       coexistence_rtol: float = 0.5) -> AttenuationReport:
    """Attenuation figures of a controller from open-loop and closed-loop sweeps on the same
    frequency grid.

    Parameters
    ----------
    open_loop : sequence of FrequencyResponse
        The open-loop sweeps (e.g. up and down of
        :func:`~nscontrol.analysis.periodic.frequency_sweep`); ``P_OL`` is their pointwise
        maximum, the worst steady state the history can select.
    closed_loop : FrequencyResponse
        The closed loop on the same grid (its ``effort`` and ``effort_rms`` give
        :attr:`AttenuationReport.max_effort` and :attr:`AttenuationReport.max_effort_rms`).
    points : mapping of str to float or (float, float), optional
        Named frequencies (Hz) or windows ``(lo, hi)`` (Hz) where the ratio is reported: a
        window takes the open loop's largest local maximum inside it (its largest value if it
        has none).
    coexistence_rtol : float
        Relative difference ``|P_a - P_b|/min(P_a, P_b)`` between two open-loop sweeps above
        which a frequency counts as having coexisting steady states.

    Raises
    ------
    DimensionError
        Sweeps on different grids, or no open-loop sweep.
    ModelError
        A window with no grid frequency inside.

    Notes
    -----
    Only a convergent closed loop has one steady state per frequency (its ``P_CL`` does not
    depend on the sweep direction); the open loop's ``P_OL`` does, hence the maximum over the
    directions.

    Examples
    --------
    >>> import numpy as np
    >>> from nscontrol.analysis.periodic import FrequencyResponse
    >>> w = 2 * np.pi * np.array([10.0, 20.0, 30.0])
    >>> def fr(g):
    ...     return FrequencyResponse.from_points(w, [None] * 3, direction="up", amplitude=1.0,
    ...                                          n_harmonics=1)
    >>> import dataclasses
    >>> ol = dataclasses.replace(fr(0), gamma=np.array([1.0, 4.0, 2.0]))
    >>> cl = dataclasses.replace(fr(0), gamma=np.array([0.5, 0.5, 0.25]))
    >>> rep = attenuation_report([ol], cl, points={"peak": (15.0, 25.0)})
    >>> rep.sup_ratio, rep.ratios["peak"], rep.at["peak"]
    (8.0, 8.0, 20.0)
    """
    if not open_loop:
        raise DimensionError("open_loop: expected at least one sweep, got none")
    f = closed_loop.omega / (2 * np.pi)
    for r in open_loop:
        if r.omega.shape != closed_loop.omega.shape or not np.allclose(r.omega,
                                                                       closed_loop.omega):
            raise DimensionError("open_loop: expected sweeps on the closed loop's frequency "
                                 "grid")
    rtol = check_positive("coexistence_rtol", coexistence_rtol)
    P_ol_all = np.vstack([response_amplitude(r) for r in open_loop])
    with np.errstate(invalid="ignore"):
        P_ol = np.nanmax(P_ol_all, axis=0)
    P_cl = response_amplitude(closed_loop)
    ratios, at = {}, {}
    for name, where in (points or {}).items():
        if isinstance(where, tuple):
            lo, hi = (as_real_scalar(f"points[{name!r}]", v) for v in where)
            inside = np.flatnonzero((f >= lo - 1e-9) & (f <= hi + 1e-9))
            if inside.size == 0:
                raise ModelError(f"points[{name!r}]: no grid frequency in [{lo:g}, {hi:g}] Hz")
            peaks = [i for i in local_maxima(P_ol) if i in set(inside)]
            i = max(peaks, key=lambda j: P_ol[j]) if peaks else \
                int(inside[np.nanargmax(P_ol[inside])])
        else:
            i = int(np.argmin(np.abs(f - as_real_scalar(f"points[{name!r}]", where))))
        ratios[name], at[name] = float(P_ol[i] / P_cl[i]), float(f[i])
    coexist = np.zeros(f.shape, bool)
    if len(open_loop) > 1:
        with np.errstate(invalid="ignore"):
            lo_, hi_ = np.nanmin(P_ol_all, axis=0), np.nanmax(P_ol_all, axis=0)
            coexist = (hi_ - lo_) > rtol * lo_
    return AttenuationReport(
        f, P_ol, P_cl, float(np.nanmax(P_ol) / np.nanmax(P_cl)), ratios, at,
        _band_max(closed_loop.effort), _windows(coexist, f), f[local_maxima(P_cl)],
        _band_max(closed_loop.effort_rms))


def _band_max(values: FloatArray) -> float:
    """Largest finite entry (NaN when there is none, e.g. no control law)."""
    v = np.asarray(values, float)
    return float(np.nanmax(v)) if np.any(np.isfinite(v)) else float("nan")


# -- the trade-off of the L2 design ----------------------------------------------------------

@dataclass(frozen=True, eq=False)
class AttenuationTradeoff:
    """Gain, certified L2 gain and closed-loop figures of the L2 state feedback of the beam,
    one entry per control penalty ``ρ``.

    Attributes
    ----------
    rho
        The penalties (m/N), as given.
    gain
        ``‖K‖₂`` in the model's units (N per state unit).
    scaled_gain
        ``‖K̃‖₂`` in the scaled coordinates of the design (forces in units of ``k_mid``).
    gamma
        Certified L2 gain from the force to ``z = (y_s, ρu)`` (m/N).
    sup_response
        Band supremum of ``P_CL(f) = max_t|ȳ_s|`` on the grid (m).
    max_effort, max_effort_rms
        Band maxima of ``max_t|u|`` and ``RMS(u)`` (N).
    frequency
        The grid (Hz).
    designs
        The :class:`~nscontrol.design.beam_attenuation.AttenuationDesign` per ``ρ``.
    responses
        The closed-loop :class:`~nscontrol.analysis.periodic.FrequencyResponse` per ``ρ``.
    """

    rho: FloatArray
    gain: FloatArray
    scaled_gain: FloatArray
    gamma: FloatArray
    sup_response: FloatArray
    max_effort: FloatArray
    max_effort_rms: FloatArray
    frequency: FloatArray
    designs: tuple[Any, ...]
    responses: tuple[Any, ...]


def attenuation_tradeoff(plant: MechanicalPWL, rhos: Any, *, frequencies: Any,
                         amplitude: Any = 1.0, decay: float = 0.1, slack: float = 0.1,
                         omega_ref: float | None = None, n_samples: int = 256,
                         executor: Any = "serial") -> AttenuationTradeoff:
    """The attenuation/effort trade-off of the L2 state feedback over control penalties.

    For each ``ρ``: the design ``design_attenuation(plant, structure="state", rho=ρ)``,
    then the steady states of its closed loop on the grid ``frequencies`` by shooting
    (:func:`~nscontrol.analysis.periodic.frequency_response`, exact PWA integration), and
    their band figures.

    Parameters
    ----------
    plant : MechanicalPWL
        The beam.
    rhos : array_like
        Control penalties (m/N), each finite and ``> 0``.
    frequencies : array_like
        The grid (Hz); a coarse one suffices for band maxima of smooth curves.
    amplitude : float or callable
        The force amplitude, or ``ω -> a(ω)`` (e.g. :class:`~nscontrol.systems.beam.
        Unbalance`).
    decay, slack, omega_ref : float
        As in :func:`~nscontrol.design.beam_attenuation.design_attenuation` (``decay`` in
        units of ``ω_ref``).
    n_samples : int
        Uniform samples per period.
    executor
        As in :func:`nscontrol.sweep.run` (default ``"serial"``: each point costs a few ms).

    Returns
    -------
    AttenuationTradeoff

    Raises
    ------
    ModelError
        A bad ``ρ`` or grid.
    InfeasibleDesignError
        A design failed.

    Notes
    -----
    The closed loops are convergent (the design certifies the decay rate), so each
    frequency has one steady state and shooting finds it. On a steady state the design's
    dissipation inequality gives ``mean|y_s|² + ρ² mean|u|² <= γ² mean|F|²``.

    Examples
    --------
    >>> from nscontrol.systems.beam import Unbalance, two_mode_beam
    >>> tr = attenuation_tradeoff(two_mode_beam(), [1e-6, 1e-5], frequencies=[20.0, 40.0],
    ...                           amplitude=Unbalance(1e-4))
    >>> bool(tr.gain[0] > tr.gain[1] and tr.gamma[0] < tr.gamma[1])
    True
    """
    from ..design.beam_attenuation import design_attenuation
    from .periodic import frequency_response

    rho = np.atleast_1d(np.asarray(rhos, float))
    if rho.ndim != 1 or rho.size == 0:
        raise ModelError(f"rhos: expected a non-empty 1-d array of penalties, got {rhos!r}")
    f = np.atleast_1d(np.asarray(frequencies, float))
    designs, responses = [], []
    for r in rho:
        des = design_attenuation(plant, structure="state", rho=float(r), decay=decay,
                                 slack=slack, omega_ref=omega_ref)
        designs.append(des)
        responses.append(frequency_response(
            des.closed_loop(), 2 * np.pi * f, amplitude=amplitude,
            output=des.performance_output, control=des.control(), n_samples=n_samples,
            executor=executor, progress=False))
    scaled = [float(d.feedback.gain_bound) if d.feedback is not None else float("nan")
              for d in designs]
    return AttenuationTradeoff(
        rho, np.array([np.linalg.norm(d.K, 2) for d in designs]), np.array(scaled),
        np.array([d.gamma for d in designs]),
        np.array([float(np.nanmax(response_amplitude(r))) for r in responses]),
        np.array([_band_max(r.effort) for r in responses]),
        np.array([_band_max(r.effort_rms) for r in responses]), f, tuple(designs),
        tuple(responses))
