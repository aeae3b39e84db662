"""Chapter 3: tracking control of complementarity Lagrangian systems (two-link arm, 1-DOF twin).

The end effector of a planar two-link arm tracks a circle cut by the ground: free motion on
the upper half, a transition phase with impacts, sliding on the ground, take-off; three or
more cycles. The switching passivity-based controller is
:class:`~nscontrol.design.complementarity_tracking.SwitchingTrackingController`, the plant is
integrated by Moreau–Jean, the cycles are analysed by :mod:`nscontrol.analysis.tracking_cycles`.
Two configurations of the arm are selectable by name (``"siconos-current"``,
``"siconos-2007"``); ``one_dof_tracking`` runs the same controller on a mass above the ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelError
from . import Check, Example, ExampleResult, check, verdict_from

__all__ = ["TrackingConfig", "TrackingRun", "CONFIGS", "two_link_tracking",
           "one_dof_tracking", "EXAMPLES"]


@dataclass(frozen=True)
class TrackingConfig:
    """One configuration of the two-link tracking task.

    Attributes
    ----------
    name
        ``"siconos-current"`` or ``"siconos-2007"``.
    period
        Period of the circle (s).
    gains
        ``(γ1, γ2, K_f)``.
    h, theta
        Moreau–Jean step and θ.
    restitution
        Newton coefficient of the ground.
    theta0
        Initial joint angles (rad), at rest.
    switching
        ``"designed"`` (virtual dive, force ramp, lift-off) or ``"impact-triggered"``.
    """

    name: str
    period: float
    gains: tuple[float, float, float]
    h: float
    theta: float
    restitution: float
    theta0: tuple[float, float]
    switching: str


#: The two Siconos configurations of the task (current example; the 2007 one with figures).
CONFIGS: dict[str, TrackingConfig] = {
    "siconos-current": TrackingConfig("siconos-current", 10.0, (8.0, 7.0, 0.5), 1e-4, 0.5,
                                      0.7, (0.9, -1.6), "designed"),
    "siconos-2007": TrackingConfig("siconos-2007", 3.0, (25.0, 30.0, 3.0), 5e-3, 0.500001,
                                   0.7, (1.0, -1.5), "impact-triggered"),
}


@dataclass
class TrackingRun:
    """A closed-loop run: the trajectory (controller log merged as signals) and the
    controller (its per-cycle instants in ``controller.cycles``).

    Attributes
    ----------
    traj
        Moreau–Jean trajectory with signals ``impulse``, ``gap`` and the controller's log
        (``V``, ``V1``, ``phase``, ``cycle``, ``lam_d``, ``lam_hat``, ``depth``, ``q_task``,
        ``dq_task``, ``qd``), one row per sample.
    controller
        The controller after the run.
    restitution
        The plant's coefficient.
    h
        The step.
    model
        The plant model (task map).
    """

    traj: Any
    controller: Any
    restitution: float
    h: float
    model: Any = None
    extras: dict[str, Any] = field(default_factory=dict)


def _run_loop(model: Any, controller: Any, x0: np.ndarray, T: float, h: float,
              theta: float, restitution: float) -> TrackingRun:
    """Simulate plant + controller with Moreau–Jean and merge the controller's log."""
    import nscontrol as nsc

    controller.reset_run()
    loop = nsc.closed_loop(model.system(restitution), controller)
    traj = nsc.simulate(loop, x0, (0.0, T), method="moreau_jean", h=h, theta=theta,
                        progress=False)
    log = controller.signals()
    # the log holds one row per step start; the final sample gets its own evaluation
    n = model.n_dof
    xf = traj.x[-1]
    V, V1 = controller.lyapunov(float(traj.t[-1]), xf)
    q, dq = model.task_state(xf[:n], xf[n:])
    last = {"t": traj.t[-1], "phase": log["phase"][-1], "cycle": log["cycle"][-1], "V": V,
            "V1": V1, "lam_d": log["lam_d"][-1], "lam_hat": log["lam_hat"][-1],
            "depth": log["depth"][-1], "q_task": q, "dq_task": dq, "qd": log["qd"][-1]}
    if log["t"].shape[0] + 1 != traj.t.shape[0]:
        raise ModelError(f"record: expected one controller row per step "
                         f"({traj.t.shape[0] - 1}), got {log['t'].shape[0]}")
    signals = dict(traj.signals)
    for key, rows in log.items():
        if key != "t":
            signals[key] = np.concatenate([rows, np.atleast_1d(last[key])[None] if
                                           np.ndim(rows) > 1 else [last[key]]])
    return TrackingRun(replace(traj, signals=signals), controller, restitution, h, model)


