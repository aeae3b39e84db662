"""Every figure an example draws is inspected before it is saved: labelled axes, legends
readable at the size the report shows them, a caption."""

import pytest

from nscontrol.examples import all_examples
from nscontrol.examples._figures import FIGURE_HOOKS, small_legends, unlabelled_axes


@pytest.fixture(autouse=True)
def figures_are_labelled_and_captioned():
    """Collects the figures the test's example finishes (through ``FIGURE_HOOKS``) and, after
    the test, refuses a panel without x or y label and a figure its example gives no caption."""
    seen: list[tuple[str, list[str]]] = []
    small: dict[str, list[str]] = {}

    def inspect(name, fig):
        seen.append((name, unlabelled_axes(fig)))
        if small_legends(fig):
            small[name] = small_legends(fig)

    FIGURE_HOOKS.append(inspect)
    yield seen
    FIGURE_HOOKS.remove(inspect)
    captioned = {stem for ex in all_examples() for stem in ex.captions}
    unlabelled = {name: missing for name, missing in seen if missing}
    assert not unlabelled, f"figures with unlabelled axes: {unlabelled}"
    assert not small, f"legends too small to read in the report: {small}"
    uncaptioned = sorted({name for name, _ in seen} - captioned)
    assert not uncaptioned, f"figures without a caption in their Example: {uncaptioned}"
