"""Chapter 8 cross-check: plant + Lur'e observer of spec §5.1 (Siconos ObserverLCS), ours vs
Siconos, in the same run.

Ours integrates the design's closed loop ``[x; xhat]`` (one stacked Lur'e system). The
Siconos script receives only the plant matrices and the gains ``L = [1, 1]ᵀ``, ``K = 0`` and
builds the observer itself (``A - L C``, relation ``H - K C``) as a second dynamical system
fed by the plant's output, so an error in our closed-loop construction would show up as a
difference. Both use the θ-method with the same input sampling (``D = 1``,
``u(t) = 30 sin(50 t)``, ``g = u``). Scenarios: θ = 1 (backward Euler, the scheme whose discrete
Lyapunov guarantee ch08 §3.2 proves) and θ = 1/2 (the Siconos example's choice), h = 1e-3 and
1e-4, T = 2. ``accuracy`` holds ``max |e_ours - e_siconos|`` over the run (estimation errors
``e = x - xhat``), the same for the full state relative to its size, ``|e(2)|`` on both sides,
the guaranteed bound ``10 exp(-2)`` and Siconos' largest complementarity residual.

Run: ``nscontrol bench ch08 --json`` (``--quick``: h = 1e-3 only).
"""

# No `from __future__ import annotations`: the CLI loads this file without registering it.
import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from harness import run_siconos, siconos_available, siconos_version, time_per_call

from nscontrol import simulate
from nscontrol.design.lure_observer import observer_from_gains
from nscontrol.examples import ch08_lure_observer as ex

T_END = 2.0


def _loop() -> tuple[Any, Any, Any, np.ndarray]:
    s = ex.siconos_observer_lcs()
    design = observer_from_gains(**s.matrices, L=ex.SICONOS_L, P=np.eye(2), alpha=1.0)
    return s, design, design.closed_loop(s.plant()), np.r_[s.x0, s.xhat0]


def _payload(s: Any, design: Any, h: float, theta: float) -> dict[str, Any]:
    """Plant matrices and gains only: the Siconos side builds the observer itself."""
    return {"A": s.A.tolist(), "G": s.G.tolist(), "H": s.H.tolist(), "C": s.C.tolist(),
            "B": s.B.tolist(), "D": s.D.tolist(), "E": [[1.0]],  # g(t) = u(t) (spec 5.1)
            "L": design.L.tolist(), "K": design.K.tolist(), "x0": s.x0.tolist(),
            "xhat0": s.xhat0.tolist(), "h": h, "T": T_END, "theta": theta,
            "amplitude": 30.0, "omega": 50.0}


def run(quick: bool = False) -> Iterator[dict[str, Any]]:
    s, design, loop, x0 = _loop()
    have_siconos, why = siconos_available()
    for h in (1e-3,) if quick else (1e-3, 1e-4):
        for theta in (1.0, 0.5):
            def ours(h: float = h, theta: float = theta) -> Any:
                return simulate(loop, x0, (0.0, T_END), h=h, theta=theta, progress=False)

            traj = ours()
            steps = traj.stats["steps"]
            seconds = time_per_call(ours, budget=1.0 if quick else 2.0)
            e_ours = traj.signal("e")
            record: dict[str, Any] = {
                "scenario": f"ch08 ObserverLCS plant + observer, theta = {theta:g}, h = {h:g}",
                "size": steps, "ours_steps_per_s": steps / seconds, "reference": None,
                "reference_steps_per_s": None, "ratio": None,
                "accuracy": {"error_norm_at_T_ours": float(np.linalg.norm(e_ours[-1])),
                             "guaranteed_bound_at_T": 10 * math.exp(-T_END)}}
            if not have_siconos:
                record["note"] = why
                yield record
                continue
            sic = run_siconos("ch08_observer_lcs.py", _payload(s, design, h, theta))[-1]
            xs = np.hstack([np.array(sic["x"]), np.array(sic["xhat"])])
            e_sic = xs[:, :2] - xs[:, 2:]
            scale = float(np.max(np.abs(traj.x)))
            record.update(
                reference=siconos_version() + " EulerMoreauOSI + LCP",
                reference_steps_per_s=sic["steps_per_s"],
                ratio=(steps / seconds) / sic["steps_per_s"])
            record["accuracy"].update(
                max_error_difference=float(np.max(np.abs(e_ours - e_sic))),
                max_state_difference_relative=float(np.max(np.abs(traj.x - xs))) / scale,
                error_norm_at_T_siconos=float(np.linalg.norm(e_sic[-1])),
                siconos_max_complementarity_residual=sic["max_complementarity_residual"])
            yield record


if __name__ == "__main__":
    import json

    for rec in run(quick=False):
        print(json.dumps(rec))
