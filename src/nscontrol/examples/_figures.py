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
        fig.savefig(path, dpi=SAVE_DPI)
        figures.append(path)
    plt.close(fig)


def unlabelled_axes(fig: Any) -> list[str]:
    """The panels of ``fig`` that draw data without an x or a y label (``[]`` when all are
    labelled); a panel sharing its x axis with a labelled one below it needs no x label, and a
    colour bar needs only the label along its length."""
    missing = []
    for k, ax in enumerate(fig.axes):
        if not (ax.lines or ax.collections or ax.patches or ax.images):
            continue
        bar = getattr(ax, "_colorbar", None)   # set by Figure.colorbar on the bar's axes
        if bar is not None:
            label = ax.get_ylabel() if bar.orientation == "vertical" else ax.get_xlabel()
            if not label:
                missing.append(f"panel {k} (colour bar): no label")
            continue
        shared = [o for o in ax.get_shared_x_axes().get_siblings(ax) if o is not ax]
        has_x = bool(ax.get_xlabel()) or any(o.get_xlabel() for o in shared)
        if not has_x:
            missing.append(f"panel {k} ({ax.get_title() or 'untitled'}): no x label")
        if not ax.get_ylabel():
            missing.append(f"panel {k} ({ax.get_title() or 'untitled'}): no y label")
    return missing


#: Width of the report's figure column in CSS pixels (``report.py``: a 1100 px page less its
#: padding); a wider figure is scaled down to it.
REPORT_COLUMN_PX = 1068
#: Smallest legend text, in pixels at report size, that stays readable (11 px: the size of
#: the smallest captions browsers show by default is 10-12 px).
MIN_LEGEND_PX = 11.0
#: The resolution ``save_figure`` writes at.
SAVE_DPI = 110


def small_legends(fig: Any) -> list[str]:
    """The legends of ``fig`` whose text is smaller than :data:`MIN_LEGEND_PX` once the saved
    image is shown in the report (``[]`` when all are readable)."""
    width_px = fig.get_figwidth() * SAVE_DPI
    scale = min(1.0, REPORT_COLUMN_PX / width_px)
    found = []
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
    legends += [a for ax in fig.axes for a in ax.artists if type(a).__name__ == "Legend"]
    for k, legend in enumerate(leg for leg in legends if leg is not None):
        texts = legend.get_texts()
        if not texts:
            continue
        px = min(t.get_fontsize() for t in texts) * SAVE_DPI / 72.0 * scale
        if px < MIN_LEGEND_PX:
            found.append(f"legend {k} ('{texts[0].get_text()[:30]}'): {px:.1f} px at report "
                         f"size")
    return found
