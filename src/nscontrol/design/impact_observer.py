"""Observers for bodies that are unobservable without impacts (chapter 2).

Two bodies on a line interact only through impacts; only ``y = q_1`` (body a) is measured, so
body b is invisible between impacts. This module designs

* the asymptotic high-gain observer of equation (7) for the (n-1, 1) case: flow
  ``xh_a' = A_a xh_a + B_a u + G_eps (y - C_a xh_a)``, ``xh_b' = A_b xh_b`` and, at each impact
  of the plant, the jumps (7c)-(7g) with the restitution matrix of coefficient ``e``
  (Remark 1) -- :func:`design_impact_observer`, returning an :class:`ImpactObserverDesign`
  that builds the closed loop "plant + observer + exosystem" as one
  :class:`~nscontrol.simulate.hybrid.LinearHybridSystem`;
* dead-beat observers built from the constructive proofs (**our choice**, the seed is
  truncated): :func:`deadbeat_n1` (finite-window reconstruction of body a, restarted at each
  impact, plus the impact formula for the free mass) and :func:`deadbeat_1n` (body b of n-1
  masses recovered from the data of n-1 impacts).

Gain placement (**our choice**, for the high gains of small ``eps``): ``(C_a, A_a)`` is put in
observer canonical form ``P^{-1} A_a P = A_c`` (coefficients in the first column,
``C_a P = e_1^T``), where the gain placing ``Lambda_eps = Lambda_1 / eps`` is read off the
characteristic polynomials, ``g_eps[k] = p_k / eps^k - a_k``. In the scaled coordinates
``xi = S_eps P^{-1} xh_a``, ``S_eps = diag(1, eps, ..., eps^{N-1})``, the observer's flow matrix
is exactly ``companion(Lambda_1) / eps``: the closed loop integrates the observer there, so the
matrix exponentials never see the ``O(eps^-N)`` gain. The design reports ``cond(P)``, the gain
norm and how far the spectrum computed in the original coordinates strays from
``Lambda_1 / eps`` (a measure of the ill-conditioning the scaled realisation avoids).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from .._validation import as_square, as_vector, check_positive
from ..analysis.observability import (
    EpsilonCertificate,
    Theorem1Result,
    alpha_limit,
    pbh_observability,
    search_epsilon,
    theorem1_test,
)
from ..errors import DimensionError, InfeasibleDesignError, ModelError

__all__ = [
    "ImpactPlant",
    "PlacementConditioning",
    "ImpactObserverDesign",
    "DeadbeatEstimate",
    "impact_plant",
    "place_scaled",
    "design_impact_observer",
    "observer_jump",
    "deadbeat_n1",
    "deadbeat_1n",
]

FloatArray = NDArray[np.float64]


# ----------------------------------------------------------------------------------------------
# The plant, as the design sees it
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ImpactPlant:
    """The matrices of an impacting-bodies plant that the observer designs need.

    Built by :func:`impact_plant` from an
    :class:`~nscontrol.systems.mechanical.ImpactingBodies`; not a model of its own.

    Attributes
    ----------
    A_a, B_a, C_a, A_b
        Flow, input and measurement matrices of body a (state ``[q_a; v_a]``), flow of body b.
    n_a, n_b
        Number of masses of each body.
    M
        Restitution matrix of the colliding pair (masses ``n_a`` and ``n_a + 1``).
    masses
        All masses, body a first.
    bodies
        The ``ImpactingBodies`` model it came from.
    """

    A_a: FloatArray
    B_a: FloatArray
    C_a: FloatArray
    A_b: FloatArray
    n_a: int
    n_b: int
    M: FloatArray
    masses: FloatArray
    bodies: Any

    @property
    def C_contact(self) -> FloatArray:
        """Row of ``x_a`` picking ``q_{n_a}``, the position of body a's contact mass."""
        row = np.zeros(2 * self.n_a)
        row[self.n_a - 1] = 1.0
        return row

    @property
    def equal_masses(self) -> bool:
        return bool(self.M[1, 1] == 0.0)


def impact_plant(bodies: Any) -> ImpactPlant:
    """Extract :class:`ImpactPlant` from an
    :class:`~nscontrol.systems.impacting_bodies.ImpactingBodies` model."""
    if isinstance(bodies, ImpactPlant):
        return bodies
    needed = ("A_a", "B_a", "C_a", "A_b", "H_a", "H_b", "restitution_matrix", "hybrid")
    missing = [k for k in needed if not hasattr(bodies, k)]
    if missing:
        raise ModelError(f"bodies: expected an ImpactingBodies model, got "
                         f"{type(bodies).__name__} (missing {', '.join(missing)})")
    masses = np.concatenate([np.diag(bodies.H_a), np.diag(bodies.H_b)])
    return ImpactPlant(np.asarray(bodies.A_a, float), np.ravel(bodies.B_a).astype(float),
                       np.ravel(bodies.C_a).astype(float), np.asarray(bodies.A_b, float),
                       int(bodies.n_a), int(bodies.n_b),
                       np.asarray(bodies.restitution_matrix, float), masses, bodies)


