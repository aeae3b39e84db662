"""Rigid bodies with Coulomb friction at their contacts, as :class:`LagrangianSystem`.

Every model here has a constant mass, constant forces (gravity) and affine gaps and tangent
velocities, so that Moreau–Jean's step is one frictional contact problem with a constant
Delassus matrix per active set:

- :func:`inclined_block`: a block on a plane inclined by ``α`` (one planar contact);
- :func:`rolling_disk`: a disk on the ground (planar), slipping then rolling;
- :func:`rolling_sphere`: a sphere on the ground (spatial contact, two tangents);
- :func:`brick_stack`: ``n`` planar bricks stacked on the ground (on a plane inclined by
  ``α``), two corner contacts per interface, linearised in the rotations about the upright
  stack.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from .._validation import FloatArray, check_in_interval, check_integer, check_positive
from .lagrangian import LagrangianSystem

__all__ = ["inclined_block", "rolling_disk", "rolling_sphere", "brick_stack",
           "brick_stack_rest_state"]


def inclined_block(mu: float, angle: float = 0.0, *, g: float = 9.81,
                   mass: float = 1.0) -> LagrangianSystem:
    """A block on a plane inclined by ``angle``: ``q = (x, y)``, ``x`` down the slope.

    Gravity has the components ``m g sin α`` along the slope and ``-m g cos α`` normal to it;
    the gap is ``y``, the slip velocity ``x'``. Sticks when ``tan α <= μ``, otherwise slides
    with acceleration ``g (sin α - μ cos α)``.

    Parameters
    ----------
    mu : float
        Friction coefficient, ``>= 0``.
    angle : float
        Slope ``α`` in radians, in ``[0, π/2)``.
    g : float
        Gravity, ``>= 0``.
    mass : float
        Mass, ``> 0``.

    Examples
    --------
    >>> block = inclined_block(0.5, 0.2)
    >>> block.friction_dim, block.n_contacts
    (1, 1)
    """
    mu = check_positive("mu", mu, allow_zero=True)
    angle = _check_slope(angle)
    g, mass = check_positive("g", g, allow_zero=True), check_positive("mass", mass)
    return LagrangianSystem(np.full(2, mass),
                            constant_force=[mass * g * np.sin(angle), -mass * g * np.cos(angle)],
                            gap_matrix=[[0.0, 1.0]], friction=mu, tangent_matrix=[[1.0, 0.0]],
                            names=("x", "y"))


def _ball(mu: float, radius: float, mass: float, g: float) -> tuple[float, ...]:
    """The checked ``(μ, R, m, g)`` of a rolling body."""
    return (check_positive("mu", mu, allow_zero=True), check_positive("radius", radius),
            check_positive("mass", mass), check_positive("g", g, allow_zero=True))


def rolling_disk(mu: float, *, radius: float = 0.1, mass: float = 1.0,
                 g: float = 9.81) -> LagrangianSystem:
    """A uniform disk on the ground: ``q = (x, y, θ)``, ``θ`` counter-clockwise.

    Gap ``y - R``, slip velocity of the contact point ``x' + R θ'``; inertia ``m R²/2``.
    Thrown with slip ``s0 = x'0 + R θ'0 > 0`` it rolls after ``t* = s0 / (3 μ g)`` (the slip
    decreases at ``μ g (1 + m R²/I) = 3 μ g``) with ``x' = x'0 - μ g t*``.

    Parameters
    ----------
    mu : float
        Friction coefficient, ``>= 0``.
    radius : float
        ``R > 0``.
    mass : float
        ``m > 0``.
    g : float
        Gravity, ``>= 0``.

    Examples
    --------
    >>> rolling_disk(0.3).tangent_matrix.tolist()
    [[1.0, 0.0, 0.1]]
    """
    mu, R, mass, g = _ball(mu, radius, mass, g)
    return LagrangianSystem([mass, mass, 0.5 * mass * R * R],
                            constant_force=[0.0, -mass * g, 0.0], gap_matrix=[[0.0, 1.0, 0.0]],
                            gap_offset=[-R], friction=mu, tangent_matrix=[[1.0, 0.0, R]],
                            names=("x", "y", "theta"))


def rolling_sphere(mu: float, *, radius: float = 0.1, mass: float = 1.0,
                   g: float = 9.81) -> LagrangianSystem:
    """A uniform sphere on the ground: ``q = (x, y, z, φx, φy, φz)`` (the angles integrate
    the angular velocity; the gap does not depend on them).

    Gap ``z - R``; the contact point's velocity ``v + ω × (-R e_z)`` has the tangential
    components ``(x' - R ωy, y' + R ωx)``; inertia ``2 m R²/5``. The slip velocity decreases
    at ``μ g (1 + m R²/I) = 7 μ g / 2`` along a fixed direction: rolling after
    ``t* = 2 |s0| / (7 μ g)``.

    Parameters
    ----------
    mu : float
        Friction coefficient, ``>= 0``.
    radius : float
        ``R > 0``.
    mass : float
        ``m > 0``.
    g : float
        Gravity, ``>= 0``.

    Examples
    --------
    >>> rolling_sphere(0.3).friction_dim
    2
    """
    mu, R, mass, g = _ball(mu, radius, mass, g)
    inertia = 0.4 * mass * R * R
    T = [[1.0, 0.0, 0.0, 0.0, -R, 0.0], [0.0, 1.0, 0.0, R, 0.0, 0.0]]
    return LagrangianSystem([mass] * 3 + [inertia] * 3,
                            constant_force=[0.0, 0.0, -mass * g, 0.0, 0.0, 0.0],
                            gap_matrix=[[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]], gap_offset=[-R],
                            friction=mu, tangent_matrix=T,
                            names=("x", "y", "z", "phi_x", "phi_y", "phi_z"))


def brick_stack(n: int, mu: float, *, width: float = 0.2, height: float = 0.1,
                mass: float = 1.0, g: float = 9.81, angle: float = 0.0,
                restitution: float = 0.0) -> LagrangianSystem:
    """``n`` planar bricks stacked on the ground: ``q = (x_i, y_i, θ_i)`` per brick.

    Two contacts per interface, at the corners ``a = ∓ width/2`` of the upper brick's base;
    linearised in the rotations about the upright stack: gap
    ``y_i + a θ_i - y_{i-1} - a θ_{i-1} - height`` (ground: ``y_0 + a θ_0 - height/2``),
    slip velocity ``x_i' + (height/2) θ_i' - x_{i-1}' + (height/2) θ_{i-1}'``. The ground
    is inclined by ``angle`` (coordinates along and normal to it): every interface carries
    the tangential to normal load ratio ``tan α``, so the stack stays at rest when
    ``tan α < μ``. Gap and tangent matrices are sparse.

    Parameters
    ----------
    n : int
        Number of bricks, ``>= 1``.
    mu : float
        Friction coefficient of every contact.
    width, height : float
        Brick size, ``> 0``.
    mass : float
        Brick mass (inertia ``m (w² + h²)/12``).
    g : float
        Gravity.
    angle : float
        Slope of the ground, radians in ``[0, π/2)``.
    restitution : float
        Newton coefficient of every contact.

    Examples
    --------
    >>> s = brick_stack(3, 0.5)
    >>> s.n_dof, s.n_contacts, s.friction_dim
    (9, 6, 1)
    """
    n = check_integer("n", n, minimum=1)
    mu = check_positive("mu", mu, allow_zero=True)
    w, H = check_positive("width", width), check_positive("height", height)
    mass, g = check_positive("mass", mass), check_positive("g", g, allow_zero=True)
    angle = _check_slope(angle)
    inertia = mass * (w * w + H * H) / 12.0
    rows, cols, vals, trows, tcols, tvals = [], [], [], [], [], []
    offset = np.empty(2 * n)
    for i in range(n):
        for c, a in enumerate((-0.5 * w, 0.5 * w)):
            j = 2 * i + c
            rows += [j, j]
            cols += [3 * i + 1, 3 * i + 2]
            vals += [1.0, a]
            trows += [j, j]
            tcols += [3 * i, 3 * i + 2]
            tvals += [1.0, 0.5 * H]
            if i:
                rows += [j, j]
                cols += [3 * i - 2, 3 * i - 1]
                vals += [-1.0, -a]
                trows += [j, j]
                tcols += [3 * i - 3, 3 * i - 1]
                tvals += [-1.0, 0.5 * H]
            offset[j] = -H if i else -0.5 * H
    G = sparse.csr_matrix((vals, (rows, cols)), shape=(2 * n, 3 * n))
    T = sparse.csr_matrix((tvals, (trows, tcols)), shape=(2 * n, 3 * n))
    masses = np.tile([mass, mass, inertia], n)
    f0 = np.tile([-mass * g * np.sin(angle), -mass * g * np.cos(angle), 0.0], n)
    names = tuple(f"{s}{i}" for i in range(n) for s in ("x", "y", "theta"))
    return LagrangianSystem(masses, constant_force=f0, gap_matrix=G, gap_offset=offset,
                            restitution=restitution, friction=mu, tangent_matrix=T,
                            names=names)


def brick_stack_rest_state(n: int, *, height: float = 0.1) -> FloatArray:
    """The state of :func:`brick_stack` at rest: every gap zero, every velocity zero.

    Parameters
    ----------
    n : int
        Number of bricks.
    height : float
        Brick height.

    Examples
    --------
    >>> brick_stack_rest_state(2).tolist()
    [0.0, 0.05, 0.0, 0.0, 0.15000000000000002, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    """
    n = check_integer("n", n, minimum=1)
    q = np.zeros(3 * n)
    q[1::3] = height * (0.5 + np.arange(n))
    return np.concatenate([q, np.zeros(3 * n)])


def _check_slope(angle: float) -> float:
    """A slope in ``[0, π/2)`` radians."""
    angle = check_in_interval("angle", angle, 0.0, np.pi / 2)
    if angle == np.pi / 2:
        check_in_interval("angle", angle, 0.0, np.pi / 2, open_interval=True)
    return angle
