"""Saltation matrices: how a perturbation of the state is carried through a discrete event.

A trajectory of a non-smooth system reaches a guard ``h(x, t) = 0`` at ``t_e``, where the
state jumps ``x+ = J(x-)`` (impact: ``J`` reverses the normal velocity; facet crossing,
sliding entry and exit, PWM switching: ``J = I``) and the vector field changes from ``f-`` to
``f+``. A perturbation ``δx-`` of the state just before the event shifts the event time by
``δt = -∇h·δx- / ḣ-`` (``ḣ- = ∇h·f- + ∂h/∂t``, the guard's rate of approach); to first order
the perturbation just after the event is ``δx+ = S δx-`` with the **saltation matrix**

    S = J' + (f+ - J' f-) ∇hᵀ / ḣ-,        J' = ∂J/∂x at x-.

This is the matrix analysis multiplies between the flows' transition matrices to get the
monodromy of an orbit through events. Special cases:

* **impact** with Newton restitution on one contact of a mechanical system
  (:func:`impact_jump_jacobian` gives ``J'``; with a mass matrix ``M(q)`` or a nonlinear gap
  ``g(q)`` it adds the block ``∂v+/∂q``, the turning of the normal and the change of inertia
  with the configuration, so ``S`` is the saltation matrix of the nonlinear mechanics);
* **facet crossing** of a piecewise-affine system and **sliding entry** (``J' = I``; ``f+``
  the next mode's or the sliding vector field);
* **sliding exit**: the sliding field equals the leaving mode's field at the exit point, so
  ``f+ = f-`` and ``S = I``;
* a **switching instant fixed in time** (PWM edge at a given time, ``∇h = 0``): ``S = I``;
  a PWM edge whose instant depends on the sampled state ``x_k`` (``t_e = t_k + τ(x_k)``)
  adds ``(f- - f+) ∂τ/∂x_k`` to the transition from ``x_k``, which
  :func:`time_shift_term` returns.

Grazing (``ḣ- = 0``) makes ``S`` unbounded: :func:`saltation_matrix` refuses it with
``SolverError``.

:func:`saltation_matrix`, :func:`impact_jump_jacobian`, :func:`impact_velocity` and
:func:`time_shift_term` are defined in :mod:`nscontrol.numerics.saltation`, below ``simulate``
(the event-driven integrator applies the first three while it integrates the variational
equation, the PWM integrator the last), and re-exported here.

Examples
--------
The impact of a unit mass on a stop at ``q = d`` with restitution ``r = 0.5``, approaching
at ``v = 2`` with acceleration ``-1`` before and ``-1`` after:

>>> import numpy as np
>>> J = np.diag([1.0, -0.5])
>>> S = saltation_matrix(J, f_minus=[2.0, -1.0], f_plus=[-1.0, -1.0], guard_gradient=[1.0, 0.0])
>>> S.tolist()
[[-0.5, 0.0], [-0.75, -0.5]]
"""

from __future__ import annotations

from ..numerics.saltation import (  # the simulate layer uses them too
    impact_jump_jacobian,
    impact_velocity,
    saltation_matrix,
    time_shift_term,
)

__all__ = ["saltation_matrix", "impact_jump_jacobian", "impact_velocity", "time_shift_term"]
