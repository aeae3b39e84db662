"""The built-in integrators as a family: what each integrates, can do and accepts.

Each class declares its facts for the driver (:mod:`nscontrol.simulate.driver`); the work is
the ``integrate`` function of the module named in ``module``, whose docstring holds the
algorithm. No method integrates a closed loop as given: :func:`nscontrol.simulate` lowers it
first (:mod:`nscontrol.simulate.lowering`), and a loop's blocks reach the method as the
internal option ``blocks=`` (``event_driven``, ``moreau_jean``, ``implicit_euler``,
``sampled_zoh``).

=================  ==========================================  ============================
method             systems                                     capabilities
=================  ==========================================  ============================
``event_driven``   LinearHybridSystem, LagrangianSystem,       events, exact flow,
                   ImpactingBodies                             listeners, multipliers,
                                                               sensitivity (Lagrangian)
``moreau_jean``    LagrangianSystem, ImpactingBodies           time stepping, listeners,
                                                               multipliers
``implicit_euler`` LureSystem                                  time stepping, multipliers,
                                                               sensitivity (discrete map)
``switching``      PiecewiseAffineSystem, FilippovSystem,      events, exact flow,
                   SwitchedAffineSystem, NonlinearSystem       sensitivity, t_eval
``sampled_zoh``    SlidingModePlant, with the sampled          exact flow
                   controller of its closed loop (blocks=)
=================  ==========================================  ============================
"""

from __future__ import annotations

from typing import Any, ClassVar

from .driver import _ModuleIntegrator

__all__ = ["EventDriven", "MoreauJean", "ImplicitEuler", "Switching", "SampledZOH"]


class EventDriven(_ModuleIntegrator):
    """Flow until the next event, apply the jump (:mod:`nscontrol.simulate.event_driven`)."""

    name = "event_driven"
    module = "nscontrol.simulate.event_driven"
    # sensitivity: LagrangianSystem only (DOP853 with the variational equation); the
    # integrator refuses it for the other systems with a ModelError
    capabilities = frozenset({"events", "exact_flow", "listeners", "multipliers",
                              "sensitivity"})
    # blocks: internal, a closed loop's static law set by the python_blocks lowering
    options: ClassVar[frozenset[str]] = frozenset(
        {"u", "blocks", "dt", "max_events", "min_interval", "zeno_ratio_tol",
         "zeno_horizon", "zeno_rel", "rtol", "atol"})

    @classmethod
    def supports(cls, system: Any) -> bool:   # ImpactingBodies: lowering.impacting_bodies
        from ..systems.hybrid import LinearHybridSystem
        from ..systems.lagrangian import LagrangianSystem

        return isinstance(system, LinearHybridSystem | LagrangianSystem)

    @classmethod
    def systems(cls) -> str:
        return "LinearHybridSystem, LagrangianSystem and ImpactingBodies"


class MoreauJean(_ModuleIntegrator):
    """Event-capturing time-stepping with one LCP a step
    (:mod:`nscontrol.simulate.moreau_jean`)."""

    name = "moreau_jean"
    module = "nscontrol.simulate.moreau_jean"
    capabilities = frozenset({"time_stepping", "listeners", "multipliers"})
    # blocks: the BlockRunner of a closed loop, set by the python_blocks lowering
    options: ClassVar[frozenset[str]] = frozenset(
        {"h", "theta", "gamma", "u", "activation", "forces", "mass_at", "projection",
         "contact_tol", "blocks"})

    @classmethod
    def supports(cls, system: Any) -> bool:   # ImpactingBodies: lowering.impacting_bodies
        from ..systems.lagrangian import LagrangianSystem

        return isinstance(system, LagrangianSystem)

    @classmethod
    def systems(cls) -> str:
        return "LagrangianSystem and ImpactingBodies"


class ImplicitEuler(_ModuleIntegrator):
    """The θ-method on a Lur'e system, one inclusion a step
    (:mod:`nscontrol.simulate.implicit_euler`)."""

    name = "implicit_euler"
    module = "nscontrol.simulate.implicit_euler"
    capabilities = frozenset({"time_stepping", "multipliers", "sensitivity"})
    # blocks: a closed loop's block runner, set by the python_blocks lowering (internal)
    options: ClassVar[frozenset[str]] = frozenset({"h", "theta", "u", "blocks"})

    @classmethod
    def supports(cls, system: Any) -> bool:
        from ..systems.lure import LureSystem

        return isinstance(system, LureSystem)

    @classmethod
    def systems(cls) -> str:
        return ("LureSystem (for PWA/Filippov/switched systems use method='switching', for "
                "mechanics 'moreau_jean')")


class Switching(_ModuleIntegrator):
    """Switched and piecewise-affine systems with located switchings
    (:mod:`nscontrol.simulate.switching`)."""

    name = "switching"
    module = "nscontrol.simulate.switching"
    capabilities = frozenset({"events", "exact_flow", "sensitivity", "t_eval"})
    options: ClassVar[frozenset[str]] = frozenset(
        {"u", "n_samples", "rtol", "atol", "max_events", "max_steps", "min_rel_step"})
    pass_through: ClassVar[frozenset[str]] = frozenset({"progress"})

    @classmethod
    def supports(cls, system: Any) -> bool:
        from ..systems.nonlinear import NonlinearSystem
        from ..systems.pwa import PiecewiseAffineSystem
        from ..systems.switched import FilippovSystem, SwitchedAffineSystem

        return isinstance(system, PiecewiseAffineSystem | FilippovSystem | SwitchedAffineSystem
                          | NonlinearSystem)

    @classmethod
    def systems(cls) -> str:
        return ("PiecewiseAffineSystem, FilippovSystem, SwitchedAffineSystem and "
                "NonlinearSystem (for Lur'e systems use method='implicit_euler')")


class SampledZOH(_ModuleIntegrator):
    """A plant and a sampled controller, the plant stepped exactly over each period with the
    controller's output held (:mod:`nscontrol.simulate.sampled_zoh`)."""

    name = "sampled_zoh"
    module = "nscontrol.simulate.sampled_zoh"
    capabilities = frozenset({"exact_flow"})
    # blocks: the loop's sampled controller (its BlockRunner), set by the python_blocks
    # lowering (internal)
    options: ClassVar[frozenset[str]] = frozenset({"blocks"})

    @classmethod
    def supports(cls, system: Any) -> bool:
        """A ``SlidingModePlant`` (its loop's blocks come as ``blocks=``, from the lowering
        of ``closed_loop(plant, controller)``)."""
        from ..systems.sliding_mode import SlidingModePlant

        return isinstance(system, SlidingModePlant)

    @classmethod
    def systems(cls) -> str:
        return ("closed_loop(plant, controller) of a SlidingModePlant and a sampled "
                "controller")
