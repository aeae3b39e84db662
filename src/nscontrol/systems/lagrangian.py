"""Lagrangian systems with unilateral constraints and Newton restitution.

    M(q) v' = f(t, q, v) + S u + G(q)^T λ,     0 <= g(q) ⟂ λ >= 0,
    f(t, q, v) = f0 - K q - D v + force(t, q, v),
    at an impact of contact j:  G_j v+ = -e_j G_j v-   (multi-contact: Newton's law by one LCP).

The state of every integrator is ``x = [q; v]`` (length ``2 n``). ``G(q)`` is the Jacobian
``∂g/∂q`` of the gaps, shape ``(m, n)``; the matrix ``W = G^T`` of Siconos' notation is its
transpose. When ``M`` is constant, the forces linear (``f0, K, D`` only) and the gaps affine
(``g(q) = G q + g0``), the system is *linear between events* and the event-driven integrator is
exact (matrix exponentials, roots to machine precision).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .._validation import (
    FloatArray,
    as_matrix,
    as_real_scalar,
    as_square,
    as_vector,
    check_in_interval,
    check_positive,
    check_positive_definite,
)
from ..errors import DimensionError, InadmissibleStateError, ModelError, NscontrolWarning

__all__ = ["LagrangianSystem", "CompiledModel", "affine_compiled_model", "two_link_arm_mass",
           "two_link_arm_coriolis", "two_link_arm_gravity", "two_link_arm_force_jacobian"]

ForceFn = Callable[[float, FloatArray, FloatArray], FloatArray]
#: ``(t, q, v) -> (∂force/∂q, ∂force/∂v)``.
ForceJacobianFn = Callable[[float, FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
#: ``q -> M(q)`` (a configuration-dependent mass matrix), ``q -> g(q)``, ``q -> ∂g/∂q``.
ConfigurationFn = Callable[[FloatArray], FloatArray]
#: ε^(1/3): the central-difference step (relative) balancing truncation and roundoff.
_CBRT_EPS = float(np.finfo(float).eps) ** (1.0 / 3.0)


@dataclass(frozen=True, eq=False)
class CompiledModel:
    """Compiled forms of a :class:`LagrangianSystem`'s callables, for Moreau–Jean's compiled
    loop (a configuration-dependent ``M(q)``, a nonlinear force, nonlinear gaps).

    Each function is compiled by ``numba.njit`` with its signature declared (from
    ``nscontrol.systems.lagrangian``'s kernels module ``_lagrangian_kernels``:
    ``MASS_SIGNATURE`` etc.), takes plain ``float64`` arrays and the parameter array last::

        mass(q, params) -> M (n, n)
        force(t, q, v, params) -> the system's force term (n,)   (zeros if it has none)
        force_jacobian(t, q, v, params) -> [∂force/∂q; ∂force/∂v] stacked (2n, n)
        gaps(q, params) -> g (m,),   gap_jacobian(q, params) -> ∂g/∂q (m, n)
        potential(q, params) -> V   (optional: the recorded energy's potential)

    The linear terms (``f0, K, D``), the actuation and the restitution stay the system's.
    The system probes the compiled functions against its Python callables at
    construction (:meth:`check_against`).

    Attributes
    ----------
    mass, force, force_jacobian, gaps, gap_jacobian : numba dispatcher
        The compiled functions.
    params : ndarray of float64, shape (p,)
        The model's parameters, passed to every function.
    potential : numba dispatcher, optional
        The compiled ``potential`` (the energy signal otherwise calls the Python one).
    entries : tuple
        The five functions as the compiled loop takes them (read-only).
    """

    mass: Any
    force: Any
    force_jacobian: Any
    gaps: Any
    gap_jacobian: Any
    params: FloatArray
    potential: Any = None

    def __post_init__(self) -> None:
        from . import _lagrangian_kernels as lk
        from .feedback import _has_signature

        for name, sig in (("mass", lk.MASS_SIGNATURE), ("force", lk.FORCE_SIGNATURE),
                          ("force_jacobian", lk.FORCE_JACOBIAN_SIGNATURE),
                          ("gaps", lk.GAP_SIGNATURE),
                          ("gap_jacobian", lk.GAP_JACOBIAN_SIGNATURE),
                          ("potential", lk.POTENTIAL_SIGNATURE)):
            if name == "potential" and self.potential is None:
                continue
            if not _has_signature(getattr(self, name), sig):
                raise ModelError(f"{name}: a CompiledModel needs a function compiled by "
                                 f"numba.njit({name.upper()}_SIGNATURE) (declared), got "
                                 f"{getattr(self, name)!r}")
        object.__setattr__(self, "params", np.ascontiguousarray(
            np.asarray(self.params, dtype=np.float64).reshape(-1)))

    @property
    def entries(self) -> Any:
        """``((mass,), (force,), (force_jacobian,), (gaps,), (gap_jacobian,))`` as the
        compiled loop's argument, its numba type found once per process (a tuple of
        dispatchers is typed and unboxed afresh at every call, about a millisecond for
        five; ``nscontrol.systems._feedback_kernels.compiled_entries``)."""
        from ._feedback_kernels import compiled_entries

        return compiled_entries((self.mass,), (self.force,), (self.force_jacobian,),
                                (self.gaps,), (self.gap_jacobian,))

    def check_against(self, system: LagrangianSystem, tol: float = 1e-10) -> None:
        """Compare with the system's Python callables at a fixed configuration
        ``q = 0.1 (1, 2, ..., n) / n``, ``v = -q``, ``t = 0.3``; the compiled and Python forms
        differ by the order of their operations only, so ``tol`` (relative to each value's
        largest entry) is far above their roundoff and far below a modelling slip.

        Parameters
        ----------
        system : LagrangianSystem
            The system this model compiles.
        tol : float
            Relative tolerance.

        Raises
        ------
        ModelError
            A compiled function disagrees (its name and the difference in the message).
        """
        n, p = system.n_dof, self.params
        q = 0.1 * np.arange(1.0, n + 1.0) / n
        v, t = -q, 0.3
        force = (np.zeros(n) if system.force is None else
                 np.asarray(system.force(t, q, v), float))
        pairs = [("mass", self.mass(q, p), system.mass_matrix(q)),
                 ("force", self.force(t, q, v, p), force),
                 ("gaps", self.gaps(q, p), system.gaps(q)),
                 ("gap_jacobian", self.gap_jacobian(q, p), system.gap_jacobian(q))]
        if self.potential is not None and system.potential is not None:
            pairs.append(("potential", np.array(self.potential(q, p)),
                          np.array(system.potential(q))))
        if system.force_jacobian is not None:
            Jq, Jv = system.force_jacobian(t, q, v)
            pairs.append(("force_jacobian", self.force_jacobian(t, q, v, p),
                          np.vstack([Jq, Jv])))
        for name, ours, theirs in pairs:
            theirs = np.asarray(theirs, float)
            if np.shape(ours) != theirs.shape:
                raise DimensionError(f"compiled.{name}: returned shape {np.shape(ours)}, the "
                                     f"system's {name} {theirs.shape}")
            scale = max(1.0, float(np.abs(theirs).max(initial=0.0)))
            err = float(np.abs(ours - theirs).max(initial=0.0))
            if not err <= tol * scale:
                raise ModelError(f"compiled.{name}: disagrees with the system's {name} at "
                                 f"q = {q!r} (max difference {err:.3g}); it must compute the "
                                 f"same function")


def affine_compiled_model(system: LagrangianSystem) -> CompiledModel | None:
    """The compiled model of a system with a constant mass, no nonlinear force and affine
    gaps (its linear forces stay the system's), or ``None`` for any other system; what
    Moreau–Jean's compiled loop runs for such a plant closed by compiled blocks.

    Parameters
    ----------
    system : LagrangianSystem
        The system.

    Returns
    -------
    CompiledModel or None
    """
    if not system.constant_mass or system.force is not None or system.gap_matrix is None:
        return None
    from . import _lagrangian_kernels as lk

    n, m = system.n_dof, system.n_contacts
    params = np.concatenate([[float(n), float(m)], system.mass_matrix().ravel(),
                             system.dense_gap_matrix().ravel(), system.gap_offset])
    # kept per parameters: a model's checks cost far more than a short run's set-up
    key = params.tobytes()
    model = _AFFINE_MODELS.pop(key, None)
    if model is None:
        model = CompiledModel(lk.constant_mass, lk.no_force, lk.no_force_jacobian,
                              lk.affine_gaps, lk.affine_gap_jacobian, params)
        if len(_AFFINE_MODELS) >= 64:           # the least recently used goes
            del _AFFINE_MODELS[next(iter(_AFFINE_MODELS))]
    _AFFINE_MODELS[key] = model
    return model


_AFFINE_MODELS: dict[bytes, CompiledModel] = {}


@dataclass(frozen=True, eq=False)
class LagrangianSystem:
    """A mechanical system with unilateral constraints ``g(q) >= 0`` and Newton restitution.

    Parameters
    ----------
    mass : array_like (n, n) or callable ``q -> (n, n)``
        Symmetric positive definite mass matrix, constant or configuration-dependent.
    stiffness, damping : array_like (n, n), optional
        Linear force ``-K q - D v`` (zero by default).
    constant_force : array_like (n,), optional
        Constant generalised force ``f0`` (gravity).
    force : callable ``(t, q, v) -> (n,)``, optional
        Any further (nonlinear) generalised force, e.g. ``-C(q, v) v - ∇V(q)``.
    force_jacobian : callable ``(t, q, v) -> (∂force/∂q, ∂force/∂v)``, optional
        Analytic derivatives of ``force`` (two ``(n, n)`` arrays; the linear terms ``-K q - D v``
        are added by :meth:`force_jacobians`). Used by the implicit forces of Moreau–Jean;
        central differences when missing. Probed at ``(0, 0, 0)`` here: shapes checked,
        a warning when it disagrees with central differences of ``force`` there.
    gap_matrix, gap_offset : array_like (m, n) and (m,), optional
        Affine gaps ``g(q) = gap_matrix @ q + gap_offset``.
    gap : callable ``q -> (m,)``, optional
        Nonlinear gaps (instead of ``gap_matrix``); ``m`` is read from ``gap(zeros(n))``.
    jacobian : callable ``q -> (m, n)``, optional
        Analytic ``∂g/∂q`` for a nonlinear ``gap``; central differences (with a warning) when
        missing.
    restitution : float or array_like (m,)
        Newton coefficients ``e_j`` in ``[0, 1]``.
    actuation : array_like (n, p), optional
        ``S``: how the input ``u`` enters (default: identity, fully actuated).
    potential : callable ``q -> float``, optional
        Potential of ``force`` (added to ``½ qᵀKq - f0ᵀq`` in :meth:`energy`).
    names : sequence of str, optional
        Names of the coordinates (states are named ``q_name``, ``v_name``).
    friction : float or array_like (m,), optional
        Coulomb coefficients ``μ_j >= 0`` of the contacts (with ``tangent_matrix``); the
        contact impulse ``(P_n, P_t)`` then lies in the cone ``|P_t| <= μ_j P_n`` and opposes
        slip (``docs/frictional_contacts.md``). Only with affine gaps.
    tangent_matrix : array_like (m d, n), optional
        Constant tangent Jacobian: rows ``d j .. d j + d - 1`` map ``v`` to the tangential
        (slip) velocity of contact ``j``; ``d = 1`` for planar contacts, ``d = 2`` for
        spatial ones.
    compiled : CompiledModel, optional
        Compiled forms of ``mass``, ``force``, ``force_jacobian``, ``gap`` and ``jacobian``
        (numba-jitted): Moreau–Jean then runs the model in a compiled loop instead of its
        Python one (probed against the Python callables here).

    Raises
    ------
    ModelError
        Non-symmetric or indefinite mass matrix, restitution outside ``[0, 1]``, neither or both
        of ``gap_matrix`` and ``gap``, ``force_jacobian`` without ``force`` or not a pair of
        finite matrices; a negative or non-finite ``friction``, ``friction`` without
        ``tangent_matrix`` (or the converse), friction on nonlinear gaps.
    DimensionError
        Shapes that disagree with ``n`` or ``m`` (``force_jacobian``'s too; ``tangent_matrix``
        rows not ``m`` or ``2 m``).

    Notes
    -----
    A constant ``mass`` is checked (symmetric, positive definite) here; a callable one is checked
    at the initial configuration by :meth:`check_state` and by the integrators.

    References
    ----------
    Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical Systems*, Springer 2008, ch. 1;
    spec ``ch03-ch05-lagrangian-tracking.md`` §1 and ``ch04-walking-contacts.md`` §2.1.

    Examples
    --------
    A mass on a spring hitting a wall at ``q = 0.3`` (gap ``0.3 - q >= 0``), forced by an
    exosystem input, simulated exactly:

    >>> import nscontrol as nsc
    >>> from nscontrol.numerics.lti import Exosystem
    >>> osc = LagrangianSystem(np.eye(1), stiffness=[[1.0]], gap_matrix=[[-1.0]],
    ...                        gap_offset=[0.3], restitution=0.8, actuation=[[1.0]])
    >>> traj = nsc.simulate(osc, [0.0, 0.0], (0.0, 20.0), u=Exosystem.sinusoid(0.9, 1.7))
    >>> ev = traj.events_of("impact")[0]
    >>> bool(abs(ev.post[1] + 0.8 * ev.pre[1]) < 1e-14)   # Newton's law at the wall
    True
    """

    # The fields hold the normalised values (float arrays); __init__ accepts array_like.
    mass: Any   # FloatArray (n, n) or (n,) (a diagonal), or a ConfigurationFn
    stiffness: FloatArray | None = None
    damping: FloatArray | None = None
    constant_force: FloatArray = None  # type: ignore[assignment]  # None -> zeros(n) at init
    force: ForceFn | None = None
    gap_matrix: FloatArray | None = None
    gap_offset: FloatArray | None = None
    gap: ConfigurationFn | None = None
    jacobian: ConfigurationFn | None = None
    restitution: FloatArray = 0.0  # type: ignore[assignment]  # a scalar -> full(m) at init
    actuation: FloatArray | None = None
    potential: Callable[[FloatArray], float] | None = None
    names: Sequence[str] = ()
    force_jacobian: ForceJacobianFn | None = None
    friction: FloatArray | None = None
    tangent_matrix: FloatArray | None = None
    compiled: Any = None   # a CompiledModel
    n_dof: int = field(init=False)
    n_contacts: int = field(init=False)
    #: Tangent directions per contact: 0 (frictionless), 1 (planar) or 2 (spatial).
    friction_dim: int = field(init=False)

    if TYPE_CHECKING:
        # What the constructor accepts (the dataclass fields hold the normalised values).
        def __init__(self, mass: ArrayLike | ConfigurationFn, stiffness: ArrayLike | None = None,
                     damping: ArrayLike | None = None, constant_force: ArrayLike | None = None,
                     force: ForceFn | None = None,
                     gap_matrix: Any = None,   # array_like or a scipy.sparse matrix (untyped)
                     gap_offset: ArrayLike | None = None, gap: ConfigurationFn | None = None,
                     jacobian: ConfigurationFn | None = None, restitution: ArrayLike = 0.0,
                     actuation: ArrayLike | None = None,
                     potential: Callable[[FloatArray], float] | None = None,
                     names: Sequence[str] = (),
                     force_jacobian: ForceJacobianFn | None = None,
                     friction: ArrayLike | None = None,
                     tangent_matrix: ArrayLike | None = None,
                     compiled: CompiledModel | None = None) -> None: ...

    default_method = "event_driven"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if callable(self.mass):
            n = _infer_dof(self)
        elif np.ndim(self.mass) == 1:
            # a diagonal mass matrix given by its diagonal (large chains and stacks)
            M = as_vector("mass", self.mass)
            for i, mi in enumerate(M):
                check_positive(f"mass[{i}]", mi)
            set_(self, "mass", M)
            n = M.shape[0]
        else:
            M = as_square("mass", self.mass)
            check_positive_definite("mass", M)
            set_(self, "mass", M)
            n = M.shape[0]
        set_(self, "n_dof", n)
        for name in ("stiffness", "damping"):
            value = getattr(self, name)
            if value is not None:
                set_(self, name, as_square(name, value, n))
        f0 = np.zeros(n) if self.constant_force is None else as_vector(
            "constant_force", self.constant_force, n)
        set_(self, "constant_force", f0)
        m = self._check_constraints(n)
        set_(self, "n_contacts", m)
        e = np.full(m, as_real_scalar("restitution", self.restitution)) \
            if np.ndim(self.restitution) == 0 else as_vector("restitution", self.restitution, m)
        for j, ej in enumerate(e):
            check_in_interval(f"restitution[{j}]", ej, 0.0, 1.0)
        set_(self, "restitution", e)
        if self.actuation is not None:
            set_(self, "actuation", as_matrix("actuation", self.actuation, rows=n))
        names = tuple(self.names) or tuple(str(i) for i in range(n))
        if len(names) != n:
            raise DimensionError(f"names: expected {n} coordinate names, got {len(names)}")
        set_(self, "names", names)
        self._check_force_jacobian(n)
        self._check_friction(n, m)
        if self.compiled is not None:
            if not isinstance(self.compiled, CompiledModel):
                raise ModelError(f"compiled: expected a CompiledModel, got "
                                 f"{type(self.compiled).__name__}")
            self.compiled.check_against(self)

    def _check_friction(self, n: int, m: int) -> None:
        """``friction`` (μ_j >= 0, one per contact) and ``tangent_matrix`` (``m d`` rows,
        ``d`` 1 or 2) come together, on affine gaps only."""
        set_ = object.__setattr__
        if self.friction is None and self.tangent_matrix is None:
            set_(self, "friction_dim", 0)
            return
        if self.friction is None or self.tangent_matrix is None:
            given, missing = (("friction", "tangent_matrix") if self.tangent_matrix is None
                              else ("tangent_matrix", "friction"))
            raise ModelError(f"{missing}: {given} was given without it; Coulomb friction needs "
                             "both the coefficients and the tangent Jacobian")
        if self.gap_matrix is None:
            raise ModelError("friction: supported on affine gaps (gap_matrix) only; linearise "
                             "the gaps about the working configuration")
        mu = np.full(m, as_real_scalar("friction", self.friction)) \
            if np.ndim(self.friction) == 0 else as_vector("friction", self.friction, m)
        for j, mu_j in enumerate(mu):
            check_positive(f"friction[{j}]", mu_j, allow_zero=True)
        shape = getattr(self.tangent_matrix, "shape", None) or np.shape(self.tangent_matrix)
        if len(shape) != 2 or shape[0] not in (m, 2 * m):
            raise DimensionError(f"tangent_matrix: expected {m} rows (planar contacts, one "
                                 f"tangent each) or {2 * m} (spatial, two each), got shape "
                                 f"{shape}")
        T = _as_gap_matrix(self.tangent_matrix, n, "tangent_matrix")
        set_(self, "friction", mu)
        set_(self, "tangent_matrix", T)
        set_(self, "friction_dim", T.shape[0] // m if m else 0)
        if self.friction_dim:   # the integrator that resolves Coulomb's law at the contacts
            set_(self, "default_method", "moreau_jean")

    def _check_force_jacobian(self, n: int) -> None:
        """Probe ``force_jacobian`` at ``(t, q, v) = (0, 0, 0)``: shapes, and agreement with
        central differences of ``force`` (a transposed or sign-flipped Jacobian would make
        the implicit forces wrong without any error)."""
        if self.force_jacobian is None:
            return
        if self.force is None:
            raise ModelError("force_jacobian: given without force; it holds the derivatives "
                             "of force (the linear terms -K q - D v are known)")
        if not callable(self.force_jacobian):
            raise ModelError("force_jacobian: expected a callable (t, q, v) -> (dforce/dq, "
                             f"dforce/dv), got {type(self.force_jacobian).__name__}")
        zero = np.zeros(n)
        Jq, Jv = _as_jacobian_pair(self.force_jacobian(0.0, zero, zero.copy()), n, "at t = 0")
        fd_q, fd_v = _central_force_jacobians(self.force, 0.0, zero, zero.copy())
        for label, J, fd in (("dforce/dq", Jq, fd_q), ("dforce/dv", Jv, fd_v)):
            scale = np.abs(fd).max(initial=0.0) + np.abs(J).max(initial=0.0)
            err = float(np.abs(fd - J).max(initial=0.0))
            if scale > 0.0 and err > 1e-6 * scale:  # central differences: ~eps^(2/3) = 4e-11
                warnings.warn(f"force_jacobian: its {label} disagrees with central differences "
                              f"of force at (t, q, v) = 0 (max difference {err:.3g}, scale "
                              f"{scale:.3g}); check signs and layout (row i = gradient of "
                              "force_i)", NscontrolWarning, stacklevel=5)

    def _check_constraints(self, n: int) -> int:
        set_ = object.__setattr__
        if (self.gap_matrix is None) == (self.gap is None):
            raise ModelError("constraints: expected exactly one of gap_matrix (affine gaps "
                             "G q + g0) or gap (a callable q -> g(q)); got "
                             f"{'both' if self.gap is not None else 'neither'}")
        if self.gap_matrix is not None:
            G = _as_gap_matrix(self.gap_matrix, n)
            set_(self, "gap_matrix", G)
            g0 = np.zeros(G.shape[0]) if self.gap_offset is None else as_vector(
                "gap_offset", self.gap_offset, G.shape[0])
            set_(self, "gap_offset", g0)
            return int(G.shape[0])
        g = as_vector("gap(q)", self._gap_function()(np.zeros(n)))
        m = g.shape[0]
        if self.jacobian is None:
            warnings.warn("jacobian: not given; using central differences of gap (give an "
                          "analytic jacobian for accuracy and speed)", NscontrolWarning,
                          stacklevel=4)
        else:
            J = as_matrix("jacobian(q)", self.jacobian(np.zeros(n)), rows=m, cols=n)
            _warn_if_jacobian_disagrees(self._gap_function(), J, n)
        return int(m)

    # -- structure ----------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Length of the state ``[q; v]``."""
        return 2 * self.n_dof

    @property
    def constant_mass(self) -> bool:
        return not callable(self.mass)

    @property
    def is_linear(self) -> bool:
        """Constant mass, linear forces and affine gaps: linear between events."""
        return self.constant_mass and self.force is None and self.gap is None

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"q_{s}" for s in self.names) + tuple(f"v_{s}" for s in self.names)

    # -- evaluation ---------------------------------------------------------------------
    def mass_matrix(self, q: FloatArray | None = None) -> FloatArray:
        """``M(q)`` as a dense matrix (``q`` unused when the mass is constant)."""
        if callable(self.mass):
            return np.asarray(self.mass(q), float)
        return np.diag(self.mass) if self.mass.ndim == 1 else self.mass

    @property
    def mass_diagonal(self) -> FloatArray | None:
        """The diagonal of a constant diagonal mass matrix, ``None`` otherwise."""
        if callable(self.mass):
            return None
        if self.mass.ndim == 1:
            return self.mass
        d = np.diag(self.mass)
        return d.copy() if np.array_equal(self.mass, np.diag(d)) else None

    def dense_gap_matrix(self) -> FloatArray:
        """The affine gaps' matrix as a dense array."""
        G = self.gap_matrix
        if G is None:
            raise ModelError("gap_matrix: this system has nonlinear gaps (gap=...); "
                             "use gap_jacobian(q) for their Jacobian")
        return G.toarray() if hasattr(G, "toarray") else np.asarray(G)

    def forces(self, t: float, q: FloatArray, v: FloatArray,
               u: FloatArray | None = None) -> FloatArray:
        """Generalised smooth force ``f(t, q, v) + S u``."""
        f = self.constant_force.copy()
        if self.stiffness is not None:
            f -= self.stiffness @ q
        if self.damping is not None:
            f -= self.damping @ v
        if self.force is not None:
            f += self.force(t, q, v)
        if u is not None:
            f += (np.asarray(u, float) if self.actuation is None
                  else self.actuation @ np.atleast_1d(u))
        return f

    def force_jacobians(self, t: float, q: FloatArray, v: FloatArray
                        ) -> tuple[FloatArray, FloatArray, bool]:
        """``(∂f/∂q, ∂f/∂v, analytic)`` of the smooth force ``f = f0 - K q - D v + force``.

        The derivatives of ``force`` come from ``force_jacobian`` when given (``analytic``
        true), otherwise from central differences with the step ``δ = ε^(1/3) (1 + ‖x‖∞)``
        (``ε`` the unit roundoff, ``x`` = ``q`` or ``v``: the step balancing truncation
        ``O(δ²)`` and roundoff ``O(ε/δ)``, relative error about ``ε^(2/3) ≈ 4e-11``;
        ``4 n`` evaluations of ``force``). Shapes of an analytic pair are checked
        (``ModelError`` naming ``force_jacobian`` and ``t``).
        """
        n = self.n_dof
        if self.force is None:
            Jq, Jv, analytic = np.zeros((n, n)), np.zeros((n, n)), True
        elif self.force_jacobian is not None:
            Jq, Jv = _as_jacobian_pair(self.force_jacobian(t, q, v), n, f"at t = {t:.6g}",
                                       runtime=True)
            analytic = True
        else:
            Jq, Jv = _central_force_jacobians(self.force, t, q, v)
            analytic = False
        if self.stiffness is not None:
            Jq = Jq - self.stiffness
        if self.damping is not None:
            Jv = Jv - self.damping
        return Jq, Jv, analytic

    def gaps(self, q: FloatArray) -> FloatArray:
        """``g(q)``, shape ``(m,)``."""
        G, g0 = self.gap_matrix, self.gap_offset
        if G is not None and g0 is not None:   # affine gaps: __post_init__ set both
            return np.asarray(G @ q + g0, float)
        return np.asarray(self._gap_function()(q), float)

    def gap_jacobian(self, q: FloatArray) -> FloatArray:
        """``∂g/∂q``, shape ``(m, n)``."""
        if self.gap_matrix is not None:
            return self.gap_matrix
        if self.jacobian is not None:
            return np.asarray(self.jacobian(q), float)
        eps = 1e-7 * max(1.0, float(np.max(np.abs(q), initial=0.0)))
        gap = self._gap_function()
        cols = [(gap(q + eps * d) - gap(q - eps * d)) / (2 * eps)
                for d in np.eye(self.n_dof)]
        return np.array(cols).T

    def _gap_function(self) -> ConfigurationFn:
        """The nonlinear gap callable (``ModelError`` for a system with affine gaps)."""
        if self.gap is None:
            raise ModelError("gap: this system has affine gaps (gap_matrix); there is no "
                             "gap callable")
        return self.gap

    def energy(self, x: FloatArray) -> FloatArray:
        """Mechanical energy ``½ vᵀMv + ½ qᵀKq - f0ᵀq (+ potential)``; ``x`` (.., 2n)."""
        x = np.asarray(x, float)
        n = self.n_dof
        q, v = x[..., :n], x[..., n:]
        if self.constant_mass and self.mass.ndim == 1:
            kin = 0.5 * np.einsum("...i,i,...i->...", v, self.mass, v)
        elif self.constant_mass:
            kin = 0.5 * np.einsum("...i,ij,...j->...", v, self.mass, v)
        else:
            kin = np.array([0.5 * vi @ self.mass(qi) @ vi for qi, vi in
                            zip(q.reshape(-1, n), v.reshape(-1, n), strict=True)]
                           ).reshape(q.shape[:-1])
        pot = -q @ self.constant_force
        if self.stiffness is not None:
            pot = pot + 0.5 * np.einsum("...i,ij,...j->...", q, self.stiffness, q)
        if self.potential is not None:
            pot = pot + np.array([self.potential(qi) for qi in q.reshape(-1, n)]
                                 ).reshape(q.shape[:-1])
        return kin + pot

    def check_state(self, x0: ArrayLike, *, tol: float = 1e-12) -> FloatArray:
        """Validate ``x0 = [q0; v0]``: no penetration, no approaching velocity at contact.

        Raises
        ------
        DimensionError
            ``x0`` is not of length ``2 n``.
        InadmissibleStateError
            Some gap is negative, or zero with a closing normal velocity.
        ModelError
            A configuration-dependent mass matrix is not SPD at ``q0``.
        """
        x0 = as_vector("x0", x0, self.n_states)
        q, v = x0[: self.n_dof], x0[self.n_dof:]
        if not self.constant_mass:
            check_positive_definite("mass(q0)", as_square("mass(q0)", self.mass(q),
                                                           self.n_dof))
        g = self.gaps(q)
        scale = max(1.0, float(np.max(np.abs(q), initial=0.0)))
        bad = np.flatnonzero(g < -tol * scale)
        if bad.size:
            j = int(bad[0])
            raise InadmissibleStateError(
                f"x0: contact {j} is penetrated, gap g_{j}(q0) = {g[j]:.3g} < 0; start from a "
                "configuration with all gaps >= 0")
        closed = np.flatnonzero(g <= tol * scale)
        if closed.size:
            un = self.gap_jacobian(q)[closed] @ v
            vscale = max(1.0, float(np.max(np.abs(v), initial=0.0)))
            approaching = closed[un < -tol * vscale]
            if approaching.size:
                j = int(approaching[0])
                raise InadmissibleStateError(
                    f"x0: contact {j} is closed (gap {g[j]:.3g}) with approaching normal "
                    f"velocity {float(self.gap_jacobian(q)[j] @ v):.3g} < 0; apply the impact "
                    "law first or start with a separating velocity")
        return x0

    def pairwise_contacts(self) -> tuple[np.ndarray, ...] | None:
        """For affine gaps touching at most two coordinates each: ``(ia, ib, ca, cb)``.

        Contact ``j`` reads ``g_j = ca[j] q[ia[j]] + cb[j] q[ib[j]] + g0[j]`` (``ib = -1`` when
        it touches one coordinate). ``None`` for any other structure. Computed once per model
        (it is frozen) and shared by every run: do not modify the arrays.
        """
        cached = self.__dict__.get("_pairwise")
        if cached is None:
            cached = (self._find_pairwise(),)
            object.__setattr__(self, "_pairwise", cached)
        return cached[0]

    def _find_pairwise(self) -> tuple[np.ndarray, ...] | None:
        if self.gap_matrix is None:
            return None
        from scipy import sparse

        G = sparse.csr_matrix(self.gap_matrix)
        G.eliminate_zeros()
        G.sort_indices()
        counts = np.diff(G.indptr)
        if np.any(counts == 0) or np.any(counts > 2):
            return None
        m = G.shape[0]
        first = G.indptr[:-1]
        ia, ca = G.indices[first].astype(np.int64), G.data[first].copy()
        two = counts == 2
        ib = np.full(m, -1, np.int64)
        cb = np.zeros(m)
        ib[two] = G.indices[first[two] + 1]
        cb[two] = G.data[first[two] + 1]
        return ia, ib, ca, cb

    # -- constructors -------------------------------------------------------------------
    @classmethod
    def point_masses(cls, masses: ArrayLike, **kwargs: Any) -> LagrangianSystem:
        """Point masses on lines: ``M = diag(masses)``.

        Parameters
        ----------
        masses : array_like (n,)
            Positive masses.
        **kwargs
            The other arguments of :class:`LagrangianSystem` (stiffness, gaps, restitution).

        Examples
        --------
        >>> s = LagrangianSystem.point_masses([1.0, 2.0], gap_matrix=[[-1.0, 1.0]])
        >>> s.n_dof, s.n_contacts
        (2, 1)
        """
        m = as_vector("masses", masses)
        for i, mi in enumerate(m):
            check_positive(f"masses[{i}]", mi)
        return cls(m, **kwargs)

    @classmethod
    def bouncing_ball(cls, restitution: float = 0.9, g: float = 9.81,
                      mass: float = 1.0) -> LagrangianSystem:
        """A ball of mass ``mass`` above the ground ``q >= 0`` under gravity ``g``.

        Parameters
        ----------
        restitution : float
            Newton coefficient of the ground, in ``[0, 1]``.
        g : float
            Gravity, ``>= 0``.
        mass : float
            Mass, ``> 0``.

        Examples
        --------
        >>> import nscontrol as nsc
        >>> traj = nsc.simulate(LagrangianSystem.bouncing_ball(0.5), [1.0, 0.0], (0.0, 1.0))
        >>> bool(abs(traj.event_times("impact")[0] - np.sqrt(2 / 9.81)) < 1e-14)
        True
        """
        mass = check_positive("mass", mass)
        g = check_positive("g", g, allow_zero=True)
        return cls(np.array([[mass]]), constant_force=[-mass * g], gap_matrix=[[1.0]],
                   restitution=restitution, names=("ball",))

    @classmethod
    def stack(cls, n: int, *, mass: float = 1.0, g: float = 9.81,
              restitution: float = 0.0) -> LagrangianSystem:
        """``n`` point masses stacked on the ground: ``q_0 >= 0``, ``q_k - q_{k-1} >= 0``.

        At rest (all gaps zero) the contact ``k`` carries ``(n - k) m g``. The gap matrix is
        sparse (bidiagonal), so the Moreau–Jean integrator takes its O(n) path.

        Parameters
        ----------
        n : int
            Number of masses, ``>= 1``.
        mass, g : float
            Mass of each body, gravity.
        restitution : float
            Coefficient of every contact.

        Examples
        --------
        >>> LagrangianSystem.stack(1000).n_contacts
        1000
        """
        n = _check_count("n", n)
        from scipy import sparse

        mass = check_positive("mass", mass)
        G = sparse.diags([np.ones(n), -np.ones(n - 1)], [0, -1], format="csr")
        return cls(np.full(n, mass), constant_force=np.full(n, -mass * check_positive(
            "g", g, allow_zero=True)), gap_matrix=G, restitution=restitution)

    @classmethod
    def chain(cls, masses: ArrayLike, *, stiffness: ArrayLike | None = None, spacing: float = 0.0,
              restitution: Any = 1.0) -> LagrangianSystem:
        """Point masses on a line, consecutive ones unilateral: ``q_{k+1} - q_k >= spacing``.

        Parameters
        ----------
        masses : array_like (n,)
            Positive masses, ``n >= 2``.
        stiffness : array_like (n, n), optional
            Springs between the masses (``-K q``).
        spacing : float
            Smallest distance between neighbours, ``>= 0``.
        restitution : float or array_like (n - 1,)
            Coefficients of the ``n - 1`` contacts.

        Examples
        --------
        >>> LagrangianSystem.chain([1.0, 1.0, 1.0], spacing=0.01).gaps(np.array([0.0, 0.02, 0.05]))
        array([0.01, 0.02])
        """
        from scipy import sparse

        m = as_vector("masses", masses)
        n = m.shape[0]
        if n < 2:
            raise ModelError(f"masses: a chain needs at least 2 masses, got {n}")
        G = sparse.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n),
                         format="csr")
        spacing = check_positive("spacing", spacing, allow_zero=True)
        return cls.point_masses(m, stiffness=stiffness, gap_matrix=G,
                                gap_offset=np.full(n - 1, -spacing), restitution=restitution)

    @classmethod
    def newtons_cradle(cls, n: int, *, mass: float = 1.0, restitution: float = 1.0,
                       diameter: float = 0.0) -> LagrangianSystem:
        """``n`` equal beads on a line (free flight between collisions), gaps ``>= diameter``.

        Parameters
        ----------
        n : int
            Number of beads, ``>= 2``.
        mass : float
            Mass of each bead.
        restitution : float
            Coefficient of every contact (1: elastic, the velocity is handed along).
        diameter : float
            Bead diameter (smallest distance of neighbouring centres).

        Examples
        --------
        >>> import nscontrol as nsc
        >>> cradle = LagrangianSystem.newtons_cradle(3)
        >>> traj = nsc.simulate(cradle, [0.0, 0.1, 0.2, 1.0, 0.0, 0.0], (0.0, 0.5))
        >>> bool(np.allclose(traj.x[-1, 3:], [0.0, 0.0, 1.0], atol=1e-14))
        True
        """
        n = _check_count("n", n, minimum=2)
        return cls.chain(np.full(n, check_positive("mass", mass)), spacing=diameter,
                         restitution=restitution)

    @classmethod
    def two_link_arm(cls, *, l1: float = 0.5, l2: float = 0.5, m1: float = 1.0,
                     m2: float = 1.0, I1: float = 1.0, I2: float = 1.0, g: float = 9.8,
                     restitution: float = 0.0) -> LagrangianSystem:
        """The planar two-link arm of ch03 §4.1, end effector above the ground ``y >= 0``.

        Coordinates ``θ = (θ1, θ2)``; force ``-C(θ, θ')θ' - G(θ)`` (Christoffel form);
        constraint ``y = l1 sin θ1 + l2 sin(θ1 + θ2) >= 0`` with its analytic Jacobian; a
        :class:`CompiledModel` of all of them (Moreau–Jean's compiled loop, with compiled
        blocks or without a controller).

        Parameters
        ----------
        l1, l2, m1, m2, I1, I2 : float
            Link lengths, masses and inertias (``> 0``).
        g : float
            Gravity.
        restitution : float
            Coefficient of the end effector's contact with the ground.

        References
        ----------
        Spec ``ch03-ch05-lagrangian-tracking.md`` §4.1.

        Examples
        --------
        >>> arm = LagrangianSystem.two_link_arm()
        >>> M = arm.mass_matrix(np.array([0.3, -0.6]))
        >>> bool(np.allclose(M, M.T) and np.all(np.linalg.eigvalsh(M) > 0))
        True
        """
        for key, value in dict(l1=l1, l2=l2, m1=m1, m2=m2, I1=I1, I2=I2).items():
            check_positive(key, value)
        g = check_positive("g", g, allow_zero=True)
        from . import _two_link_kernels as tk

        # one source: the Python callables are the compiled kernels (the arrays made
        # contiguous float64, as their declared signatures take them)
        p = tk.arm_array(l1, l2, m1, m2, I1, I2, g)

        def force(t: float, q: FloatArray, v: FloatArray) -> FloatArray:
            return tk.force(float(t), _f64(q), _f64(v), p)

        def force_jacobian(t: float, q: FloatArray, v: FloatArray
                           ) -> tuple[FloatArray, FloatArray]:
            J = tk.force_jacobian(float(t), _f64(q), _f64(v), p)
            return J[:2], J[2:]

        compiled = CompiledModel(tk.mass, tk.force, tk.force_jacobian, tk.gaps,
                                 tk.gap_jacobian, p, potential=tk.potential)
        return cls(lambda q: tk.mass(_f64(q), p), force=force,
                   gap=lambda q: tk.gaps(_f64(q), p),
                   jacobian=lambda q: tk.gap_jacobian(_f64(q), p), restitution=restitution,
                   potential=lambda q: float(tk.potential(_f64(q), p)),
                   names=("theta1", "theta2"), force_jacobian=force_jacobian,
                   compiled=compiled)


