r"""A periodic gait found as a periodic optimal control problem: a ball juggled by a paddle
that vibrates vertically, ``s(t) = A sin(ω t + ψ)``, with the amplitude ``A`` and the timing
``ψ`` chosen by the optimiser.

**The model** (in the paddle's frame, which makes the contact an affine gap): the ball's
height above the paddle ``z`` obeys ``z'' = -g - s''(t)`` in flight, ``z >= 0``, and Newton's
law ``z'+ = -e z'-`` on the *relative* velocity at an impact (the paddle's motion is imposed).
So it is a one-degree-of-freedom :class:`~nscontrol.systems.LagrangianSystem` (unit mass,
force ``-g``, actuation 1) driven by the input ``u(t) = -s''(t) = A ω² sin(ω t + ψ)``.

**Period-1 gait, closed form.** One impact per period ``T = 2π/ω``, at ``t = 0``. In the
ground frame the ball leaves the paddle at ``v+`` and comes back to the same paddle height one
period later, so ``v+ = gT/2`` and it arrives at ``v- = -gT/2``; Newton's law with the paddle's
speed ``ṡ(0)`` gives ``ṡ(0) = c = (1 - e) g T / (2 (1 + e))``, that is ``A ω cos ψ = c``: an
orbit exists for ``A >= A₀ = c / ω`` (the fold), at the phase ``cos ψ = A₀ / A``.

**Its stability, closed form.** Write the impact map on (impact time, take-off speed) and
differentiate it at the orbit: with ``a = gT / (1 + e)`` the relative approach speed and
``s̈₀ = -A ω² sin ψ`` the paddle's acceleration at the impact, the Jacobian is
``[[1, T/a], [(1+e) s̈₀, T((1+e) s̈₀ + e g)/a - e]]``: determinant ``e²`` and trace
``1 + e² + (1 + e)² s̈₀ / g``. Its eigenvalues are the Floquet multipliers of the orbit (the
stroboscopic map is conjugate to the impact map near the orbit). The orbit is stable when the
paddle decelerates at the impact, ``-2 g (1 + e²) / (1 + e)² < s̈₀ < 0``; at the fold
(``s̈₀ = 0``) one multiplier is 1.

**The optimal control problem.** The least paddle amplitude ``A²`` for which a period-1 gait
exists whose paddle decelerates at the impact by at least ``κ g`` (a stability margin):
``A cos ψ = A₀`` and ``A sin ψ >= κ g / ω²``, hence

    A* = sqrt(A₀² + (κ g / ω²)²),     tan ψ* = κ g / (ω² A₀),

with multipliers the roots of ``λ² - (1 + e² - κ (1 + e)²) λ + e² = 0``.

**Transcription** (:class:`JugglerProblem`): the Moreau–Jean steps of
:class:`~nscontrol.optimal.ContactProblem` at ``h = T / N`` with the periodicity ``x_N = x_0``
in place of an initial state, the impact pinned at ``t = 0`` (``z_0 = 0``), the inputs tied
to the paddle's sinusoid sampled at the step starts, ``u_k = A ω² sin(ω k h + ψ)``, and the
margin ``u_0 >= κ g``. The plan replays through ``simulate(..., method="moreau_jean", h=h,
u=plan.input())``; the orbit tools (``find_orbit`` with the exact sinusoid, event-driven) then
find the period-1 orbit of the planned paddle and its multipliers (the example
``juggler``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import (
    FloatArray,
    check_in_interval,
    check_integer,
    check_positive,
    check_type,
)
from ..errors import ModelError
from ..systems.lagrangian import LagrangianSystem
from .contact import ContactProblem, Relaxation, _ContactNLP, _plan, casadi, solve_rounds
from .plan import ContactPlan

__all__ = ["VibratingTable", "JugglerProblem", "JugglerPlan"]


@dataclass(frozen=True)
class VibratingTable:
    """A ball bouncing on a vertically vibrating paddle (the module docstring): the model,
    the closed forms of its period-1 gait and of the optimal control problem.

    Parameters
    ----------
    g : float
        Gravity.
    restitution : float
        ``e`` in ``(0, 1)``.
    omega : float
        The paddle's angular frequency ``ω`` (period ``T = 2π/ω``).
    margin : float
        ``κ >= 0``: the paddle decelerates at the impact by at least ``κ g``.

    Raises
    ------
    ModelError
        A value out of range.
    """

    g: float = 9.81
    restitution: float = 0.6
    omega: float = 2.0 * np.pi
    margin: float = 0.5

    def __post_init__(self) -> None:
        check_positive("g", self.g)
        check_in_interval("restitution", self.restitution, 0.0, 1.0, open_interval=True)
        check_positive("omega", self.omega)
        check_positive("margin", self.margin, allow_zero=True)

    @property
    def period(self) -> float:
        """``T = 2π / ω``."""
        return 2.0 * np.pi / self.omega

    @property
    def impact_speed(self) -> float:
        """``c``: the paddle's upward speed at the impact on a period-1 gait."""
        e = self.restitution
        return (1.0 - e) * self.g * self.period / (2.0 * (1.0 + e))

    @property
    def fold_amplitude(self) -> float:
        """``A₀ = c / ω``: the least amplitude with a period-1 gait."""
        return self.impact_speed / self.omega

    def system(self) -> LagrangianSystem:
        """The ball in the paddle's frame: ``z'' = -g + u``, gap ``z``, restitution ``e``."""
        return LagrangianSystem(np.eye(1), constant_force=[-self.g], gap_matrix=[[1.0]],
                                gap_offset=[0.0], restitution=self.restitution,
                                actuation=[[1.0]], names=("z",))

    def optimum(self) -> tuple[float, float]:
        """``(A*, ψ*)`` of the optimal control problem."""
        lift = self.margin * self.g / self.omega ** 2
        return float(np.hypot(self.fold_amplitude, lift)), float(
            np.arctan2(lift, self.fold_amplitude))

    def impact_phase(self, amplitude: float) -> float:
        """``ψ`` with ``A cos ψ = A₀`` on the branch ``sin ψ > 0`` (the paddle decelerating
        at the impact)."""
        ratio = self.fold_amplitude / check_positive("amplitude", amplitude)
        if ratio > 1.0:
            raise ModelError(f"amplitude: {amplitude:g} is below the fold "
                             f"{self.fold_amplitude:g}; no period-1 gait exists")
        return float(np.arccos(ratio))

    def multipliers(self, amplitude: float) -> np.ndarray:
        """Floquet multipliers of the period-1 gait of the paddle of ``amplitude`` (branch of
        :meth:`impact_phase`), by decreasing modulus."""
        e = self.restitution
        sdd = -amplitude * self.omega ** 2 * np.sin(self.impact_phase(amplitude))
        trace = 1.0 + e ** 2 + (1.0 + e) ** 2 * sdd / self.g
        mu = np.roots([1.0, -trace, e ** 2])
        return mu[np.argsort(-np.abs(mu), kind="stable")]

    def state(self, amplitude: float, t: Any) -> FloatArray:
        """``(z, z')`` on the period-1 gait at ``t`` in ``[0, T]`` after the impact (the
        take-off state at ``t = 0``), shape ``(len(t), 2)``."""
        t = np.atleast_1d(np.asarray(t, float))
        A, w, psi = amplitude, self.omega, self.impact_phase(amplitude)
        v_up = self.g * self.period / 2.0
        z = A * np.sin(psi) + v_up * t - self.g * t ** 2 / 2 - A * np.sin(w * t + psi)
        v = v_up - self.g * t - A * w * np.cos(w * t + psi)
        return np.column_stack([z, v])

    def paddle(self, amplitude: float, phase: float) -> Any:
        """The input ``u(t) = A ω² sin(ω t + phase)`` as an exosystem (what the event-driven
        integrator and the orbit tools take)."""
        from ..numerics.lti import Exosystem

        return Exosystem.sinusoid(amplitude * self.omega ** 2, self.omega, phase=phase)

    def problem(self, steps: int) -> JugglerProblem:
        """The transcription with ``steps`` Moreau–Jean steps per period."""
        return JugglerProblem(self, steps)


