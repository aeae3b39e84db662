"""Moreau–Jean with nonlinear forces: the linearised θ-method, its order and stability, and
controllers that read the contact multiplier."""

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from nscontrol import closed_loop
from nscontrol.errors import DimensionError, ModelError, NscontrolWarning, SolverError
from nscontrol.simulate import simulate
from nscontrol.systems.feedback import StaticLaw
from nscontrol.systems.lagrangian import LagrangianSystem

EPS = np.finfo(float).eps
#: Central differences with step ε^(1/3) scale: relative error about ε^(2/3) (truncation and
#: roundoff balanced).
FD_REL = EPS ** (2 / 3)
#: A gap that never closes in the smooth tests (the systems need one constraint).
FAR = dict(gap_matrix=[[1.0]], gap_offset=[1e6])


def _scalar_jacobian(dq, dv=0.0):
    return lambda t, q, v: (np.array([[dq(t, q, v)]]), np.array([[dv]]))


# -- agreement with the compiled paths -------------------------------------------------------
@pytest.mark.parametrize("analytic", [True, False])
def test_python_path_agrees_with_the_compiled_path_on_a_linear_system(analytic: bool) -> None:
    # a ball on a spring-damper bouncing on the ground: linear, so the compiled path runs it;
    # the same spring-damper given as a force callable runs on the Python path
    k, c, g, e = 50.0, 0.5, 9.81, 0.7
    common = dict(constant_force=[-g], gap_matrix=[[1.0]], gap_offset=[0.1], restitution=e)
    linear = LagrangianSystem(np.eye(1), stiffness=[[k]], damping=[[c]], **common)
    jac = (lambda t, q, v: (np.array([[-k]]), np.array([[-c]]))) if analytic else None
    python = LagrangianSystem(np.eye(1), force=lambda t, q, v: -k * q - c * v,
                              force_jacobian=jac, **common)
    h, x0 = 1e-3, [1.0, 0.0]
    a = simulate(linear, x0, (0.0, 10.0), method="moreau_jean", h=h)
    b = simulate(python, x0, (0.0, 10.0), method="moreau_jean", h=h)
    assert a.stats["path"] == "tridiagonal" and b.stats["path"] == "python"
    assert b.stats["forces"] == "implicit"
    assert b.stats["force_jacobian"] == ("analytic" if analytic else "central differences")
    n = b.stats["steps"]
    scale = np.max(np.abs(a.x))
    # the same step with the operations in another order (inverse vs precomputed 1/M̂, a
    # closed-form single-contact LCP): a few ε of relative error per step, accumulated over
    # n steps of a contracting (damped, e < 1) motion: 8 ε n scale. Central differences of a
    # linear force add their error FD_REL (k + c) to J, which enters each step through
    # h θ J (relative to M = 1): n h (k + c) FD_REL scale.
    tol = 8 * EPS * n * scale + (0.0 if analytic else n * h * (k + c) * FD_REL * scale)
    assert np.max(np.abs(a.x - b.x)) <= tol
    assert np.max(np.abs(a.signals["impulse"] - b.signals["impulse"])) <= tol
    assert len(a.events_of("impact")) == len(b.events_of("impact")) >= 5


def test_explicit_forces_run_a_sparse_linear_stack_on_the_python_path() -> None:
    # constant forces: explicit and implicit are the same scheme; the stack's gaps are sparse
    from nscontrol.testing.mechanics_problems import RestingStack

    stack = RestingStack(10)
    h = 1e-3
    traj = simulate(stack.system(), stack.x0, (0.0, 5 * h), method="moreau_jean", h=h,
                    forces="explicit", signals=["impulse"])
    assert traj.stats["path"] == "python" and traj.stats["forces"] == "explicit"
    # the impulses (N - k) m g h from a 10 x 10 Lemke solve: relative error a few ε times
    # the Delassus matrix's condition number (<= 4 N² = 400): 1e-10 covers it 100 times
    p = traj.signals["impulse"][1:]
    assert np.max(np.abs(p - stack.impulses(h)) / stack.impulses(h)) < 1e-10


