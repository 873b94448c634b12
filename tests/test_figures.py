"""How the figures are laid out and saved."""

import io

import matplotlib.pyplot as plt

from ptwin.reporting.figures import tight


def _figure():
    figure, ax = plt.subplots(figsize=(4, 3))
    ax.semilogy([1.0, 2.0, 3.0], [1e-16, 3e-16, 2e-15], "o-", label="K")
    ax.set_title("a title long enough to need the room")
    ax.legend()
    return figure


def _saved(figure) -> tuple[bytes, int]:
    """(the PNG, how many times savefig drew the figure)."""
    draws = []
    draw = figure.draw
    figure.draw = lambda renderer: draws.append(renderer) or draw(renderer)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=50)
    plt.close(figure)
    return buffer.getvalue(), len(draws)


def test_a_tight_figure_is_drawn_once_when_saved_and_looks_as_tight_layout_leaves_it():
    # tight_layout() leaves a placeholder layout engine, for which savefig first draws the figure without rendering:
    # 0.38 s of the demo's 6.15 s, for no change of a pixel.
    laid_out = _figure()
    laid_out.tight_layout()
    before, drawn_before = _saved(laid_out)
    once = _figure()
    tight(once)
    after, drawn_after = _saved(once)
    assert (drawn_before, drawn_after) == (2, 1)
    assert after == before


def test_log_axes_read_as_matplotlibs_own_in_unicode_and_label_minor_ticks_only_between_decades():
    # Matplotlib writes log-axis labels as mathtext, which a figure then parses; ours are the same labels in Unicode.
    # Minor ticks are labelled only where no decade is in view: beside one, their labels ran into one another.
    from ptwin.reporting.figures import _logarithmic

    def labels(low, high):
        figure, ax = plt.subplots(figsize=(4, 3))
        ax.plot([low, high], [1.0, 2.0], "o")
        _logarithmic(ax, "x")
        figure.canvas.draw()
        major = [label.get_text() for label in ax.get_xticklabels()]
        minor = [label.get_text() for label in ax.get_xticklabels(minor=True) if label.get_text()]
        plt.close(figure)
        return major, minor

    assert labels(1.2e-16, 3e-16) == (["10⁻¹⁶", "10⁻¹⁵"], ["2×10⁻¹⁶", "3×10⁻¹⁶", "4×10⁻¹⁶", "6×10⁻¹⁶"])
    assert labels(2.0, 80.0) == (["10⁰", "10¹", "10²"], [])
    assert labels(1e-3, 1e2) == (["10⁻⁴", "10⁻³", "10⁻²", "10⁻¹", "10⁰", "10¹", "10²", "10³"], [])


def test_a_speed_axis_is_ticked_and_labelled_at_the_speeds_measured():
    # Two decades of speeds had held a single decade label; a reader looks for the curves' own speeds.
    from ptwin.reporting.figures import _speed_axis

    figure, ax = plt.subplots(figsize=(4.5, 3))
    speeds = [0.5e-6 * 1e6, 2.0, 8.0, 40.0, 80.0, float("nan")]  # µm/s, as the figures compute them
    ax.plot(speeds, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], "o")
    _speed_axis(ax, speeds)
    figure.canvas.draw()
    labelled = [(tick, label.get_text()) for tick, label in zip(ax.get_xticks(), ax.get_xticklabels())]
    minor = [label.get_text() for label in ax.get_xticklabels(minor=True) if label.get_text()]
    plt.close(figure)
    assert labelled == [(0.5, "0.5"), (2.0, "2"), (8.0, "8"), (40.0, "40"), (80.0, "80")]
    assert minor == []