@dataclass(frozen=True)
class JugglerPlan:
    """A planned period-1 gait: the paddle's amplitude and timing and the motion.

    Attributes
    ----------
    amplitude : float
        ``A``.
    phase : float
        ``ψ`` (the paddle's phase at the impact, ``t = 0``).
    plan : ContactPlan
        The periodic motion on the grid (``x[0] = x[N]``, the impact on step 0).
    """

    amplitude: float
    phase: float
    plan: ContactPlan


@dataclass(frozen=True, eq=False)
class JugglerProblem:
    """The least paddle amplitude with a period-1 gait and a stability margin (the module
    docstring), transcribed by ``steps`` Moreau–Jean steps per period.

    Parameters
    ----------
    table : VibratingTable
        The model and its margin.
    steps : int
        Steps per period ``N`` (``h = T / N``).

    Raises
    ------
    ModelError
        A bad value.
    """

    table: VibratingTable
    steps: int
    contact: ContactProblem = field(init=False, repr=False)

    def __post_init__(self) -> None:
        check_type("table", self.table, VibratingTable)
        check_integer("steps", self.steps, minimum=4)
        h = self.table.period / self.steps
        object.__setattr__(self, "contact", ContactProblem(
            self.table.system(), [0.0, 0.0], self.steps, h, effort=0.0))

    def guess(self) -> dict[str, Any]:
        """A hop over a paddle at rest (the parabola of period ``T``, arriving at ``-gT/2``
        on the last grid point, which is also the first), twice the fold amplitude, the
        paddle at a quarter of its rise."""
        tb, N = self.table, self.steps
        T, h = tb.period, self.contact.h
        t = h * np.arange(N + 1)
        X = np.vstack([tb.g * t * (T - t) / 2.0, tb.g * (T / 2.0 - t)])
        X[1, 0] = X[1, -1]
        A, psi = 2.0 * tb.fold_amplitude, np.pi / 4
        U = A * tb.omega ** 2 * np.sin(tb.omega * t[:-1] + psi)
        zeros = np.zeros((1, N))
        return {"X": X, "U": U[None, :], "LN": zeros, "BP": zeros, "BM": zeros, "S": zeros,
                "h": h, "A": A, "psi": psi, "lam_g": None}

    def solve(self, relaxation: Relaxation | None = None, *, max_rounds: int = 5
              ) -> JugglerPlan:
        """Solve the homotopy (and the polish), re-deriving the active sets from the plan.

        Parameters
        ----------
        relaxation : Relaxation, optional
            The homotopy (default :class:`Relaxation()`).
        max_rounds : int
            Rounds of the active-set iteration.

        Returns
        -------
        JugglerPlan

        Raises
        ------
        SolverError
            IPOPT failed on a relaxed problem.
        """
        relaxation = Relaxation() if relaxation is None else check_type(
            "relaxation", relaxation, Relaxation)
        check_integer("max_rounds", max_rounds, minimum=1)
        sol, active, stages, polished, rounds, consistent = solve_rounds(
            self.contact, lambda active: _JugglerNLP(self, active), self.guess(), relaxation,
            max_rounds)
        plan = _plan(self.contact, sol, active, stages, polished, rounds, consistent)
        return JugglerPlan(amplitude=float(sol["A"]), phase=float(sol["psi"]), plan=plan)


