"""Siconos side of bench_ch08.py: plant + Lur'e observer of spec ch08 §5.1 (ObserverLCS).

Run by /usr/bin/python3 (Debian's python3-siconos, numpy 1.x). Reads JSON on stdin::

    {"A", "G", "H", "C", "B", "D", "E", "L", "K", "x0", "xhat0", "h", "T", "theta",
     "amplitude", "omega"}

the plant matrices (``x' = A x + G w + B u``, ``z = H x + D w + E u``, ``0 <= w ⟂ z >= 0``,
``y = C x``) and the observer gains ``L``, ``K``. The observer is built here, independently of
nscontrol's closed loop: two first-order linear DS, each with its own complementarity
interaction and its own simulation (``FirstOrderLinearTIDS``, ``FirstOrderLinearTIR``,
``ComplementarityConditionNSL``, ``EulerMoreauOSI(theta)``, ``LCP``):

* the plant, ``b = B u``, relation ``(H, G)``, ``e = E u``;
* the observer, ``A - L C`` (formed here from ``A``, ``L``, ``C``), fed by the plant's output:
  ``b = B u + L y``, relation ``(H - K C, G)``, ``e = K y + E u``.

Each step the plant is advanced first; its new output ``y_{k+1} = C x_{k+1}`` then drives the
observer's step (the stepping order of nscontrol's closed loop, spec §3.1). The inputs are
set before every step with the θ-method's sampling: ``b = (1-θ) b(t_k) + θ b(t_{k+1})``,
``e = e(t_{k+1})``. Prints one JSON line: ``{"t", "x", "xhat", "steps", "steps_per_s",
"max_complementarity_residual"}``; the residual is ``max |min(w, z)|`` over both
interactions and all steps, recomputed from the states and multipliers Siconos returns.
"""

import json
import sys
import time

import numpy as np
import siconos.kernel as sk


def _system(x0, A, H, G, D, T, h, theta):
    """One DS with one complementarity interaction, in its own simulation."""
    ds = sk.FirstOrderLinearTIDS(np.array(x0, dtype=float), np.array(A, dtype=float))
    ds.setbPtr(np.zeros(len(x0)))
    rel = sk.FirstOrderLinearTIR(np.array(H, dtype=float).copy(),
                                 np.array(G, dtype=float).copy())  # copies: strides pitfall
    rel.setDPtr(np.array(D, dtype=float).copy())
    rel.setePtr(np.zeros(len(H)))
    inter = sk.Interaction(sk.ComplementarityConditionNSL(len(H)), rel)
    nsds = sk.NonSmoothDynamicalSystem(0.0, T)
    nsds.insertDynamicalSystem(ds)
    nsds.link(inter, ds)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, h), sk.EulerMoreauOSI(theta),
                          sk.LCP())
    return ds, rel, inter, sim


def main():
    p = json.load(sys.stdin)
    A, G, H, C = (np.array(p[k], dtype=float) for k in ("A", "G", "H", "C"))
    B, D, E = (np.array(p[k], dtype=float) for k in ("B", "D", "E"))
    L, K = np.array(p["L"], dtype=float), np.array(p["K"], dtype=float)
    h, T, theta = p["h"], p["T"], p["theta"]
    plant = _system(p["x0"], A, H, G, D, T, h, theta)
    observer = _system(p["xhat0"], A - L @ C, H - K @ C, G, D, T, h, theta)
    n_steps = int(round(T / h))

    def u(t):
        return np.array([p["amplitude"] * np.sin(p["omega"] * t)])

    def residual(ds, rel_H, inter, e):
        w = np.array(inter.lambda_(0)).copy()
        z = rel_H @ np.array(ds.x()) + D @ w + e
        return float(np.max(np.abs(np.minimum(w, z))))

    ts, xs, xhats = [0.0], [list(p["x0"])], [list(p["xhat0"])]
    worst = 0.0
    x_prev = np.array(p["x0"], dtype=float)
    start = time.perf_counter()
    for k in range(n_steps):
        t0, t1 = k * h, (k + 1) * h
        u0, u1 = u(t0), u(t1)
        ds, rel, inter, sim = plant
        ds.setbPtr(B @ ((1.0 - theta) * u0 + theta * u1))
        rel.setePtr(E @ u1)
        sim.computeOneStep()
        x_next = np.array(ds.x()).copy()
        worst = max(worst, residual(ds, H, inter, E @ u1))
        y0, y1 = C @ x_prev, C @ x_next
        ds_o, rel_o, inter_o, sim_o = observer
        ds_o.setbPtr(B @ ((1.0 - theta) * u0 + theta * u1)
                     + L @ ((1.0 - theta) * y0 + theta * y1))
        e_o = K @ y1 + E @ u1
        rel_o.setePtr(e_o)
        sim_o.computeOneStep()
        worst = max(worst, residual(ds_o, H - K @ C, inter_o, e_o))
        xs.append(x_next.tolist())
        xhats.append(np.array(ds_o.x()).copy().tolist())
        ts.append(t1)
        x_prev = x_next
        sim.nextStep()
        sim_o.nextStep()
    elapsed = time.perf_counter() - start
    print(json.dumps({"t": ts, "x": xs, "xhat": xhats, "steps": n_steps,
                      "steps_per_s": n_steps / elapsed,
                      "max_complementarity_residual": worst}), flush=True)


if __name__ == "__main__":
    main()
