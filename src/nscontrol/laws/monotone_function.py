"""Single-valued nondecreasing laws ``phi(z)_i = f(z)_i``: a general continuous curve
(:class:`MonotoneFunction`) and the piecewise-linear case given by breakpoints
(:class:`PiecewiseLinearFunction`, e.g. a saturation), which has an exact complementarity form.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validation import FloatArray, as_float_array, as_real_scalar, as_vector
from ..errors import DimensionError, ModelError
from ._roots import solve_increasing
from .base import ComplementarityForm, SetValuedLaw, check_dim

__all__ = ["MonotoneFunction", "PiecewiseLinearFunction"]

_PROBE = np.linspace(-10.0, 10.0, 81)


@dataclass(frozen=True, eq=False)
class MonotoneFunction(SetValuedLaw):
    """A continuous nondecreasing function acting componentwise, as a (single-valued) law.

    Parameters
    ----------
    f
        Vectorised map ``R^dim -> R^dim`` whose component ``i`` depends on ``z_i`` only and is
        continuous and nondecreasing in it (e.g. ``np.tanh``, a saturation, ``z**3``).
    df
        Optional componentwise derivative ``f'(z)`` (speeds up the resolvent).
    dim
        Number of components.

    Notes
    -----
    The constructor samples ``f`` on ``[-10, 10]`` and refuses a function found decreasing
    there (a cheap check, not a proof). Resolvent: the root of ``z + gamma f(z) = x``, bracketed
    in ``[min(x, x - gamma f(x)), max(x, x - gamma f(x))]`` and found by safeguarded Newton to a
    few ulps. ``graph_residual`` is the vertical distance ``|v - f(z)|`` (an upper bound of the
    Euclidean distance, zero exactly on the graph).

    No complementarity form: an LCP has finitely many pieces (one per active set), each a
    polyhedron, so it encodes exactly the graphs made of finitely many straight pieces, and a
    curved ``f`` has none. For a piecewise-linear ``f`` (a saturation, a dead zone, any
    polyline) use :class:`PiecewiseLinearFunction`, which has an exact form. With a curved
    ``f`` the integrators use the resolvent instead: ``implicit_euler`` solves the one-step
    inclusion in closed form (this resolvent) when its step matrix is diagonal and by
    forward-backward splitting on resolvents otherwise; ``solve_inclusion`` refuses a full step
    matrix with a :class:`~nscontrol.errors.ModelError`.
    """

    f: Callable[[FloatArray], Any]
    df: Callable[[FloatArray], Any] | None = None
    dim: int = 1
    monotone = True
    componentwise = True

    def __post_init__(self) -> None:
        if not callable(self.f) or (self.df is not None and not callable(self.df)):
            raise ModelError(f"f, df: expected callables, got {type(self.f).__name__} and "
                             f"{type(self.df).__name__}")
        object.__setattr__(self, "dim", check_dim(self.dim))
        values = np.array([self._f(np.full(self.dim, s)) for s in _PROBE])
        drops = np.diff(values, axis=0)
        if np.any(drops < -1e-12 * np.maximum(1.0, np.abs(values[:-1]))):
            s = _PROBE[int(np.argmax(np.min(drops, axis=1) < 0))]
            raise ModelError(f"f: expected a nondecreasing function, but it decreases near "
                             f"z = {s:.3g}; a non-monotone law needs a loop transformation "
                             "(see Stribeck)")

    def _f(self, z: FloatArray) -> FloatArray:
        out = self.f(z)
        if not (isinstance(out, np.ndarray) and out.dtype == np.float64):
            out = as_float_array("f", out, finite=False)   # refuses complex/str output
        if out.shape != (self.dim,):
            raise DimensionError(f"f: expected an output of shape ({self.dim},), got {out.shape}")
        if not np.all(np.isfinite(out)):
            raise ModelError(f"f: returned non-finite values at z = {z}")
        return out

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        other = x - gamma * self._f(x)
        df = self.df
        dg = None if df is None else (lambda z: 1.0 + gamma * np.asarray(df(z), dtype=float))
        return solve_increasing(lambda z: z + gamma * self._f(z) - x, dg,
                                np.minimum(x, other), np.maximum(x, other))

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        return float(np.linalg.norm(v - self._f(z)))

    def _select(self, z: FloatArray) -> FloatArray:
        return self._f(z)

    def __repr__(self) -> str:
        return f"MonotoneFunction(f={getattr(self.f, '__name__', self.f)!r}, dim={self.dim})"

    def complementarity_form(self) -> ComplementarityForm:
        """Refused: a curved graph has no finite LCP encoding (see Notes of the class)."""
        raise ModelError(
            f"{self!r} has no complementarity (LCP) form: an LCP encodes only graphs made of "
            "finitely many straight pieces, and f is a general curve. For a piecewise-linear f "
            "use PiecewiseLinearFunction (exact LCP form); otherwise use the resolvent: "
            "solve_inclusion needs a diagonal positive step matrix M for this law, and "
            "implicit_euler falls back to forward-backward splitting on resolvents")


@dataclass(frozen=True, eq=False)
class PiecewiseLinearFunction(SetValuedLaw):
    """A continuous nondecreasing piecewise-linear function, the same on every component.

    ``f`` interpolates the points ``(breakpoints[j], values[j])`` linearly and continues with
    slope ``slope_left`` left of the first breakpoint and ``slope_right`` right of the last.
    A saturation is :meth:`saturation`; a dead zone is ``breakpoints=(-d, d)``,
    ``values=(0, 0)``, ``slope_left=slope_right=k``.

    Parameters
    ----------
    breakpoints
        Strictly increasing abscissae ``b_0 < ... < b_K`` (at least one).
    values
        ``f(b_j)``, nondecreasing, as many as ``breakpoints``.
    slope_left, slope_right
        Slopes ``>= 0`` of the two outer half-lines.
    dim
        Number of components (``f`` acts on each alike).

    Notes
    -----
    Resolvent, in closed form: ``z + gamma f(z)`` is piecewise linear and strictly increasing
    with nodes ``b_j + gamma f(b_j)``, so ``z = (I + gamma f)^{-1}(x)`` is the interpolation of
    ``b_j`` at those nodes (outer slopes ``1 / (1 + gamma s)``). ``graph_residual`` is the exact
    Euclidean distance to the polyline.

    Complementarity form, per component (with ``w = -f(z)``): ``f`` is ``f(b_0)`` plus the
    portions ``delta_j in [0, f(b_{j+1}) - f(b_j)]`` of its rising segments that ``z`` has
    filled, plus the outer half-lines::

        w = -f(b_0) + delta_L - sum_j delta_j - delta_R
        0 <= delta_L ⟂ z - b_0 + delta_L / s_L >= 0                     (s_L > 0)
        0 <= delta_j ⟂ delta_j / s_j + b_j - z + beta_j >= 0,
        0 <= beta_j  ⟂ f(b_{j+1}) - f(b_j) - delta_j >= 0                (rising segment j)
        0 <= delta_R ⟂ delta_R / s_R + b_K - z >= 0                     (s_R > 0)

    (``s_j`` the segment's slope; flat pieces need no variable). ``delta_j`` solves a
    box-constrained monotone problem, so it is ``clip(s_j (z - b_j), 0, Delta f_j)``: the sum is
    ``f(z)`` exactly. ``Nz = E^T``, so for ``z = M w + q`` the LCP matrix is
    ``E^T M E + Nxi`` with ``Nxi`` = diag(1/s) plus a skew part: positive semidefinite whenever
    ``M`` is, and Lemke's method solves it.

    Examples
    --------
    >>> sat = PiecewiseLinearFunction.saturation(level=1.0, slope=2.0)
    >>> sat.select([0.25]).tolist(), sat.select([3.0]).tolist()
    ([0.5], [1.0])
    >>> sat.resolvent([4.0], gamma=1.0).tolist()      # z + sat(z) = 4
    [3.0]
    >>> from nscontrol.laws.inclusion import solve_inclusion
    >>> law = PiecewiseLinearFunction.saturation(level=1.0, slope=2.0, dim=2)
    >>> sol = solve_inclusion(law, [[2.0, 1.0], [1.0, 2.0]], [1.0, -4.0])   # via its LCP form
    >>> sol.method, bool(sol.residual < 1e-12)
    ('lcp', True)
    """

    breakpoints: Any
    values: Any
    slope_left: Any = 0.0
    slope_right: Any = 0.0
    dim: int = 1
    monotone = True
    componentwise = True

    def __post_init__(self) -> None:
        b = as_vector("breakpoints", self.breakpoints)
        v = as_vector("values", self.values, size=b.shape[0])
        if b.shape[0] > 1 and np.any(np.diff(b) <= 0.0):
            i = int(np.argmax(np.diff(b) <= 0.0))
            raise ModelError(f"breakpoints: expected strictly increasing values, got "
                             f"breakpoints[{i}] = {b[i]} >= breakpoints[{i + 1}] = {b[i + 1]}")
        if b.shape[0] > 1 and np.any(np.diff(v) < 0.0):
            i = int(np.argmax(np.diff(v) < 0.0))
            raise ModelError(f"values: expected nondecreasing values (a monotone f), got "
                             f"values[{i}] = {v[i]} > values[{i + 1}] = {v[i + 1]}; a "
                             "non-monotone law needs a loop transformation (see Stribeck)")
        for name in ("slope_left", "slope_right"):
            s = as_real_scalar(name, getattr(self, name))
            if not (np.isfinite(s) and s >= 0.0):
                raise ModelError(f"{name}: expected a finite slope >= 0 (a monotone f), got "
                                 f"{getattr(self, name)!r}")
            object.__setattr__(self, name, s)
        object.__setattr__(self, "breakpoints", b)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "dim", check_dim(self.dim))

    @classmethod
    def saturation(cls, level: Any = 1.0, slope: Any = 1.0, dim: int = 1
                   ) -> PiecewiseLinearFunction:
        """``f(z) = clip(slope z, -level, level)`` (``level > 0``, ``slope > 0``)."""
        c = as_real_scalar("level", level)
        k = as_real_scalar("slope", slope)
        if not (np.isfinite(c) and c > 0.0):
            raise ModelError(f"level: expected a finite saturation level > 0, got {level!r}")
        if not (np.isfinite(k) and k > 0.0):
            raise ModelError(f"slope: expected a finite slope > 0, got {slope!r}")
        return cls((-c / k, c / k), (-c, c), 0.0, 0.0, dim)

    # -- evaluation -----------------------------------------------------------------------
    def _eval(self, z: FloatArray) -> FloatArray:
        b, v = self.breakpoints, self.values
        out = np.interp(z, b, v)
        out = np.where(z < b[0], v[0] + self.slope_left * (z - b[0]), out)
        return np.where(z > b[-1], v[-1] + self.slope_right * (z - b[-1]), out)

    def _resolvent(self, x: FloatArray, gamma: FloatArray) -> FloatArray:
        b, v = self.breakpoints, self.values
        nodes = b[None, :] + gamma[:, None] * v[None, :]          # (dim, K+1), increasing
        z = np.empty_like(x)
        for i in range(x.shape[0]):                              # K and dim are small
            z[i] = np.interp(x[i], nodes[i], b)
        left = x < nodes[:, 0]
        right = x > nodes[:, -1]
        z = np.where(left, b[0] + (x - nodes[:, 0]) / (1.0 + gamma * self.slope_left), z)
        return np.where(right, b[-1] + (x - nodes[:, -1]) / (1.0 + gamma * self.slope_right), z)

    def _pieces(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Polyline of the graph: segment starts ``P``, directions ``D`` and parameter caps
        (``inf`` for the two half-lines), as arrays of shape ``(K + 2, 2)``, ``(K + 2,)``."""
        b, v = self.breakpoints, self.values
        starts = [(b[0], v[0])] + [(b[j], v[j]) for j in range(b.shape[0] - 1)] + [(b[-1], v[-1])]
        dirs = [(-1.0, -self.slope_left)] + [(b[j + 1] - b[j], v[j + 1] - v[j])
                                            for j in range(b.shape[0] - 1)]
        dirs += [(1.0, self.slope_right)]
        caps = [np.inf] + [1.0] * (b.shape[0] - 1) + [np.inf]
        return np.array(starts), np.array(dirs), np.array(caps)

    def _graph_distance(self, z: FloatArray, v: FloatArray) -> float:
        P, D, cap = self._pieces()
        rel = np.stack([z[:, None] - P[None, :, 0], v[:, None] - P[None, :, 1]], axis=-1)
        t = np.clip(np.einsum("ikc,kc->ik", rel, D) / np.einsum("kc,kc->k", D, D), 0.0, cap)
        d = rel - t[:, :, None] * D[None, :, :]
        return float(np.linalg.norm(np.min(np.hypot(d[..., 0], d[..., 1]), axis=1)))

    def _select(self, z: FloatArray) -> FloatArray:
        return self._eval(z)

    def complementarity_form(self) -> ComplementarityForm:
        """The segment-filling encoding of the Notes (exact; PSD LCP for PSD steps)."""
        b, fv, m = self.breakpoints, self.values, self.dim
        cols: list[tuple[str, float, Any]] = []      # one template per piece: (kind, slope, data)
        if self.slope_left > 0.0:
            cols.append(("left", self.slope_left, -b[0]))
        for j in range(b.shape[0] - 1):
            df = fv[j + 1] - fv[j]
            if df > 0.0:
                cols.append(("segment", df / (b[j + 1] - b[j]), (b[j], df)))
        if self.slope_right > 0.0:
            cols.append(("right", self.slope_right, b[-1]))
        per = sum(2 if kind == "segment" else 1 for kind, _, _ in cols)
        k = per * m
        E, Nz, Nxi, r = np.zeros((m, k)), np.zeros((k, m)), np.zeros((k, k)), np.zeros(k)
        for i in range(m):
            row = i * per
            for kind, s, extra in cols:
                if kind == "left":
                    E[i, row], Nz[row, i], Nxi[row, row], r[row] = 1.0, 1.0, 1.0 / s, extra
                    row += 1
                elif kind == "right":
                    E[i, row], Nz[row, i], Nxi[row, row], r[row] = -1.0, -1.0, 1.0 / s, extra
                    row += 1
                else:
                    bj, df = extra
                    d, beta = row, row + 1
                    E[i, d], Nz[d, i], Nxi[d, d], Nxi[d, beta], r[d] = -1.0, -1.0, 1.0 / s, \
                        1.0, bj
                    Nxi[beta, d], r[beta] = -1.0, df
                    row += 2
        return ComplementarityForm(
            w0=np.full(m, -fv[0]), E=E, Nz=Nz, Nxi=Nxi, r=r,
            description="piecewise-linear monotone f: w = -f(b_0) + delta_L - sum delta_j - "
                        "delta_R, each rising segment a box MCP 0 <= delta_j <= Delta f_j")

    def __repr__(self) -> str:
        return (f"PiecewiseLinearFunction(breakpoints={self.breakpoints.tolist()}, "
                f"values={self.values.tolist()}, slope_left={self.slope_left}, "
                f"slope_right={self.slope_right}, dim={self.dim})")
