"""Periodic steady states, Floquet multipliers and frequency responses of forced systems.

* :func:`periodic_steady_state` — shooting: Newton on ``φ_T(x0) - x0 = 0`` with the monodromy
  ``Φ(T) = ∂φ_T/∂x0`` assembled by the integrator from flow exponentials and saltation
  matrices (``sensitivity=True``; never finite differences), with a fixed-point (long
  integration) fallback; Floquet multipliers are the eigenvalues of ``Φ(T)``.
* :func:`check_uniqueness` — shooting from several random initial guesses (convergent systems
  have exactly one periodic steady state).
* :func:`brute_force_steady_state` — transient, then record; period multiplicity (for models
  that are *not* convergent: subharmonics, coexisting solutions).
* :func:`frequency_response` — the generalized Bode plot ``γ_a(ω) = max_t|z̄(t)|/a`` of a
  convergent system (refined peak), RMS gain, DFT harmonics and Floquet multipliers per
  frequency, the frequencies running in parallel through :func:`nscontrol.sweep.run`;
  :func:`frequency_sweep` — sweeps up and down in frequency that follow the attractor's
  orbit by continuation (hysteresis of non-convergent models, the coexisting unstable orbits
  and the located folds and flips), the two directions in parallel.

The system must be simulable by ``simulate(system, x0, (0, T), method=..., u=...,
t_eval=..., sensitivity=True)`` (default ``method="switching"``: PWA, Filippov and PWM
systems); the input is an :class:`~nscontrol.numerics.lti.Exosystem` (or any periodic input
the method accepts) with period ``T``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import (
    as_vector,
    check_bool,
    check_in_interval,
    check_integer,
    check_positive,
)
from ..errors import BudgetExceededError, DimensionError, ModelError, SolverError

if TYPE_CHECKING:   # imported where used at run time
    from ..systems.protocols import InputSignal, SimulableSystem

__all__ = [
    "PeriodicOrbit", "periodic_steady_state", "UniquenessCheck", "check_uniqueness",
    "BruteForceResult", "brute_force_steady_state", "period_multiplicity",
    "refined_peak", "dft_harmonics", "HarmonicResponse", "harmonic_response",
    "FrequencyResponse", "frequency_response", "frequency_sweep",
]

FloatArray = NDArray[np.float64]

#: ``control=``: the effort ``u`` of time-major states ``x`` (shape ``(k, n)`` -> ``(k, p)``).
ControlMap = Callable[[FloatArray], ArrayLike]

#: ``amplitude=``: a constant ``a`` or a picklable callable ``ω -> a(ω)`` (a forcing whose
#: amplitude grows with frequency, e.g. a rotating unbalance ``m_e r_e ω²``).
AmplitudeSpec = float | Callable[[float], float]


def _amplitude_spec(amplitude: Any) -> Any:
    """A validated ``amplitude=``: a positive number, or a callable kept as it is (checked
    at every frequency by :func:`_amplitude_at`)."""
    return amplitude if callable(amplitude) else float(check_positive("amplitude", amplitude))


def _amplitude_at(amplitude: Any, omega: float) -> float:
    """``a(ω)`` of an :data:`AmplitudeSpec`."""
    if not callable(amplitude):
        return float(amplitude)
    a = amplitude(float(omega))
    try:
        return float(check_positive("amplitude", a))
    except ModelError:
        raise ModelError(f"amplitude: the callable returned {a!r} at ω = {omega:g}; expected "
                         f"a finite number > 0") from None


@dataclass(frozen=True, eq=False)
class PeriodicOrbit:
    """A ``T``-periodic solution found by shooting.

    Attributes
    ----------
    x0
        State at ``t = 0`` (the start of the input's period).
    period
        ``T``.
    monodromy
        ``Φ(T) = ∂φ_T/∂x0`` from the integrator's state transition (saltation-based).
    floquet
        Eigenvalues of the monodromy, by decreasing modulus.
    trajectory
        One period sampled at ``n_samples`` uniform times (plus event instants).
    iterations
        Newton iterations (plus fixed-point periods when the fallback ran).
    residual
        ``|φ_T(x0) - x0|``.
    method
        ``"newton"`` or ``"fixed_point+newton"``.
    n_crossings
        Mode changes (events) during one period.
    n_uniform
        Number of uniform sample times in :attr:`trajectory` (``0``, ``T`` included).
    """

    x0: FloatArray
    period: float
    monodromy: FloatArray
    floquet: FloatArray
    trajectory: Any
    iterations: int
    residual: float
    method: str
    n_crossings: int
    n_uniform: int

    @property
    def max_multiplier(self) -> float:
        """Largest Floquet multiplier modulus."""
        return float(np.abs(self.floquet[0]))

    @property
    def stable(self) -> bool:
        """All multipliers strictly inside the unit circle."""
        return self.max_multiplier < 1.0

    def uniform_samples(self) -> tuple[FloatArray, FloatArray]:
        """``(t, x)`` at the uniform sample times of one period (event instants removed),
        excluding the final ``t = T`` (periodic wrap)."""
        tr = self.trajectory
        grid = np.linspace(0.0, self.period, self.n_uniform)[:-1]
        idx = np.searchsorted(tr.t, grid, side="left")
        idx = np.clip(idx, 0, len(tr.t) - 1)
        return tr.t[idx], tr.x[idx]


def _shoot(system: Any, x0: FloatArray, period: float, method: str, u: Any,
           t_eval: FloatArray | None, options: dict[str, Any]) -> Any:
    from ..simulate import simulate

    opts = dict(options)
    if u is not None:
        opts["u"] = u
    if t_eval is None:
        t_eval = np.array([0.0, period])
    return simulate(system, x0, (0.0, period), method=method, t_eval=t_eval,
                    sensitivity=True, **opts)


def _require_sensitivity(system: Any, method: Any) -> None:
    """Shooting needs the state-transition matrix: ask the integrator for the capability."""
    from ..simulate.driver import METHODS, integrator_for

    cls = integrator_for(system, method)
    if "sensitivity" not in cls.capabilities:
        able = sorted(k for k in METHODS if "sensitivity" in METHODS[k].capabilities)
        raise ModelError(f"method: shooting needs sensitivities, which {cls.name!r} does not "
                         f"compute; use one of {able}")


def _scale(x: FloatArray) -> float:
    return max(1.0, float(np.linalg.norm(x)))


def periodic_steady_state(system: SimulableSystem, period: float, *, u: InputSignal = None,
                          x0: ArrayLike | None = None,
                          method: str = "switching", tol: float = 1e-11, max_iter: int = 12,
                          fallback: bool = True, max_periods: int = 5000,
                          n_samples: int = 1001, **options: Any) -> PeriodicOrbit:
    """Periodic steady state of a ``T``-periodically forced system by shooting.

    Parameters
    ----------
    system
        A model simulable with ``method`` (default: ``"switching"``).
    period
        ``T > 0``, the period of the input.
    u
        The ``T``-periodic input (e.g. ``Exosystem.sinusoid(a, 2π/T)``); default: the
        system's own.
    x0
        Initial guess (default: the steady state of the mode-averaged linear system, or
        zeros).
    tol
        Newton stops when ``|φ_T(x) - x| <= tol·max(1, |x|)``.
    max_iter
        Newton iterations per start (the linear guess, then zeros) before the fallback;
        ``0`` goes straight to the fallback.
    fallback
        When Newton fails, iterate ``x ← φ_T(x)`` (converges for convergent systems, by
        ``e^{-σT}`` per period) for up to ``max_periods`` periods, then polish by Newton
        (``max(max_iter, 6)`` iterations).
    n_samples
        Uniform samples of the returned period.
    method : str
        The integrator (default ``"switching"``).
    max_periods : int
        Periods of the fallback iteration at most.
    **options
        Passed to the integrator.

    Returns
    -------
    PeriodicOrbit

    Raises
    ------
    ModelError
        Non-positive period, tolerance or budget.
    BudgetExceededError
        No periodic solution found within the budgets (``budget="max_iter"``, or
        ``"max_periods"`` when the fallback's iteration did not settle): not convergent, or
        an unstable orbit out of Newton's reach; the message gives the last residual,
        ``err.partial`` the last iterate.
    SolverError
        Newton failed otherwise (a singular Jacobian).

    Notes
    -----
    For a uniformly convergent system a unique ``T``-periodic steady state exists (ch11 P1)
    and all its Floquet multipliers lie strictly inside the unit circle (P6); for a
    non-convergent system Newton may return an *unstable* periodic solution — read
    :attr:`PeriodicOrbit.floquet`. For a continuous vector field the saltation matrices are
    the identity, and the monodromy is the product of the flows' exponentials.

    References
    ----------
    D5.3 chapter 11; A. Pavlov, N. van de Wouw, H. Nijmeijer, "Frequency
    response functions for nonlinear convergent systems", IEEE TAC 52(6), 2007.

    Examples
    --------
    The open-loop one-sided oscillator of ch11 §4.1 at ω = 2.9 has an *unstable* T-orbit:

    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> from nscontrol.numerics.lti import Exosystem
    >>> orbit = periodic_steady_state(one_sided_oscillator(0.1), 2 * np.pi / 2.9,
    ...                               u=Exosystem.sinusoid(1.0, 2.9))
    >>> round(float(orbit.floquet[0].real), 2), orbit.stable
    (-2.19, False)
    """
    period = check_positive("period", period)
    tol = check_positive("tol", tol)
    max_iter = check_integer("max_iter", max_iter, minimum=0)
    max_periods = check_integer("max_periods", max_periods, minimum=1)
    n_samples = check_integer("n_samples", n_samples, minimum=2)
    fallback = check_bool("fallback", fallback)
    _require_sensitivity(system, method)
    n = int(system.n_states)
    starts = [_linear_guess(system, u), np.zeros(n)] if x0 is None else \
        [as_vector("x0", x0, n)]
    t_eval = np.linspace(0.0, period, n_samples)
    iters, periods, settled = 0, 0, True
    for m, start in enumerate(starts):  # cheap restarts before the slow fallback
        budget = max_iter if m == len(starts) - 1 else min(max_iter, 4)
        x, traj, k, failure = _newton(system, start, period, method, u, t_eval, tol, budget,
                                      options)
        iters += k
        if failure is None:
            break
    how = "newton"
    if failure is not None and fallback:
        x, periods, settled = _fixed_point(system, x if np.all(np.isfinite(x)) else np.zeros(n),
                                           period, method, u, tol, max_periods, options)
        x, traj, more, failure = _newton(system, x, period, method, u, t_eval, tol,
                                         max(max_iter, 6), options)
        iters += more
        iters += periods
        how = "fixed_point+newton"
    if failure is not None:
        spent = "max_periods" if not settled else "max_iter"
        what = (f"the fixed-point iteration did not settle in max_periods = {max_periods} "
                f"periods and Newton did not converge from where it ended" if not settled
                else f"Newton did not converge within max_iter = {max_iter} iterations per "
                f"start{' (and the fallback)' if fallback else ''}")
        message = (f"{spent}: no T-periodic solution found for T={period:g} after {iters} "
                   f"iterations: {what} (last: {failure}); raise {spent}, or the system may "
                   f"not be convergent — use brute_force_steady_state; the last iterate is in "
                   f"err.partial")
        if isinstance(failure, BudgetExceededError) or not settled:
            last = failure.partial[0] if isinstance(failure, BudgetExceededError) else x
            raise BudgetExceededError(message, budget=spent,
                                      limit=max_periods if not settled else max_iter,
                                      used=periods if not settled else iters,
                                      partial=np.asarray(last, float))
        raise SolverError(message.replace(f"{spent}: ", "periodic_steady_state: ", 1),
                          status="max_iter")
    Phi = np.asarray(traj.stats["state_transition"])
    mult = np.linalg.eigvals(Phi)
    mult = mult[np.argsort(-np.abs(mult), kind="stable")]
    return PeriodicOrbit(x, period, Phi, mult, traj, iters,
                         float(np.linalg.norm(traj.x[-1] - x)), how, len(traj.events),
                         int(n_samples))


def _linear_guess(system: Any, u: Any) -> FloatArray:
    """Steady state at ``t = 0`` of the mode-averaged linear system driven by an exosystem
    input (``x = Πw + x_c`` with ``AΠ - ΠS = -E C_u``): a cheap, usually close start for
    Newton. Zeros when that is not available (no exosystem, resonance, singular average)."""
    from scipy.linalg import solve_sylvester

    n = int(system.n_states)
    A_list = getattr(system, "A", None)
    exo = u if u is not None else getattr(system, "u", None)
    if not isinstance(A_list, (list, tuple)) or exo is None or not hasattr(exo, "S"):
        return np.zeros(n)
    try:
        A = sum(np.asarray(a, float) for a in A_list) / len(A_list)
        b = sum(np.asarray(v, float) for v in system.b) / len(A_list)
        Pi = solve_sylvester(A, -exo.S, -system.E @ exo.Cu)
        guess = Pi @ exo.w0 - np.linalg.solve(A, b)
    except (np.linalg.LinAlgError, ValueError, AttributeError, TypeError):
        return np.zeros(n)
    return guess if np.all(np.isfinite(guess)) else np.zeros(n)


def _newton(system: Any, x: FloatArray, period: float, method: str, u: Any,
            t_eval: FloatArray, tol: float, max_iter: int, options: dict[str, Any]
            ) -> tuple[FloatArray, Any, int, SolverError | None]:
    """Newton on ``F(x) = φ_T(x) - x`` by the orbit engine
    (:func:`~nscontrol.analysis.orbits.find_orbit`: damped Newton with the integrator's
    state transition); the converged period is then sampled on ``t_eval``. On failure: the
    start, ``None`` and the error (a :class:`BudgetExceededError` holds the last iterate)."""
    from .orbits import Forced, find_orbit

    forced = Forced(system, u, period, method, tuple(options.items()))
    try:
        orbit = find_orbit(forced, x, tol=tol, max_iter=max_iter)
    except SolverError as exc:
        return x, None, int(max_iter), exc
    tr = _shoot(system, orbit.x0, period, method, u, t_eval, options)
    return orbit.x0, tr, orbit.iterations, None


def _fixed_point(system: Any, x: FloatArray, period: float, method: str, u: Any, tol: float,
                 max_periods: int, options: dict[str, Any]) -> tuple[FloatArray, int, bool]:
    """Long integration: Poincaré samples ``x_{k+1} = φ_T(x_k)`` until they settle (to 1e-6
    relative, enough for Newton to take over) or ``max_periods`` elapse; returns the last
    sample, the periods run and whether they settled."""
    from ..simulate import simulate

    chunk = 50
    done = 0
    opts = dict(options)
    if u is not None:
        opts["u"] = u
    while done < max_periods:
        times = np.arange(chunk + 1) * period
        tr = simulate(system, x, (0.0, chunk * period), method=method, t_eval=times, **opts)
        samples = tr.x[np.searchsorted(tr.t, times[-2:], side="left")]
        x = tr.x[-1]
        done += chunk
        if np.linalg.norm(samples[-1] - samples[0]) <= max(tol, 1e-6) * _scale(x):
            return x, done, True
    return x, done, False


# -- uniqueness ------------------------------------------------------------------------------

@dataclass(frozen=True)
class UniquenessCheck:
    """Shooting from several initial guesses.

    Attributes
    ----------
    guesses
        The initial guesses, ``(k, n)``.
    solutions
        The periodic initial states found, ``(k, n)``.
    max_relative_spread
        ``max_j |x_j - x_0| / max(1e-300, |x_0|)``.
    unique
        ``max_relative_spread <= rtol``.
    """

    guesses: FloatArray
    solutions: FloatArray
    max_relative_spread: float
    unique: bool


def check_uniqueness(system: SimulableSystem, period: float, *, u: InputSignal = None,
                     n_guesses: int = 5,
                     spread: float = 5.0, rtol: float = 1e-8, seed: int = 0,
                     method: str = "switching", **options: Any) -> UniquenessCheck:
    """Shoot from ``n_guesses`` random initial states spread ``spread`` times the size of the
    response and compare the periodic solutions (convergent ⇒ one solution, ch11 P3/P6).

    Parameters
    ----------
    system
        A model simulable with ``method``.
    period : float
        ``T > 0``, the period of the input.
    u
        The ``T``-periodic input (default: the system's own).
    n_guesses : int
        Number of random initial states.
    spread : float
        Their standard deviation, in units of the response's size (``max|x|``).
    rtol : float
        Relative agreement demanded of the periodic solutions.
    seed : int
        Seed of the random initial states.
    method : str
        The integrator (default ``"switching"``).
    **options
        Passed to :func:`periodic_steady_state`.

    Raises
    ------
    SolverError
        Shooting failed from one of the guesses.

    Notes
    -----
    Hypothesis of the property tested: the system is uniformly convergent for the input
    class (ch11 §2.1), so its bounded solution — here the ``T``-periodic one (P1) — is unique
    and every solution converges to it (P3). Agreement from finitely many guesses is
    evidence, not a proof; a non-convergent system may have several periodic solutions, and
    Newton may find any of them (stable or not).

    References
    ----------
    D5.3 chapter 11 (≥ 5 guesses spread ~5× the response, 1e-8 relative);
    A. Pavlov, A. Pogromsky, N. van de Wouw, H. Nijmeijer, "Convergent dynamics, a tribute to
    Boris Pavlovich Demidovich", Systems & Control Letters 52, 2004.
    """
    ref = periodic_steady_state(system, period, u=u, method=method, **options)
    size = max(float(np.max(np.abs(ref.trajectory.x))), 1e-12)
    rng = np.random.default_rng(seed)
    guesses = spread * size * rng.standard_normal((int(n_guesses), ref.x0.shape[0]))
    sols = np.array([periodic_steady_state(system, period, u=u, x0=g, method=method,
                                           **options).x0 for g in guesses])
    dev = float(np.max(np.linalg.norm(sols - ref.x0, axis=1)) / max(np.linalg.norm(ref.x0),
                                                                      1e-300))
    return UniquenessCheck(guesses, sols, dev, dev <= rtol)


# -- brute force -----------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class BruteForceResult:
    """Long simulation of a periodically forced system.

    Attributes
    ----------
    trajectory
        The recorded window (``n_record`` periods after the transient).
    poincare
        States at ``t = kT`` over the recorded window, ``(n_record + 1, n)``.
    multiplicity
        Smallest ``p ∈ {1..6}`` with ``x((k+p)T) = x(kT)`` (to ``rtol·max|x|``); ``0``: not
        periodic within ``6T``.
    x_end
        Final state (to continue a sweep from).
    period, samples_per_period, t0
        ``T``, uniform samples per period and the start of the recorded window.
    """

    trajectory: Any
    poincare: FloatArray
    multiplicity: int
    x_end: FloatArray
    period: float = np.nan
    samples_per_period: int = 0
    t0: float = 0.0

    def uniform_samples(self, n_periods: int | None = None) -> tuple[FloatArray, FloatArray]:
        """``(t, x)`` on the uniform grid of the last ``n_periods`` recorded periods (default:
        the whole window), event instants removed, without the final endpoint (periodic
        wrap)."""
        n_rec = self.poincare.shape[0] - 1
        k = n_rec if n_periods is None else int(n_periods)
        if not 1 <= k <= n_rec:
            raise ModelError(f"n_periods: expected 1..{n_rec} (the recorded periods), got "
                             f"{n_periods!r}")
        n = self.samples_per_period
        grid = self.t0 + np.linspace(0.0, n_rec * self.period, n_rec * n + 1)
        grid = grid[(n_rec - k) * n:-1]
        tr = self.trajectory
        idx = np.clip(np.searchsorted(tr.t, grid, side="left"), 0, len(tr.t) - 1)
        return tr.t[idx], tr.x[idx]


def _multiplicity_rtol(rtol: Any) -> float:
    """The relative tolerance of :func:`period_multiplicity`: in ``(0, 1)`` (``<= 0`` would
    find no period in floating point, ``>= 1`` a period 1 everywhere)."""
    return check_in_interval("rtol", rtol, 0.0, 1.0, open_interval=True)


def period_multiplicity(poincare: Any, *, rtol: float = 1e-3, max_p: int = 6) -> int:
    """Smallest ``p <= max_p`` with ``max_k |x_{k+p} - x_k| <= rtol·max|x|`` over Poincaré
    samples ``x_k = x(t0 + kT)``; ``0`` when none (quasi-periodic, chaotic, or transient).

    Parameters
    ----------
    poincare : (K, n) array_like
        The Poincaré samples ``x_k``, one per row.
    rtol : float
        Tolerance relative to ``max|x|``, in ``(0, 1)``.
    max_p : int
        Largest multiplicity tried.
    """
    rtol = _multiplicity_rtol(rtol)
    max_p = check_integer("max_p", max_p, minimum=1)
    X = np.asarray(poincare, float)
    scale = max(float(np.max(np.abs(X))), 1e-300)
    for p in range(1, max_p + 1):
        if p >= X.shape[0]:
            break
        if float(np.max(np.linalg.norm(X[p:] - X[:-p], axis=1))) <= rtol * scale:
            return p
    return 0


def brute_force_steady_state(system: SimulableSystem, period: float, *, u: InputSignal = None,
                             x0: ArrayLike | None = None,
                             n_transient: int = 200, n_record: int = 12,
                             samples_per_period: int = 200, rtol: float = 1e-3,
                             method: str = "switching", **options: Any) -> BruteForceResult:
    """Simulate ``n_transient`` periods, then record ``n_record`` more and find the period
    multiplicity — for models that are not (known to be) convergent.

    The recorded window is sampled at ``samples_per_period`` uniform times per period (plus
    the event instants; :meth:`BruteForceResult.uniform_samples` returns the uniform ones).

    Parameters
    ----------
    system
        A model simulable with ``method``.
    period : float
        ``T > 0``, the period of the input.
    u
        The ``T``-periodic input (default: the system's own).
    x0 : array_like, optional
        Initial state (default zeros).
    n_transient : int
        Periods simulated and discarded.
    n_record : int
        Periods recorded after them.
    samples_per_period : int
        Uniform samples per recorded period.
    rtol : float
        Relative tolerance of the period multiplicity (see Notes).
    method : str
        The integrator (default ``"switching"``).
    **options
        Passed to the integrator.

    Raises
    ------
    ModelError
        Non-positive period or negative counts.

    Notes
    -----
    No hypothesis on the system beyond existence of solutions: that is the point of brute
    force. What the result means does depend on one: the transient must have died out, i.e.
    ``n_transient·T`` must exceed several of the slowest decay times of the attractor reached
    (ch11 §3.3 uses at least 7); otherwise a slow transient shows as multiplicity 0.
    Multiplicity ``p`` is the smallest ``p <= 6`` with
    ``max_k |x((k+p)T) - x(kT)| <= rtol·max|x|`` on the ``n_record + 1`` Poincaré samples.

    References
    ----------
    D5.3 chapter 11 (brute force and period multiplicity).

    Examples
    --------
    The open loop of ch11 §4.1 at ω = 2.9 settles on a 2T-periodic orbit (check 7):

    >>> import numpy as np
    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> from nscontrol.numerics.lti import Exosystem
    >>> bf = brute_force_steady_state(one_sided_oscillator(0.1), 2 * np.pi / 2.9,
    ...                               u=Exosystem.sinusoid(1.0, 2.9), n_transient=300)
    >>> bf.multiplicity, round(float(np.max(np.abs(bf.trajectory.x[:, 0]))), 2)
    (2, 1.22)
    """
    from ..simulate import simulate

    period = check_positive("period", period)
    rtol = _multiplicity_rtol(rtol)
    if int(n_transient) < 0 or int(n_record) < 1:
        raise ModelError(f"n_transient, n_record: expected >= 0 and >= 1, got {n_transient}, "
                         f"{n_record}")
    if int(samples_per_period) < 3:
        raise ModelError(f"samples_per_period: expected >= 3, got {samples_per_period!r}")
    n = int(system.n_states)
    x = np.zeros(n) if x0 is None else as_vector("x0", x0, n)
    opts = dict(options)
    if u is not None:
        opts["u"] = u
    if n_transient:
        tr = simulate(system, x, (0.0, n_transient * period), method=method,
                      t_eval=np.array([0.0, n_transient * period]), **opts)
        x = tr.x[-1]
    t0 = n_transient * period
    t_eval = t0 + np.linspace(0.0, n_record * period, n_record * samples_per_period + 1)
    rec = simulate(system, x, (t0, t0 + n_record * period), method=method, t_eval=t_eval,
                   **opts)
    marks = t0 + np.arange(n_record + 1) * period
    idx = np.clip(np.searchsorted(rec.t, marks - 1e-12 * period, side="left"), 0,
                  len(rec.t) - 1)
    poinc = rec.x[idx]
    return BruteForceResult(rec, poinc, period_multiplicity(poinc, rtol=rtol), rec.x[-1],
                            period, int(samples_per_period), t0)


# -- frequency response ----------------------------------------------------------------------

def refined_peak(values: Any) -> float:
    """Maximum of a periodic, uniformly sampled signal refined by a parabola through the
    largest sample and its two (cyclic) neighbours; plain sampled maxima are biased low by
    about ``(π/N)²/2`` relative.

    Parameters
    ----------
    values : (N,) array_like
        One period of the signal, uniformly sampled (without the repeated endpoint).
    """
    y = np.asarray(values, float)
    i = int(np.argmax(y))
    ym, y0, yp = y[i - 1], y[i], y[(i + 1) % y.size]
    den = ym - 2.0 * y0 + yp
    if den >= 0.0:  # flat or not a local maximum: nothing to refine
        return float(y0)
    off = 0.5 * (ym - yp) / den
    return float(y0 - 0.25 * (ym - yp) * off)


def dft_harmonics(values: Any, n_harmonics: int) -> FloatArray:
    """``|Z_k|``, ``Z_k = (2/N) Σ_n z_n e^{-2πikn/N}``, k = 1..K, for N uniform samples of one
    period (without the repeated endpoint).

    Parameters
    ----------
    values : (N,) array_like
        The samples ``z_n``.
    n_harmonics : int
        ``K``, the number of harmonics returned.
    """
    z = np.asarray(values, float)
    Z = np.fft.rfft(z) * (2.0 / z.size)
    return np.abs(Z[1:int(n_harmonics) + 1])


@dataclass(frozen=True)
class HarmonicResponse:
    """Steady-state figures at one frequency (ch11 §2.6).

    Attributes
    ----------
    omega, amplitude
        Excitation ``a sin(ωt)``.
    gamma
        ``max_t |z̄(t)|/a`` with a refined peak (the generalized Bode magnitude).
    rms_gain
        ``RMS(z̄)/RMS(w)``.
    harmonics
        ``|Z_k|/a``, k = 1..K.
    max_floquet
        Largest Floquet multiplier modulus (``nan`` for brute force).
    multiplicity
        1 for a shot orbit; the detected multiplicity for brute force.
    n_crossings
        Mode changes per period of the response (per ``pT`` for a brute-force response of
        multiplicity ``p``).
    x0
        Steady state at ``t = 0``.
    state_peak
        ``max_t |x̄(t)|`` (refined peak; the quantity the ISC bound ``γ_ISC·a`` bounds).
    effort
        ``max_t |u(t)|`` of the control law given as ``control`` (``nan`` without one).
    effort_rms
        ``RMS_t |u(t)|`` over the steady-state period (the ``p`` periods of a brute-force
        response of multiplicity ``p``; ``nan`` without a control law).
    """

    omega: float
    amplitude: float
    gamma: float
    rms_gain: float
    harmonics: FloatArray
    max_floquet: float
    multiplicity: int
    n_crossings: int
    x0: FloatArray
    state_peak: float = np.nan
    effort: float = np.nan
    effort_rms: float = np.nan


def _output_matrix(system: Any, output: Any) -> FloatArray:
    n = int(system.n_states)
    if output is None:
        output = getattr(system, "C", None)
        if output is None:
            output = np.eye(1, n)
    Cz = np.asarray(output, float)
    Cz = Cz.reshape(1, -1) if Cz.ndim == 1 else Cz
    if Cz.ndim != 2 or Cz.shape[1] != n:
        raise DimensionError(f"output: expected a (k, {n}) matrix, got shape {Cz.shape}")
    return Cz


def _check_control(control: Any) -> None:
    if control is not None and not callable(control):
        raise ModelError(f"control: expected a callable x -> u on time-major states (e.g. "
                         f"ConvergentStateFeedback.control), got {type(control).__name__}")


def _effort(control: Any, x: FloatArray) -> FloatArray | None:
    """``|u|`` per row of the time-major ``x`` (None without a control law)."""
    if control is None:
        return None
    u = np.asarray(control(x), float).reshape(x.shape[0], -1)
    return np.linalg.norm(u, axis=1)


def _rms(values: FloatArray | None) -> float:
    """RMS of uniform samples of whole periods (NaN for ``None``): the sampled mean of a
    trigonometric polynomial of degree below ``N/2`` is its exact mean, so no refinement is
    needed, unlike a peak."""
    return np.nan if values is None else float(np.sqrt(np.mean(values**2)))


def harmonic_response(orbit: PeriodicOrbit, *, amplitude: float, output: Any = None,
                      system: Any = None, n_harmonics: int = 5,
                      control: Any = None) -> HarmonicResponse:
    """Generalized-Bode figures of a shot orbit: refined ``γ_a``, RMS gain, harmonics, peak
    state and (with ``control``, a callable ``x -> u`` on time-major states) the effort
    ``max|u|`` and its RMS over the period.

    Parameters
    ----------
    orbit : PeriodicOrbit
        From :func:`periodic_steady_state`.
    amplitude : float
        The excitation's amplitude ``a``.
    output : array_like, optional
        Performance output matrix ``C_z`` (default: the system's ``C``, else the first state).
    system : optional
        The model, for its default output.
    n_harmonics : int
        Number of harmonics measured.
    control : callable, optional
        The feedback law ``x -> u`` on time-major states, for the effort.
    """
    n = orbit.x0.shape[0]
    Cz = _output_matrix(system, output) if system is not None else \
        (np.eye(1, n) if output is None else np.reshape(output, (-1, n)))
    _check_control(control)
    _, x = orbit.uniform_samples()
    z = x @ Cz.T
    mag = np.linalg.norm(z, axis=1)
    a = check_positive("amplitude", amplitude)
    u = _effort(control, x)
    return HarmonicResponse(
        omega=2 * np.pi / orbit.period, amplitude=a, gamma=refined_peak(mag) / a,
        rms_gain=float(np.sqrt(np.mean(mag**2))) / (a / np.sqrt(2.0)),
        harmonics=dft_harmonics(z[:, 0], n_harmonics) / a, max_floquet=orbit.max_multiplier,
        multiplicity=1, n_crossings=orbit.n_crossings, x0=orbit.x0,
        state_peak=refined_peak(np.linalg.norm(x, axis=1)),
        effort=np.nan if u is None else refined_peak(u), effort_rms=_rms(u))


@dataclass(frozen=True)
class _ShootPoint:
    """Picklable per-frequency task of :func:`frequency_response`."""

    system: Any
    amplitude: Any
    output: Any
    n_samples: int
    n_harmonics: int
    method: str
    options: dict[str, Any] = field(default_factory=dict)
    control: Any = None

    def __call__(self, omega: float) -> HarmonicResponse:
        from ..numerics.lti import Exosystem

        T = 2 * np.pi / omega
        a = _amplitude_at(self.amplitude, omega)
        orbit = periodic_steady_state(self.system, T, u=Exosystem.sinusoid(a, omega),
                                      method=self.method, n_samples=self.n_samples + 1,
                                      **self.options)
        return harmonic_response(orbit, amplitude=a, output=self.output,
                                 system=self.system, n_harmonics=self.n_harmonics,
                                 control=self.control)


@dataclass(frozen=True)
class FrequencyResponse:
    """Figures per frequency (NaN where a point failed; see ``errors``).

    Attributes
    ----------
    omega, gamma, rms_gain, max_floquet
        Arrays over the frequency grid.
    harmonics
        ``(n_ω, K)`` first-harmonic and superharmonic gains ``|Z_k|/a``.
    multiplicity, n_crossings
        Integer arrays (``-1`` where a point failed).
    state_peak
        ``max_t |x̄(t)|`` per frequency.
    effort
        Control effort ``max_t |u(t)|`` per frequency (NaN when no control law was given).
    effort_rms
        ``RMS_t |u(t)|`` over the steady-state period(s) per frequency (NaN when no control
        law was given; empty for a response built without it).
    direction
        ``"independent"`` (shooting, every point on its own), ``"up"`` or ``"down"``.
    amplitude
        Input amplitude ``a`` (NaN when it depends on ``ω``: see :attr:`amplitudes`).
    errors
        Per-point :class:`~nscontrol.sweep.PointError` or ``None`` (one entry per frequency,
        its ``index`` the position in :attr:`omega`).
    branches
        :func:`frequency_sweep`: the orbit branches continued in ``ω`` (one
        :class:`~nscontrol.analysis.continuation.Branch` per attractor the sweep landed on,
        unstable parts past a fold included: the coexisting orbits); ``()`` otherwise.
    amplitudes
        The input amplitude ``a(ω)`` per frequency (``gamma·amplitudes`` is the response
        amplitude ``max|z̄|``).
    """

    omega: FloatArray
    gamma: FloatArray
    rms_gain: FloatArray
    harmonics: FloatArray
    max_floquet: FloatArray
    multiplicity: NDArray[np.int64]
    n_crossings: NDArray[np.int64]
    state_peak: FloatArray
    effort: FloatArray
    direction: str
    amplitude: float
    errors: tuple[Any, ...] = ()
    branches: tuple[Any, ...] = ()
    amplitudes: FloatArray = field(default_factory=lambda: np.empty(0))
    effort_rms: FloatArray = field(default_factory=lambda: np.empty(0))

    @classmethod
    def from_points(cls, omegas: ArrayLike, points: Sequence[HarmonicResponse | None],
                    *, direction: str, amplitude: Any, n_harmonics: int,
                    errors: Sequence[Any] = (), branches: Sequence[Any] = ()
                    ) -> FrequencyResponse:
        def col(attr: str, fill: Any) -> np.ndarray:
            return np.array([getattr(p, attr) if p is not None else fill for p in points])

        w = np.asarray(omegas, float)
        a = np.array([_amplitude_at(amplitude, wi) for wi in w])
        return cls(w, col("gamma", np.nan), col("rms_gain", np.nan),
                   np.array([p.harmonics if p is not None else np.full(n_harmonics, np.nan)
                             for p in points]),
                   col("max_floquet", np.nan), col("multiplicity", -1).astype(np.int64),
                   col("n_crossings", -1).astype(np.int64), col("state_peak", np.nan),
                   col("effort", np.nan), direction,
                   np.nan if callable(amplitude) else float(amplitude), tuple(errors),
                   tuple(branches), a, col("effort_rms", np.nan).astype(float))


def _omega_grid(omegas: Any) -> FloatArray:
    w = np.atleast_1d(np.asarray(omegas, float))
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ModelError(f"omegas: expected a non-empty 1-d array of positive frequencies, "
                         f"got {omegas!r}")
    return w


def frequency_response(system: SimulableSystem, omegas: ArrayLike, *,
                       amplitude: AmplitudeSpec = 1.0,
                       output: ArrayLike | None = None, n_samples: int = 1000,
                       n_harmonics: int = 5, method: str = "switching",
                       control: ControlMap | None = None,
                       executor: Any = "auto", progress: bool | None = None,
                       **options: Any) -> FrequencyResponse:
    """Generalized Bode plot of a convergent system: shoot the steady state at each ``ω``
    under ``a sin(ωt)`` and measure ``γ_a(ω)``, the RMS gain, harmonics, the peak state,
    the control effort and Floquet multipliers; frequencies run independently through
    :func:`nscontrol.sweep.run`.

    Parameters
    ----------
    system
        A convergent model; its input matrix takes the scalar excitation.
    omegas
        Positive frequencies (rad per time unit).
    amplitude
        ``a``, or a picklable callable ``ω -> a(ω)`` (e.g.
        :class:`~nscontrol.systems.beam.Unbalance`: ``m_e r_e ω²``); the gains are divided
        by ``a(ω)``.
    output
        Performance output matrix ``C_z`` (default: the model's ``C``, else the first state).
    n_samples
        Uniform samples per period for the peak and the DFT (``>= 64·n_harmonics``).
    n_harmonics : int
        Number of harmonics measured (``|Z_1| .. |Z_K|``).
    method
        Integrator (default ``"switching"``).
    control
        The feedback law the loop was built from, as a callable ``x -> u`` on time-major
        states: ``ConvergentStateFeedback.control``, ``PWAStateFeedback.control``, or
        ``EstimateFeedback(feedback, n)`` for an observer-based loop
        (:mod:`nscontrol.design.convergent_pwa`); gives :attr:`FrequencyResponse.effort`
        ``= max_t|u|`` and :attr:`FrequencyResponse.effort_rms` ``= RMS_t|u|``. Must be
        picklable for process executors (those are).
    executor
        As in :func:`nscontrol.sweep.run`. Default ``"auto"``: the first frequency runs
        here, timed, and the rest go to a local process pool only when the predicted serial
        time exceeds :data:`nscontrol.sweep.AUTO_PARALLEL_SECONDS` (0.15 s) — measured on
        the project's 2-core machine, a chapter-11 point costs ~8 ms (400 samples) and a
        pool ~0.035 s: break-even near 10 points, 60 points take 0.46 s serial and 0.32 s in
        two processes. ``"serial"``, ``None`` (always processes) or a Dask client/address —
        the system must then be picklable.
    progress
        Progress bar on stderr (see :func:`nscontrol.sweep.run`).
    **options
        Passed to :func:`periodic_steady_state` (and on to the integrator).

    Returns
    -------
    FrequencyResponse
        ``direction="independent"``; failed points are NaN with their error recorded.

    Raises
    ------
    ModelError
        Bad frequency grid or ``control``.
    DimensionError
        ``output`` of the wrong width.

    Notes
    -----
    Only meaningful for convergent systems (ch11 §2.6): the steady state is then unique and
    equals ``α(v(t), ω)``; for PWL systems ``γ_a`` does not depend on ``a`` (P5). The peak is
    refined by a parabola through the three largest samples (plain maxima are biased low by
    ``(π/N)²/2``). Convergence is not checked here: run
    :func:`~nscontrol.analysis.convergence.quadratic_convergence` first, and read
    :attr:`FrequencyResponse.max_floquet` (``< 1`` everywhere for a convergent system, P6).

    References
    ----------
    A. Pavlov, N. van de Wouw, H. Nijmeijer, "Frequency response functions for nonlinear
    convergent systems", IEEE TAC 52(6), 2007; D5.3 chapter 11.

    Examples
    --------
    A linear oscillator (``k_s = 0``) gives ``|G(iω)|``; the effort of ``u = Kx`` comes
    with it:

    >>> import numpy as np
    >>> from nscontrol.design.convergent_pwa import design_state_feedback
    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> linear = one_sided_oscillator(0.1, ks=0.0)
    >>> frf = frequency_response(linear, [0.5, 1.0, 2.0], progress=False)
    >>> G = [abs(1 / (1 - w**2 + 0.1j * w)) for w in (0.5, 1.0, 2.0)]
    >>> bool(np.allclose(frf.gamma, G, rtol=1e-6))
    True
    >>> plant = one_sided_oscillator(0.1)
    >>> sf = design_state_feedback(plant, sigma=0.3)
    >>> frf = frequency_response(sf.closed_loop(plant), [2.9], control=sf.control,
    ...                          progress=False)
    >>> round(float(frf.gamma[0]), 4), bool(frf.effort[0] > 0)
    (0.1892, True)
    """
    from .. import sweep

    w = _omega_grid(omegas)
    _output_matrix(system, output)  # bad shapes fail here, not once per point
    _check_control(control)
    progress = check_bool("progress", progress, allow_none=True)
    task = _ShootPoint(system, _amplitude_spec(amplitude), output,
                       int(n_samples), int(n_harmonics), method, dict(options), control)
    res = sweep.run(task, list(w), executor=executor, progress=progress, desc="FRF")
    return FrequencyResponse.from_points(w, res.values, direction="independent",
                                         amplitude=amplitude, n_harmonics=n_harmonics,
                                         errors=res.errors)


def _brute_response(bf: BruteForceResult, omega: float, amplitude: float, Cz: FloatArray,
                    n_harmonics: int, control: Any) -> HarmonicResponse:
    """Figures of a brute-force window on its *uniform* grid (event rows removed). For
    multiplicity ``p >= 1`` over the last ``p`` periods (peaks refined cyclically, harmonics
    of ω at DFT bins ``p, 2p, ...``, RMS of ``z`` and ``u`` over the ``p`` periods); for
    ``p = 0`` plain maxima over the whole window, RMS over the window and harmonics over the
    last period."""
    p = int(bf.multiplicity)
    k = max(p, 1)
    _, x = bf.uniform_samples(k)
    z = x @ Cz.T
    mag = np.linalg.norm(z, axis=1)
    u = _effort(control, x)
    Z = np.abs(np.fft.rfft(z[:, 0]) * (2.0 / z.shape[0]))
    harmonics = Z[k * np.arange(1, int(n_harmonics) + 1)] / amplitude
    if p >= 1:
        gamma, peak = refined_peak(mag), refined_peak(np.linalg.norm(x, axis=1))
        effort = np.nan if u is None else refined_peak(u)
        effort_rms = _rms(u)
        rms = float(np.sqrt(np.mean(mag**2)))
    else:  # not periodic: every recorded row, and the RMS of the whole window
        xa = bf.trajectory.x
        gamma = float(np.max(np.linalg.norm(xa @ Cz.T, axis=1)))
        peak = float(np.max(np.linalg.norm(xa, axis=1)))
        ua = _effort(control, xa)
        effort = np.nan if ua is None else float(np.max(ua))
        _, xw = bf.uniform_samples()
        effort_rms = _rms(_effort(control, xw))
        rms = float(np.sqrt(np.mean(np.linalg.norm(xw @ Cz.T, axis=1)**2)))
    t_end = bf.t0 + (bf.poincare.shape[0] - 1) * bf.period
    times = bf.trajectory.event_times()
    crossings = int(np.count_nonzero((times >= t_end - k * bf.period) & (times < t_end)))
    return HarmonicResponse(omega=float(omega), amplitude=amplitude, gamma=gamma / amplitude,
                            rms_gain=rms / (amplitude / np.sqrt(2.0)), harmonics=harmonics,
                            max_floquet=np.nan, multiplicity=p, n_crossings=crossings,
                            x0=bf.poincare[-1], state_peak=peak, effort=effort,
                            effort_rms=effort_rms)


#: Shooting tolerance of the sweeps' orbits (relative to ``max(1, |x|)``), as in
#: :func:`~nscontrol.analysis.continuation.continue_orbit`.
_SWEEP_TOL = 1e-10


@dataclass(frozen=True)
class _FrequencyFamily:
    """Picklable continuation factory ``ω -> Forced(system, a sin(ωt), 2π/ω)``."""

    system: Any
    amplitude: Any
    method: Any
    options: tuple[tuple[str, Any], ...] = ()

    def __call__(self, omega: float) -> Any:
        from ..numerics.lti import Exosystem
        from .orbits import Forced

        return Forced(self.system, Exosystem.sinusoid(_amplitude_at(self.amplitude, omega),
                                                      omega), 2 * np.pi / omega,
                      self.method, self.options)


@dataclass(frozen=True)
class _SweepBranch:
    """Picklable task: one sweep direction over ``(direction, ((index, ω), ...))``, in the
    given order, by continuation of the attractor's orbit (see :func:`frequency_sweep`).
    Returns ``(responses, branches)``; a frequency that fails is that frequency's error and
    the sweep goes on from the last good state."""

    system: Any
    amplitude: Any
    output: Any
    n_transient: int
    n_record: int
    n_harmonics: int
    samples_per_period: int
    method: str
    options: dict[str, Any] = field(default_factory=dict)
    control: Any = None
    transient_time: float | None = None

    def __call__(self, branch: tuple[str, tuple[tuple[int, float], ...]]
                 ) -> tuple[list[Any], list[Any]]:
        import traceback

        from ..sweep import PointError

        direction, points = branch
        Cz = _output_matrix(self.system, self.output)
        family = _FrequencyFamily(self.system, self.amplitude, self.method,
                                  tuple(self.options.items()))
        x = np.zeros(int(self.system.n_states))
        out: list[Any] = [None] * len(points)
        curves: list[Any] = []
        span = (min(wj for _, wj in points), max(wj for _, wj in points))
        i = 0
        while i < len(points):
            idx, w = points[i]
            try:        # land on the attractor: transient, record, multiplicity
                bf = self._brute_force(w, x)
                out[i] = _brute_response(bf, w, _amplitude_at(self.amplitude, w), Cz,
                                         self.n_harmonics, self.control)
            except Exception as exc:  # this frequency's error; the sweep continues
                out[i] = PointError(int(idx), type(exc).__name__,
                                    f"ω = {w:g} ({direction} sweep): {exc}",
                                    traceback.format_exc())
                i += 1
                continue
            x = bf.x_end
            orbit = _stable_orbit(family(w), bf)
            if orbit is None:   # not periodic, or no stable orbit by shooting: brute force
                i += 1
                continue
            out[i] = self._orbit_response(family, w, orbit, Cz)
            x = orbit.x0
            covered, more = self._follow(family, w, orbit, [wj for _, wj in points[i + 1:]],
                                         Cz, span)
            curves.extend(more)
            for j, (resp, xj) in enumerate(covered, start=i + 1):
                out[j], x = resp, xj
            i += 1 + len(covered)
        return out, curves

    def _brute_force(self, w: float, x: FloatArray) -> BruteForceResult:
        from ..numerics.lti import Exosystem

        n_transient = self.n_transient if self.transient_time is None else \
            int(np.ceil(self.transient_time * w / (2 * np.pi) - 1e-9))
        return brute_force_steady_state(
            self.system, 2 * np.pi / w, u=Exosystem.sinusoid(_amplitude_at(self.amplitude, w), w),
            x0=x, n_transient=n_transient, n_record=self.n_record,
            samples_per_period=self.samples_per_period, method=self.method, **self.options)

    def _orbit_response(self, family: _FrequencyFamily, w: float, orbit: Any,
                        Cz: FloatArray) -> HarmonicResponse:
        """The figures of a shot ``pT`` orbit: ``p`` periods from its node at ``t = 0``,
        measured like a brute-force window, with its largest multiplier."""
        from dataclasses import replace

        forced = family(w)
        p = int(orbit.n_periods)
        bf = brute_force_steady_state(self.system, forced.period, u=forced.u, x0=orbit.x0,
                                      n_transient=0, n_record=p,
                                      samples_per_period=self.samples_per_period,
                                      method=self.method, **self.options)
        bf = replace(bf, multiplicity=p)     # exact by construction (shooting residual)
        resp = _brute_response(bf, w, _amplitude_at(self.amplitude, w), Cz, self.n_harmonics,
                               self.control)
        return replace(resp, max_floquet=float(np.abs(orbit.multipliers[0])))

    def _follow(self, family: _FrequencyFamily, w0: float, orbit: Any, ahead: list[float],
                Cz: FloatArray, span: tuple[float, float]
                ) -> tuple[list[tuple[HarmonicResponse, FloatArray]], list[Any]]:
        """Follow the stable orbit ``orbit`` (at ``w0``) over the frequencies ``ahead`` (in
        sweep order): the responses it covers, with their states, and the branches continued
        on the way.

        From one frequency to the next the orbit is predicted by secant extrapolation of
        the nodes and corrected by shooting at the exact frequency. Where that fails or
        ends on an unstable orbit, a bifurcation or a steep stretch lies between the two
        frequencies: pseudo-arclength continuation (:func:`~nscontrol.analysis.continuation.
        continue_orbit`) from the last good orbit locates the flip, Neimark–Sacker point or
        fold (stopping at the first two: the attractor changes period, the next frequency
        lands afresh), passes a fold onto the coexisting unstable orbits (within the sweep's
        ``span`` and a step budget), and otherwise carries the orbit across to the next
        frequency."""
        from ..errors import NscontrolError
        from .continuation import _orbit_at

        covered: list[tuple[HarmonicResponse, FloatArray]] = []
        curves: list[Any] = []
        k = int(orbit.n_periods)
        known = [(w0, orbit.nodes)]
        last = orbit
        for w in ahead:
            new = None
            if len(known) > 1:      # secant predictor: free
                new = _shoot_nodes(family, w, _secant_nodes(known, w))
            if new is None:         # Euler predictor, halving the frequency step twice
                new = _advance(family, known[-1][0], last, w, depth=2)
            if new is None or not new.stable:
                curve = self._continue(family, known[-1][0], last, w, span)
                if curve is None:
                    break
                curves.append(curve)
                new = _stable_on_branch(family, curve, w)
                if new is None:
                    break
            d = period_multiplicity(np.vstack([new.nodes, new.nodes[:1]]))
            if d < k:   # a kT orbit merged into a dT one (reverse flip): follow that one
                try:
                    new = _orbit_at(family, w, new.nodes[:d], tol=_SWEEP_TOL)
                except NscontrolError:
                    break
                k, known = d, []
            covered.append((self._orbit_response(family, w, new, Cz), new.x0))
            known = [*known[-1:], (w, new.nodes)]
            last = new
        return covered, curves

    def _continue(self, family: _FrequencyFamily, w0: float, orbit: Any, w: float,
                  span: tuple[float, float]) -> Any:
        """Pseudo-arclength continuation from the last good ``orbit`` (at ``w0``) towards
        ``w`` (``None`` when it cannot start); past a fold it runs on along the unstable
        orbits within ``span`` and a budget of 30 steps. Steps are measured against the
        arclength of one frequency interval, ``h = |Δω|·√(1 + |dX/dω|²)`` (the Euler slope
        at ``orbit``; a secant over the last interval overestimates it where the orbit
        changed a lot, and the nodes of a resonant orbit move much faster than ``ω``): first
        ``h/2``, at most ``2h`` — longer steps could pass a flip and the
        flip back within one step, where no test function changes sign."""
        from ..errors import NscontrolError
        from .continuation import continue_orbit

        slope = _node_slope(family, w0, orbit)
        h = abs(w - w0) * float(np.sqrt(1.0 + np.sum(slope**2)))
        try:
            return continue_orbit(family, w0, orbit.nodes, n_periods=int(orbit.n_periods),
                                  p_range=span, step=h / 2,
                                  step_max=2 * h, step_min=1e-2 * h, max_steps=30,
                                  direction=1 if w > w0 else -1, locate_tol=1e-6, tol=_SWEEP_TOL,
                                  detect=("fold", "flip", "neimark_sacker"),
                                  stop_at=("flip", "neimark_sacker"), parameter_name="omega")
        except NscontrolError:
            return None


def _shoot_nodes(family: _FrequencyFamily, w: float, guess: FloatArray) -> Any:
    """The orbit at ``w`` from predicted nodes by plain Newton (the engine's corrector with
    ``ω`` pinned: quadratic from a good prediction, a fast failure from a bad one), or
    ``None``."""
    from ..errors import NscontrolError
    from .continuation import _orbit_at

    try:
        return _orbit_at(family, w, guess, tol=_SWEEP_TOL)
    except NscontrolError:
        return None


def _advance(family: _FrequencyFamily, w0: float, orbit: Any, w: float, depth: int) -> Any:
    """The orbit at ``w`` from ``orbit`` at ``w0``: Euler predictor and Newton; on failure
    through the midpoint (``depth`` halvings at most: the nodes of a resonant or
    subharmonic orbit can move by ~10 per unit ``ω``), then damped Newton
    (:func:`~nscontrol.analysis.orbits.find_orbit`: where the orbit has ceased to exist,
    e.g. a 2T orbit merged into the doubled T orbit, it reaches what is there). An orbit
    at ``w`` that converges but is unstable is returned as it is (a bifurcation lies before
    it); ``None`` when none is found or the midpoint's is unstable."""
    from ..errors import NscontrolError
    from .orbits import find_orbit

    new = _shoot_nodes(family, w, orbit.nodes + (w - w0) * _node_slope(family, w0, orbit))
    if new is not None:
        return new
    if depth > 0:
        mid = _advance(family, w0, orbit, 0.5 * (w0 + w), depth - 1)
        if mid is None or not mid.stable:
            return None
        return _advance(family, 0.5 * (w0 + w), mid, w, depth - 1)
    try:
        return find_orbit(family(w), orbit.nodes, n_periods=int(orbit.n_periods), max_iter=6)
    except NscontrolError:
        return None


def _node_slope(family: _FrequencyFamily, w0: float, orbit: Any) -> FloatArray:
    """``dX/dω = -G_X⁻¹ ∂G/∂ω`` of the shooting equations at the orbit (``G_X`` from its node
    Jacobians; ``∂G/∂ω`` a forward difference, step ``√ε·ω``, from ``G = 0`` up to the
    shooting residual): the Euler predictor where no secant is known yet. A 2T orbit just
    born at a flip lies close to the doubled T orbit, so a predictor this good keeps Newton
    on the right one."""
    from .orbits import _shooting_system

    X = orbit.nodes
    k, n = X.shape
    J = np.zeros((k * n, k * n))
    for i, Ji in enumerate(orbit.node_jacobians):
        j = (i + 1) % k
        J[i * n:(i + 1) * n, i * n:(i + 1) * n] += Ji
        J[i * n:(i + 1) * n, j * n:(j + 1) * n] -= np.eye(n)
    dw = float(np.finfo(float).eps) ** 0.5 * max(1.0, abs(w0))
    G_w = _shooting_system(family(w0 + dw), X)[0] / dw
    try:
        return -np.linalg.solve(J, G_w).reshape(k, n)
    except np.linalg.LinAlgError:
        return np.zeros_like(X)


def _secant_nodes(known: list[tuple[float, FloatArray]], w: float) -> FloatArray:
    """Nodes at ``w`` extrapolated linearly from the last two known ``(ω, nodes)``."""
    if len(known) < 2:
        return known[-1][1]
    (w1, n1), (w2, n2) = known[-2], known[-1]
    return n2 + (w - w2) / (w2 - w1) * (n2 - n1)


def _stable_on_branch(family: _FrequencyFamily, br: Any, w: float) -> Any:
    """The stable orbit at ``w`` on the branch's first monotone stretch in ``ω`` (up to
    its first fold), by shooting from the nodes interpolated there; ``None`` past it."""
    from ..errors import NscontrolError
    from .orbits import find_orbit

    if len(br) < 2:
        return None
    sign = 1.0 if br.p[1] > br.p[0] else -1.0
    q = sign * br.p
    back = np.flatnonzero(np.diff(q) <= 0.0)
    end = int(back[0]) + 1 if back.size else len(br)
    j = int(np.searchsorted(q[:end], sign * w))
    if j == 0 or j >= end or not (br.stable[j - 1] or br.stable[j]):
        return None
    lam = (sign * w - q[j - 1]) / (q[j] - q[j - 1])
    guess = (1 - lam) * br.nodes[j - 1] + lam * br.nodes[j]
    try:
        orbit = find_orbit(family(w), guess, n_periods=br.nodes.shape[1], max_iter=8)
    except NscontrolError:
        return None
    return orbit if orbit.stable else None


def _stable_orbit(forced: Any, bf: BruteForceResult) -> Any:
    """The stable ``pT`` orbit through the end of a brute-force window of multiplicity
    ``p >= 1`` (Newton from its last Poincaré sample), or ``None``."""
    from ..errors import NscontrolError
    from .orbits import find_orbit

    if bf.multiplicity < 1:
        return None
    try:
        orbit = find_orbit(forced, bf.poincare[-1], n_periods=int(bf.multiplicity),
                           max_iter=10)
    except NscontrolError:
        return None
    return orbit if orbit.stable else None


def frequency_sweep(system: SimulableSystem, omegas: ArrayLike, *,
                    amplitude: AmplitudeSpec = 1.0, output: ArrayLike | None = None,
                    directions: Sequence[str] = ("up", "down"), n_transient: int = 100,
                    transient_time: float | None = None,
                    n_record: int = 12, n_harmonics: int = 5, samples_per_period: int = 200,
                    method: str = "switching", control: ControlMap | None = None,
                    executor: Any = "auto",
                    progress: bool | None = None,
                    **options: Any) -> dict[str, FrequencyResponse]:
    """Frequency sweeps up and/or down by continuation of the attractor's periodic orbit in
    ``ω``; the directions run in parallel through :func:`nscontrol.sweep.run`. Differences
    between the directions reveal coexisting steady states (hysteresis) of non-convergent
    models, and the continued branches carry the unstable orbits between them.

    A sweep *lands* on an attractor by brute force (:func:`brute_force_steady_state` from
    the last state: ``n_transient`` periods, then ``n_record`` recorded, multiplicity
    ``p``), shoots its ``pT`` orbit and *follows* it: at each next frequency the orbit is
    predicted (Euler, then secant on the nodes) and corrected by shooting at that exact
    frequency. Where the correction fails or the orbit is unstable, pseudo-arclength
    continuation (:func:`~nscontrol.analysis.continuation.continue_orbit`) from the last
    orbit locates the flip or Neimark–Sacker point (the attractor changes period: the next
    frequency lands afresh) or the fold, which it passes onto the coexisting unstable orbits;
    a ``pT`` orbit that merges into a ``dT`` one (``d < p``) is followed as that.

    Parameters
    ----------
    system, omegas, amplitude, output, n_harmonics, method, control, progress
        As in :func:`frequency_response`.
    directions
        ``"up"`` and/or ``"down"``.
    n_transient, n_record, samples_per_period
        Per landing, as in :func:`brute_force_steady_state` (``samples_per_period`` also
        samples the shot orbits).
    transient_time
        When given, the transient of a landing lasts this long in time units instead of
        ``n_transient`` periods (``⌈transient_time·ω/2π⌉`` periods: the same decay at every
        frequency, as in an experiment's fixed settling time).
    executor
        As in :func:`nscontrol.sweep.run`. Default ``"auto"``: local processes when two
        directions run on a machine with two or more CPUs (a direction costs one landing of
        ``n_transient + n_record`` periods per attractor, a few shooting passes per
        frequency and a continuation per bifurcation — 0.05–0.3 s per frequency for the
        ch11 oscillator, against ~0.035 s to start a pool), else serial.
    **options
        Passed to the integrator.

    Returns
    -------
    dict of str to FrequencyResponse
        One per direction, on the increasing frequency grid; ``gamma`` is ``max|z|/a`` of
        the response over its ``p`` periods (refined peak) — of the shot orbit, or of the
        brute-force window where no stable orbit was shot — ``multiplicity`` the period
        multiplicity (0: not periodic within 6T), ``max_floquet`` the shot orbit's largest
        multiplier modulus (NaN for a brute-force point), ``branches`` the continued
        branches with their located points. A failing frequency is NaN with its own error
        in ``errors`` (index and frequency); the sweep continues from the last good state.

    Raises
    ------
    ModelError
        Bad frequency grid, direction or ``control``.

    Notes
    -----
    Continuation is sequential within a direction: the point of sweeping up *and* down is
    that each frequency starts on the attractor the previous one ended on, so a coexisting
    branch is followed until it disappears (a fold, located) and the jump shows where it
    does.
    Splitting a direction into segments seeded from a coarse pass would be exact except
    where it matters — near folds the landing attractor depends on the seed — and on two
    CPUs it gains nothing over running the two directions side by side (coarse pass
    ``n/s`` plus ``n/2`` fine points per worker versus ``n``: a gain only with more than two
    workers). Only the directions run in parallel.

    References
    ----------
    D5.3 chapter 11; A. Pavlov, N. van de Wouw, H. Nijmeijer, "Frequency
    response functions for nonlinear convergent systems", IEEE TAC 52(6), 2007 (FRFs exist
    only for convergent systems; hence sweeps that follow attractors here).

    Examples
    --------
    The open loop of ch11 §4.1 is period-2 at ω = 2.9 in both directions:

    >>> from nscontrol.examples.ch11_convergent_pwa import one_sided_oscillator
    >>> res = frequency_sweep(one_sided_oscillator(0.1), [2.8, 2.9], n_transient=150,
    ...                       n_record=6, executor="serial", progress=False)
    >>> [int(res[d].multiplicity[1]) for d in ("up", "down")]
    [2, 2]
    """
    import os

    from .. import sweep
    from ..simulate.driver import check_run

    w = np.sort(_omega_grid(omegas))
    if isinstance(directions, str):
        raise ModelError(f"directions: expected a sequence of 'up' and/or 'down', got the "
                         f"string {directions!r}; write e.g. ({directions!r},)")
    for d in directions:
        if d not in ("up", "down"):
            raise ModelError(f"directions: expected 'up' and/or 'down', got {d!r}")
    _output_matrix(system, output)
    _check_control(control)
    # every frequency would fail alike on these (NaN points with an ok status): refuse now
    progress = check_bool("progress", progress, allow_none=True)
    n_transient = check_integer("n_transient", n_transient, minimum=0)
    n_record = check_integer("n_record", n_record, minimum=1)
    n_harmonics = check_integer("n_harmonics", n_harmonics, minimum=1)
    least = max(3, 2 * n_harmonics + 1)   # Nyquist: the K-th harmonic needs > 2K samples
    if check_integer("samples_per_period", samples_per_period, minimum=1) < least:
        raise ModelError(f"samples_per_period: expected an integer >= {least} (more than "
                         f"2·n_harmonics = {2 * n_harmonics} samples per period resolve "
                         f"harmonic {n_harmonics}), got {samples_per_period!r}; raise it or "
                         f"lower n_harmonics")
    options.setdefault("progress", False)  # one bar for the sweep, not one per simulation
    check_run(system, method, {**options, "u": None, "t_eval": None})
    if transient_time is not None:
        transient_time = check_positive("transient_time", transient_time)
    task = _SweepBranch(system, _amplitude_spec(amplitude), output,
                        n_transient, n_record, n_harmonics,
                        int(samples_per_period), method, dict(options), control,
                        transient_time)
    order = np.arange(w.size)
    grids = [(d, tuple((int(i), float(w[i])) for i in (order if d == "up" else order[::-1])))
             for d in directions]
    if isinstance(executor, str) and executor == "auto":
        executor = None if len(grids) > 1 and (os.cpu_count() or 1) > 1 else "serial"
    res = sweep.run(task, grids, executor=executor, progress=progress, desc="sweep")
    out = {}
    for (d, pts), result, err in zip(grids, res.values, res.errors, strict=True):
        resp: list[HarmonicResponse | None] = [None] * w.size
        errs: list[Any] = [None] * w.size
        values, curves = result if result is not None else ([None] * len(pts), [])
        for (i, wi), v in zip(pts, values, strict=True):
            if isinstance(v, HarmonicResponse):
                resp[i] = v
            elif v is not None:
                errs[i] = v
            elif err is not None:  # the whole branch task failed (lost worker, pickling...)
                errs[i] = sweep.PointError(i, err.type, f"ω = {wi:g}: the {d} sweep failed "
                                           f"as a whole: {err.message}", err.traceback)
        out[d] = FrequencyResponse.from_points(w, resp, direction=d, amplitude=amplitude,
                                               n_harmonics=n_harmonics, errors=errs,
                                               branches=curves)
    return out
