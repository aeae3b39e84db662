"""A closed loop is a system too: a plant, its controller, observer and exogenous input.

:func:`closed_loop` validates the parts and returns a :class:`ClosedLoop`, plain data that
:func:`nscontrol.simulate` runs like any model: the simulation layer *lowers* it to what the
chosen method integrates (:mod:`nscontrol.simulate.lowering`) and records the loop's named
signals:

* ``"xhat"`` — the observer's estimate, ``"e"`` — the estimation error ``S x - x̂`` (with
  an observer; also kept under its older name ``"error"``), and ``"y"`` the plant's measured
  output (the stacked Lur'e model's own output is that error);
* ``"u"`` — the controller's output (with a controller);
* the plant's own signals (``"gap"``, ``"impulse"``, ``"z"``, ``"w"``, ``"y"`` ...).

How a loop is composed (:attr:`ClosedLoop.composition`), by what its parts are:

=========================================  ===============================================
parts                                      composition, and what the integrator sees
=========================================  ===============================================
linear blocks (:class:`StateFeedback`,     ``"stacked"``: ONE model of the plant's family,
:class:`PiecewiseStateFeedback`,           a :class:`LinearHybridSystem` (exact
continuous :class:`LinearController`,      event-driven flow, compiled event loop when the
:class:`LinearObserver`,                   jumps are matrices), a :class:`LureSystem`
:class:`PiecewiseObserver`) around a       (implicit Euler's compiled paths, the observer's
LinearHybridSystem / ImpactingBodies,      law solved with the plant's), a
LureSystem or PiecewiseAffineSystem        :class:`PiecewiseAffineSystem`
continuous static state feedback           ``"folded"``: the plant's own model with the
(:class:`StateFeedback` on the state) on   feedback folded into its linear forces
a LagrangianSystem or ImpactingBodies      (stiffness, damping, constant force; the
                                           bodies through their Lagrangian form): exact
                                           event-driven flow when the plant is linear,
                                           compiled Moreau–Jean
any :class:`Controller` or                 ``"blocks"``: Moreau–Jean on the plant, the
:class:`Observer` (Python, sampled or      blocks stepped at the start of every step
continuous, with state) around a           (zero-order hold), fed the contact multipliers
LagrangianSystem or ImpactingBodies        ``λ̂`` and reset at impacts
the same around a LureSystem               ``"blocks"``: implicit Euler on the plant (its
                                           set-valued law solved every step)
a sampled controller around a              ``"blocks"``: ``sampled_zoh`` on the plant, the
SlidingModePlant                           controller stepped at its ticks (exact
                                           zero-order hold between them)
=========================================  ===============================================

Any other combination is refused with a :class:`~nscontrol.errors.ModelError` that says what
would run.

The state of a stacked or folded loop is ``[x; xo; xc]`` (plant, observer, controller); for a
loop of Python blocks the integrator's state is the plant's and the blocks' states are the
signals ``"xo"`` and ``"xc"``. :meth:`ClosedLoop.initial_state` builds the right ``x0``
either way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_matrix, as_vector, check_bool, check_positive
from ..errors import DimensionError, ModelError
from .feedback import (
    Controller,
    LinearController,
    LinearObserver,
    Observer,
    PiecewiseObserver,
    PiecewiseStateFeedback,
    StateFeedback,
)
from .protocols import Exogenous, SimulableSystem

# the function is public as nscontrol.closed_loop (and nscontrol.simulate.closed_loop): the
# package nscontrol.systems cannot export it, its name is this module's
__all__ = ["ClosedLoop"]


def closed_loop(plant: SimulableSystem, controller: Controller | None = None,
                observer: Observer | None = None, exosystem: Exogenous | None = None, *,
                input_matrix: ArrayLike | None = None,
                output_matrix: ArrayLike | None = None, compiled: bool = True) -> ClosedLoop:
    """Compose a plant with a controller and/or an observer (and an exogenous input).

    Parameters
    ----------
    plant
        A model of :mod:`nscontrol.systems`.
    controller : Controller, optional
        Its output is the plant input ``u`` (see :mod:`nscontrol.systems.feedback`).
    observer : Observer, optional
        Reads the measured output; its estimate feeds ``StateFeedback(on="estimate")``.
    exosystem : Exosystem, optional
        Exogenous input of the plant (its reference or disturbance), for plants that take it
        as an input (Lagrangian systems, impacting bodies).
    input_matrix : array_like (n, m), optional
        How ``u`` enters ``x'`` when the plant does not say (``B`` of a Lur'e system and the
        ``actuation`` of a mechanical system are used by default).
    output_matrix : array_like (p, n), optional
        The measured output ``y = C x`` (default: the plant's ``C``, its ``"y"`` output, or
        the whole state).
    compiled : bool
        Run blocks that offer a compiled form (``compiled()``, see
        :class:`~nscontrol.systems.feedback.CompiledBlock`) in the integrator's compiled loop
        when every block of the loop has one (default); ``False`` runs their Python methods
        (to compare the two, or to debug a block).

    Returns
    -------
    ClosedLoop

    Raises
    ------
    ModelError
        A block that is neither a controller nor an observer; a combination no integrator
        runs (the message says which would).
    DimensionError
        A state-feedback gain that does not fit the plant it is folded into.

    Examples
    --------
    A mass on a spring against a wall, with a PD law folded into the model (so the flow
    stays exact between impacts):

    >>> import nscontrol as nsc
    >>> from nscontrol.systems.lagrangian import LagrangianSystem
    >>> from nscontrol.systems.feedback import StateFeedback
    >>> mass = LagrangianSystem([[1.0]], gap_matrix=[[1.0]], gap_offset=[0.0],
    ...                         restitution=0.5, constant_force=[-1.0])
    >>> loop = nsc.closed_loop(mass, StateFeedback([[-4.0, -1.0]], k=[5.0]))
    >>> loop.composition
    'folded'
    >>> tr = nsc.simulate(loop, [0.2, 0.0], (0.0, 40.0))
    >>> bool(abs(tr.x[-1, 0] - 1.0) < 1e-6)   # equilibrium 5 - 1 - 4 q = 0; decay e^(-t/2)
    True
    """
    for name, block in (("controller", controller), ("observer", observer)):
        if block is not None and not all(hasattr(block, a) for a in
                                         ("n_states", "output", "update", "reset")):
            raise ModelError(f"{name}: expected a block with n_states, output(t, xc, m), "
                             f"update(t, xc, m) and reset(t, xc, jump) (see "
                             f"nscontrol.systems.feedback), got {type(block).__name__}")
    if observer is not None and isinstance(observer, StateFeedback | LinearController):
        raise ModelError("observer: a StateFeedback/LinearController outputs an input, not an "
                         "estimate; pass it as controller=")
    for name, block in (("controller", controller), ("observer", observer)):
        period = getattr(block, "period", None)
        if block is not None and period is not None:   # a sampled block's own period
            check_positive(f"{name}.period", period,
                           hint="a block's period is None (continuous-time) or its sampling "
                                "period T > 0")
    compiled = check_bool("compiled", compiled)
    return ClosedLoop(plant, controller, observer, exosystem, input_matrix, output_matrix,
                      compiled)


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """A plant with its controller, observer and exogenous input (see :func:`closed_loop`).

    Plain data: how it runs is decided by the lowerings of :mod:`nscontrol.simulate.lowering`
    (the stacked model of a ``"stacked"`` loop is ``nscontrol.simulate.lowering.stacked_model
    (loop)``).

    Attributes
    ----------
    plant
        The plant model.
    controller : Controller or None
        Its output is the plant input ``u``.
    observer : Observer or None
        Reads the measured output ``y``.
    exosystem : Exogenous or None
        The plant's exogenous input.
    input_matrix : array_like or None
        How ``u`` enters ``x'`` when the plant does not say.
    output_matrix : array_like or None
        The measured output ``y = C x``.
    compiled : bool
        Whether blocks with a compiled form run in the integrators' compiled loops.
    """

    plant: Any
    controller: Any = None
    observer: Any = None
    exosystem: Any = None
    input_matrix: Any = None
    output_matrix: Any = None
    compiled: bool = True
    _composition: str = field(default="", init=False, repr=False)
    _plant_model: Any = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        composition = _composition(self)
        object.__setattr__(self, "_composition", composition)
        object.__setattr__(self, "_plant_model", self._model_of_plant())
        if composition == "folded":
            self._check_folded_gain()

    # -- what the loop is -------------------------------------------------------------------
    @property
    def composition(self) -> str:
        """``"stacked"`` (linear blocks and plant are one model of the plant's family),
        ``"folded"`` (static state feedback folded into a linear Lagrangian plant) or
        ``"blocks"`` (the blocks run as code beside the plant's integrator)."""
        return self._composition

    @property
    def plant_model(self) -> Any:
        """The plant as a stacked loop sees it: an :class:`ImpactingBodies` plant as its
        :class:`LinearHybridSystem` (the exosystem's state appended), any other as is."""
        return self._plant_model

    @property
    def default_method(self) -> str:
        from .lure import LureSystem
        from .sliding_mode import SlidingModePlant

        if isinstance(self.plant, SlidingModePlant):    # exact between its ticks
            return "sampled_zoh"
        if self._composition == "blocks":
            return "implicit_euler" if isinstance(self.plant, LureSystem) else "moreau_jean"
        return str(self._plant_model.default_method)   # the stacked model's family

    @property
    def n_states(self) -> int:
        """Length of the ``x0`` :func:`simulate` takes: the stacked state, or the plant's."""
        if self._composition == "blocks":
            return int(self.plant.n_states)
        return int(self._plant_model.n_states) + sum(
            int(block.n_states) for block in (self.observer, self.controller)
            if block is not None)

    @property
    def state_names(self) -> tuple[str, ...]:
        """The plant's state names (``x1``... when it has none), then the stacked blocks'
        (the observer's own names or ``xhat1``..., the controller's ``xc1``...); a loop whose
        blocks run as code beside the plant has the plant's."""
        names = tuple(getattr(self._plant_model, "state_names", ()))
        if self._composition == "blocks":
            return names
        obs, ctrl = self.observer, self.controller
        if not names and (obs is not None and obs.n_states or ctrl is not None
                          and ctrl.n_states):
            names = tuple(f"x{i + 1}" for i in range(int(self._plant_model.n_states)))
        if obs is not None:
            own = tuple(getattr(obs, "names", ()) or ())
            names += own if own else tuple(f"xhat{i + 1}" for i in range(obs.n_states))
        if ctrl is not None:
            names += tuple(f"xc{i + 1}" for i in range(ctrl.n_states))
        return names

    def force_input_matrix(self) -> FloatArray:
        """``S`` with which ``u`` enters a Lagrangian plant's forces ``S u``: the loop's
        ``input_matrix``, the plant's ``actuation``, or the identity (impacting bodies: the
        forces on ``[q_a; q_b]``, their actuation ``[E; 0]``).

        Raises
        ------
        DimensionError
            An ``input_matrix`` without one row per degree of freedom.
        """
        from .impacting_bodies import ImpactingBodies

        plant = self.plant
        if isinstance(plant, ImpactingBodies):   # its force enters [q_a; q_b] through [E; 0]
            n, actuation = plant.n, np.concatenate([plant.E, np.zeros(plant.n_b)])[:, None]
        else:
            n, actuation = int(plant.n_dof), plant.actuation
        if self.input_matrix is not None:
            return as_matrix("input_matrix", self.input_matrix, rows=n)
        return np.eye(n) if actuation is None else actuation

    def initial_state(self, plant: Any, observer: Any = None, controller: Any = None
                      ) -> FloatArray:
        """``x0`` for :func:`simulate`: the plant's initial state and the blocks' (zeros by
        default), stacked when the loop is one model.

        Parameters
        ----------
        plant : array_like
            The plant's initial state (with an exosystem appended to impacting bodies, the
            exosystem's state too).
        observer, controller : array_like, optional
            The blocks' initial states (zeros by default).

        Returns
        -------
        ndarray

        Raises
        ------
        DimensionError
            A part of the wrong length.
        ModelError
            A block's state given for a loop whose blocks run in Python.
        """
        xp = as_vector("plant", plant, int(self._plant_model.n_states))
        parts = [xp]
        for name, block, value in (("observer", self.observer, observer),
                                   ("controller", self.controller, controller)):
            if block is None:
                continue
            parts.append(np.zeros(block.n_states) if value is None else
                         as_vector(name, value, block.n_states))
        if self._composition == "blocks":
            if any(p.size for p in parts[1:]):
                raise ModelError("initial_state: this loop runs its blocks in Python; give "
                                 "their initial states to the blocks themselves (x0 is the "
                                 "plant's)")
            return xp
        return np.concatenate(parts)

    def _model_of_plant(self) -> Any:
        from .impacting_bodies import ImpactingBodies

        if isinstance(self.plant, ImpactingBodies) and _needs_hybrid(self):
            return self.plant.hybrid(self.exosystem)
        return self.plant

    def _check_folded_gain(self) -> None:
        S = self.force_input_matrix()
        n = S.shape[0]
        K = self.controller.K
        if K.shape != (S.shape[1], 2 * n):
            raise DimensionError(f"controller: K must have shape ({S.shape[1]}, {2 * n}) "
                                 f"(inputs x [q; v]), got {K.shape}")


def _needs_hybrid(loop: ClosedLoop) -> bool:
    """An ImpactingBodies plant is stacked as its hybrid form with an observer or a dynamic
    linear controller."""
    return loop.observer is not None or isinstance(loop.controller, LinearController)


def _is_linear_block(block: Any, role: str) -> bool:
    if block is None:
        return True
    if role == "controller" and isinstance(block, StateFeedback | PiecewiseStateFeedback |
                                           LinearController):
        return block.period is None
    return role == "observer" and isinstance(block, LinearObserver | PiecewiseObserver)


def _composition(loop: ClosedLoop) -> str:
    """How the loop is composed (see :attr:`ClosedLoop.composition`); refuses the
    combinations no integrator runs."""
    from .hybrid import LinearHybridSystem
    from .impacting_bodies import ImpactingBodies
    from .lagrangian import LagrangianSystem
    from .lure import LureSystem
    from .pwa import PiecewiseAffineSystem
    from .sliding_mode import SlidingModePlant

    plant, ctrl, obs = loop.plant, loop.controller, loop.observer
    linear_blocks = (_is_linear_block(ctrl, "controller") and
                     _is_linear_block(obs, "observer"))
    if isinstance(plant, PiecewiseAffineSystem) or isinstance(plant, LinearHybridSystem) or (
            isinstance(plant, ImpactingBodies) and _needs_hybrid(loop)):
        if not linear_blocks:
            raise ModelError(
                f"closed_loop: a {type(plant).__name__} plant runs with blocks given as "
                f"matrices (StateFeedback, PiecewiseStateFeedback, continuous "
                f"LinearController, LinearObserver), stacked into one model; blocks written as "
                f"Python code (or sampled) run around LagrangianSystem and ImpactingBodies "
                f"plants with method='moreau_jean' and around LureSystem plants with "
                f"method='implicit_euler'")
        return "stacked"
    if isinstance(plant, LureSystem):
        return "stacked" if linear_blocks else "blocks"   # Python blocks: implicit Euler
    if isinstance(plant, LagrangianSystem | ImpactingBodies) and obs is None and \
            isinstance(ctrl, StateFeedback) and ctrl.on == "state" and ctrl.period is None:
        return "folded"   # u = K x + k is a linear force: the plant's own model runs it
    if isinstance(plant, LagrangianSystem | ImpactingBodies | SlidingModePlant):
        return "blocks"         # blocks stepped beside the plant's integrator
    raise ModelError(f"plant: closed_loop composes LagrangianSystem, ImpactingBodies, "
                     f"LinearHybridSystem, LureSystem, PiecewiseAffineSystem and "
                     f"SlidingModePlant plants, got "
                     f"{type(plant).__name__}")