class _JugglerNLP(_ContactNLP):
    """The Moreau–Jean transcription with periodic ends and the paddle's two unknowns."""

    def __init__(self, juggler: JugglerProblem, active: np.ndarray) -> None:
        super().__init__(juggler.contact, active)
        self.juggler = juggler

    def variables(self, opti: Any) -> dict[str, Any]:
        var = super().variables(opti)
        var["A"], var["psi"] = opti.variable(), opti.variable()
        return var

    def constraints(self, opti: Any, var: dict[str, Any]) -> None:
        ca, tb, N = casadi(), self.juggler.table, self.juggler.steps
        self.x0 = var["X"][:, N]          # periodic: x_0 = x_N
        super().constraints(opti, var)
        t = self.problem.h * np.arange(N)
        w2 = tb.omega ** 2
        opti.subject_to(ca.vec(var["U"]) == var["A"] * w2 * ca.sin(tb.omega * t + var["psi"]))
        opti.subject_to(var["X"][0, 0] == 0)      # the impact at t = 0
        opti.subject_to(var["U"][0, 0] >= tb.margin * tb.g)
        opti.subject_to(opti.bounded(0.0, var["A"], 10.0 * tb.g / w2))
        opti.subject_to(opti.bounded(-np.pi, var["psi"], np.pi))

    def cost(self, var: dict[str, Any]) -> Any:
        return var["A"] ** 2
