"""Beams with a one-sided support under a rotating-unbalance excitation (chapter 6).

* :class:`OneSidedSpring` — a spring that acts only when a displacement ``hᵀq`` falls below
  a gap: force ``-h·k·min(hᵀq - gap, 0)``;
* :class:`MechanicalPWL` — a validated linear mechanical model
  ``M q'' + C_d q' + K q = h_F F(t) + h_u u - h_s k_s min(h_sᵀq - δ, 0)`` and its state form,
  a continuous bimodal piecewise-affine system (:meth:`MechanicalPWL.to_pwa`);
* :func:`two_mode_beam` — the two-mode surrogate of the chapter-6 beam (support, excitation,
  actuator and sensor at the midpoint);
* :func:`beam_fe_model` — a finite-element beam on leaf springs, reduced to a few modes plus
  the static residual flexibility at the midpoint;
* :class:`Unbalance` — the amplitude ``m_e r_e ω²`` of a rotating unbalance, a picklable
  ``ω -> a(ω)`` for the frequency sweeps of :mod:`nscontrol.analysis.periodic`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import (
    as_finite_scalar,
    as_matrix,
    as_square,
    as_vector,
    check_bool,
    check_positive,
    check_positive_definite,
    check_symmetric,
)
from ..errors import DimensionError, ModelError

if TYPE_CHECKING:
    from .protocols import InputSignal
    from .pwa import PiecewiseAffineSystem

__all__ = ["OneSidedSpring", "MechanicalPWL", "Unbalance", "two_mode_beam", "beam_fe_model"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class OneSidedSpring:
    """A one-sided spring: force ``-h·k·min(hᵀq - gap, 0)`` on the generalized coordinates.

    Attributes
    ----------
    h
        Direction ``h`` (the support displacement is ``y_s = hᵀq``), nonzero.
    k
        Stiffness ``k_s > 0`` while engaged (``y_s < gap``).
    gap
        ``δ``: the spring engages below ``y_s = δ`` (``0``: touching at rest, no preload).
    """

    h: FloatArray
    k: float
    gap: float = 0.0

    if TYPE_CHECKING:
        def __init__(self, h: ArrayLike, k: float, gap: float = 0.0) -> None: ...

    def __post_init__(self) -> None:
        h = as_vector("h", self.h)
        if not np.any(h):
            raise ModelError("h: expected a nonzero direction of the support, got zeros")
        object.__setattr__(self, "h", h)
        object.__setattr__(self, "k", check_positive("k", self.k))
        object.__setattr__(self, "gap", as_finite_scalar("gap", self.gap))


@dataclass(frozen=True, eq=False)
class MechanicalPWL:
    """``M q'' + C_d q' + K q = h_F F(t) + h_u u - h_s k_s min(h_sᵀq - δ, 0)``, validated.

    State ``x = (q, q')``; measured output ``y_m = C_m x``; performance output the support
    displacement ``y_s = h_sᵀq``. Written about the static equilibrium (gravity removed).

    Attributes
    ----------
    M
        Mass matrix, symmetric positive definite.
    Cd
        Damping matrix, symmetric positive semidefinite.
    K
        Stiffness matrix, symmetric positive definite.
    support
        The one-sided support.
    h_F
        Where the excitation force ``F(t)`` acts.
    h_u
        Where the actuator force ``u`` acts.
    C_m
        Measured output matrix on the state, shape ``(q, 2N)``.

    Raises
    ------
    DimensionError
        Shapes that do not agree with ``M``.
    ModelError
        ``M`` or ``K`` not symmetric positive definite, ``C_d`` not symmetric positive
        semidefinite, non-finite entries.

    Examples
    --------
    >>> beam = two_mode_beam()
    >>> free, contact = beam.frequencies(contact=False), beam.frequencies(contact=True)
    >>> np.round(free[0], 2), np.round(contact[0], 2)
    (array([ 20., 100.]), array([ 44.18, 110.88]))
    """

    M: FloatArray
    Cd: FloatArray
    K: FloatArray
    support: OneSidedSpring
    h_F: FloatArray
    h_u: FloatArray
    C_m: FloatArray

    if TYPE_CHECKING:
        def __init__(self, M: ArrayLike, Cd: ArrayLike, K: ArrayLike, support: OneSidedSpring,
                     h_F: ArrayLike, h_u: ArrayLike, C_m: ArrayLike) -> None: ...

    def __post_init__(self) -> None:
        M = as_square("M", self.M)
        N = M.shape[0]
        Cd = as_square("Cd", self.Cd, N)
        K = as_square("K", self.K, N)
        check_positive_definite("M", M)
        check_positive_definite("K", K)
        check_symmetric("Cd", Cd)
        lam = float(np.linalg.eigvalsh(0.5 * (Cd + Cd.T))[0])
        if lam < -1e-12 * max(float(np.max(np.abs(Cd))), 1e-300):
            raise ModelError(f"Cd: expected a positive semidefinite damping matrix, got "
                             f"smallest eigenvalue {lam:.3g}")
        if not isinstance(self.support, OneSidedSpring):
            raise ModelError(f"support: expected a OneSidedSpring, got "
                             f"{type(self.support).__name__}")
        if self.support.h.shape[0] != N:
            raise DimensionError(f"support.h: expected length {N} (one entry per coordinate), "
                                 f"got {self.support.h.shape[0]}")
        fields = {"M": M, "Cd": Cd, "K": K, "h_F": as_vector("h_F", self.h_F, N),
                  "h_u": as_vector("h_u", self.h_u, N),
                  "C_m": as_matrix("C_m", np.reshape(self.C_m, (1, -1))
                                   if np.ndim(self.C_m) == 1 else self.C_m, cols=2 * N)}
        for key, value in fields.items():
            object.__setattr__(self, key, value)

    # -- sizes and state-space blocks --------------------------------------------------------
    @property
    def n_dof(self) -> int:
        """Number ``N`` of generalized coordinates."""
        return int(self.M.shape[0])

    @property
    def n_states(self) -> int:
        """``2N``."""
        return 2 * self.n_dof

    def _lift(self, f: FloatArray) -> FloatArray:
        """A force direction as a state-space column ``[0; M⁻¹f]``."""
        return np.concatenate([np.zeros(self.n_dof), np.linalg.solve(self.M, f)])

    @property
    def H(self) -> FloatArray:
        """``H = [h_sᵀ, 0]``: the support displacement ``y_s = Hx``."""
        return np.concatenate([self.support.h, np.zeros(self.n_dof)])

    @property
    def B(self) -> FloatArray:
        """Actuator input matrix ``[0; M⁻¹h_u]``, shape ``(2N, 1)``."""
        return self._lift(self.h_u)[:, None]

    @property
    def D(self) -> FloatArray:
        """Excitation input matrix ``[0; M⁻¹h_F]``, shape ``(2N, 1)``."""
        return self._lift(self.h_F)[:, None]

    @property
    def support_static_stiffness(self) -> float:
        """``(h_sᵀK⁻¹h_s)⁻¹``: the static stiffness the support sees (``k_mid``)."""
        h = self.support.h
        return float(1.0 / (h @ np.linalg.solve(self.K, h)))

    def state_matrix(self, contact: bool) -> FloatArray:
        """``A_1`` (free, ``contact=False``) or ``A_2 = A_1 - k_s g H`` (support engaged).

        Parameters
        ----------
        contact : bool
            Whether the support is engaged.
        """
        N = self.n_dof
        Minv = np.linalg.inv(self.M)
        A = np.block([[np.zeros((N, N)), np.eye(N)], [-Minv @ self.K, -Minv @ self.Cd]])
        if check_bool("contact", contact):
            A = A - self.support.k * np.outer(self._lift(self.support.h), self.H)
        return A

    def frequencies(self, contact: bool) -> tuple[FloatArray, FloatArray]:
        """Natural frequencies ``|λ|/2π`` (Hz, increasing) and damping ratios
        ``-Re λ/|λ|`` of the linear mode ``contact`` (its damped frequencies are ``Im λ/2π``).

        Parameters
        ----------
        contact : bool
            Whether the support is engaged.
        """
        lam = np.linalg.eigvals(self.state_matrix(contact))
        lam = lam[lam.imag > 0]
        if lam.size != self.n_dof:
            raise ModelError(f"contact={contact}: {self.n_dof - lam.size} mode(s) are "
                             f"overdamped; their natural frequency is not defined")
        wn = np.abs(lam)
        order = np.argsort(wn)
        return wn[order] / (2 * np.pi), -lam.real[order] / wn[order]

    def to_pwa(self, *, u: InputSignal = None) -> PiecewiseAffineSystem:
        """The state form as a continuous bimodal :class:`~nscontrol.systems.pwa.
        PiecewiseAffineSystem`: region 0 (``Hx <= δ``, support engaged)
        ``x' = A_2 x + k_s δ g + D F``, region 1 (``Hx >= δ``) ``x' = A_1 x + D F``, with the
        excitation ``F`` as its input (``E = D``) and the measured output as its ``C``.
        Conewise linear (``is_pwl``) when ``δ = 0``.

        Parameters
        ----------
        u : InputSignal, optional
            Default excitation ``F(t)`` (e.g. ``Unbalance(me_r).force(ω)``).
        """
        from .pwa import PiecewiseAffineSystem

        N = self.n_dof
        names = tuple(f"q{i + 1}" for i in range(N)) + tuple(f"dq{i + 1}" for i in range(N))
        g = self._lift(self.support.h)
        return PiecewiseAffineSystem.bimodal(
            self.state_matrix(True), self.state_matrix(False), self.H, d=self.support.gap,
            b1=self.support.k * self.support.gap * g, b2=np.zeros(2 * N), E=self.D, u=u,
            C=self.C_m, state_names=names)


@dataclass(frozen=True)
class Unbalance:
    """A rotating unbalance ``m_e r_e``: vertical force ``F(t) = m_e r_e ω² sin(ωt)``.

    An instance is the picklable amplitude map ``ω -> m_e r_e ω²`` that the frequency sweeps
    accept as ``amplitude=`` (:func:`~nscontrol.analysis.periodic.frequency_sweep`).

    Attributes
    ----------
    me_r
        ``m_e r_e`` (kg·m), positive.

    Examples
    --------
    >>> round(Unbalance(1e-4)(2 * np.pi * 27.5), 3)
    2.986
    """

    me_r: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "me_r", check_positive("me_r", self.me_r))

    def __call__(self, omega: float) -> float:
        return self.me_r * float(omega) ** 2

    def force(self, omega: float) -> Any:
        """``F(t) = m_e r_e ω² sin(ωt)`` as an :class:`~nscontrol.numerics.lti.Exosystem`.

        Parameters
        ----------
        omega : float
            Rotation speed (rad/s), positive.
        """
        from ..numerics.lti import Exosystem

        omega = check_positive("omega", omega)
        return Exosystem.sinusoid(self(omega), omega)


def two_mode_beam(*, alpha: float = 5.0, f1: float = 20.0, f2: float = 100.0,
                  m: tuple[float, float] = (5.0, 5.0), zeta: tuple[float, float] = (0.02, 0.02),
                  gap: float = 0.0) -> MechanicalPWL:
    """The two-mode surrogate "beam2" of the chapter-6 beam (our choice of numbers).

    The first two symmetric bending modes in modal coordinates ``q = (η1, η2)``, mode
    shapes scaled to 1 at the midpoint, where the support, the unbalance, the actuator and
    the displacement sensor all sit: ``h_s = h_F = h_u = (1, 1)``, ``y_m = η1 + η2``.
    ``M = diag(m)``, ``K = diag(m_i ω_i²)``, ``C_d = diag(2ζ_i m_i ω_i)``, support stiffness
    ``k_s = α·k_mid`` with ``k_mid = (h_sᵀK⁻¹h_s)⁻¹`` the static midpoint stiffness.

    Parameters
    ----------
    alpha : float
        One-sided stiffness ratio ``k_s/k_mid`` (> 0).
    f1, f2 : float
        No-contact modal frequencies (Hz), ``0 < f1 < f2``.
    m : tuple of float
        Modal masses (kg).
    zeta : tuple of float
        Modal damping ratios (>= 0).
    gap : float
        ``δ`` (m): 0 gives a conewise linear model.

    Returns
    -------
    MechanicalPWL

    Raises
    ------
    ModelError
        Non-positive ``alpha``, masses or frequencies, ``f1 >= f2``, negative damping.

    Examples
    --------
    >>> beam = two_mode_beam()
    >>> round(beam.support_static_stiffness, 2), round(beam.support.k, 2)
    (75920.03, 379600.17)
    """
    alpha = check_positive("alpha", alpha)
    f = np.array([check_positive("f1", f1), check_positive("f2", f2)])
    if f[0] >= f[1]:
        raise ModelError(f"f1, f2: expected f1 < f2 (first and second mode), got {f1}, {f2}")
    mm = np.array([check_positive(f"m[{i}]", v) for i, v in enumerate(_pair("m", m))])
    zz = np.array([check_positive(f"zeta[{i}]", v, allow_zero=True)
                   for i, v in enumerate(_pair("zeta", zeta))])
    om = 2 * np.pi * f
    K = np.diag(mm * om**2)
    h = np.ones(2)
    k_mid = 1.0 / float(h @ np.linalg.solve(K, h))
    return MechanicalPWL(np.diag(mm), np.diag(2 * zz * mm * om), K,
                         OneSidedSpring(h, alpha * k_mid, gap), h, h,
                         np.concatenate([h, np.zeros(2)])[None, :])


def _pair(name: str, value: Any) -> tuple[Any, Any]:
    v = tuple(np.atleast_1d(np.asarray(value, dtype=object)).ravel())
    if len(v) != 2:
        raise DimensionError(f"{name}: expected two values (one per mode), got {value!r}")
    return v[0], v[1]


def _element_matrices(EI: float, rhoA: float, le: float) -> tuple[FloatArray, FloatArray]:
    """Euler–Bernoulli element (cubic Hermite, DOFs ``w1, θ1, w2, θ2``): stiffness and
    consistent mass."""
    k = EI / le**3 * np.array([[12, 6 * le, -12, 6 * le],
                               [6 * le, 4 * le**2, -6 * le, 2 * le**2],
                               [-12, -6 * le, 12, -6 * le],
                               [6 * le, 2 * le**2, -6 * le, 4 * le**2]])
    m = rhoA * le / 420 * np.array([[156, 22 * le, 54, -13 * le],
                                     [22 * le, 4 * le**2, 13 * le, -3 * le**2],
                                     [54, 13 * le, 156, -22 * le],
                                     [-13 * le, -3 * le**2, -22 * le, 4 * le**2]])
    return k, m


def beam_fe_model(L: float, E: float, rho: float, b: float, t: float, k_leaf: float,
                  m_motor: float, k_s: float, n_el: int = 20, n_modes: int = 2, *,
                  zeta: float = 0.02, gap: float = 0.0) -> MechanicalPWL:
    """A beam on two leaf springs with a motor mass and a one-sided support at midspan,
    reduced to ``n_modes`` free-interface modes plus one static correction.

    The full model: ``n_el`` Euler–Bernoulli elements (cubic Hermite, consistent mass) of a
    rectangular section ``b × t``, vertical springs ``k_leaf`` at both ends (rotations
    free), a point mass ``m_motor`` at midspan. The reduction basis is the ``n_modes`` lowest
    mass-normalised modes ``Φ`` of the no-contact structure that move the midpoint (the
    antisymmetric ones are neither excited, actuated nor measured there) and the static
    residual flexibility vector ``r = K⁻¹h − ΦΩ⁻²Φᵀh`` of the midpoint (``h`` its unit
    load), so the reduced model has the full model's static flexibility at the midpoint
    exactly (the static deflection under a midpoint load lies in the basis) and its lowest
    ``n_modes`` frequencies (the modes are in the basis). Support, unbalance, actuator and
    sensor act at the midpoint. Damping: modal, ratio ``zeta`` for every mode of the reduced
    model. The generalized coordinates are the basis amplitudes (not physical
    displacements); ``y_s = h_rᵀq`` is the midpoint displacement.

    Parameters
    ----------
    L, E, rho, b, t : float
        Length (m), Young's modulus (Pa), density (kg/m³), width and thickness (m).
    k_leaf : float
        Vertical stiffness of each end support (N/m).
    m_motor : float
        Point mass at midspan (kg), ``>= 0``.
    k_s : float
        One-sided support stiffness (N/m).
    n_el : int
        Number of elements, even (midspan is a node), ``>= 2``.
    n_modes : int
        Modes kept, ``1 <= n_modes < 2(n_el + 1) - 1``.
    zeta : float
        Modal damping ratio of the reduced model, ``>= 0``.
    gap : float
        ``δ`` of the support (m).

    Returns
    -------
    MechanicalPWL
        ``n_modes + 1`` coordinates.

    Raises
    ------
    ModelError
        A non-positive dimension or stiffness, an odd or too small ``n_el``, a bad
        ``n_modes``.

    Notes
    -----
    No published geometry of the experimental beam was available; the builder has no default
    parameters. The reduction is a Craig–Bampton-like static correction of a modal basis.

    Examples
    --------
    >>> beam = beam_fe_model(1.6, 2.1e11, 7850.0, 0.05, 0.01, 1e5, 1.0, 1e6)
    >>> beam.n_dof, np.round(beam.frequencies(contact=False)[0][:2], 2)
    (3, array([ 7.69, 53.21]))
    """
    from .._validation import check_integer

    for name, v in (("L", L), ("E", E), ("rho", rho), ("b", b), ("t", t),
                    ("k_leaf", k_leaf), ("k_s", k_s)):
        check_positive(name, v)
    check_positive("m_motor", m_motor, allow_zero=True)
    zeta = check_positive("zeta", zeta, allow_zero=True)
    n_el = check_integer("n_el", n_el, minimum=2)
    if n_el % 2:
        raise ModelError(f"n_el: expected an even number of elements (midspan must be a node), "
                         f"got {n_el}")
    n_full = 2 * (n_el + 1)
    n_modes = check_integer("n_modes", n_modes, minimum=1)
    if n_modes >= n_full - 1:
        raise ModelError(f"n_modes: expected fewer than {n_full - 1} modes for {n_el} "
                         f"elements, got {n_modes}")
    EI, rhoA, le = E * b * t**3 / 12.0, rho * b * t, L / n_el
    ke, me = _element_matrices(EI, rhoA, le)
    K, M = np.zeros((n_full, n_full)), np.zeros((n_full, n_full))
    for e in range(n_el):
        idx = slice(2 * e, 2 * e + 4)
        K[idx, idx] += ke
        M[idx, idx] += me
    mid = 2 * (n_el // 2)
    K[0, 0] += k_leaf
    K[2 * n_el, 2 * n_el] += k_leaf
    M[mid, mid] += m_motor
    h = np.zeros(n_full)
    h[mid] = 1.0
    from scipy.linalg import eigh

    lam, Phi = eigh(K, M)
    # modes with a node at midspan (antisymmetric) are neither excited, actuated nor measured
    # there: keep the lowest that move the midpoint
    moving = np.flatnonzero(np.abs(Phi[mid]) > 1e-8 * np.max(np.abs(Phi), axis=0))
    if moving.size < n_modes:
        raise ModelError(f"n_modes: only {moving.size} modes move the midpoint with {n_el} "
                         f"elements, got n_modes = {n_modes}")
    lam, Phi = lam[moving[:n_modes]], Phi[:, moving[:n_modes]]
    static = np.linalg.solve(K, h)
    r = static - Phi @ (Phi.T @ h / lam)
    T = np.column_stack([Phi, r / np.sqrt(r @ M @ r)])
    Kr, Mr = T.T @ K @ T, T.T @ M @ T
    Kr, Mr = 0.5 * (Kr + Kr.T), 0.5 * (Mr + Mr.T)
    hr = T.T @ h
    lr, Psi = eigh(Kr, Mr)                       # mass-normalised: ΨᵀMΨ = I
    Cr = Mr @ Psi @ np.diag(2 * zeta * np.sqrt(lr)) @ Psi.T @ Mr
    n = n_modes + 1
    return MechanicalPWL(Mr, 0.5 * (Cr + Cr.T), Kr, OneSidedSpring(hr, k_s, gap), hr, hr,
                         np.concatenate([hr, np.zeros(n)])[None, :])
