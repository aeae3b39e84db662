"""Nonsmooth laws: set-valued maximal monotone maps (relay, normal cones, complementarity,
Coulomb friction, monotone functions, products), their resolvents and complementarity forms,
and impact laws (Newton restitution, single and multi-contact).

Every public name is importable from here (``from nscontrol.laws import ...``);
the defining module loads on first use, so importing the package stays cheap.
"""

from __future__ import annotations

from .._lazy import lazy_exports

#: Public name -> the module of this package that defines it.
_EXPORTS: dict[str, str] = {
    # base.py
    "SetValuedLaw": "base", "ComplementarityForm": "base", "LoopTransformation": "base",
    "require_monotone": "base",
    # relay.py
    "Relay": "relay",
    # normal_cone.py
    "NormalConeBox": "normal_cone", "NormalConeInterval": "normal_cone",
    "Complementarity": "normal_cone",
    # friction.py
    "Coulomb": "friction", "Stribeck": "friction", "AsymmetricStribeck": "friction",
    # monotone_function.py
    "MonotoneFunction": "monotone_function", "PiecewiseLinearFunction": "monotone_function",
    # super_twisting.py
    "SuperTwistingLaw": "super_twisting", "super_twisting_resolvent": "super_twisting",
    # product.py
    "Product": "product",
    # inclusion.py
    "solve_inclusion": "inclusion", "InclusionSolution": "inclusion",
    # impact.py
    "NewtonImpactLaw": "impact", "ImpactResult": "impact", "restitution_matrix": "impact",
    "delassus_matrix": "impact", "impact_energy_change": "impact",
}

__all__ = list(_EXPORTS)


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
