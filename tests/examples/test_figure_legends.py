"""``small_legends``: legend text measured at the size the report shows the saved image."""

from nscontrol.examples._figures import REPORT_COLUMN_PX, SAVE_DPI, new_figure, small_legends


def _figure(width_in, fontsize):
    fig, ax = new_figure(figsize=(width_in, 4))
    ax.plot([0, 1], [0, 1], label="a curve")
    ax.legend(fontsize=fontsize)
    return fig


def test_a_wide_figure_with_x_small_legend_is_flagged():
    # 12 in at 110 dpi = 1320 px, shown at 1068 px: x-small (6.9 pt) -> 8.6 px
    assert small_legends(_figure(12, "x-small"))


def test_small_legend_in_a_figure_that_fits_the_column_is_readable():
    assert REPORT_COLUMN_PX >= 7.5 * SAVE_DPI          # 7.5 in is shown at its own size
    assert small_legends(_figure(7.5, "small")) == []  # 8.33 pt -> 12.7 px


def test_second_legend_added_as_artist_is_seen():
    fig, ax = new_figure(figsize=(7, 4))
    ax.plot([0, 1], [0, 1], label="a")
    first = ax.legend(fontsize=5)
    ax.legend(fontsize="medium")
    ax.add_artist(first)
    assert len(small_legends(fig)) == 1
