"""Parameter sweeps of the examples (``nscontrol sweep``).

An example module offers sweeps by defining ``SWEEPS``, a dict from a parameter's name to a
:class:`SweepSpec`: a module-level (picklable) function of one value returning a few named
figures. :func:`run_sweep` maps it over a grid with :func:`nscontrol.sweep.run` — local
processes, or a Dask scheduler — and writes the result as JSON (values, figures and, per
failed point, its error: a failed point never loses the others) with one labelled figure.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelError

__all__ = ["SweepSpec", "example_sweeps", "run_sweep"]


@dataclass(frozen=True)
class SweepSpec:
    """A sweepable parameter of an example.

    Attributes
    ----------
    function : callable
        ``value -> tuple of floats`` (one per output), module-level so that it pickles.
    outputs : tuple of str
        The figures it returns, with units (``"final error [rad]"``).
    label : str
        The parameter in words, with its unit (the x axis of the figure).
    """

    function: Callable[[float], Sequence[float]]
    outputs: tuple[str, ...]
    label: str


def example_sweeps(example: Any) -> dict[str, SweepSpec]:
    """The ``SWEEPS`` of an example's module (``{}`` when it defines none).

    Parameters
    ----------
    example : Example
        An example of the registry.
    """
    return dict(getattr(sys.modules[example.run.__module__], "SWEEPS", {}))


def run_sweep(example: Any, parameter: str, values: Sequence[float], *,
              executor: Any = "auto", out: Path, progress: bool | None = True
              ) -> tuple[Path, Path, Any]:
    """Sweep ``parameter`` of ``example`` over ``values``; write JSON and a figure.

    Parameters
    ----------
    example : Example
        An example whose module defines ``SWEEPS``.
    parameter : str
        One of its sweepable parameters.
    values : sequence of float
        The grid.
    executor : str or Executor
        As in :func:`nscontrol.sweep.run` (``"auto"``, ``"serial"``, a scheduler address).
    out : Path
        Folder for ``sweep_<example>_<parameter>.json`` and ``.png``.
    progress : bool or None
        The sweep's progress bar.

    Returns
    -------
    (Path, Path, SweepResult)
        The JSON file, the figure and the sweep's result.

    Raises
    ------
    ModelError
        ``parameter`` not one the example offers (the message lists them).
    """
    from .. import sweep

    specs = example_sweeps(example)
    if parameter not in specs:
        offered = ", ".join(sorted(specs)) or "none"
        raise ModelError(f"param: {parameter!r} is no sweepable parameter of example "
                         f"{example.name!r} (it offers: {offered})")
    spec = specs[parameter]
    res = sweep.run(spec.function, [float(v) for v in values], executor=executor,
                    progress=progress, desc=f"sweep {example.name} {parameter}")
    out.mkdir(parents=True, exist_ok=True)
    stem = f"sweep_{example.name}_{parameter}"
    data = _table(spec, res)
    json_path = out / f"{stem}.json"
    _write_atomically(json_path, json.dumps({"example": example.name, "parameter": parameter,
                                             "label": spec.label, **data}, indent=1))
    png_path = out / f"{stem}.png"
    _figure(spec, data, png_path, f"{example.title}: sweep of {parameter}")
    return json_path, png_path, res


def _table(spec: SweepSpec, res: Any) -> dict[str, Any]:
    """Values, one column per output (``None`` where the point failed) and the errors."""
    columns: dict[str, list[float | None]] = {name: [] for name in spec.outputs}
    for value, error in zip(res.values, res.errors, strict=True):
        row = (None,) * len(spec.outputs) if error is not None else tuple(value)
        for name, v in zip(spec.outputs, row, strict=True):
            columns[name].append(None if v is None or not np.isfinite(v) else float(v))
    errors = [{"value": float(res.grid[i]), "error": f"{e.type}: {e.message}"}
              for i, e in enumerate(res.errors) if e is not None]
    return {"values": [float(v) for v in res.grid], "outputs": columns, "errors": errors}


def _figure(spec: SweepSpec, data: dict[str, Any], path: Path, title: str) -> None:
    from ._figures import new_figure

    names = list(spec.outputs)
    fig, axes = new_figure(len(names), 1, sharex=True, squeeze=False,
                           figsize=(7, 1.2 + 2.0 * len(names)))
    x = np.array(data["values"])
    failed = np.array([e["value"] for e in data["errors"]])
    for ax, name in zip(axes[:, 0], names, strict=True):
        y = np.array([np.nan if v is None else v for v in data["outputs"][name]])
        ax.plot(x, y, "o-", ms=3)
        for xf in failed:
            ax.axvline(xf, color="tab:red", lw=0.8, alpha=0.6)
        ax.set_ylabel(name)
    axes[-1, 0].set_xlabel(spec.label)
    axes[0, 0].set_title(title + (" (red lines: failed points)" if failed.size else ""),
                         fontsize=9)
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)


def _write_atomically(path: Path, text: str) -> None:
    # a failed write never destroys an earlier result
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
