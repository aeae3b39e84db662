"""Disturbance attenuation for a periodically excited beam with a one-sided support
(chapter 6), built on the convergent-PWA designs of :mod:`nscontrol.design.convergent_pwa`.

Three controller structures, one design object :class:`AttenuationDesign`:

* ``"state"`` — ``u = Kx`` from the decay-rate LMI (SF-σ) in the beam's mechanical
  coordinates (:func:`beam_scaling`), or, given a control penalty ``rho``, from the L2
  design (SF-L2) for the performance output ``z = (y_s, ρu)``;
* ``"output"`` — ``u = Kx̂`` with the piecewise-linear observer (OBS-σ) fed by the measured
  midpoint displacement: by separation the steady state is that of ``"state"``;
* ``"pd"`` — collocated servo-stiffness and servo-damping ``u = -k_p y_s - k_d y_s'``, the
  baseline, to be certified afterwards (the CQLF test and the threshold ``d*`` are analysis:
  :func:`nscontrol.analysis.attenuation.min_velocity_gain`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import check_positive
from ..errors import ModelError

if TYPE_CHECKING:
    from ..numerics.scaling import Scaling
    from ..systems.beam import MechanicalPWL
    from ..systems.pwa import PiecewiseAffineSystem
    from .convergent_pwa import ConvergentObserver, ConvergentStateFeedback

__all__ = ["AttenuationDesign", "LinearLaw", "beam_scaling", "design_attenuation", "pd_gain"]

FloatArray = NDArray[np.float64]

#: The controller structures of :func:`design_attenuation`.
STRUCTURES = ("state", "output", "pd")


def beam_scaling(plant: MechanicalPWL, omega_ref: float | None = None) -> Scaling:
    """The coordinates the beam's LMIs are solved in: ``S = diag(I, I/ω_ref)``,
    ``τ = ω_ref t``, forces in units of the support's static stiffness ``k_mid`` (so the
    gain bound ``‖K̃‖`` compares a gain with the beam's own stiffness).

    Parameters
    ----------
    plant : MechanicalPWL
        The beam.
    omega_ref : float, optional
        Reference frequency (rad/s); default the lowest no-contact natural frequency.
    """
    from ..numerics.scaling import Scaling

    if omega_ref is None:
        omega_ref = 2 * np.pi * float(plant.frequencies(contact=False)[0][0])
    return Scaling.mechanical(plant.n_dof, check_positive("omega_ref", omega_ref),
                              plant.support_static_stiffness)


@dataclass(frozen=True)
class LinearLaw:
    """``u = Kx`` as a picklable callable on time-major states (the ``control=`` of the
    frequency-response helpers).

    Attributes
    ----------
    K
        Gain, shape ``(p, n)``.
    """

    K: FloatArray

    def control(self, x: ArrayLike) -> FloatArray:
        """``u = Kx`` for time-major ``x`` of shape ``(k, n)``.

        Parameters
        ----------
        x : array_like
            States, one per row.
        """
        return np.asarray(x, float) @ self.K.T

    def __call__(self, x: ArrayLike) -> FloatArray:
        return self.control(x)


@dataclass(frozen=True, eq=False)
class AttenuationDesign:
    """A controller for the beam with its certificates.

    Attributes
    ----------
    structure
        ``"state"``, ``"output"`` or ``"pd"``.
    plant
        The beam it was designed for.
    K
        Gain of ``u = Kx`` (``u = Kx̂`` for ``"output"``), shape ``(1, 2N)``, in N per state
        unit.
    feedback
        The (SF-σ) design (``None`` for ``"pd"``).
    observer
        The (OBS-σ) design (``"output"`` only).
    P
        Certificate of the plant loop: ``(A_i + BK)ᵀP + P(A_i + BK) + 2σP <= 0`` for both
        modes, re-checked in NumPy by the design (``None`` for ``"pd"``: certify it with
        :func:`~nscontrol.analysis.convergence.quadratic_convergence`).
    decay
        Certified decay rate ``σ`` (1/s) of the plant loop (NaN for ``"pd"``).
    """

    structure: str
    plant: MechanicalPWL
    K: FloatArray
    feedback: ConvergentStateFeedback | None
    observer: ConvergentObserver | None
    P: FloatArray | None
    decay: float

    @property
    def gamma(self) -> float:
        """The certified L2 gain from the force ``F`` to ``z = (y_s, ρu)`` (m/N) of an L2
        design (``rho`` given); NaN otherwise."""
        return float("nan") if self.feedback is None else float(self.feedback.gamma)

    def modes(self) -> tuple[FloatArray, FloatArray]:
        """The plant loop's mode matrices ``A_i + BK`` (contact, free)."""
        A0, A1 = self.plant.to_pwa().A
        return A0 + self.plant.B @ self.K, A1 + self.plant.B @ self.K

    @property
    def kappa(self) -> float:
        """Condition number of :attr:`P` (NaN without one): the overshoot factor of the
        incremental bound ``|Δx(t)| <= √κ e^{-σt}|Δx(0)|``."""
        if self.P is None:
            return float("nan")
        lam = np.linalg.eigvalsh(self.P)
        return float(lam[-1] / lam[0])

    def closed_loop(self) -> PiecewiseAffineSystem:
        """The closed loop as one PWA system: ``x`` (``"state"``, ``"pd"``: ``2N`` states,
        2 regions) or ``(x, x̂)`` (``"output"``: ``4N`` states, 4 regions); the excitation
        ``F`` is its input and the support displacement its first output."""
        from ..simulate.lowering import stacked_model
        from ..systems.closed_loop import closed_loop
        from ..systems.feedback import PiecewiseStateFeedback
        from .convergent_pwa import output_feedback_loop

        pwa = self.plant.to_pwa()
        if self.observer is not None:
            return output_feedback_loop(pwa, self.observer, self.feedback)
        zero = np.zeros(1)
        return stacked_model(closed_loop(pwa, PiecewiseStateFeedback((self.K, self.K),
                                                                     (zero, zero)),
                                         input_matrix=self.plant.B))

    def control(self) -> Any:
        """The control law on the closed loop's time-major state (picklable): the effort
        ``u`` of :meth:`closed_loop` trajectories."""
        from .convergent_pwa import EstimateFeedback

        if self.structure == "output":
            return EstimateFeedback(LinearLaw(self.K), self.plant.n_states)
        return LinearLaw(self.K)

    @property
    def performance_output(self) -> FloatArray:
        """``C_z`` picking the support displacement ``y_s = Hx`` from the loop's state."""
        H = self.plant.H
        n_loop = 2 * H.size if self.structure == "output" else H.size
        return np.concatenate([H, np.zeros(n_loop - H.size)])[None, :]


