"""The set-valued laws in one namespace (the pinned import path ``nscontrol.laws.set_valued``).

Each concept lives in its own module (``base``, ``relay``, ``normal_cone``, ``friction``,
``monotone_function``, ``product``, ``inclusion``); this module gathers them.
"""

from .base import ComplementarityForm, LoopTransformation, SetValuedLaw, require_monotone
from .friction import AsymmetricStribeck, Coulomb, Stribeck
from .inclusion import InclusionSolution, solve_inclusion
from .monotone_function import MonotoneFunction, PiecewiseLinearFunction
from .normal_cone import Complementarity, NormalConeBox, NormalConeInterval
from .product import Product
from .relay import Relay

__all__ = [
    "SetValuedLaw",
    "ComplementarityForm",
    "LoopTransformation",
    "require_monotone",
    "Relay",
    "NormalConeInterval",
    "NormalConeBox",
    "Complementarity",
    "Coulomb",
    "Stribeck",
    "AsymmetricStribeck",
    "MonotoneFunction",
    "PiecewiseLinearFunction",
    "Product",
    "solve_inclusion",
    "InclusionSolution",
]
