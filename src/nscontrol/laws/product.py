"""Products of laws: ``phi(z) = phi_1(z_1) x … x phi_k(z_k)`` on stacked components."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import FloatArray, as_vector
from ..errors import ModelError
from .base import (
    ComplementarityForm,
    LoopTransformation,
    SetValuedLaw,
    as_gamma,
    broadcast_parameter,
)

__all__ = ["Product"]


class Product(SetValuedLaw):
    """The product law acting on consecutive blocks of components, one block per part.

    ``z = [z_1; ...; z_k]`` with ``z_j`` of length ``parts[j].dim``; everything (resolvent,
    residual, selection, complementarity form, loop transformation) acts blockwise. A plant +
    observer closed loop uses ``Product(plant_law, observer_law)``.

    Parameters
    ----------
    *laws
        The parts (at least one :class:`SetValuedLaw`). Nested products are flattened.
    """

    def __init__(self, *laws: SetValuedLaw) -> None:
        if not laws:
            raise ModelError("laws: Product needs at least one law, got none")
        flat: list[SetValuedLaw] = []
        for i, law in enumerate(laws):
            if not isinstance(law, SetValuedLaw):
                raise ModelError(f"laws[{i}]: expected a SetValuedLaw, got {type(law).__name__}")
            flat.extend(law.parts if isinstance(law, Product) else (law,))
        self.parts: tuple[SetValuedLaw, ...] = tuple(flat)
        self.dim = sum(p.dim for p in flat)
        self.monotone = all(p.monotone for p in flat)
        self.componentwise = all(p.componentwise for p in flat)
        self._slices = tuple(slice(s - p.dim, s) for p, s in
                             zip(flat, np.cumsum([p.dim for p in flat]), strict=True))

    def __setattr__(self, name: str, value: Any) -> None:
        if hasattr(self, "_slices"):
            raise AttributeError(f"Product is immutable; cannot set {name!r}")
        super().__setattr__(name, value)

    def split(self, x: FloatArray) -> list[FloatArray]:
        """The blocks of a stacked vector, one per part."""
        return [x[s] for s in self._slices]

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        return np.concatenate([p._resolvent(x[s], gamma[s])
                               for p, s in zip(self.parts, self._slices, strict=True)])

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        return float(np.hypot.reduce([p._graph_distance(z[s], v[s])
                                      for p, s in zip(self.parts, self._slices, strict=True)]))

    def _in_domain(self, z: FloatArray, tol: float) -> bool:
        return all(p._in_domain(z[s], tol) for p, s in zip(self.parts, self._slices, strict=True))

    def _select(self, z: FloatArray) -> FloatArray:
        return np.concatenate([p._select(z[s])
                               for p, s in zip(self.parts, self._slices, strict=True)])

    def resolvent(self, x: ArrayLike, gamma: ArrayLike = 1.0) -> FloatArray:
        """Blockwise resolvent; ``gamma`` may be a vector when every part accepts one for its
        block (a non-componentwise part needs a constant ``gamma`` on its block)."""
        x = as_vector("x", x, self.dim)
        g = as_gamma(gamma, self.dim)
        for p, s in zip(self.parts, self._slices, strict=True):
            if not p.componentwise and np.ptp(g[s]) > 0.0:
                raise ModelError(f"gamma: part {p!r} is not componentwise, so gamma must be "
                                 f"constant on its block, got {g[s]}")
        return self._resolvent(x, g)

    def complementarity_form(self) -> ComplementarityForm:
        """The parts' forms side by side (``ModelError`` if a part has none)."""
        return ComplementarityForm.block_diagonal([p.complementarity_form() for p in self.parts])

    def loop_transformation(self, sigma: ArrayLike | None = None) -> LoopTransformation:
        """Blockwise loop transformation; monotone parts keep zero slope.

        ``sigma`` (optional) is the stacked vector of slopes, split over the parts.
        """
        sig = None if sigma is None else broadcast_parameter("sigma", sigma, self.dim)
        splits = [p.loop_transformation(None if sig is None or (p.monotone and not np.any(sig[s]))
                                        else sig[s])
                  for p, s in zip(self.parts, self._slices, strict=True)]
        return LoopTransformation(monotone_part=Product(*(t.monotone_part for t in splits)),
                                  slope=np.concatenate([t.slope for t in splits]))

    def __repr__(self) -> str:
        return "Product(" + ", ".join(repr(p) for p in self.parts) + ")"