def pd_gain(plant: MechanicalPWL, kp: float, kd: float) -> FloatArray:
    """``K`` of ``u = -k_p y_s - k_d y_s'`` (``y_s = h_sᵀq``): ``K = -[k_p h_sᵀ, k_d h_sᵀ]``.

    Parameters
    ----------
    plant : MechanicalPWL
        The beam.
    kp, kd : float
        Servo-stiffness (N/m) and servo-damping (N s/m), ``>= 0``.
    """
    kp = check_positive("kp", kp, allow_zero=True)
    kd = check_positive("kd", kd, allow_zero=True)
    h = plant.support.h
    return -np.concatenate([kp * h, kd * h])[None, :]


def design_attenuation(plant: MechanicalPWL, *, structure: str = "output",
                       decay: float = 0.1, observer_decay: float = 0.5,
                       omega_ref: float | None = None, kp: float = 0.0,
                       kd: float | None = None, rho: float | None = None,
                       slack: float = 0.1) -> AttenuationDesign:
    """Design a convergent attenuating controller for the beam.

    Parameters
    ----------
    plant : MechanicalPWL
        The beam (its one-sided support makes it a continuous bimodal PWA system).
    structure : {"output", "state", "pd"}
        Observer-based output feedback (the reference), state feedback, or collocated
        servo-stiffness/servo-damping.
    decay : float
        Decay rate ``σ̃`` of the plant loop in units of ``ω_ref`` (``σ = σ̃ ω_ref``, 1/s)
        certified by (SF-σ); ignored for ``"pd"``.
    observer_decay : float
        Error decay rate ``σ̃_o`` of the observer, in units of ``ω_ref``.
    omega_ref : float, optional
        As in :func:`beam_scaling`.
    kp, kd : float
        ``"pd"`` only: the gains (N/m, N s/m); ``kd`` is required.
    rho : float, optional
        ``"state"`` and ``"output"``: a control penalty (m/N) selects the L2 design
        :func:`~nscontrol.design.convergent_pwa.design_state_feedback_l2` for the
        performance output ``z = (y_s, ρu)`` (support displacement, penalised force) and the
        unbalance force as disturbance, with decay rate ``decay``, instead of (SF-σ).
    slack : float
        L2 design only: ``γ = (1 + slack)·γ_inf`` (see
        :func:`~nscontrol.design.convergent_pwa.design_state_feedback_l2`).

    Returns
    -------
    AttenuationDesign

    Raises
    ------
    ModelError
        Unknown ``structure``; ``"pd"`` without ``kd`` or with ``rho``; a bad ``rho``.
    InfeasibleDesignError
        No gain certifies the decay rate.

    Notes
    -----
    Hypotheses: a continuous PWA plant (one-sided spring, no impact) and known excitation
    (the observer is fed ``F(t)``: the motor angle gives its phase). (SF-σ) minimises the gain
    bound ``‖K̃‖`` in the scaled coordinates of :func:`beam_scaling`; with the actuator
    collocated with the excitation (``B = D``) a gain-bounded design is essential, since the
    unpenalised attenuation problem drives the gain to infinity. Separation (ch11):
    the output-feedback loop is convergent and its steady state has ``x̂ = x`` equal to the
    state-feedback one. The ``"pd"`` law uses ``y_s'`` exactly (a velocity sensor, or an
    observer whose error has decayed).

    References
    ----------
    A. Doris, N. van de Wouw, H. Nijmeijer, D5.3 chapter 6; A. Pavlov, N. van de Wouw,
    H. Nijmeijer, "Convergent systems: analysis and synthesis", LNCIS 322, Springer 2005;
    M.F. Heertjes, M.J.G. van de Molengraft, "Controlling the nonlinear dynamics of a beam
    system", Chaos, Solitons and Fractals 12, 2001 (the servo-damping baseline).

    Examples
    --------
    >>> from nscontrol.systems.beam import two_mode_beam
    >>> sf = design_attenuation(two_mode_beam(), structure="state")
    >>> np.round(sf.K / 1e3, 1)
    array([[-95.5, -41.1,  -0.9,  -0.2]])
    """
    from .convergent_pwa import design_observer, design_state_feedback, design_state_feedback_l2

    if structure not in STRUCTURES:
        raise ModelError(f"structure: expected one of {STRUCTURES}, got {structure!r}")
    sc = beam_scaling(plant, omega_ref)
    pwa = plant.to_pwa()
    if structure == "pd":
        if kd is None:
            raise ModelError("kd: the 'pd' structure needs the servo-damping gain kd (N s/m); "
                             "nscontrol.analysis.min_velocity_gain(plant) gives the smallest "
                             "one with a common quadratic Lyapunov function")
        if rho is not None:
            raise ModelError("rho: the control penalty selects the L2 state-feedback design; "
                             "the 'pd' structure has fixed gains kp, kd")
        return AttenuationDesign("pd", plant, pd_gain(plant, kp, kd), None, None, None,
                                 float("nan"))
    sigma = check_positive("decay", decay) * sc.omega
    if rho is None:
        sf = design_state_feedback(pwa, sigma=sigma, B=plant.B, scale=sc)
    else:
        sf = design_state_feedback_l2(pwa, rho=rho, Cz=plant.H, D=plant.D, B=plant.B,
                                      sigma=sigma, slack=slack, scale=sc)
    obs = None
    if structure == "output":
        obs = design_observer(pwa, sigma=check_positive("observer_decay", observer_decay)
                              * sc.omega, C=plant.C_m, scale=sc)
    return AttenuationDesign(structure, plant, sf.K, sf, obs, sf.P, sigma)