def _f64(a: ArrayLike) -> FloatArray:
    """``a`` as a contiguous ``float64`` array (what a declared kernel takes)."""
    return np.ascontiguousarray(a, dtype=np.float64)


def two_link_arm_mass(q: ArrayLike, *, l1: float, l2: float, m1: float, m2: float,
                      I1: float, I2: float) -> FloatArray:
    """Mass matrix of the two-link arm (ch03 §4.1).

    The compiled model's kernel (``nscontrol.systems._two_link_kernels.mass``): one source.

    Parameters
    ----------
    q : (2,) array_like
        Joint angles ``θ``.
    l1, l2 : float
        Link lengths.
    m1, m2 : float
        Link masses.
    I1, I2 : float
        Link moments of inertia about their centres of mass.
    """
    from . import _two_link_kernels as tk

    return tk.mass(_f64(q), tk.arm_array(l1, l2, m1, m2, I1, I2))


def two_link_arm_coriolis(q: ArrayLike, v: ArrayLike, *, l1: float, l2: float, m1: float,
                          m2: float, I1: float, I2: float) -> FloatArray:
    """Coriolis matrix in Christoffel form (``Ṁ - 2C`` skew-symmetric), ch03 §4.1.

    Parameters
    ----------
    q : (2,) array_like
        Joint angles ``θ``.
    v : (2,) array_like
        Joint velocities ``θ'``.
    l1, l2 : float
        Link lengths.
    m1, m2 : float
        Link masses.
    I1, I2 : float
        Link moments of inertia about their centres of mass.
    """
    from . import _two_link_kernels as tk

    return tk.coriolis(_f64(q), _f64(v), tk.arm_array(l1, l2, m1, m2, I1, I2))


