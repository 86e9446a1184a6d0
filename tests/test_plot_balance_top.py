"""mocaplab.plot.balance_top: the support polygons and ZMP seen from above (lessons 08 and 09)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

from mocaplab import plot


class _Walk:
    """What balance_top reads from a mocaplab.physics.Balance: com, zmp, polygon(frame)."""

    def __init__(self, along: int, n: int = 60, length: float = 4.0) -> None:
        t = np.linspace(0.0, length, n)
        self.com = np.zeros((n, 3))
        self.com[:, along] = t
        self.com[:, 2 - along] = 0.03 * np.sin(6 * t)
        self.com[:, 1] = 0.9
        self.zmp = self.com * [1, 0, 1]
        self.zmp[n // 2] = np.nan  # a flight frame

    def polygon(self, frame: int) -> np.ndarray:
        c = self.zmp[frame] if np.all(np.isfinite(self.zmp[frame])) else self.com[frame] * [1, 0, 1]
        return c + np.array([[-0.1, 0, -0.05], [0.1, 0, -0.05], [0.1, 0, 0.05], [-0.1, 0, 0.05]])


@pytest.fixture(autouse=True)
def _close():
    yield
    plt.close("all")


def test_a_straight_walk_is_not_a_sliver_and_the_legend_is_off_the_data():
    fig, ax = plt.subplots(figsize=(10, 2.8), layout="constrained")
    out = plot.balance_top(_Walk(along=0), frames=range(0, 60, 6), ax=ax)
    assert out is ax
    assert ax.get_aspect() == 1.0
    lo, hi = sorted(ax.get_ylim())
    assert hi - lo >= 1.0 - 1e-9, f"across the walk only {hi - lo:.2f} m shown"
    assert ax.get_xlim()[0] < 0.0 and ax.get_xlim()[1] > 4.0, "the whole walk is in view"
    assert ax.yaxis_inverted(), "x to the right: z grows down the page (the view from above)"
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1, "the legend is outside the axes, to their right"


def test_travel_along_z_is_drawn_horizontally_with_x_up():
    ax = plot.balance_top(_Walk(along=2))
    assert ax.get_xlabel() == "z (m)" and ax.get_ylabel() == "x (m)"
    assert not ax.yaxis_inverted()


def test_bad_input_is_named():
    with pytest.raises(TypeError, match="balance"):
        plot.balance_top(np.zeros((3, 3)))
    with pytest.raises(IndexError, match="frames"):
        plot.balance_top(_Walk(along=0), frames=[60])
