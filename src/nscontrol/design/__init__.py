"""Designs: one module per method family; each returns a design object holding the gains and
the re-checked certificate, able to build its closed loop.

Every public name is importable from here (``from nscontrol.design import ...``);
the defining module loads on first use, so importing the package stays cheap.
"""

from __future__ import annotations

from .._lazy import lazy_exports

#: Public name -> the module of this package that defines it.
_EXPORTS: dict[str, str] = {
    # sliding_mode.py
    "super_twisting_gains": "sliding_mode", "FirstOrderSMC": "sliding_mode",
    "SuperTwistingController": "sliding_mode", "LevantDifferentiator": "sliding_mode",
    "differentiate": "sliding_mode", "run_sampled": "sliding_mode",
    # impact_conditions.py
    "Theorem1Result": "impact_conditions", "EpsilonCertificate": "impact_conditions",
    "theorem1_test": "impact_conditions", "jury_second_order": "impact_conditions",
    "alpha_limit": "impact_conditions", "observer_flow_norms": "impact_conditions",
    "search_epsilon": "impact_conditions", "certified_rate": "impact_conditions",
    # impact_observer.py
    "ImpactPlant": "impact_observer", "PlacementConditioning": "impact_observer",
    "ScaledPlacement": "impact_observer", "ImpactObserverDesign": "impact_observer",
    "DeadbeatEstimate": "impact_observer", "impact_plant": "impact_observer",
    "place_scaled": "impact_observer", "certificate_velocity_scale": "impact_observer",
    "design_impact_observer": "impact_observer", "observer_jump": "impact_observer",
    "deadbeat_n1": "impact_observer", "deadbeat_1n": "impact_observer",
    # lure_observer.py
    "LureObserverCertificate": "lure_observer", "LureObserverDesign": "lure_observer",
    "structural_infeasibility": "lure_observer", "lure_observer_lmi": "lure_observer",
    "max_observer_decay_rate": "lure_observer", "design_lure_observer": "lure_observer",
    "lure_from_statespace": "lure_observer", "loop_transformed_lure_system": "lure_observer",
    "observer_from_gains": "lure_observer", "recheck_lure_certificate": "lure_observer",
    # friction_compensation.py
    "SetPoint": "friction_compensation",
    "Sinusoid": "friction_compensation",
    "PDLaw": "friction_compensation",
    "compensation_model": "friction_compensation",
    "FrictionCompensatingPD": "friction_compensation",
    "ReducedOrderVelocityObserver": "friction_compensation",
    "OneLinkGains": "friction_compensation",
    "one_link_gains": "friction_compensation",
    "FrictionLoopRun": "friction_compensation",
    "simulate_friction_loop": "friction_compensation",
    "friction_loop": "friction_compensation",
    # pwl_linearization.py
    "FEEDBACK_CLASSES": "pwl_linearization", "PWLLinearization": "pwl_linearization",
    "LinearizationResult": "pwl_linearization", "pwl_feedback_linearize": "pwl_linearization",
    "linearize_or_raise": "pwl_linearization", "brunovsky": "pwl_linearization",
    "input_generator": "pwl_linearization",
    # convergent_pwa.py
    "ConvergentStateFeedback": "convergent_pwa", "PWAStateFeedback": "convergent_pwa",
    "ConvergentObserver": "convergent_pwa", "EstimateFeedback": "convergent_pwa",
    "design_state_feedback": "convergent_pwa", "design_pwa_state_feedback": "convergent_pwa",
    "design_state_feedback_l2": "convergent_pwa",
    "tune_pwa_state_feedback": "convergent_pwa", "design_observer": "convergent_pwa",
    "output_feedback_loop": "convergent_pwa",
    # beam_attenuation.py
    "AttenuationDesign": "beam_attenuation", "LinearLaw": "beam_attenuation",
    "beam_scaling": "beam_attenuation", "design_attenuation": "beam_attenuation",
    "pd_gain": "beam_attenuation",
    # contact_posture.py
    "StaticPostureDesign": "contact_posture", "ContactRegulator": "contact_posture",
    "static_contact_forces": "contact_posture", "design_contact_regulator": "contact_posture",
    # complementarity_tracking.py
    "PBCGains": "complementarity_tracking", "TransitionDesign": "complementarity_tracking",
    "ContactPhaseDesign": "complementarity_tracking",
    "CyclicTask": "complementarity_tracking", "CircleTask": "complementarity_tracking",
    "HalfSineTask": "complementarity_tracking", "TaskSpaceModel": "complementarity_tracking",
    "SwitchingTrackingController": "complementarity_tracking",
    "TrackingCycle": "complementarity_tracking",
    "slotine_li_force": "complementarity_tracking",
    "lyapunov_decay_rate": "complementarity_tracking",
    "virtual_dive": "complementarity_tracking", "liftoff_blend": "complementarity_tracking",
    # limit_cycle_switching.py
    "corner_gain": "limit_cycle_switching", "gain_for_corner_gain": "limit_cycle_switching",
    "crossing_gain_interval": "limit_cycle_switching",
    "reachable_multipliers": "limit_cycle_switching",
    "CornerDiscontinuityMap": "limit_cycle_switching",
    "corner_discontinuity_map": "limit_cycle_switching",
    "PWLFixedPoint": "limit_cycle_switching", "PWLReturnMap": "limit_cycle_switching",
    "Section": "limit_cycle_switching", "CornerSite": "limit_cycle_switching",
    "corner_site": "limit_cycle_switching", "CornerDesign": "limit_cycle_switching",
    "design_corner_controller": "limit_cycle_switching",
    "SLIDING_GAIN_FACTOR": "limit_cycle_switching",
    # converter_regulation.py
    "ZADController": "converter_regulation", "ZADLoopMap": "converter_regulation",
    "ZADOrbit": "converter_regulation", "ZADRun": "converter_regulation",
    "ZADDesign": "converter_regulation", "zad_flip_coefficients": "converter_regulation",
    "zad_flip_boundary": "converter_regulation", "zad_multipliers_series": "converter_regulation",
    "leading_duty": "converter_regulation", "critical_ks": "converter_regulation",
    "design_zad": "converter_regulation",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