def two_link_arm_gravity(q: ArrayLike, *, g: float, l1: float, l2: float, m1: float,
                         m2: float, I1: float, I2: float) -> FloatArray:
    """Gravity torques ``G = ∂P/∂θ`` of the two-link arm, ch03 §4.1.

    Parameters
    ----------
    q : (2,) array_like
        Joint angles ``θ``.
    g : float
        Gravitational acceleration.
    l1, l2 : float
        Link lengths.
    m1, m2 : float
        Link masses.
    I1, I2 : float
        Link moments of inertia about their centres of mass.
    """
    from . import _two_link_kernels as tk

    return tk.gravity(_f64(q), tk.arm_array(l1, l2, m1, m2, I1, I2, g))


def two_link_arm_force_jacobian(q: ArrayLike, v: ArrayLike, *, g: float, l1: float,
                                l2: float, m1: float, m2: float, I1: float, I2: float
                                ) -> tuple[FloatArray, FloatArray]:
    """``(∂f/∂θ, ∂f/∂θ')`` of the two-link arm's force ``f = -C(θ, θ')θ' - G(θ)``.

    With ``c = m2 l1 l2 / 2``: ``-C θ' = c sin θ2 (2 θ1'θ2' + θ2'², -θ1'²)``.

    Parameters
    ----------
    q : (2,) array_like
        Joint angles ``θ``.
    v : (2,) array_like
        Joint velocities ``θ'``.
    g : float
        Gravitational acceleration.
    l1, l2 : float
        Link lengths.
    m1, m2 : float
        Link masses.
    I1, I2 : float
        Link moments of inertia about their centres of mass.
    """
    from . import _two_link_kernels as tk

    J = tk.force_jacobian(0.0, _f64(q), _f64(v), tk.arm_array(l1, l2, m1, m2, I1, I2, g))
    return J[:2], J[2:]


