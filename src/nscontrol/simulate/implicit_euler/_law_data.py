"""What the compiled steps read of a set-valued law: its componentwise kinds and parameters
(closed-form resolvents), its per-step LCP (complementarity form), and its parts."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError

__all__ = ["componentwise_spec", "curve_parameters", "lcp_step_data", "law_parts"]


def componentwise_spec(law: Any) -> tuple[np.ndarray, FloatArray, FloatArray] | None:
    """The compiled description of a law that acts componentwise with a known resolvent.

    Parameters
    ----------
    law : SetValuedLaw
        A relay, Coulomb, interval/box normal cone, complementarity law or a product of them.

    Returns
    -------
    (kind, p1, p2) or None
        Per component: ``kind[i] = 0`` for ``c Sign`` with ``c = p1[i]`` (relay, Coulomb),
        ``kind[i] = 1`` for the normal cone of ``[p1[i], p2[i]]`` (complementarity:
        ``[0, inf)``), ``kind[i] = 2`` for a monotone set-valued Stribeck law (its parameters
        in :func:`curve_parameters`). ``None`` for any other law.

    Examples
    --------
    >>> from nscontrol.laws.normal_cone import Complementarity
    >>> from nscontrol.laws.product import Product
    >>> from nscontrol.laws.relay import Relay
    >>> kind, p1, p2 = componentwise_spec(Product(Relay(2.0), Complementarity(1)))
    >>> kind.tolist(), p1.tolist(), p2.tolist()
    ([0, 1], [2.0, 0.0], [0.0, inf])
    """
    from ...laws.friction import Stribeck
    from ...laws.normal_cone import NormalConeBox
    from ...laws.product import Product
    from ...laws.relay import Relay

    if isinstance(law, Product):
        specs = [componentwise_spec(p) for p in law.parts]
        parts = [p for p in specs if p is not None]
        if len(parts) < len(specs):
            return None
        kinds, p1, p2 = (np.concatenate([p[i] for p in parts]) for i in range(3))
        return kinds, p1, p2
    m = int(law.dim)
    if isinstance(law, Relay):  # Coulomb is a Relay of bound mu·N
        return np.zeros(m, np.int64), _per_component(law.bound, m), np.zeros(m)
    if isinstance(law, NormalConeBox):
        return (np.ones(m, np.int64), _per_component(law.lower, m),
                _per_component(law.upper, m))
    if isinstance(law, Stribeck) and law.monotone:   # parameters in curve_parameters(law)
        return np.full(m, 2, np.int64), np.zeros(m), np.zeros(m)
    return None


def curve_parameters(law: Any) -> FloatArray:
    """The parameters of the monotone Stribeck components of ``law``.

    Parameters
    ----------
    law : SetValuedLaw
        A law whose :func:`componentwise_spec` is not ``None``.

    Returns
    -------
    (m, 5) ndarray
        Per component ``(T_s, T_c, omega_s, delta, b)`` for kind 2, zeros for the others.
    """
    from ...laws.friction import Stribeck
    from ...laws.product import Product

    parts = law.parts if isinstance(law, Product) else [law]
    rows = []
    for part in parts:
        if isinstance(part, Stribeck):
            rows.append(np.column_stack([part.static, part.coulomb, part.stribeck_velocity,
                                         part.delta, part.viscous]))
        else:
            rows.append(np.zeros((int(part.dim), 5)))
    return np.ascontiguousarray(np.vstack(rows), dtype=np.float64)


def _per_component(value: Any, m: int) -> FloatArray:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, float), (m,)), dtype=float)


def lcp_step_data(law: Any, Dh: FloatArray) -> tuple[FloatArray, ...] | None:
    """The per-step LCP of the inclusion ``w ∈ -φ(a + D_h w)``, from the law's complementarity
    form.

    Parameters
    ----------
    law : SetValuedLaw
        The law ``φ``.
    Dh : (m, m) ndarray
        The one-step matrix.

    Returns
    -------
    (M, Qa, q0, T, s) or None
        The LCP ``0 <= ξ ⟂ Mξ + Qa·a + q0 >= 0`` and the multiplier ``w = Tξ + s``; ``None``
        when the law has no complementarity form (curved graphs).

    Notes
    -----
    With the form ``w = w0 + Eξ``, ``η = Nz z + Nξ ξ + r``: ``M = Nz D_h E + Nξ``, ``Qa = Nz``,
    ``q0 = Nz D_h w0 + r``, ``T = E``, ``s = w0``; ``M`` is monotone when ``D_h`` is.

    Examples
    --------
    >>> from nscontrol.laws.normal_cone import Complementarity
    >>> M, Qa, q0, T, s = lcp_step_data(Complementarity(1), np.array([[2.0]]))
    >>> M.tolist(), Qa.tolist(), T.tolist()
    ([[2.0]], [[1.0]], [[1.0]])
    """
    try:
        form = law.complementarity_form()
    except ModelError:
        return None
    M = form.Nz @ Dh @ form.E + form.Nxi
    q0 = form.Nz @ Dh @ form.w0 + form.r
    return (np.ascontiguousarray(M), np.ascontiguousarray(form.Nz), q0,
            np.ascontiguousarray(form.E), np.asarray(form.w0, float).copy())


def law_parts(law: Any) -> list[tuple[slice, Any]]:
    """The parts of ``law`` with their slices of the law's components.

    Parameters
    ----------
    law : SetValuedLaw
        A ``Product`` (its parts) or any other law (itself, one part).

    Returns
    -------
    list of (slice, SetValuedLaw)
    """
    from ...laws.product import Product

    if isinstance(law, Product):
        return list(zip(law._slices, law.parts, strict=True))
    return [(slice(0, int(law.dim)), law)]
