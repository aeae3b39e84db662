"""Numerical kernels: complementarity solvers (:mod:`.lcp`), exact LTI propagation and root
location (:mod:`.lti`), LMI helpers on CVXPY and the Lyapunov re-check (:mod:`.lmi`),
balancing and scaling (:mod:`.scaling`), observability tests
(:mod:`~nscontrol.numerics.observability`), central differences (:mod:`.differences`),
saltation matrices and the transition term of a sampled switching instant
(:mod:`~nscontrol.numerics.saltation`)."""

# Also the converter from state-space objects such as python-control's StateSpace
# (statespace.py). Every public name is importable from here (from nscontrol.numerics import
# ...); the defining module loads on first use, so importing the package stays cheap.

from __future__ import annotations

from .._lazy import lazy_exports

#: Public name -> the module of this package that defines it.
_EXPORTS: dict[str, str] = {
    # lcp.py
    "LCPResult": "lcp", "LCPSolver": "lcp", "solve_lcp": "lcp", "residual": "lcp",
    "solve_lcp_kernel": "lcp",
    # friction_contact.py
    "FrictionContactResult": "friction_contact", "solve_friction_contact": "friction_contact",
    "friction_residual": "friction_contact", "contact_states": "friction_contact",
    "planar_friction_lcp": "friction_contact", "CONTACT_STATES": "friction_contact",
    "frictionless_impulses": "friction_contact", "FrictionContactSolver": "friction_contact",
    # lti.py
    "Exosystem": "lti", "augment": "lti", "LTIFlow": "lti", "discretize": "lti",
    "Discretization": "lti", "GuardEvent": "lti", "first_event": "lti",
    "project_restart": "lti",
    # lmi.py
    "LMIProblem": "lmi", "LMIResult": "lmi", "BisectionResult": "lmi", "LyapunovCheck": "lmi",
    "LYAPUNOV_RECHECK_RTOL": "lmi", "bisect_max": "lmi", "lyapunov_certificate": "lmi",
    "max_lyapunov_decay_rate": "lmi", "recheck_lyapunov": "lmi", "sym": "lmi",
    "SDP_SOLVERS": "lmi", "solver_order": "lmi", "solver_options": "lmi",
    "fallback_hint": "lmi", "SCS_INSTALL_HINT": "lmi",
    # scaling.py
    "balance": "scaling", "balanced_unit_norm": "scaling", "Scaling": "scaling",
    # observability.py
    "RANK_RTOL": "observability", "pbh_observability": "observability",
    "krylov_basis": "observability",
    # statespace.py
    "StateSpaceMatrices": "statespace", "is_state_space": "statespace",
    "state_space_matrices": "statespace", "state_matrix": "statespace",
    "state_space_names": "statespace",
    # differences.py
    "central_difference_gradient": "differences", "central_difference_jacobian": "differences",
    # saltation.py
    "saltation_matrix": "saltation", "impact_jump_jacobian": "saltation",
    "impact_velocity": "saltation", "time_shift_term": "saltation",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
