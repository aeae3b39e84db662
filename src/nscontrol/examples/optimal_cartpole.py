"""A cart-pole balanced between two walls by contact-implicit MPC, where a linear MPC that
ignores the walls lets the pole fall.

The plant is :class:`~nscontrol.optimal.cartpole.CartPole` (linearised about the upright
pole, rigid walls at the tip's height, restitution 0.5), integrated by the library's
Moreau–Jean step at the controllers' step. Both controllers are
:class:`~nscontrol.optimal.ContactMPC` blocks in ``closed_loop`` with the same horizon,
weights, input bound and terminal cost (the LQR value of the wall-free model): the
contact-implicit one plans with the walls (impacts and restitution as complementarity
constraints), the linear one with the wall-free model (a QP with input bounds). From a pole
kicked towards a wall faster than the bounded force can catch, the first plans the bounce and
brings the pole upright; the second saturates, the pole hits the wall unplanned and the state
diverges. The same holds on the cart-pole without the small-angle approximation
(:meth:`~nscontrol.optimal.cartpole.CartPole.nonlinear_system`) as the plant, both
controllers still planning on the linear models. The scenario and its numbers are ours.

Needs the ``optimal`` extra (CasADi).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import Example, ExampleResult, check, verdict_from
from ._figures import new_figure, save_figure

__all__ = ["PARAMETERS", "EXAMPLES", "run_controllers"]

#: The MPC's step and horizon, input bound, weights, the run's length and start, and the
#: claim's settling time and bound.
PARAMETERS: dict[str, Any] = {
    "h": 0.01, "steps": 25, "u_max": 5.0, "state_weight": (10.0, 10.0, 1.0, 1.0),
    "effort": 1e-2, "T": 3.0, "x0": (0.0, 0.0, 0.0, 3.0),
    "settle_time": 2.5, "settle_bound": 1e-2, "fallen_angle": float(np.pi / 2),
}


def controllers(cart: Any = None, *, steps: int | None = None,
                **options: Any) -> dict[str, Any]:
    """The contact-implicit and the linear MPC of the example (fresh blocks).

    Parameters
    ----------
    cart : CartPole, optional
        Default ``CartPole()``.
    steps : int, optional
        The horizon (default ``PARAMETERS["steps"]``).
    **options
        Further keywords of :class:`~nscontrol.optimal.ContactMPC` for both blocks
        (``solver=``, ``max_mode_iterations=``, ...).

    Returns
    -------
    dict
        ``"contact"`` and ``"linear"``: the two :class:`~nscontrol.optimal.ContactMPC`.
    """
    from ..optimal import ContactMPC
    from ..optimal.cartpole import CartPole

    p = PARAMETERS
    cart = CartPole() if cart is None else cart
    W = np.array(p["state_weight"])
    _, P = cart.lqr(p["h"], W, p["effort"])
    kw = {"state_weight": W, "effort": p["effort"], "u_min": -p["u_max"],
          "u_max": p["u_max"], "terminal": False, "terminal_weight": P, **options}
    n = p["steps"] if steps is None else steps
    return {"contact": ContactMPC(cart.system(), np.zeros(4), n, p["h"], **kw),
            "linear": ContactMPC(cart.free_system(), np.zeros(4), n, p["h"], **kw)}


def run_controllers(x0: Any = None, T: float | None = None, plant: str = "linear"
                    ) -> dict[str, Any]:
    """Both closed loops through ``simulate`` (Moreau–Jean at the MPC's step).

    Parameters
    ----------
    x0 : array_like (4,), optional
        Initial state (default ``PARAMETERS["x0"]``).
    T : float, optional
        Length of the runs (default ``PARAMETERS["T"]``).
    plant : {"linear", "nonlinear"}
        The plant: the model the contact-implicit MPC plans with, or the cart-pole without
        the small-angle approximation.

    Returns
    -------
    dict
        Per controller name: ``(mpc, trajectory)``; a run the plant ends early (a failed
        solve) keeps the samples recorded until then.
    """
    from ..optimal.cartpole import CartPole
    from ..simulate import simulate
    from ..systems.closed_loop import closed_loop

    p = PARAMETERS
    cart = CartPole()
    x0 = np.array(p["x0"] if x0 is None else x0, float)
    T = p["T"] if T is None else T
    if plant not in ("linear", "nonlinear"):
        raise ValueError(f"plant: expected 'linear' or 'nonlinear', got {plant!r}")
    out = {}
    for name, mpc in controllers(cart).items():
        model = cart.system() if plant == "linear" else cart.nonlinear_system()
        traj = simulate(closed_loop(model, mpc), x0, (0.0, T), method="moreau_jean",
                        h=p["h"], progress=False)
        out[name] = (mpc, traj)
    return out


def _settled(traj: Any) -> float:
    late = traj.t >= PARAMETERS["settle_time"] - 1e-9
    return float(np.abs(traj.x[late]).max())


def _checks(runs: dict[str, Any], nonlinear: dict[str, Any]
            ) -> tuple[list[Any], dict[str, Any]]:
    p = PARAMETERS
    mpc, traj = runs["contact"]
    _, lin = runs["linear"]
    sig = mpc.signals(traj)
    settled = _settled(traj)
    impulses = np.abs(traj.signals["impulse"]).sum(axis=1)
    fell = float(np.abs(lin.x[:, 1]).max())
    settled_nl = _settled(nonlinear["contact"][1])
    fell_nl = float(np.abs(nonlinear["linear"][1].x[:, 1]).max())
    cpu = sig["cpu_time"][1:]
    metrics = {
        "contact_max_state_after_settle": settled,
        "contact_max_angle_rad": float(np.abs(traj.x[:, 1]).max()),
        "contact_impacts": int(np.count_nonzero(impulses)),
        "contact_residual_max": float(sig["residual"].max()),
        "contact_cpu_per_sample_median_s": float(np.median(cpu)),
        "contact_cpu_per_sample_p90_s": float(np.percentile(cpu, 90)),
        "contact_cpu_per_sample_p99_s": float(np.percentile(cpu, 99)),
        "contact_cpu_per_sample_max_s": float(cpu.max()),
        "contact_wall_per_sample_median_s": float(np.median(sig["solve_time"][1:])),
        "contact_iterations_median": float(np.median(sig["iterations"][1:])),
        "contact_mode_iterations_max": float(sig["mode_iterations"][1:].max()),
        "contact_ipopt_fallbacks": int(sig["ipopt"][1:].sum()),
        "contact_residual_max_warm": float(sig["residual"][1:].max()),
        "linear_max_angle_rad": fell,
        "linear_final_state_norm": float(np.abs(lin.x[-1]).max()),
        "nonlinear_plant_contact_max_state_after_settle": settled_nl,
        "nonlinear_plant_linear_max_angle_rad": fell_nl,
    }
    after = f"after {p['settle_time']} s"
    checks = [
        check(f"contact-implicit MPC: largest |state| {after}", settled, p["settle_bound"],
              key="contact_settles", note="every component of (x, theta, x', theta') in SI "
                                          "units"),
        check("contact-implicit MPC: impacts of the tip on a wall", metrics["contact_impacts"],
              1, ">=", key="contact_uses_walls"),
        check("contact-implicit MPC: largest complementarity residual of a sample's plan",
              metrics["contact_residual_max"], 1e-3, key="contact_residual",
              note="IPOPT's samples relaxed at sigma = 1e-6: at most sqrt(sigma) = 1e-3; the "
                   "mode iteration's exact to roundoff"),
        check("linear MPC ignoring the walls: largest pole angle [rad]", fell,
              p["fallen_angle"], ">=", key="linear_falls",
              note="past the horizontal: the pole has fallen"),
        check(f"nonlinear plant, contact-implicit MPC: largest |state| {after}", settled_nl,
              p["settle_bound"], key="nonlinear_contact_settles",
              note="the plant without the small-angle approximation; the MPC plans on the "
                   "linear model"),
        check("nonlinear plant, linear MPC: largest pole angle [rad]", fell_nl,
              p["fallen_angle"], ">=", key="nonlinear_linear_falls"),
    ]
    return checks, metrics


def _figures(runs: dict[str, Any], nonlinear: dict[str, Any], out_dir: Path | None,
             figures: list[Path]) -> None:
    from ..optimal.cartpole import CartPole

    cart, p = CartPole(), PARAMETERS
    fig, (ax1, ax2) = new_figure(2, 1, figsize=(7.0, 6.0), sharex=True)
    for name, style, style_nl in (("contact", "C0-", "C2:"), ("linear", "C3--", "C1:")):
        label = "contact-implicit MPC" if name == "contact" else "linear MPC (no walls)"
        _, traj = runs[name]
        ax1.plot(traj.t, traj.x[:, 1], style, label=label)
        ax2.plot(traj.t, cart.tip(traj.x), style, label=label)
        _, traj = nonlinear[name]
        ax1.plot(traj.t, traj.x[:, 1], style_nl, lw=2.0, label=f"{label}, nonlinear plant")
    ax1.set_ylim(-0.6, 0.6)
    ax1.set_ylabel("pole angle theta [rad]")
    ax1.set_title("Cart-pole between walls, pole kicked at 3 rad/s, |u| <= 5 N")
    ax1.legend(fontsize=8)
    for side in (-1, 1):
        ax2.axhline(side * cart.wall, color="k", lw=1.5)
    ax2.set_ylabel("tip position x + l theta [m]")
    ax2.set_xlabel("time [s]")
    ax2.legend(fontsize=8, title="walls: black lines", title_fontsize=8)
    save_figure(fig, out_dir, "cartpole_walls", figures)

    mpc, traj = runs["contact"]
    sig = mpc.signals(traj)
    fig, ax = new_figure(figsize=(6.5, 4.0))
    ax.hist(1e3 * sig["cpu_time"][1:], bins=30, color="C0", alpha=0.7, label="CPU time")
    ax.hist(1e3 * sig["solve_time"][1:], bins=30, color="C1", alpha=0.5, label="wall time")
    ax.axvline(1e3 * p["h"], color="k", ls=":", label="sampling period (100 Hz)")
    ax.set_xlabel("solve time per sample [ms]")
    ax.set_ylabel("samples")
    ax.set_title("Contact-implicit MPC: time of each sample's solve")
    ax.legend(fontsize=8)
    save_figure(fig, out_dir, "cartpole_solve_times", figures)


def run(out_dir: Path | None = None) -> ExampleResult:
    """Both closed loops, the checks and the figures."""
    runs = run_controllers()
    nonlinear = run_controllers(plant="nonlinear")
    checks, metrics = _checks(runs, nonlinear)
    figures: list[Path] = []
    _figures(runs, nonlinear, out_dir, figures)
    return ExampleResult(
        "optimal-cartpole", metrics=metrics, checks=checks, figures=figures,
        summary="Contact-implicit MPC (ContactMPC with the walls in its model) against a "
                "linear MPC with the same horizon, weights, bound and LQR terminal cost but "
                "no walls, both as blocks in closed_loop, the plant integrated by Moreau-Jean: "
                "the linear model, then the cart-pole without the small-angle approximation. "
                "The scenario and its numbers are ours.")


EXAMPLES = [Example(
    name="optimal-cartpole", chapter="optimal",
    title="Cart-pole between two walls: contact-implicit MPC against linear MPC", run=run,
    claim="A pole kicked towards a wall faster than a 5 N cart force can catch falls under a "
          "linear MPC that ignores the walls, although the walls are there: it plans as if "
          "the pole fell through them. An MPC that plans the impacts with the walls "
          "(restitution included) uses the bounce and brings the pole upright, on the "
          "linear model it plans with and on the nonlinear cart-pole.",
    verdict=verdict_from(
        ("contact_settles", "contact-implicit MPC: |state| <= {value} after 2.5 s"),
        ("linear_falls", "linear MPC: the pole reaches {value} rad"),
        ("nonlinear_contact_settles", "on the nonlinear cart-pole: |state| <= {value}")),
    key_figure="cartpole_walls",
    captions={
        "cartpole_walls": "Pole angle (top; dotted: the nonlinear plant) and tip position "
        "between the walls (bottom, linear plant): the contact-implicit MPC lets the tip "
        "bounce once off the right wall and settles upright; the linear MPC, planning "
        "without walls, loses the pole.",
        "cartpole_solve_times": "Distribution of the contact-implicit MPC's solve time per "
        "sample (CPU and wall), against the 10 ms sampling period."})]