# ----------------------------------------------------------------------------------------------
# Gain placement in scaled observer-canonical coordinates
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlacementConditioning:
    """How well-conditioned the high-gain placement is.

    Attributes
    ----------
    cond_P
        2-norm condition number of the observer-canonical transformation ``P``.
    gain_norm
        ``||G_eps||`` in the original coordinates (grows like ``eps^-N``).
    spectrum_error_original
        Largest ``|lambda_i(A_a - G_eps C_a) - lambda_i/eps| / |lambda_i/eps|``, eigenvalues
        computed in the original coordinates (what an unscaled implementation would see).
    spectrum_error_scaled
        The same for the scaled flow matrix the closed loop integrates.
    """

    cond_P: float
    gain_norm: float
    spectrum_error_original: float
    spectrum_error_scaled: float


def _companion_first_column(coeffs: FloatArray) -> FloatArray:
    """``[[-c1, 1, 0..], [-c2, 0, 1..], .., [-cN, 0..0]]``: char. poly ``s^N + c1 s^{N-1}..``."""
    n = coeffs.size
    F = np.zeros((n, n))
    F[:, 0] = -coeffs
    F[np.arange(n - 1), np.arange(1, n)] = 1.0
    return F


def _spectrum_error(computed: np.ndarray, wanted: np.ndarray) -> float:
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(computed[:, None] - wanted[None, :]) / np.abs(wanted)[None, :]
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())


def _check_lambda(Lambda1: Any, size: int) -> np.ndarray:
    lam = np.atleast_1d(np.asarray(Lambda1, dtype=complex)).ravel()
    if lam.size != size:
        raise DimensionError(f"Lambda1: expected {size} eigenvalues (2 n_a, one per state of "
                             f"body a), got {lam.size}")
    if not np.all(np.isfinite(lam)):
        raise ModelError("Lambda1: expected finite eigenvalues, got NaN or inf")
    if np.any(lam.real >= 0.0):
        bad = lam[lam.real >= 0.0][0]
        raise ModelError(f"Lambda1: expected every eigenvalue with negative real part, got "
                         f"{bad:.6g}; the observer error would not decay")
    if not np.allclose(np.sort_complex(lam), np.sort_complex(lam.conj()), rtol=1e-12,
                       atol=0.0):
        raise ModelError("Lambda1: expected a set closed under complex conjugation (the gain "
                         f"is real), got {lam}")
    return lam


def _check_eps(eps: Any) -> float:
    try:
        v = float(eps)
    except (TypeError, ValueError):
        raise ModelError(f"eps: expected a real number in (0, 1], got {eps!r}") from None
    if not (np.isfinite(v) and 0.0 < v <= 1.0):
        raise ModelError(f"eps: expected a value in (0, 1] (smaller = faster, higher gain), got "
                         f"{eps!r}")
    return v


@dataclass(frozen=True, eq=False)
class ScaledPlacement:
    """Result of :func:`place_scaled`: the gain and the scaled realisation of the observer.

    Attributes
    ----------
    G
        Gain ``G_eps`` in the original coordinates.
    P
        Observer-canonical transformation, ``P^{-1} A_a P = A_c``, ``C_a P = e_1^T``.
    T, T_inv
        ``P S_eps^{-1}`` (``xh_a = T xi``) and its inverse ``S_eps P^{-1}``.
    F
        ``companion(Lambda_1)``: the scaled flow matrix is ``F / eps``.
    g_scaled
        ``S_eps P^{-1} G_eps`` (the gain as it enters ``xi'``), computed without cancellation.
    conditioning
        :class:`PlacementConditioning`.
    """

    G: FloatArray
    P: FloatArray
    T: FloatArray
    T_inv: FloatArray
    F: FloatArray
    g_scaled: FloatArray
    conditioning: PlacementConditioning


