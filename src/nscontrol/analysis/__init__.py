"""Analysis: observability, convergence, periodic orbits, Floquet multipliers, sweeps of
trajectories against a theorem's claim.

Every public name is importable from here (``from nscontrol.analysis import ...``);
the defining module loads on first use, so importing the package stays cheap.
"""

from __future__ import annotations

from .._lazy import lazy_exports

#: Public name -> the module of this package that defines it.
_EXPORTS: dict[str, str] = {
    # chattering.py
    "chattering_amplitude": "chattering", "switching_frequency": "chattering",
    "fitted_order": "chattering", "OrderFit": "chattering", "reaching_time": "chattering",
    # observability.py
    "Theorem1Result": "observability", "ReconstructibilityResult": "observability",
    "EpsilonCertificate": "observability", "DecayMeasurement": "observability",
    "RANK_RTOL": "observability", "theorem1_test": "observability",
    "impact_observability": "observability", "pbh_observability": "observability",
    "reconstructibility": "observability", "jury_second_order": "observability",
    "alpha_limit": "observability", "observer_flow_norms": "observability",
    "search_epsilon": "observability", "certified_rate": "observability",
    "impact_decay_rate": "observability", "impact_error_contraction": "observability",
    "ErrorContraction": "observability", "ROUNDING_PER_STATE": "observability",
    "MAX_RELATIVE_ROUNDING": "observability",
    # pwl_maps.py
    "coherent_orientation": "pwl_maps", "preimage_counts": "pwl_maps",
    "HomeomorphismReport": "pwl_maps", "homeomorphism_report": "pwl_maps",
    "CrossingRatios": "pwl_maps", "crossing_ratios": "pwl_maps",
    "linear_reference": "pwl_maps", "conjugacy_error": "pwl_maps",
    # convergence.py
    "ConvergenceCertificate": "convergence", "quadratic_convergence": "convergence",
    "decay_rate": "convergence", "BimodalTests": "convergence", "bimodal_tests": "convergence",
    "product_test": "convergence", "circle_test": "convergence",
    "circle_criterion_minimum": "convergence", "most_negative_real_eigenvalue": "convergence",
    "bisect_boundary": "convergence", "SteadyStateBound": "convergence", "isc_gain": "convergence",
    "peak_to_peak_bound": "convergence", "incremental_l2_bound": "convergence",
    "equilibrium": "convergence",
    # periodic.py
    "PeriodicOrbit": "periodic", "periodic_steady_state": "periodic",
    "UniquenessCheck": "periodic", "check_uniqueness": "periodic", "BruteForceResult": "periodic",
    "brute_force_steady_state": "periodic", "period_multiplicity": "periodic",
    "refined_peak": "periodic", "dft_harmonics": "periodic", "HarmonicResponse": "periodic",
    "harmonic_response": "periodic", "FrequencyResponse": "periodic",
    "frequency_response": "periodic", "frequency_sweep": "periodic",
    # attenuation.py
    "VelocityGainThreshold": "attenuation", "min_velocity_gain": "attenuation",
    "response_amplitude": "attenuation", "local_maxima": "attenuation",
    "AttenuationReport": "attenuation", "attenuation_report": "attenuation",
    "AttenuationTradeoff": "attenuation", "attenuation_tradeoff": "attenuation",
    # orbits.py
    "Forced": "orbits", "MapResult": "orbits", "Orbit": "orbits", "stroboscopic_map": "orbits",
    "find_orbit": "orbits", "Cycle": "orbits", "find_cycle": "orbits", "SectionReturn": "orbits",
    "Autonomous": "orbits",
    "hyperplane_map": "orbits", "floquet_multipliers": "orbits",
    # saltation.py
    "saltation_matrix": "saltation", "impact_jump_jacobian": "saltation",
    "impact_velocity": "saltation",
    "time_shift_term": "saltation",
    # continuation.py
    "SpecialPoint": "continuation", "Branch": "continuation", "continue_orbit": "continuation",
    "switch_at_flip": "continuation",
    # equilibria.py
    "EquilibriumPoint": "equilibria",
    "continue_equilibrium": "equilibria",
    # bifurcation.py
    "BifurcationDiagram": "bifurcation", "bifurcation_diagram": "bifurcation",
    "parse_grid": "bifurcation",
    # converter_orbits.py
    "ZADFamily": "converter_orbits", "DutyDiagram": "converter_orbits",
    "duty_diagram": "converter_orbits", "duty_period": "converter_orbits",
    "brute_force_flip": "converter_orbits", "multiplier_branch": "converter_orbits",
    "mean_error_against_period": "converter_orbits",
    # impact_oscillator.py
    "ImpactOscillator": "impact_oscillator", "OneImpactOrbit": "impact_oscillator",
    "OscillatorFamily": "impact_oscillator",
    # posture_certificate.py
    "PostureCertificate": "posture_certificate", "posture_certificate": "posture_certificate",
    "gain_threshold": "posture_certificate", "KineticAngleReport": "posture_certificate",
    "kinetic_angle_condition": "posture_certificate",
    "ConstrainedMinimum": "posture_certificate", "constrained_minimum": "posture_certificate",
    # tracking_cycles.py
    "ImpactEvent": "tracking_cycles", "CycleReport": "tracking_cycles",
    "WeakStabilityVerdict": "tracking_cycles", "impact_events": "tracking_cycles",
    "cycle_reports": "tracking_cycles", "accumulation_estimate": "tracking_cycles",
    "check_weak_stability": "tracking_cycles", "free_phase_growth": "tracking_cycles",
    "PHASE_NAMES": "tracking_cycles",
    # friction_equilibria.py
    "ExactCompensationCondition": "friction_equilibria",
    "exact_compensation_condition": "friction_equilibria",
    "observer_error_bound": "friction_equilibria",
    "stick_margin": "friction_equilibria",
    "stick_equilibria": "friction_equilibria",
    "equilibrium_halfwidth": "friction_equilibria",
    "LureForm": "friction_equilibria",
    "closed_loop_lure_form": "friction_equilibria",
    "lure_form_certificate": "friction_equilibria",
    "limit_cycle_summary": "friction_equilibria",
    # corner_maps.py
    "corner_gain": "corner_maps", "gain_for_corner_gain": "corner_maps",
    "crossing_gain_interval": "corner_maps", "reachable_multipliers": "corner_maps",
    "CornerDiscontinuityMap": "corner_maps", "corner_discontinuity_map": "corner_maps",
    "PWLFixedPoint": "corner_maps", "PWLReturnMap": "corner_maps", "Section": "corner_maps",
    "CornerSite": "corner_maps", "corner_site": "corner_maps", "section_returns": "corner_maps",
    "ControlledCycle": "corner_maps", "controlled_cycle": "corner_maps",
    "wedge_events": "corner_maps", "verify_corner_design": "corner_maps",
    "CornerFamily": "corner_maps", "CornerDiagram": "corner_maps",
    "corner_diagram": "corner_maps",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