# -- order of convergence ------------------------------------------------------------------
def _pendulum() -> tuple[LagrangianSystem, callable, list, float]:
    w2 = 9.81  # g / l with l = 1
    system = LagrangianSystem(np.eye(1), force=lambda t, q, v: -w2 * np.sin(q),
                              force_jacobian=_scalar_jacobian(
                                  lambda t, q, v: -w2 * np.cos(q[0])), **FAR)
    return system, lambda t, x: [x[1], -w2 * np.sin(x[0])], [1.0, 0.0], np.sqrt(w2)


def _duffing() -> tuple[LagrangianSystem, callable, list, float]:
    # forced, damped: x'' + δ x' + α x + β x³ = γ cos(ω t); no force_jacobian (central
    # differences), a force depending on t
    d, a, b, gam, w = 0.2, 1.0, 1.0, 0.5, 1.2

    def force(t, q, v):
        return gam * np.cos(w * t) - a * q - b * q**3 - d * v

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no jacobian warning for forces: none is expected
        system = LagrangianSystem(np.eye(1), force=force, **FAR)
    return system, lambda t, x: [x[1], force(t, x[0], x[1])], [1.0, 0.5], 2.0


@pytest.mark.parametrize("problem", [_pendulum, _duffing])
@pytest.mark.parametrize("theta, order", [(1.0, 1.0), (0.5, 2.0)])
def test_order_of_the_linearised_theta_method(problem, theta: float, order: float) -> None:
    system, rhs, x0, omega = problem()
    T = 2.0
    ref = solve_ivp(rhs, (0.0, T), x0, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
    hs = 0.02 / 2.0 ** np.arange(5)
    errs = [abs(simulate(system, x0, (0.0, T), method="moreau_jean", h=h, theta=theta,
                         signals=[]).x[-1, 0] - ref[0]) for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    # the error is C h^p (1 + c h + ...): the next term moves a halving's slope by about
    # c h / (2 ln 2); margin 0.1 allows |c| up to 7 at h = 0.02, a few times the fastest
    # frequency ω (3.1 for the pendulum, about 2 for the Duffing oscillator). The
    # reference's error (1e-12) is far below the smallest error (> 1e-7).
    assert abs(slope - order) <= 0.1, (slope, errs)
    assert min(errs) > 1e3 * 1e-12


@pytest.mark.parametrize("mass_at, order", [("start", 1.0), ("predicted", 2.0)])
def test_order_with_a_configuration_dependent_mass(mass_at: str, order: float) -> None:
    # m(q) = 1 + q², V = k q²/2: Lagrange's equation m q'' = -q q'² - k q. With M frozen at
    # q_k, θ = ½ is first order; at the predicted q_k + θ h v_k second order again.
    k = 4.0
    system = LagrangianSystem(
        lambda q: np.array([[1.0 + q[0] ** 2]]), force=lambda t, q, v: -q * v**2 - k * q,
        force_jacobian=lambda t, q, v: (np.array([[-v[0] ** 2 - k]]),
                                        np.array([[-2 * q[0] * v[0]]])),
        names=("x",), **FAR)
    x0, T = [1.0, 0.0], 2.0
    ref = solve_ivp(lambda t, x: [x[1], (-x[0] * x[1] ** 2 - k * x[0]) / (1 + x[0] ** 2)],
                    (0.0, T), x0, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
    hs = 0.02 / 2.0 ** np.arange(5)
    errs = [abs(simulate(system, x0, (0.0, T), method="moreau_jean", h=h, theta=0.5,
                         mass_at=mass_at, signals=[]).x[-1, 0] - ref[0]) for h in hs]
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    # as for constant M: the next term of the error, relative size c h with |c| a few times
    # ω = 2, moves a halving's slope by c h / (2 ln 2); margin 0.1 (|c| <= 7 at h = 0.02)
    assert abs(slope - order) <= 0.1, (slope, errs)


# -- stability on a stiff spring --------------------------------------------------------------
def test_implicit_forces_stay_stable_on_a_stiff_spring_where_explicit_ones_blow_up() -> None:
    h, hw = 1e-2, 2.5  # h ω > 2: beyond the explicit scheme's stability limit
    k = (hw / h) ** 2
    spring = LagrangianSystem(np.eye(1), force=lambda t, q, v: -k * q,
                              force_jacobian=_scalar_jacobian(lambda t, q, v: -k),
                              potential=lambda q: 0.5 * k * float(q[0] ** 2), **FAR)
    x0, span = [1e-3, 0.0], (0.0, 0.3)
    explicit = simulate(spring, x0, span, method="moreau_jean", h=h, theta=1.0,
                        forces="explicit")
    # explicit, θ = 1: the map [[1 - (hω)², h], [-hω², 1]], det 1, trace 2 - (hω)²: its
    # spectral radius |(tr - √(tr² - 4))/2| = 4; once the other eigenvalue (1/4) has died out
    # (after 10 steps, 16^-10 relative), |q| grows by exactly that factor per step, up to a
    # few ε of roundoff per step: rtol 1e-12
    tr = 2 - hw**2
    rho = abs(tr - np.sqrt(tr**2 - 4)) / 2
    q = explicit.x[:, 0]
    assert np.allclose(np.abs(q[11:] / q[10:-1]), rho, rtol=1e-12, atol=0.0)
    assert abs(q[-1]) > 1e10 * x0[0]
    # explicit, θ = ½ at a small h ω = 0.5: the map [[1 - (hω)²/2, h], [-hω², 1]] has
    # complex eigenvalues of modulus √det = √(1 + (hω)²/2) > 1 for every hω < 4: it grows.
    # With A = V Λ V⁻¹ and |Λ| = ρ I, ρ^N / κ(V) <= ‖A^N x0‖ / ‖x0‖ <= κ(V) ρ^N exactly.
    hw_small = 0.5
    A = np.array([[1 - hw_small**2 / 2, h], [-(hw_small / h) ** 2 * h, 1.0]])
    rho_half = np.sqrt(1 + hw_small**2 / 2)
    assert np.allclose(np.abs(np.linalg.eigvals(A)), rho_half, rtol=1e-14)
    kappa_v = np.linalg.cond(np.linalg.eig(A)[1])
    soft = LagrangianSystem(np.eye(1), force=lambda t, q, v: -(hw_small / h) ** 2 * q, **FAR)
    grows = simulate(soft, x0, (0.0, 1.0), method="moreau_jean", h=h, theta=0.5,
                     forces="explicit")
    n_steps = grows.stats["steps"]
    gain = np.linalg.norm(grows.x[-1]) / np.linalg.norm(x0)
    assert rho_half**n_steps / kappa_v <= gain * (1 + 1e-10) and \
        gain <= kappa_v * rho_half**n_steps * (1 + 1e-10)  # 1e-10: roundoff over 100 steps
    assert gain > 1e3
    # implicit, θ = 1: A-stable and damping: the energy never increases
    damped = simulate(spring, x0, span, method="moreau_jean", h=h, theta=1.0)
    E = damped.signals["energy"]
    assert np.all(np.diff(E) <= 4 * EPS * E[0])
    assert E[-1] < E[0]
    # implicit, θ = ½ on a linear force is the trapezoidal rule: it conserves the quadratic
    # energy, up to a few ε per step (4 ε n E0)
    kept = simulate(spring, x0, span, method="moreau_jean", h=h, theta=0.5)
    E = kept.signals["energy"]
    assert np.max(np.abs(E - E[0])) <= 4 * EPS * kept.stats["steps"] * E[0]


# -- controllers that read the contact multiplier --------------------------------------------
@pytest.mark.parametrize("spring_as", ["stiffness", "force"])
def test_force_controller_drives_the_contact_force_to_its_reference(spring_as: str) -> None:
    # a mass on a spring (anchored at 0) pushed against a wall at q = w: gap w - q >= 0,
    # contact force λ acting as -λ. At rest: 0 = -k q + u - λ, the static contact force is
    # λ = u - k q. The controller does not know k: u = u_I - c v, the push u_I starting at
    # λ_ref, integral action u_I += κ (λ_ref - λ̂) once the contact has been active for two
    # steps (the impact step's λ̂ is an impulse over h, not a contact force).
    k, w, lam_ref, kappa, c, h = 4.0, 0.3, 2.0, 0.05, 3.0, 1e-3
    if spring_as == "stiffness":  # linear: the compiled path
        system = LagrangianSystem(np.eye(1), stiffness=[[k]], gap_matrix=[[-1.0]],
                                  gap_offset=[w], restitution=0.0)
    else:  # the spring as a force: the Python path with implicit forces
        system = LagrangianSystem(np.eye(1), force=lambda t, q, v: -k * q,
                                  force_jacobian=_scalar_jacobian(lambda t, q, v: -k),
                                  gap_matrix=[[-1.0]], gap_offset=[w], restitution=0.0)
    seen, state = [], {"u": lam_ref, "was_active": False}

    class Controller(StaticLaw):    # reads the measured contact force and active set
        n_outputs, period = 1, None

        def output(self, t, xc, m):
            lam_hat, active = m.lam, m.active
            seen.append((lam_hat.copy(), active.copy()))
            if active.size and state["was_active"]:
                state["u"] += kappa * (lam_ref - lam_hat[0])
            state["was_active"] = active.size > 0
            return np.array([state["u"] - c * m.x[1]])

    traj = simulate(closed_loop(system, Controller()), [0.0, 0.0], (0.0, 4.0),
                    method="moreau_jean", h=h)
    assert traj.stats["path"] == ("tridiagonal" if spring_as == "stiffness" else "python")
    p = traj.signals["impulse"][:, 0]
    # what the controller read: zeros and no active contact at the first step, then the
    # previous step's impulse over h and its active set
    assert np.array_equal(seen[0][0], [0.0]) and seen[0][1].size == 0
    assert all(np.array_equal(lam, p[i : i + 1] / h) for i, (lam, _) in enumerate(seen))
    assert seen[-1][1].tolist() == [0] and seen[-1][1].dtype.kind == "i"
    # at rest on the wall (penetration <= h |u-|), the contact force is the analytic static
    # force u - k q, to roundoff (a few ε of |u|)
    q_end, v_end, u_end = traj.x[-1, 0], traj.x[-1, 1], state["u"]
    assert abs(v_end) <= 16 * EPS * (abs(u_end) + k * w) * h
    assert abs(p[-1] / h - (u_end - k * q_end)) <= 16 * EPS * (abs(u_end) + k * w)
    # and the integral action drove it to the reference: at rest the error contracts by
    # (1 - κ) per step (3000 steps on the wall: 1e-67); the roundoff it keeps is about
    # ε (|u| + k w) / κ
    assert abs(p[-1] / h - lam_ref) <= 16 * EPS * (abs(u_end) + k * w) / kappa
    assert u_end == pytest.approx(lam_ref + k * q_end, rel=16 * EPS / kappa)
    assert abs(q_end - w) <= h * max(abs(traj.x[:, 1]))


# -- the model's force_jacobian ----------------------------------------------------------------
def test_two_link_arm_force_jacobian_matches_central_differences(rng) -> None:
    arm = LagrangianSystem.two_link_arm()
    for _ in range(5):
        q, v = rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2)
        Jq, Jv, analytic = arm.force_jacobians(0.3, q, v)
        arm_fd = LagrangianSystem(arm.mass, force=arm.force, gap=arm.gap,
                                  jacobian=arm.jacobian, names=arm.names)
        Fq, Fv, fd = arm_fd.force_jacobians(0.3, q, v)
        assert analytic and not fd
        # central differences: relative error FD_REL (plus the O(δ²) truncation, as small)
        # times the force's scale (≤ 100 here: gravity torques ~ 20, Coriolis ~ 10)
        assert np.max(np.abs(Jq - Fq)) <= 100 * 10 * FD_REL
        assert np.max(np.abs(Jv - Fv)) <= 100 * 10 * FD_REL


def test_arm_runs_implicit_and_explicit_alike_at_small_h() -> None:
    # both schemes are consistent: at h = 1e-4 over a flight (no contact yet), first order
    # at worst: they agree to a few h (the arm's velocities and accelerations are O(10))
    arm = LagrangianSystem.two_link_arm()
    x0 = [0.8, -1.2, 0.0, 0.0]
    a = simulate(arm, x0, (0.0, 0.2), method="moreau_jean", h=1e-4)
    b = simulate(arm, x0, (0.0, 0.2), method="moreau_jean", h=1e-4, forces="explicit")
    assert a.stats["forces"] == "implicit" and b.stats["forces"] == "explicit"
    assert not a.events_of("impact")
    assert np.max(np.abs(a.x - b.x)) <= 10 * 1e-4 * 10


# -- errors --------------------------------------------------------------------------------
def test_force_jacobian_is_checked_at_construction() -> None:
    with pytest.raises(ModelError, match=r"^force_jacobian: given without force"):
        LagrangianSystem(np.eye(1), force_jacobian=_scalar_jacobian(lambda t, q, v: 1.0),
                         **FAR)
    with pytest.raises(DimensionError, match=r"^force_jacobian: expected two \(1, 1\) arrays"):
        LagrangianSystem(np.eye(1), force=lambda t, q, v: -q,
                         force_jacobian=lambda t, q, v: (np.eye(2), np.eye(1)), **FAR)
    with pytest.raises(ModelError, match=r"^force_jacobian: expected a pair"):
        LagrangianSystem(np.eye(1), force=lambda t, q, v: -q,
                         force_jacobian=lambda t, q, v: np.eye(1), **FAR)
    with pytest.warns(NscontrolWarning, match=r"^force_jacobian: its dforce/dq disagrees"):
        LagrangianSystem(np.eye(1), force=lambda t, q, v: -q,
                         force_jacobian=_scalar_jacobian(lambda t, q, v: 1.0), **FAR)


def _switching(after):
    """A force ``-q`` whose jacobian (or value) turns bad for ``t > 0.5``."""
    return lambda t, q, v: (np.array([[-1.0]]), np.zeros((1, 1))) if t <= 0.5 else after


@pytest.mark.parametrize("bad, match", [
    ((np.eye(2), np.eye(1)), r"^force_jacobian: expected two \(1, 1\) arrays .*at t = 0\.50"),
    ((np.array([[np.nan]]), np.zeros((1, 1))), r"^force_jacobian: returned non-finite "
                                                 r"entries at t = 0\.50"),
])
def test_bad_force_jacobian_mid_run_is_a_model_error_with_the_run(bad, match) -> None:
    system = LagrangianSystem(np.eye(1), force=lambda t, q, v: -q,
                              force_jacobian=_switching(bad), **FAR)
    with pytest.raises(ModelError, match=match) as err:
        simulate(system, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-2)
    assert err.value.trajectory.t[-1] == pytest.approx(0.5, abs=1e-2)


def test_non_finite_force_mid_run_is_a_model_error_with_the_run() -> None:
    system = LagrangianSystem(np.eye(1), force=lambda t, q, v: -q if t < 0.5 else q * np.inf,
                              force_jacobian=_scalar_jacobian(lambda t, q, v: -1.0), **FAR)
    for forces in ("implicit", "explicit"):
        with pytest.raises(ModelError, match=r"^force: expected a finite vector .* at t = 0.5"
                           ) as err:
            simulate(system, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=1e-2,
                     forces=forces)
        assert err.value.trajectory.t[-1] == pytest.approx(0.5, abs=1e-2)


def test_singular_iteration_matrix_is_a_solver_error_with_the_run() -> None:
    # a negative stiffness M/(hθ)² from t = 0.5 on: M̂ = M - h²θ² J_q = 0
    h = 0.1
    stiff = lambda t: 0.0 if t < 0.5 else 1.0 / h**2  # noqa: E731
    system = LagrangianSystem(np.eye(1), force=lambda t, q, v: stiff(t) * q,
                              force_jacobian=_scalar_jacobian(lambda t, q, v: stiff(t)),
                              **FAR)
    with pytest.raises(SolverError, match=r"^moreau_jean: the iteration matrix .* singular "
                                          r"at t = 0\.4") as err:
        simulate(system, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=h, theta=1.0)
    assert err.value.trajectory.t[-1] == pytest.approx(0.4)
    traj = simulate(system, [1.0, 0.0], (0.0, 1.0), method="moreau_jean", h=h, theta=1.0,
                    on_failure="return")
    assert traj.status == -1 and "singular" in traj.message


def test_forces_and_mass_at_options_are_validated() -> None:
    ball = LagrangianSystem.bouncing_ball()
    with pytest.raises(ModelError, match=r"^forces: expected 'implicit' or 'explicit'"):
        simulate(ball, [1.0, 0.0], (0.0, 0.1), method="moreau_jean", h=1e-3, forces="semi")
    with pytest.raises(ModelError, match=r"^mass_at: expected 'start' or 'predicted'"):
        simulate(ball, [1.0, 0.0], (0.0, 0.1), method="moreau_jean", h=1e-3, mass_at="end")


def test_linearised_kernel_inverts_and_measures_like_numpy(rng) -> None:
    from nscontrol.simulate.moreau_jean._linearised_kernels import mj_linearised_kernel

    for n in (1, 2, 6):
        A = rng.standard_normal((n, n))
        M = A @ A.T + n * np.eye(n)
        Jq, Jv = rng.standard_normal((n, n)) * 50, rng.standard_normal((n, n))
        f, fext, v = rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n)
        h, th = 0.05, 0.5
        minv, dv = np.empty((n, n)), np.empty(n)
        rcond = mj_linearised_kernel(M, Jq, Jv, f, fext, v, h, th, minv, dv)
        Mhat = M - h * th * Jv - (h * th) ** 2 * Jq  # not symmetric: pivoting is exercised
        ref = np.linalg.inv(Mhat)
        kappa = np.linalg.cond(Mhat, 1)
        # two inversions of the same matrix: each within κ n ε of the exact inverse
        assert np.max(np.abs(minv - ref)) <= 2 * kappa * n * EPS * np.max(np.abs(ref))
        hf = h * (f + fext + h * th * Jq @ v)
        assert np.allclose(dv, ref @ hf, rtol=0, atol=2 * kappa * n * EPS * np.max(
            np.abs(ref)) * np.max(np.abs(hf)) * n)
        scale = sum(c * np.linalg.norm(X, 1) for c, X in ((1, M), (h * th, Jv),
                                                            ((h * th) ** 2, Jq)))
        assert rcond == pytest.approx(1 / (scale * np.linalg.norm(ref, 1)),
                                      rel=2 * kappa * n * EPS)
    # exactly singular: 0
    minv, dv = np.empty((2, 2)), np.empty(2)
    assert mj_linearised_kernel(np.eye(2), np.zeros((2, 2)), np.eye(2), np.zeros(2),
                                np.zeros(2), np.zeros(2), 1.0, 1.0, minv, dv) == 0.0