def _as_jacobian_pair(value: Any, n: int, where: str, *, runtime: bool = False
                      ) -> tuple[FloatArray, FloatArray]:
    """Two finite ``(n, n)`` arrays from what ``force_jacobian`` returned; the error names
    ``force_jacobian`` and ``where`` (a shape error is a ``ModelError`` during a run)."""
    shapes = None
    try:
        Jq, Jv = value
        Jq, Jv = np.asarray(Jq, dtype=float), np.asarray(Jv, dtype=float)
        shapes = (Jq.shape, Jv.shape)
    except (TypeError, ValueError):
        pass
    if shapes is None:
        raise ModelError(f"force_jacobian: expected a pair (dforce/dq, dforce/dv) of real "
                         f"({n}, {n}) arrays {where}, got {type(value).__name__}")
    if shapes != ((n, n), (n, n)):
        cls = ModelError if runtime else DimensionError
        raise cls(f"force_jacobian: expected two ({n}, {n}) arrays (dforce/dq, dforce/dv) "
                  f"{where}, got shapes {shapes[0]} and {shapes[1]}")
    if not (np.isfinite(Jq).all() and np.isfinite(Jv).all()):
        raise ModelError(f"force_jacobian: returned non-finite entries {where}")
    return Jq, Jv


def _central_force_jacobians(force: ForceFn, t: float, q: FloatArray, v: FloatArray
                             ) -> tuple[FloatArray, FloatArray]:
    """Central differences of ``force`` in ``q`` and ``v``, step ``ε^(1/3) (1 + ‖x‖∞)``."""
    n = q.shape[0]
    out = []
    for x, other_first in ((q, True), (v, False)):
        step = _CBRT_EPS * (1.0 + float(np.max(np.abs(x), initial=0.0)))
        J = np.empty((n, n))
        for i in range(n):
            xp, xm = x.copy(), x.copy()
            xp[i] += step
            xm[i] -= step
            fp = force(t, xp, v) if other_first else force(t, q, xp)
            fm = force(t, xm, v) if other_first else force(t, q, xm)
            J[:, i] = (np.asarray(fp, float) - np.asarray(fm, float)) / (xp[i] - xm[i])
        out.append(J)
    return out[0], out[1]


