"""Chapter 11 — convergent piecewise-affine systems: analysis and design (continuous case).

Example A: single-DOF oscillator with a one-sided spring (closed-form convergence boundary
``c* = √(m)(√(k + k_s) - √k)``, ``√6 - 1`` for the reference values); Example B: the same with a
gap (PWA with offset); Example C: the two-mode beam surrogate of chapter 6 (§1.3).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import Example, ExampleResult

__all__ = ["one_sided_oscillator", "one_sided_threshold", "beam_surrogate", "EXAMPLES"]


def one_sided_oscillator(c: float = 0.1, *, m: float = 1.0, k: float = 1.0, ks: float = 5.0,
                         gap: float = 0.0, u: Any = None) -> Any:
    """Example A (``gap = 0``) or B (``gap > 0``) of ch11 §4 as a continuous bimodal PWA system.

    ``m q'' + c q' + k q + k_s·min(q + gap, 0) = u(t)``, state ``x = (q, q')``, force input
    ``E = [0, 1/m]ᵀ``, measured ``y = q``. Region 0 (``q <= -gap``, spring engaged):
    ``A_0 = [[0, 1], [-(k + k_s)/m, -c/m]]``, ``b_0 = [0, -k_s·gap/m]``; region 1 (``q >= -gap``):
    ``A_1 = [[0, 1], [-k/m, -c/m]]``.
    """
    from ..systems.pwa import PiecewiseAffineSystem

    A_free = np.array([[0.0, 1.0], [-k / m, -c / m]])
    A_contact = np.array([[0.0, 1.0], [-(k + ks) / m, -c / m]])
    return PiecewiseAffineSystem.bimodal(
        A_contact, A_free, [1.0, 0.0], d=-gap, b1=[0.0, -ks * gap / m], b2=[0.0, 0.0],
        E=[[0.0], [1.0 / m]], u=u, C=[[1.0, 0.0]], state_names=("q", "v"))


def one_sided_threshold(*, m: float = 1.0, k: float = 1.0, ks: float = 5.0,
                        kp: float = 0.0) -> float:
    """Closed-form CQLF damping threshold ``c* = √m(√(k + k_p + k_s) - √(k + k_p))`` (ch11
    §2.4): the one-sided oscillator is quadratically convergent iff ``c > c*``."""
    return float(np.sqrt(m) * (np.sqrt(k + kp + ks) - np.sqrt(k + kp)))


def beam_surrogate(*, u: Any = None, zeta: float = 0.02, alpha: float = 5.0) -> Any:
    """Example C: the ch06 §1.3 two-mode beam surrogate "beam2" (state ``[η1, η2, η1', η2']``,
    support, force, actuator and sensor at the midpoint ``y = η1 + η2``)."""
    from ..systems.pwa import PiecewiseAffineSystem

    m = np.array([5.0, 5.0])
    om = 2 * np.pi * np.array([20.0, 100.0])
    K = m * om**2
    Cd = 2 * zeta * m * om
    h = np.ones(2)
    k_mid = 1.0 / float(h @ (h / K))
    ks = alpha * k_mid
    A1 = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.diag(K / m), -np.diag(Cd / m)]])
    g = np.concatenate([np.zeros(2), h / m])
    H = np.concatenate([h, np.zeros(2)])
    A2 = A1 - ks * np.outer(g, H)
    return PiecewiseAffineSystem.bimodal(A2, A1, H, d=0.0, E=g[:, None], u=u, C=H[None, :],
                                         state_names=("eta1", "eta2", "deta1", "deta2"))
EXAMPLES: list[Example] = []
