"""Models, validated at construction: mechanical systems with impacts, linear hybrid systems,
Lur'e systems, piecewise-affine, Filippov and switched affine systems, and smooth nonlinear
flows.

Every public name is importable from here (``from nscontrol.systems import ...``);
the defining module loads on first use, so importing the package stays cheap.
"""

from __future__ import annotations

from .._lazy import lazy_exports

#: Public name -> the module of this package that defines it.
_EXPORTS: dict[str, str] = {
    # lure.py
    "LureSystem": "lure",
    # one_link.py
    "OneLinkRobot": "one_link",
    # pwa.py
    "PiecewiseAffineSystem": "pwa", "CONTINUITY_RTOL": "pwa",
    # conewise.py
    "ConewiseLinearSystem": "conewise", "Facet": "conewise", "orthant_cones": "conewise",
    # beam.py
    "OneSidedSpring": "beam", "MechanicalPWL": "beam", "Unbalance": "beam",
    "two_mode_beam": "beam", "beam_fe_model": "beam",
    # switched.py
    "FilippovSystem": "switched", "SwitchedAffineSystem": "switched", "PWMController": "switched",
    # nonlinear.py
    "NonlinearSystem": "nonlinear",
    # buck.py
    "BuckConverter": "buck",
    # lagrangian.py
    "LagrangianSystem": "lagrangian", "CompiledModel": "lagrangian",
    "affine_compiled_model": "lagrangian",
    "two_link_arm_mass": "lagrangian",
    "two_link_arm_coriolis": "lagrangian", "two_link_arm_gravity": "lagrangian",
    "two_link_arm_force_jacobian": "lagrangian",
    # frictional_bodies.py
    "inclined_block": "frictional_bodies", "rolling_disk": "frictional_bodies",
    "rolling_sphere": "frictional_bodies", "brick_stack": "frictional_bodies",
    "brick_stack_rest_state": "frictional_bodies",
    # two_link.py
    "TwoLinkParams": "two_link", "TwoLinkArm": "two_link", "OneDofMass": "two_link",
    # impacting_bodies.py
    "ImpactingBodies": "impacting_bodies", "stiffness_from_springs": "impacting_bodies",
    # hybrid.py
    "LinearHybridSystem": "hybrid",
    # closed_loop.py (its function closed_loop is nscontrol.closed_loop: the module's name)
    "ClosedLoop": "closed_loop",
    # feedback.py
    "Measurement": "feedback", "Jump": "feedback", "Controller": "feedback",
    "StaticLaw": "feedback",
    "Observer": "feedback", "StateFeedback": "feedback", "PiecewiseStateFeedback": "feedback",
    "LinearController": "feedback", "LinearObserver": "feedback",
    "PiecewiseObserver": "feedback", "CompiledBlock": "feedback", "compiled_form": "feedback",
    # foot_body.py
    "ActuatedContactModel": "foot_body", "FootBodyParameters": "foot_body",
    "foot_body_model": "foot_body", "foot_body_points": "foot_body",
    "wall_mass_model": "foot_body",
    # sliding_mode.py
    "SlidingModePlant": "sliding_mode", "differentiator_loop": "sliding_mode",
    # protocols.py
    "SimulableSystem": "protocols", "StateChecked": "protocols", "InputFunction": "protocols",
    "Exogenous": "protocols", "InputSignal": "protocols",
    # wedge.py
    "Wedge": "wedge", "WedgeSwitchedSystem": "wedge", "with_marker_line": "wedge",
    "marker_crossings": "wedge", "cross": "wedge",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
