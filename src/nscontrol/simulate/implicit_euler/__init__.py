"""Implicit Euler / θ-method time-stepping for Lur'e systems (``method="implicit_euler"``).

Integrates :class:`~nscontrol.systems.lure.LureSystem` (``x' = Ax + Gw + Bu``,
``z = Hx + Dw + g``, ``w ∈ -φ(z)``). The smooth part is a θ-method, the multiplier is always
implicit, so every step is the one-step inclusion

::

    x_{k+1} = Φ x_k + Γ ū_k + G_h w,        ū_k = (1-θ) u(t_k) + θ u(t_{k+1})
    z_{k+1} = a_k + D_h w,   w ∈ -φ(z_{k+1}),   a_k = H(Φ x_k + Γ ū_k) + g(t_{k+1})

with ``W = I - hθA``, ``Φ = W⁻¹(I + h(1-θ)A)``, ``Γ = hW⁻¹B``, ``G_h = hW⁻¹G``,
``D_h = H G_h + D``. It is solved exactly at every step:

* componentwise laws (relay, Coulomb, normal cones of intervals, complementarity, the
  monotone set-valued Stribeck law -- its slip branch by safeguarded Newton -- and their
  products) with a diagonal ``D_h``, or one that a permutation makes lower triangular (a plant
  and its observer): closed-form resolvents ``z_i = (1 + d_ii φ_i)⁻¹(a_i + Σ_j d_ij w_j)``
  component after component, in a compiled loop;
* laws with a complementarity form (``law.complementarity_form()``: relay, friction, normal
  cones, products) and a full ``D_h``: one LCP per step (or per diagonal block, see below) by
  the shared Lemke kernel of :mod:`nscontrol.numerics._lcp_kernels`, in the same compiled loop,
  each solution verified by its natural residual;
* any other monotone law (curved graphs): its own resolvent when the (block of) ``D_h`` is
  diagonal, else forward–backward splitting on ``0 ∈ D_h⁻¹(z - a) + φ(z)``, in Python, each
  solution verified by the law's graph residual.

Multipliers that read one argument (the super-twisting controller ``u = -k1|s|^{1/2}sign(s) +
ν``, ``ν' = -k2 Sign(s)``: two laws of the same ``s``, entering different states): ``D_h`` then
has identical rows ``1 dᵀ`` and is singular, but the step is the scalar inclusion
``s + Σ_j d_j φ_j(s) ∋ a``. When every part of the ``Product`` law is a scalar
:class:`~nscontrol.laws.super_twisting.SuperTwistingLaw` or :class:`~nscontrol.laws.relay.Relay`,
``d > 0`` and ``D = 0``, it is solved in closed form (the quadratic in ``|s|^{1/2}`` of
:func:`~nscontrol.laws.super_twisting.super_twisting_resolvent`), in Python.

Block structure: when the law is a ``Product`` whose parts are coupled one way only through
``D_h`` (a plant and its observer: the observer sees the plant, not the reverse), ``D_h`` is
block triangular up to a permutation of the parts. Each diagonal block is then solved after the
blocks it depends on, and only the diagonal blocks need a positive definite symmetric part (the
whole ``D_h`` need not). Couplings below ``1e-14 max|D_h|`` count as structural zeros.

Inputs: an :class:`~nscontrol.numerics.lti.Exosystem` input enters through its exact mean over
each step, ``ū_k = (1/h) ∫ u`` (so ``x' = -sign(x) + d(t)`` is integrated exactly before
reaching, and the reaching time is found within one step); any other input through the
θ-combination ``ū_k = (1-θ) u(t_k) + θ u(t_{k+1})`` of its samples (first-order accurate).

Because the multiplier is implicit, a sliding motion is reached in finitely many steps and then
held with ``z`` exactly zero (no chattering).

Feedback written as blocks (a controller and/or an observer in Python, or with a compiled
form) around a Lur'e plant is a closed loop: ``simulate(closed_loop(plant, block), ...)``.
The ``python_blocks`` lowering hands the loop's block runner to this method, which steps the
blocks at the start of every step and holds their output over it (zero-order hold; a digital
controller with a friction compensation, chapter 7). When every block has a compiled form
(:class:`~nscontrol.systems.feedback.CompiledBlock`) and the closed form solves the step, the
blocks and the steps run in one compiled loop (``stats["controller"] = "compiled"``);
otherwise the blocks run as Python, one step at a time (``"python"``).

Options
-------
h : float
    Step (the span is cut into ``N = ceil((tf - t0)/h)`` equal steps).
theta : float in [1/2, 1]
    θ of the smooth part (1: backward Euler, 1/2: trapezoidal).
record_every : int
    Keep every k-th step (the final state is always kept).
signals : iterable of str, optional
    Subset of ``("z", "w", "y")`` to record (other names raise ``ModelError``).
progress : bool, optional
    Progress bar on stderr (default: shown after 2 s).
u : Exosystem or callable or array_like, optional
    External input overriding the system's ``u`` (what a periodically forced analysis passes).
sensitivity : bool
    Also compute ``stats["state_transition"]``, the exact Jacobian ``∂x_N/∂x_0`` of the
    *discrete* map (the product of the steps' Jacobians ``Φ + G_h (∂w/∂a) HΦ``, each from
    the implicit function theorem on the step's inclusion at its solution, see
    :mod:`nscontrol.simulate.implicit_euler._lure_sensitivity`), with
    ``stats["degenerate_steps"]`` (steps whose solution sits at a corner of the law's graph,
    where the map is not differentiable; the first one's time in
    ``stats["first_degenerate_time"]``, and a warning).

A failed step raises :class:`~nscontrol.errors.SolverError` with the partial trajectory
(``simulate(..., on_failure="return")`` returns it with ``status = -1``). A step fails when
its one-step problem has no verified solution: Lemke's status, or a natural residual above
``1e-10`` (LCP), or a graph residual above ``1e-9 (1 + |a| + |w|)`` (Python path).

The package, one module per concept: the options (``_options``), the step matrices
(``_matrices``), what the compiled steps read of the law (``_law_data``), the plan of the
step's solver and the structure of ``D_h`` (``_plan``), the inclusion solved in Python
(``_inclusion``), the chunks of steps by solver path (``_steps``, with the compiled kernels of
``_lure_kernels`` and ``_lure_lcp_kernels``), the run that :func:`~nscontrol.simulate.loop.drive`
advances (``_stepper``), what it records (``_recording``) and the Jacobian of the discrete map
(``_lure_sensitivity``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from numpy.typing import ArrayLike

from ..._validation import as_vector
from ...errors import ModelError
from ..loop import drive
from ..trajectory import Trajectory
from ._inclusion import GRAPH_TOL  # noqa: F401 - the module's former names stay importable
from ._law_data import componentwise_spec, curve_parameters, lcp_step_data  # noqa: F401
from ._matrices import StepMatrices, step_matrices
from ._options import ImplicitEulerOptions
from ._plan import Setup
from ._stepper import Run
from ._steps import LCP_TOL  # noqa: F401

if TYPE_CHECKING:   # imported where used at run time (import nscontrol stays light)
    from ...systems.lure import LureSystem

__all__ = ["integrate", "ImplicitEulerOptions", "StepMatrices", "step_matrices",
           "componentwise_spec", "lcp_step_data"]


def integrate(system: LureSystem, x0: ArrayLike, t_span: tuple[float, float],
              **options: Any) -> Trajectory:
    """Integrate a :class:`~nscontrol.systems.lure.LureSystem` by the θ-method.

    Parameters
    ----------
    system : LureSystem
        The Lur'e system (a plant with its observer is one stacked system).
    x0 : array_like, shape (n,)
        Initial state; with ``D = 0``, ``H x0 + g(t0)`` must lie in the law's domain.
    t_span : (float, float)
        Start and end times.
    **options
        ``h`` (required), ``theta`` (default 1), ``u``, ``sensitivity``, ``record_every``,
        ``signals``, ``progress`` -- see the package docstring; checked once into an
        :class:`ImplicitEulerOptions` (with ``blocks``, the runner of a closed loop's blocks,
        which the ``python_blocks`` lowering sets).

    Returns
    -------
    Trajectory
        States at the step times and signals ``z`` (law argument), ``w`` (multiplier) and
        ``y = C x``; ``stats`` has ``steps``, ``h``, ``theta``, ``solver`` (``closed_form``,
        ``lcp`` or ``python``), ``structure`` of ``D_h`` (``diagonal``, ``triangular``,
        ``block_triangular``, ``full`` or ``shared_argument``), ``blocks``, ``input``
        (``exact_mean``, ``samples``, ``none`` or, in a closed loop of blocks, ``controller``,
        then with ``controller``: ``compiled`` or ``python``, how the blocks ran) and, for the
        LCP and Python paths,
        ``max_residual`` (the largest accepted per-step residual); with
        ``sensitivity=True`` also ``state_transition``, ``degenerate_steps`` and
        ``first_degenerate_time``.

    Raises
    ------
    ModelError
        Not a LureSystem, bad options, ``I - hθA`` singular, or ``D_h`` (or one of its
        diagonal blocks, when block triangular) not positive definite.
    InadmissibleStateError
        ``D = 0`` and ``H x0 + g(t0)`` outside the law's domain.
    SolverError
        A one-step problem failed or its solution did not pass the residual check;
        ``err.trajectory`` holds the steps before it.

    Examples
    --------
    An ideal diode clamping a capacitor voltage (complementarity, exact ``z·w = 0``):

    >>> import numpy as np
    >>> from nscontrol import simulate
    >>> from nscontrol.testing.setvalued_problems import diode_circuit
    >>> p = diode_circuit()
    >>> tr = simulate(p.system, p.x0, p.t_span, h=1e-3)
    >>> tr.stats["solver"], bool(np.all(tr.signal("z") * tr.signal("w") == 0.0))
    ('closed_form', True)
    """
    opts = ImplicitEulerOptions.parse(options)
    _check_system(system, opts)
    t0, tf = t_span
    n_steps = max(1, math.ceil((tf - t0) / opts.h - 1e-9))
    h = (tf - t0) / n_steps
    setup = Setup.of(system, h, opts.theta)   # before the input: it does not depend on it
    system = _with_input(system, opts.u)
    x0 = as_vector("x0", x0, system.n_states)
    run = Run(system, setup, opts, n_steps, x0, t0)
    return drive(run, (t0, t0 + h * n_steps), desc="implicit_euler", progress=opts.progress)


def _check_system(system: Any, opts: ImplicitEulerOptions) -> None:
    """A Lur'e system, with an input matrix when the options feed it an input."""
    from ...systems.lure import LureSystem

    if not isinstance(system, LureSystem):
        raise ModelError(f"implicit_euler: expected a LureSystem, got {type(system).__name__}; "
                         f"for PWA/Filippov/switched systems use method='switching'")
    if opts.blocks is not None and opts.blocks.ctrl is not None and system.B is None:
        raise ModelError("controller: this LureSystem has no input matrix B, so it takes no "
                         "input; build it with B= to close a loop around it")


def _with_input(system: Any, u: Any) -> Any:
    """``system`` with its input replaced by ``u`` (``None``: unchanged)."""
    if u is None:
        return system
    if system.B is None:
        raise ModelError("u: this LureSystem has no input matrix B, so it takes no input; "
                         "build it with B= to force it")
    from dataclasses import replace

    return replace(system, u=u)