def place_scaled(A: Any, C: Any, Lambda1: Any, eps: float) -> ScaledPlacement:
    """Place ``sigma(A - G C) = Lambda1 / eps`` for a single output, in scaled coordinates.

    Parameters
    ----------
    A : (N, N) array_like
    C : (N,) or (1, N) array_like
    Lambda1 : (N,) array_like of complex
        Eigenvalues for ``eps = 1``: negative real parts, closed under conjugation.
    eps : float
        In ``(0, 1]``.

    Returns
    -------
    ScaledPlacement

    Raises
    ------
    InfeasibleDesignError
        ``(C, A)`` unobservable (``status="unobservable"``).
    ModelError, DimensionError
        Bad ``Lambda1`` or ``eps``.

    Notes
    -----
    Single output: the gain is unique (Ackermann). Computed in observer canonical form, with
    ``P = O^{-1} O_c`` (``O``, ``O_c`` the observability matrices), then scaled as in the
    chapter's equation (9); the reported conditioning says how far to trust ``G`` itself.
    """
    A = as_square("A_a", A)
    n = A.shape[0]
    C = as_vector("C_a", np.ravel(C), n)
    lam = _check_lambda(Lambda1, n)
    eps = _check_eps(eps)
    ok, margin, modes = pbh_observability(A, C.reshape(1, n))
    if not ok:
        raise InfeasibleDesignError(
            f"(C_a, A_a): unobservable (PBH margin {margin:.3g} at eigenvalue(s) "
            f"{', '.join(f'{m:.6g}' for m in modes)}); no gain places the observer spectrum -- "
            "measure another position or change the springs", status="unobservable")
    a = np.real(np.poly(A))[1:]
    p = np.real(np.poly(lam))[1:]
    A_c = _companion_first_column(a)
    O = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(n)])
    e1 = np.eye(n)[0]
    O_c = np.vstack([e1 @ np.linalg.matrix_power(A_c, k) for k in range(n)])
    P = np.linalg.solve(O, O_c)
    powers = eps ** np.arange(n)                      # diag of S_eps
    g_eps = p / (eps * powers) - a                    # p_k / eps^k - a_k, k = 1..N
    G = P @ g_eps
    T = P / powers[None, :]
    T_inv = np.linalg.inv(P) * powers[:, None]
    F = _companion_first_column(p)
    g_scaled = p / eps - powers * a                   # S_eps g_eps, no cancellation
    want = lam / eps
    err_orig = _spectrum_error(np.linalg.eigvals(A - np.outer(G, C)), want)
    err_scaled = _spectrum_error(np.linalg.eigvals(F / eps), want)
    cond = PlacementConditioning(float(np.linalg.cond(P)), float(np.linalg.norm(G)),
                                 err_orig, err_scaled)
    return ScaledPlacement(G, P, T, T_inv, F, g_scaled, cond)


# ----------------------------------------------------------------------------------------------
# Observer jumps (7c)-(7g)
# ----------------------------------------------------------------------------------------------
def observer_jump(xh_a: Any, xh_b: Any, y: float, M: Any) -> tuple[FloatArray, FloatArray]:
    """Jumps (7c)-(7g) of the observer at an impact of the plant ((n-1, 1) case).

    ``q_1 <- y``; ``q_n <- q_{n-1}``; ``[v_{n-1}, v_n] <- M [v_{n-1}, v_n]``; every other
    estimate unchanged. ``M`` is the restitution matrix (any ``e``, Remark 1).

    Returns
    -------
    xh_a_plus, xh_b_plus : ndarray
    """
    xa = np.array(xh_a, dtype=float)
    xb = np.array(xh_b, dtype=float)
    na = xa.size // 2
    v_pair = np.asarray(M) @ np.array([xa[2 * na - 1], xb[1]])
    q_contact = xa[na - 1]
    xa[0] = y                                   # (7e) uses y(t_i)
    xa[2 * na - 1] = v_pair[0]                  # (7g)
    xb[0] = q_contact                           # (7f) uses q_{n-1} before the reset
    xb[1] = v_pair[1]
    return xa, xb