def _as_gap_matrix(value: Any, n: int, name: str = "gap_matrix") -> Any:
    """A dense (m, n) array, or a scipy.sparse CSR matrix kept sparse (large chains); no zero
    row (a contact that no motion opens or closes has no normal direction)."""
    if hasattr(value, "tocsr"):
        G = value.tocsr().astype(np.float64)
        if G.shape[1] != n:
            raise DimensionError(f"{name}: expected {n} columns, got shape {G.shape}")
        if not np.all(np.isfinite(G.data)):
            raise ModelError(f"{name}: expected finite entries, got NaN or infinite ones")
        row_norms = np.asarray(abs(G).sum(axis=1)).ravel()
    else:
        G = as_matrix(name, value, cols=n)
        row_norms = np.abs(G).sum(axis=1)
    zero = np.flatnonzero(row_norms == 0.0)
    if zero.size:
        raise ModelError(f"{name}: row {int(zero[0])} is zero; every contact needs a "
                         "normal (and tangent) direction (drop the row, or give the "
                         "coordinates it constrains)")
    return G


def _warn_if_jacobian_disagrees(gap: Callable[[FloatArray], Any], J: FloatArray,
                                n: int) -> None:
    """Compare the given jacobian with central differences of ``gap`` at ``q = 0``; a wrong
    sign or a transposed row would silently reverse impacts."""
    step = 1e-6
    fd = np.empty_like(J)
    for i in range(n):
        dq = np.zeros(n)
        dq[i] = step
        fd[:, i] = (np.asarray(gap(dq), float) - np.asarray(gap(-dq), float)) / (2 * step)
    scale = np.abs(fd).max(initial=0.0) + np.abs(J).max(initial=0.0)
    err = float(np.abs(fd - J).max(initial=0.0))
    if scale > 0.0 and err > 1e-4 * scale:
        warnings.warn(f"jacobian: disagrees with central differences of gap at q = 0 (max "
                      f"difference {err:.3g}, scale {scale:.3g}); check its signs and layout "
                      "(row j = gradient of gap j)", NscontrolWarning, stacklevel=5)


def _infer_dof(system: LagrangianSystem) -> int:
    """The number of coordinates of a system whose mass is a callable."""
    for source in ("stiffness", "damping", "gap_matrix", "actuation"):
        value = getattr(system, source)
        if value is not None:
            arr = value if hasattr(value, "shape") else np.asarray(value)
            return int(arr.shape[1] if source == "gap_matrix" else arr.shape[0])
    if system.names:
        return len(system.names)
    raise ModelError("mass: a callable mass matrix needs the number of coordinates; pass "
                     "names=(...) with one name per coordinate")


def _check_count(name: str, value: Any, minimum: int = 1) -> int:
    if int(value) != value or int(value) < minimum:
        raise ModelError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return int(value)
