"""Shared figure handling for examples: a non-interactive backend and one save routine."""

from __future__ import annotations

from pathlib import Path
from typing import Any


def new_figure(*args: Any, **kwargs: Any) -> Any:
    """``plt.subplots`` on the Agg backend (examples never open windows)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kwargs)


def save_figure(fig: Any, out_dir: Path | None, name: str, figures: list[Path]) -> None:
    """Save ``fig`` as ``out_dir/name.png`` (when ``out_dir`` is given), then close it."""
    import matplotlib.pyplot as plt

    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{name}.png"
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        figures.append(path)
    plt.close(fig)
