"""The Jacobian of the discrete map of :mod:`nscontrol.simulate.implicit_euler`.

One step is ``x_{k+1} = Φ x_k + Γ ū_k + G_h w`` with ``w`` the solution of
``w ∈ -φ(a + D_h w)``, ``a = HΦ x_k + HΓ ū_k + g(t_{k+1})``. The inputs do not depend on
``x_k``, so by the implicit function theorem

::

    ∂x_{k+1}/∂x_k = Φ + G_h (∂w/∂a) HΦ.

``∂w/∂a`` comes from the graph of ``φ`` at the step's solution ``(z, v = -w)``. For a
componentwise law the graph near that point is, per component, a straight piece: with
``ρ_i ∈ [0, 1]`` the derivative of the law's resolvent ``(I + φ_i)⁻¹`` there,
``dz_i = ρ_i (dz_i + dv_i)``:

* ``ρ_i = 0``: a vertical piece, ``dz_i = 0`` (a relay in sliding, a normal cone on an
  active face: the constraint holds exactly);
* ``ρ_i = 1``: a horizontal piece, ``dw_i = 0`` (a relay off its switching surface, a normal
  cone inside the box, a saturation in saturation);
* ``ρ_i = 1/(1 + s)``: a piece of slope ``s = φ_i'(z_i)`` (a saturation's linear part, a
  monotone function; for a ``MonotoneFunction`` without ``df`` the slope is a central
  difference of ``f``, step ``ε^{1/3}(1 + |z|)``, error ``O(ε^{2/3})``).

With ``dz = da + D_h dw`` the rows ``(1 - ρ_i) dz_i - ρ_i dv_i = 0`` give

::

    K dw = -diag(1 - ρ) da,        K = diag(1 - ρ) D_h + diag(ρ),

``K`` nonsingular whenever ``D_h`` is a P-matrix (positive definite, or block triangular
with positive definite diagonal blocks: what the integrator requires anyway). This is the
derivative on the current active set for LCP-form laws, the resolvent's derivative for the
relay and the normal cones, and ``φ'`` at the solution for monotone functions.

**Degenerate points.** Where a component sits at a corner of the graph (a relay with
``z_i = 0`` and ``|w_i| = c_i``; a normal cone on a face with ``w_i = 0``; a
piecewise-linear function at a breakpoint between different slopes) the discrete map is
not differentiable: its one-sided derivatives differ. Such steps are counted
(``degenerate_steps``), the first one's time is kept, and the vertical (constraint-active)
piece is used there. A component is at a corner when both its distances to the two pieces
are within the rounding of the step (see :data:`CORNER_ULPS`) plus the solver's accepted
residual.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validation import FloatArray
from ...errors import ModelError

#: A component is on a piece when its distance to it is below ``CORNER_ULPS · ε · scale``
#: (``scale = 1 + |a_i| + Σ_j |D_ij w_j| + |w_i|``): the rounding of ``z = a + D_h w`` with a
#: few terms, with a factor 64 of margin for the solver's own rounding.
CORNER_ULPS = 64.0
_EPS = float(np.finfo(float).eps)


class StepJacobians:
    """Accumulates ``∂x_N/∂x_0`` over the steps of a run.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system.
    mats : StepMatrices
        ``Φ, G_h, HΦ`` of the step.
    D : (m, m) ndarray
        The one-step matrix ``D_h`` as the solver used it (structural zeros).
    law_parts : list of (slice, law)
        The law's parts and their components.

    Raises
    ------
    ModelError
        A law whose graph derivative is not known (only relays, normal cones of boxes,
        piecewise-linear and monotone functions, and products of these).
    """

    def __init__(self, system: Any, mats: Any, D: FloatArray,
                 law_parts: list[tuple[slice, Any]]) -> None:
        self.Phi, self.Gh, self.HPhi, self.D = mats.Phi, mats.Gh, mats.HPhi, D
        self.parts = [(sl, _piece_rule(law)) for sl, law in law_parts]
        n = system.n_states
        self.transition = np.eye(n)
        self.degenerate_steps = 0
        self.first_degenerate_time: float | None = None
        self._cache: dict[bytes, FloatArray] = {}

    def extend(self, times: FloatArray, Z: FloatArray, W: FloatArray, floor: float) -> None:
        """Multiply in the steps ending at ``times`` with solutions ``Z``, ``W``.

        Parameters
        ----------
        times : (k,) ndarray
            End time of each step.
        Z, W : (k, m) ndarray
            ``z_{k+1}`` and ``w`` of each step.
        floor : float
            The largest residual the solver accepted (added to the piece tolerances).
        """
        if Z.shape[0] == 0:
            return
        A = Z - W @ self.D.T
        scale = 1.0 + np.abs(A) + np.abs(W) @ np.abs(self.D).T + np.abs(W)
        tol = CORNER_ULPS * _EPS * scale + floor
        rho = np.empty_like(Z)
        corner = np.zeros(Z.shape, bool)
        for sl, rule in self.parts:
            rho[:, sl], corner[:, sl] = rule(Z[:, sl], W[:, sl], tol[:, sl])
        bad = corner.any(axis=1)
        if bad.any():
            self.degenerate_steps += int(bad.sum())
            if self.first_degenerate_time is None:
                self.first_degenerate_time = float(times[int(np.argmax(bad))])
        P = self.transition
        # runs of steps on one active set share one Jacobian: J^count by repeated squaring
        starts = np.flatnonzero(np.r_[True, np.any(rho[1:] != rho[:-1], axis=1)])
        counts = np.diff(np.r_[starts, rho.shape[0]])
        for i, count in zip(starts, counts, strict=True):
            J = self._step(rho[i])
            P = (J if count == 1 else np.linalg.matrix_power(J, int(count))) @ P
        self.transition = P

    def _step(self, rho: FloatArray) -> FloatArray:
        key = rho.tobytes()
        J = self._cache.get(key)
        if J is None:
            m = rho.shape[0]
            K = (1.0 - rho)[:, None] * self.D + np.diag(rho)
            dw_da = -np.linalg.solve(K, np.diag(1.0 - rho)) if m else np.zeros((0, 0))
            J = self.Phi + self.Gh @ dw_da @ self.HPhi
            if len(self._cache) < 4096:   # active sets repeat; curved laws do not
                self._cache[key] = J
        return J


# -- per-law graph pieces: (z, w, tol) -> (rho, corner) -----------------------------------
def _piece_rule(law: Any) -> Any:
    from ...laws.monotone_function import MonotoneFunction, PiecewiseLinearFunction
    from ...laws.normal_cone import NormalConeBox
    from ...laws.relay import Relay

    if isinstance(law, Relay):
        return lambda z, w, tol: _relay_pieces(law.bound, z, w, tol)
    if isinstance(law, NormalConeBox):
        return lambda z, w, tol: _box_pieces(law.lower, law.upper, z, w, tol)
    if isinstance(law, PiecewiseLinearFunction):
        return lambda z, w, tol: _polyline_pieces(law, z, tol)
    if isinstance(law, MonotoneFunction):
        return lambda z, w, tol: _function_pieces(law, z)
    raise ModelError(f"sensitivity: implicit_euler differentiates relays, normal cones of "
                     f"boxes, piecewise-linear and monotone functions (and products of "
                     f"them), not {type(law).__name__}; drop sensitivity=True or rewrite the "
                     f"law with these parts")


def _relay_pieces(c: FloatArray, z: FloatArray, w: FloatArray, tol: FloatArray
                  ) -> tuple[FloatArray, np.ndarray]:
    on_surface = np.abs(z) <= tol
    saturated = np.abs(w) >= c - CORNER_ULPS * _EPS * (1.0 + c)
    rho = np.where(on_surface, 0.0, 1.0)
    rho = np.where(c == 0.0, 1.0, rho)      # c = 0: the graph is the z-axis
    return rho, on_surface & saturated & (c > 0.0)


def _box_pieces(lo: FloatArray, hi: FloatArray, z: FloatArray, w: FloatArray,
                tol: FloatArray) -> tuple[FloatArray, np.ndarray]:
    on_face = (np.abs(z - lo) <= tol) | (np.abs(z - hi) <= tol)
    pushing = np.abs(w) > CORNER_ULPS * _EPS * (1.0 + np.abs(w))
    rho = np.where(on_face, 0.0, 1.0)
    point = lo == hi                          # the box is a point: always vertical
    return np.where(point, 0.0, rho), on_face & ~pushing & ~point


def _polyline_pieces(law: Any, z: FloatArray, tol: FloatArray
                     ) -> tuple[FloatArray, np.ndarray]:
    b, v = law.breakpoints, law.values
    slopes = np.concatenate([[law.slope_left], np.diff(v) / np.diff(b), [law.slope_right]])
    seg = np.searchsorted(b, z, side="right")          # 0: left of b_0, K + 1: right of b_K
    s = slopes[seg]
    dist = np.abs(z[..., None] - b)                    # distance to each breakpoint
    j = np.argmin(dist, axis=-1)
    kink = slopes[j] != slopes[j + 1]                  # slopes left and right of b_j differ
    corner = (np.take_along_axis(dist, j[..., None], -1)[..., 0] <= tol) & kink
    return 1.0 / (1.0 + s), corner


def _function_pieces(law: Any, z: FloatArray) -> tuple[FloatArray, np.ndarray]:
    rho = np.empty_like(z)
    for k in range(z.shape[0]):
        if law.df is not None:
            s = np.asarray(law.df(z[k]), float)
        else:   # central difference: truncation O(d²) against rounding O(ε/d)
            d = _EPS ** (1 / 3) * (1.0 + np.abs(z[k]))
            s = (np.asarray(law.select(z[k] + d), float)
                 - np.asarray(law.select(z[k] - d), float)) / (2.0 * d)
        rho[k] = 1.0 / (1.0 + np.maximum(s, 0.0))
    return rho, np.zeros(z.shape, bool)