def two_link_tracking(config: str = "siconos-current", cycles: int = 3, h: float | None = None,
                      restitution: float | None = None, model_scale: float = 1.0,
                      depth_law: str = "sqrt", depth_min: float = 0.005,
                      phi: float = 1e5) -> TrackingRun:
    """The two-link arm tracking the circle cut by the ground.

    Parameters
    ----------
    config : {"siconos-current", "siconos-2007"}
        Configuration (:data:`CONFIGS`).
    cycles : int
        Number of periods simulated.
    h : float, optional
        Step (default: the configuration's).
    restitution : float, optional
        Newton coefficient (default: the configuration's, 0.7).
    model_scale : float
        Controller's ``M, C, g`` over the plant's.
    depth_law, depth_min, phi : str, float, float
        Depth law of the virtual dive (designed switching only).
    """
    from ..design.complementarity_tracking import (
        CircleTask,
        ContactPhaseDesign,
        PBCGains,
        SwitchingTrackingController,
        TransitionDesign,
    )
    from ..systems.two_link import TwoLinkArm

    if config not in CONFIGS:
        raise ModelError(f"config: expected one of {sorted(CONFIGS)}, got {config!r}")
    cfg = CONFIGS[config]
    arm = TwoLinkArm()
    g1, g2, kf = cfg.gains
    gains = PBCGains(g1, g2, kf)
    ctrl = SwitchingTrackingController(
        arm, CircleTask(period=cfg.period), gains,
        TransitionDesign(depth_law=depth_law, depth_min=depth_min, phi=phi),
        ContactPhaseDesign(lam_rate=1.0 + kf), model_scale=model_scale,
        switching=cfg.switching)
    x0 = np.array([*cfg.theta0, 0.0, 0.0])
    e = cfg.restitution if restitution is None else restitution
    step = cfg.h if h is None else h
    return _run_loop(arm, ctrl, x0, cycles * cfg.period, step, cfg.theta, e)


def one_dof_tracking(cycles: int = 3, h: float = 1e-4, restitution: float = 0.7,
                     omega: float = 2 * math.pi / 8, q0: float = 0.05,
                     model_scale: float = 1.0) -> TrackingRun:
    """The mass above the ground under the same controller (``γ1 = γ2 = 5``).

    Parameters
    ----------
    cycles : int
        Number of periods.
    h : float
        Step.
    restitution : float
        Newton coefficient.
    omega : float
        Angular frequency of the half-sine task.
    q0 : float
        Initial height (at rest).
    model_scale : float
        Controller's model over the plant's.
    """
    from ..design.complementarity_tracking import (
        ContactPhaseDesign,
        HalfSineTask,
        PBCGains,
        SwitchingTrackingController,
        TransitionDesign,
    )
    from ..systems.two_link import OneDofMass

    plant = OneDofMass()
    gains = PBCGains(5.0, 5.0, 0.5)
    task = HalfSineTask(omega=omega)
    ctrl = SwitchingTrackingController(plant, task, gains, TransitionDesign(),
                                       ContactPhaseDesign(lam_rate=1.5),
                                       model_scale=model_scale)
    return _run_loop(plant, ctrl, np.array([q0, 0.0]), cycles * task.period, h, 0.5,
                     restitution)


def run(out_dir: Path | None) -> ExampleResult:
    """Placeholder replaced below."""
    return ExampleResult("ch03-two-link-tracking")


EXAMPLES: list[Example] = []
_ = (Check, check, verdict_from)
