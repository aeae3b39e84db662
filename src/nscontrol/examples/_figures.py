"""Shared figure handling for examples: a non-interactive backend and one save routine."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

#: Called as ``hook(name, fig)`` with every figure an example finishes, before it is saved
#: and closed, whether or not it is written: tests inspect the matplotlib objects here.
FIGURE_HOOKS: list[Callable[[str, Any], None]] = []


def new_figure(*args: Any, **kwargs: Any) -> Any:
    """``plt.subplots`` on the Agg backend (examples never open windows)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kwargs)


def save_figure(fig: Any, out_dir: Path | None, name: str, figures: list[Path]) -> None:
    """Save ``fig`` as ``out_dir/name.png`` (when ``out_dir`` is given), then close it."""
    import matplotlib.pyplot as plt

    for hook in FIGURE_HOOKS:
        hook(name, fig)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{name}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        figures.append(path)
    plt.close(fig)


def unlabelled_axes(fig: Any) -> list[str]:
    """The panels of ``fig`` that draw data without an x or a y label (``[]`` when all are
    labelled); a panel sharing its x axis with a labelled one below it needs no x label."""
    missing = []
    for k, ax in enumerate(fig.axes):
        if not (ax.lines or ax.collections or ax.patches or ax.images):
            continue
        shared = [o for o in ax.get_shared_x_axes().get_siblings(ax) if o is not ax]
        has_x = bool(ax.get_xlabel()) or any(o.get_xlabel() for o in shared)
        if not has_x:
            missing.append(f"panel {k} ({ax.get_title() or 'untitled'}): no x label")
        if not ax.get_ylabel():
            missing.append(f"panel {k} ({ax.get_title() or 'untitled'}): no y label")
    return missing