# ----------------------------------------------------------------------------------------------
# The design object
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ImpactObserverDesign:
    """The asymptotic observer (7) of chapter 2: gains, certificate and closed-loop builder.

    Attributes
    ----------
    plant
        :class:`ImpactPlant` the observer was designed for.
    Lambda1
        Eigenvalues for ``eps = 1``.
    eps
        The high-gain parameter in ``(0, 1]``.
    G_eps
        Observer gain (original coordinates).
    placement
        :class:`ScaledPlacement` (scaled realisation and conditioning).
    observability
        :class:`~nscontrol.analysis.observability.Theorem1Result` of the plant.
    alpha_L
        Rate limit ``-ln|M22| / delta_max`` (``inf`` for equal masses or unknown ``delta_max``).
    certificate
        :class:`~nscontrol.analysis.observability.EpsilonCertificate` when a target rate was
        given, else ``None``.
    """

    plant: ImpactPlant
    Lambda1: np.ndarray
    eps: float
    G_eps: FloatArray
    placement: ScaledPlacement
    observability: Theorem1Result
    alpha_L: float
    certificate: EpsilonCertificate | None = None

    @property
    def conditioning(self) -> PlacementConditioning:
        return self.placement.conditioning

    @property
    def n_observer(self) -> int:
        return 2 * (self.plant.n_a + self.plant.n_b)

    def closed_loop(self, u: Any = None, *,
                    realisation: Literal["scaled", "original"] = "scaled",
                    impacts: bool = True) -> Any:
        """Plant + observer + exosystem as ONE :class:`LinearHybridSystem`.

        Parameters
        ----------
        u : Exosystem, optional
            The input generator (``None``: no input).
        realisation : {"scaled", "original"}
            Observer state ``[xi; xh_b]`` with ``xh_a = T xi`` (well-scaled, default), or
            ``[xh_a; xh_b]`` with the raw gain (for comparison).
        impacts : bool
            ``False`` switches the contact off (body b moves on a parallel track, never hit):
            the demonstration that without impacts body b's state is not recovered.

        Returns
        -------
        LinearHybridSystem
            State ``[x_a; x_b; w; observer]``; guards and impacts are the plant's; at an impact
            the plant's restitution and the observer's jumps (7c)-(7g) apply together. Outputs
            ``"y"``, ``"xhat"`` and ``"error"`` (``x - xhat``) are recorded, plus the plant's.
        """
        from ..simulate.hybrid import LinearHybridSystem

        plant_sys = self.plant.bodies.hybrid(u)
        F_obs, g_obs, T, T_inv = self._observer_flow(realisation)
        pl = self.plant
        na2, nb2, n_p = 2 * pl.n_a, 2 * pl.n_b, plant_sys.n_states
        n = n_p + na2 + nb2
        o = n_p                                   # first observer state
        Cu = np.zeros((1, n_p - na2 - nb2)) if u is None else np.atleast_2d(u.Cu)
        A = np.zeros((n, n))
        A[:n_p, :n_p] = plant_sys.A
        A[o:o + na2, o:o + na2] = F_obs
        A[o:o + na2, :na2] = np.outer(g_obs, pl.C_a)              # G_eps y
        A[o:o + na2, na2 + nb2:n_p] = np.outer(T_inv @ pl.B_a, Cu)  # B_a u, u = Cu w
        A[o + na2:, o + na2:] = pl.A_b
        G = np.hstack([plant_sys.G, np.zeros((plant_sys.G.shape[0], na2 + nb2))])
        g0 = plant_sys.g0
        if not impacts:   # a guard that never reaches zero: body b out of reach
            G, g0 = np.zeros_like(G), np.ones_like(g0)

        def jump(x: FloatArray) -> FloatArray:
            out = np.empty_like(x)
            out[:n_p] = plant_sys.apply_jump(0.0, x[:n_p], np.array([0]))
            xa_plus, xb_plus = observer_jump(T @ x[o:o + na2], x[o + na2:],
                                             float(pl.C_a @ x[:na2]), pl.M)
            out[o:o + na2] = T_inv @ xa_plus
            out[o + na2:] = xb_plus
            return out

        # restitution and the jumps (7c)-(7g) are linear in the stacked state: their matrix
        J = np.column_stack([jump(e) for e in np.eye(n)])
        return LinearHybridSystem(A, G, g0, J,
                                  state_names=self._state_names(plant_sys, realisation),
                                  outputs=self._outputs(plant_sys, T))

    def _observer_flow(self, realisation: str
                       ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Flow matrix, output-injection gain and ``xh_a = T (observer state)``."""
        sp, pl = self.placement, self.plant
        if realisation == "scaled":
            return sp.F / self.eps, sp.g_scaled, sp.T, sp.T_inv
        if realisation == "original":
            eye = np.eye(2 * pl.n_a)
            return pl.A_a - np.outer(self.G_eps, pl.C_a), self.G_eps, eye, eye
        raise ModelError(f"realisation: expected 'scaled' or 'original', got {realisation!r}")

    def _outputs(self, plant_sys: Any, T: FloatArray) -> dict[str, FloatArray]:
        na2, nb2, n_p = 2 * self.plant.n_a, 2 * self.plant.n_b, plant_sys.n_states
        n = n_p + na2 + nb2
        to_xhat = np.zeros((na2 + nb2, n))
        to_xhat[:na2, n_p:n_p + na2] = T
        to_xhat[na2:, n_p + na2:] = np.eye(nb2)
        to_x = np.zeros((na2 + nb2, n))
        to_x[:, :na2 + nb2] = np.eye(na2 + nb2)
        outputs = {k: np.hstack([v, np.zeros((v.shape[0], na2 + nb2))])
                   for k, v in plant_sys.outputs.items()}
        outputs.update({"xhat": to_xhat, "error": to_x - to_xhat})
        return outputs

    def _state_names(self, plant_sys: Any, realisation: str) -> tuple[str, ...]:
        na2, nb2 = 2 * self.plant.n_a, 2 * self.plant.n_b
        names = tuple(plant_sys.state_names)
        if not names:
            return ()
        obs_a = (tuple(f"xi{i + 1}" for i in range(na2)) if realisation == "scaled"
                 else tuple(f"hat_{s}" for s in names[:na2]))
        return names + obs_a + tuple(f"hat_{s}" for s in names[na2:na2 + nb2])

    def initial_state(self, x_plant0: Any, xhat0: Any, *,
                      realisation: Literal["scaled", "original"] = "scaled") -> FloatArray:
        """Stack ``[x_plant0; observer state]`` for :meth:`closed_loop`.

        ``x_plant0`` is the plant's state ``[x_a; x_b; w]``, ``xhat0`` the estimate
        ``[xh_a; xh_b]``; ``realisation`` must match the one given to :meth:`closed_loop`.

        Raises
        ------
        InadmissibleStateError
            ``x_plant0`` penetrates, or touches with approaching velocities.
        """
        na2, nb2 = 2 * self.plant.n_a, 2 * self.plant.n_b
        xp = as_vector("x_plant0", x_plant0)
        if xp.size < na2 + nb2:
            raise DimensionError(f"x_plant0: expected at least {na2 + nb2} entries "
                                 f"([x_a; x_b; w]), got {xp.size}")
        xh = as_vector("xhat0", xhat0, na2 + nb2)
        self.plant.bodies.check_state(xp[:na2 + nb2])
        xa = self._observer_flow(realisation)[3] @ xh[:na2]
        return np.concatenate([xp, xa, xh[na2:]])


def design_impact_observer(bodies: Any, Lambda1: Any, eps: float | None = None, *,
                           alpha: float | None = None, delta_min: float | None = None,
                           delta_max: float | None = None,
                           eps_min: float = 1e-4) -> ImpactObserverDesign:
    """Design the asymptotic observer (7) for an (n-1, 1) impacting-bodies plant.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant; body b must be one mass.
    Lambda1 : array_like of complex, length ``2 (n - 1)``
        Observer eigenvalues for ``eps = 1`` (negative real parts, closed under conjugation).
    eps : float, optional
        High-gain parameter in ``(0, 1]``. Give either ``eps`` or ``alpha``.
    alpha : float, optional
        Target decay rate: ``eps`` is then the largest value meeting the sufficient conditions
        of Theorem 3 (equal masses) or 4 (unequal), see
        :func:`~nscontrol.analysis.observability.search_epsilon`. Needs ``delta_min`` and
        ``delta_max``.
    delta_min, delta_max : float, optional
        Dwell-time bounds of Assumption 2 (``alpha_L`` is reported when ``delta_max`` is given).
    eps_min : float
        Smallest ``eps`` the search tries.

    Returns
    -------
    ImpactObserverDesign

    Raises
    ------
    InfeasibleDesignError
        ``(C_a, A_a)`` unobservable; ``alpha >= alpha_L`` with unequal masses; no certified
        ``eps``.
    ModelError, DimensionError
        ``eps`` outside ``(0, 1]``; ``Lambda1`` of the wrong size, not in the open left
        half-plane or not conjugate-closed; body b with more than one mass; neither or both of
        ``eps`` and ``alpha``.

    Notes
    -----
    Hypotheses: ``(C_a, A_a)`` observable (checked, PBH); Assumption 2 on dwell times (not
    checkable before simulating; the certificate holds only for records with dwell times in
    ``(delta_min, delta_max)``); Theorem 4 also needs ``k_nn >= 0`` (checked when ``alpha`` is
    given). Impacts are detected in real time (Remark 3): the closed loop resets the observer
    at the plant's exact impact times. Theorem 1's condition (1), ``W(s)`` not zero, is
    reported in ``observability`` but not required (the observer works whenever impacts occur).

    References
    ----------
    Chapter 2 of SICONOS D5.3, equation (7), Theorems 3-4, Remark 1; Martinelli, Menini,
    Tornambe, ASME J. Dyn. Sys. Meas. Control 125(4), 2003.
    """
    plant = impact_plant(bodies)
    if plant.n_b != 1:
        raise ModelError(f"bodies: the asymptotic observer (7) is for the (n-1, 1) case, body b "
                         f"must be one mass, got n_b = {plant.n_b}; use deadbeat_1n for (1, n-1)")
    if (eps is None) == (alpha is None):
        raise ModelError("eps, alpha: give exactly one -- eps directly, or a target rate alpha "
                         "(with delta_min, delta_max) for the certified eps")
    lam = _check_lambda(Lambda1, 2 * plant.n_a)
    thm1 = theorem1_test(plant.A_a, plant.B_a, plant.C_a, plant.C_contact)
    alpha_L = np.inf if delta_max is None else alpha_limit(plant.M[1, 1], delta_max)
    cert = None
    if alpha is not None:
        if delta_min is None or delta_max is None:
            raise ModelError("delta_min, delta_max: a target rate alpha needs the dwell-time "
                             "bounds of Assumption 2")
        sp1 = place_scaled(plant.A_a, plant.C_a, lam, 1.0)   # raises if unobservable
        cert = search_epsilon(sp1.F, sp1.P, plant.A_b, plant.M, delta_min, delta_max, alpha,
                              eps_min=eps_min)
        eps = cert.eps
    eps = _check_eps(eps)
    sp = place_scaled(plant.A_a, plant.C_a, lam, eps)
    return ImpactObserverDesign(plant, lam, eps, sp.G, sp, thm1, alpha_L, cert)


# ----------------------------------------------------------------------------------------------
# Dead-beat observers (section 4; construction is our choice)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DeadbeatEstimate:
    """Estimates of a dead-beat observer at the query times.

    Attributes
    ----------
    t
        Query times.
    x_hat
        ``(len(t), 2 n)`` estimates ``[x_a; x_b]``; NaN rows where not yet available.
    valid
        Which rows hold an estimate.
    impacts_used
        Impact times the estimate of body b rests on.
    rank
        Numerical rank of the impact equations (``2 n_b`` when full).
    condition
        Condition number of the least-squares problem for body b.
    """

    t: FloatArray
    x_hat: FloatArray
    valid: np.ndarray
    impacts_used: FloatArray
    rank: int
    condition: float


class _WindowReconstructor:
    """``x_a(t_ref)`` from samples of ``y`` on an impact-free window (exact least squares).

    With the input generated by an exosystem, ``[x_a; w]`` is autonomous and ``w(t_ref)`` is
    known, so each sample ``y(s) = c e^{A (s - t_ref)} [x_a; w]`` is one linear equation on
    ``x_a(t_ref)``. The rows ``c e^{A tau}`` come from one decomposition of ``A^T``.
    """

    def __init__(self, plant: ImpactPlant, u: Any, rtol: float = 1e-10) -> None:
        from ..numerics.lti import LTIFlow

        na2 = plant.A_a.shape[0]
        if u is None:
            A_aug = plant.A_a
        else:
            S = np.asarray(u.S, float)
            nw = S.shape[0]
            A_aug = np.zeros((na2 + nw, na2 + nw))
            A_aug[:na2, :na2] = plant.A_a
            A_aug[:na2, na2:] = np.outer(plant.B_a, np.ravel(u.Cu))
            A_aug[na2:, na2:] = S
        self.na2, self.u, self.rtol = na2, u, rtol
        self.flow_T = LTIFlow(A_aug.T)
        self.c = np.concatenate([plant.C_a, np.zeros(A_aug.shape[0] - na2)])

    def state(self, ts: FloatArray, ys: FloatArray, t_ref: float) -> FloatArray:
        na2 = self.na2
        if ts.size < na2:
            raise InfeasibleDesignError(
                f"samples: a window holds {ts.size} samples of y, at least {na2} (= 2 n_a) are "
                "needed; sample y faster or lengthen the window", status="rank_deficient")
        rows = np.atleast_2d(self.flow_T.propagate(self.c, ts - t_ref))
        w_ref = np.zeros(0) if self.u is None else np.asarray(self.u.w(t_ref), float)
        rhs = ys - rows[:, na2:] @ w_ref
        sol, _, rank, sv = np.linalg.lstsq(rows[:, :na2], rhs, rcond=None)
        if rank < na2 or sv[-1] <= self.rtol * sv[0]:
            raise InfeasibleDesignError(
                f"window: the samples determine only {rank} of {na2} states of body a "
                f"(singular values {sv[0]:.3g} .. {sv[-1]:.3g}); lengthen the window",
                status="rank_deficient")
        return sol

    def before(self, ts: FloatArray, ys: FloatArray, t: float, window: float) -> FloatArray:
        """``x_a(t)`` from the samples in ``(t - window, t]``."""
        keep = (ts > t - window) & (ts <= t)
        return self.state(ts[keep], ys[keep], t)

    def after(self, ts: FloatArray, ys: FloatArray, t: float, window: float) -> FloatArray:
        """``x_a(t+)`` from the samples in ``(t, t + window)``."""
        keep = (ts > t) & (ts < t + window)
        return self.state(ts[keep], ys[keep], t)


def _check_samples(t_samples: Any, y_samples: Any) -> tuple[FloatArray, FloatArray]:
    ts = as_vector("t_samples", t_samples)
    ys = as_vector("y_samples", y_samples, ts.size)
    step = np.diff(ts)
    if np.any(step < 0.0):
        raise ModelError("t_samples: expected non-decreasing sample times")
    keep = np.concatenate([[True], step > 0.0])   # y is continuous: duplicates carry nothing
    return ts[keep], ys[keep]


def _impact_pair(rec: _WindowReconstructor, ts: FloatArray, ys: FloatArray, t_i: float,
                 window: float) -> tuple[FloatArray, FloatArray]:
    """``x_a(t_i-)`` and ``x_a(t_i+)`` from the windows just before and just after ``t_i``
    (both open at ``t_i``)."""
    keep = (ts > t_i - window) & (ts < t_i)
    return rec.state(ts[keep], ys[keep], t_i), rec.after(ts, ys, t_i, window)


def deadbeat_n1(bodies: Any, t_samples: Any, y_samples: Any, impact_times: Any,
                t_query: Any, *, window: float, u: Any = None) -> DeadbeatEstimate:
    """Dead-beat observer for the (n-1, 1) case: exact state after one impact plus a window.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant (body b one mass).
    t_samples, y_samples : array_like
        Samples of ``y = q_1`` (noise-free), non-decreasing times (repeated event times are
        dropped).
    impact_times : array_like
        Detected impact times (Remark 3: impacts are detected in real time).
    t_query : array_like
        Times at which to estimate the state.
    window : float
        Length ``d`` of the reconstruction windows (Assumption: ``d < delta_min``).
    u : Exosystem, optional
        Generator of the known input.

    Returns
    -------
    DeadbeatEstimate
        Valid at ``t`` when an impact ``t_i <= t - d`` has an impact-free window of length
        ``d`` before it and no impact lies in ``(t_i, t]``.

    Notes
    -----
    From the proof of Theorem 2 (**our choice** of implementation): ``x_a`` is reconstructed by
    least squares on the samples of the last impact-free window of length ``d`` (exact for
    noise-free data); at the last impact ``t_i``, ``x_a(t_i-)`` and ``x_a(t_i+)`` come from the
    windows on either side, ``q_n(t_i) = q_{n-1}(t_i)`` and
    ``v_n(t_i-) = (v_{n-1}(t_i+) - M11 v_{n-1}(t_i-)) / M12``,
    ``v_n(t_i+) = M21 v_{n-1}(t_i-) + M22 v_n(t_i-)``; the free mass is then propagated with
    ``A_b``. The reconstruction restarts at every impact.

    References
    ----------
    Chapter 2 of SICONOS D5.3, Theorem 2 and section on dead-beat observers.
    """
    from ..numerics.lti import LTIFlow

    plant = impact_plant(bodies)
    if plant.n_b != 1:
        raise ModelError(f"bodies: deadbeat_n1 is for the (n-1, 1) case, got n_b = {plant.n_b}")
    window = check_positive("window", window)
    ts, ys = _check_samples(t_samples, y_samples)
    impacts = np.sort(as_vector("impact_times", np.atleast_1d(impact_times)))
    tq = np.atleast_1d(as_vector("t_query", t_query))
    na, M = plant.n_a, plant.M
    rec = _WindowReconstructor(plant, u)
    flow_b = LTIFlow(plant.A_b)
    out = np.full((tq.size, 2 * na + 2), np.nan)
    cache: dict[int, FloatArray] = {}
    used: set[float] = set()
    for k, t in enumerate(tq):
        i = int(np.searchsorted(impacts, t, side="right")) - 1
        if i < 0 or t - impacts[i] < window:
            continue
        t_i = impacts[i]
        if (i > 0 and t_i - impacts[i - 1] < window) or t_i - ts[0] < window:
            continue
        if i not in cache:
            pre, post = _impact_pair(rec, ts, ys, t_i, window)
            v_minus = (post[2 * na - 1] - M[0, 0] * pre[2 * na - 1]) / M[0, 1]
            v_plus = M[1, 0] * pre[2 * na - 1] + M[1, 1] * v_minus
            cache[i] = np.array([pre[na - 1], v_plus])
        used.add(float(t_i))
        out[k, :2 * na] = rec.before(ts, ys, t, window)
        out[k, 2 * na:] = flow_b.propagate(cache[i], t - t_i)
    valid = ~np.isnan(out[:, 0])
    return DeadbeatEstimate(tq, out, valid, np.array(sorted(used)), 2, 1.0)


def _consecutive_usable(impacts: FloatArray, ts: FloatArray, window: float) -> list[float]:
    """Impacts from the first isolated one on, stopping before the first that is not isolated
    (closer than ``window`` to a neighbour or to the ends of the data): a skipped impact would
    break the chain of exact propagations between impacts."""
    out: list[float] = []
    for k, t in enumerate(impacts):
        ok = (t - ts[0] >= window and t + window <= ts[-1]
              and (k == 0 or t - impacts[k - 1] >= window)
              and (k + 1 == impacts.size or impacts[k + 1] - t >= window))
        if ok:
            out.append(float(t))
        elif out:
            break
    return out


def deadbeat_1n(bodies: Any, t_samples: Any, y_samples: Any, impact_times: Any,
                t_query: Any, *, window: float, u: Any = None,
                rtol: float = 1e-10) -> DeadbeatEstimate:
    """Dead-beat observer for the (1, n-1) case: body b recovered after n-1 impacts.

    Parameters
    ----------
    bodies : ImpactingBodies or ImpactPlant
        The plant: body a is one measured mass, body b has ``n - 1`` masses.
    t_samples, y_samples : array_like
        Samples of ``y = q_1``.
    impact_times : array_like
        Detected impact times.
    t_query : array_like
        Times at which to estimate.
    window : float
        Length of the windows on either side of each impact used to get ``v_1(t_i-)``,
        ``v_1(t_i+)`` (and of the window reconstructing ``x_a`` at the query times).
    u : Exosystem, optional
        Generator of the known input.
    rtol : float
        Singular values below ``rtol * sigma_max`` count as zero (rank deficiency).

    Returns
    -------
    DeadbeatEstimate

    Raises
    ------
    InfeasibleDesignError
        Fewer than ``n - 1`` usable impacts before the last query time, or impact equations of
        deficient rank (degenerate impacts), ``status="rank_deficient"``.

    Notes
    -----
    Each impact ``t_i`` gives two linear equations on ``x_b``: ``q_2(t_i) = q_1(t_i)`` and
    ``v_2(t_i-) = (v_1(t_i+) - M11 v_1(t_i-)) / M12``; the jump ``x_b(t_i+) = x_b(t_i-) +
    e_v2 (v_2(t_i+) - v_2(t_i-))`` is then known, and ``x_b(t_{i+1}-) = e^{A_b delta}
    x_b(t_i+)`` chains the impacts into one linear system in ``x_b(t_1-)``, solved by least
    squares once ``n - 1`` impacts (``2(n-1)`` equations) are available. Construction is
    **our choice** (the seed's text is truncated).

    References
    ----------
    Chapter 2 of SICONOS D5.3, section 4 (the (1, n-1) case).
    """
    from ..numerics.lti import LTIFlow

    plant = impact_plant(bodies)
    if plant.n_a != 1:
        raise ModelError(f"bodies: deadbeat_1n is for the (1, n-1) case, body a must be one "
                         f"mass, got n_a = {plant.n_a}")
    window = check_positive("window", window)
    ts, ys = _check_samples(t_samples, y_samples)
    impacts = np.sort(as_vector("impact_times", np.atleast_1d(impact_times)))
    tq = np.atleast_1d(as_vector("t_query", t_query))
    nb2, M = 2 * plant.n_b, plant.M
    rec = _WindowReconstructor(plant, u)
    flow_b = LTIFlow(plant.A_b)
    need = plant.n_b
    usable = _consecutive_usable(impacts, ts, window)
    if len(usable) < need:
        raise InfeasibleDesignError(
            f"impact_times: {len(usable)} usable consecutive impact(s) (isolated by at least "
            f"the window {window:g}, inside the data), {need} (= n - 1) needed to determine the "
            f"{nb2} states of body b; record longer or make the bodies collide more often",
            status="rank_deficient")
    e_q2, e_v2 = np.eye(nb2)[0], np.eye(nb2)[plant.n_b]
    jumps = []                           # measured v_2(t_i-), v_2(t_i+) at each usable impact
    for t_i in usable:
        pre, post = _impact_pair(rec, ts, ys, t_i, window)
        v2_minus = (post[1] - M[0, 0] * pre[1]) / M[0, 1]
        jumps.append((pre[0], v2_minus, M[1, 0] * pre[1] + M[1, 1] * v2_minus))
    rows, rhs = [], []
    Phi, offset = np.eye(nb2), np.zeros(nb2)   # x_b(t_i-) = Phi x_b(t_1-) + offset
    for k in range(need):
        if k > 0:
            step = flow_b.expm(usable[k] - usable[k - 1])
            Phi, offset = step @ Phi, step @ offset
        q1, v2_minus, v2_plus = jumps[k]
        rows += [e_q2 @ Phi, e_v2 @ Phi]
        rhs += [q1 - e_q2 @ offset, v2_minus - e_v2 @ offset]
        offset = offset + e_v2 * (v2_plus - v2_minus)
    Amat = np.array(rows)
    sv = np.linalg.svd(Amat, compute_uv=False)
    rank = int(np.sum(sv > rtol * sv[0]))
    if rank < nb2:
        raise InfeasibleDesignError(
            f"impact_times: the equations of {need} impacts determine only {rank} of the {nb2} "
            f"states of body b (singular values {sv[0]:.3g} .. {sv[-1]:.3g}): degenerate "
            "impacts; use a longer record with more impacts", status="rank_deficient")
    xb = Phi @ np.linalg.solve(Amat, np.array(rhs)) + offset
    post_states = {need - 1: xb}          # x_b(t_i+) from the (n-1)-th impact on
    for k in range(need, len(usable)):
        xb = flow_b.propagate(xb, usable[k] - usable[k - 1])
        xb = xb + e_v2 * (jumps[k][2] - xb[plant.n_b])  # measured post-impact velocity
        post_states[k] = xb
    out = np.full((tq.size, 2 + nb2), np.nan)
    for k, t in enumerate(tq):
        i = int(np.searchsorted(impacts, t, side="right")) - 1
        if i < 0 or t - impacts[i] < window or impacts[i] not in usable:
            continue
        j = usable.index(impacts[i])
        if j not in post_states:
            continue
        out[k, :2] = rec.before(ts, ys, t, window)
        out[k, 2:] = flow_b.propagate(post_states[j], t - usable[j])
    valid = ~np.isnan(out[:, 0])
    return DeadbeatEstimate(tq, out, valid, np.array(usable[:need]), rank,
                            float(sv[0] / sv[-1]))
