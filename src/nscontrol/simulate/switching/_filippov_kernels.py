"""The Filippov convex combination, the one source of the sliding field of
:mod:`nscontrol.simulate.switching`: the Python path (:mod:`._filippov`) calls it at every
evaluation of a sliding piece's field and at a sliding start, and the compiled path
(:mod:`._affine_filippov`) builds the sliding mode's affine flow from its values.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def filippov_combination(sm, sp, fm, fp):  # pragma: no cover - compiled
    """``(σ⁺F⁻ - σ⁻F⁺) / (σ⁺ - σ⁻)`` for the sides' fields ``F±`` and their normal
    components ``σ±`` (a new array)."""
    den = sp - sm
    out = np.empty(fm.shape[0])
    for c in range(fm.shape[0]):
        out[c] = (sp * fm[c] - sm * fp[c]) / den
    return out


@njit(cache=True)
def filippov_field(fm, fp, normal):  # pragma: no cover - compiled
    """The Filippov field ``F_s`` on a surface of normal ``n``: the convex combination of the
    two sides' fields tangent to it, ``σ± = nᵀF±`` (a new array)."""
    sm = 0.0
    sp = 0.0
    for c in range(normal.shape[0]):
        sm += normal[c] * fm[c]
        sp += normal[c] * fp[c]
    return filippov_combination(sm, sp, fm, fp)
