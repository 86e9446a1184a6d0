"""mocaplab.plot.path_vectors and time_warps (the drawings of lessons 02 and 04): what is drawn is the data."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mocaplab import plot  # noqa: E402
from mocaplab.editing import AbsoluteTime, MotionPath, edit  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _arc(n: int = 40) -> MotionPath:
    a = np.linspace(0.0, np.pi / 2, n)
    positions = np.c_[np.sin(a), np.cos(a)] * 3.0
    return MotionPath(positions, np.zeros(n), 30.0)


def test_path_vectors_draws_tangents_normals_and_headings_at_the_frames():
    path = _arc()
    ax = plot.path_vectors(path, frames=[0, 10, 20], headings=True, label="arc")
    tangents, normals, headings = ax.collections[:3]
    assert np.allclose(tangents.get_offsets(), path.positions[[0, 10, 20]])
    assert np.allclose(np.c_[tangents.U, tangents.V], 3.0 * path.tangents[[0, 10, 20]])  # drawn 3x by default
    assert np.allclose(np.c_[normals.U, normals.V], 3.0 * path.normals[[0, 10, 20]])
    h = path.headings[[0, 10, 20]]
    assert np.allclose(np.c_[headings.U, headings.V], 0.25 * np.c_[np.sin(h), np.cos(h)])
    assert ax.yaxis_inverted(), "a view from above: z down the page"
    assert ax.get_lines()[0].get_label() == "arc"


def test_path_vectors_every_and_unit_length():
    path = _arc()
    ax = plot.path_vectors(path, every=8, normals=False, length=0.5)
    (tangents,) = ax.collections
    assert len(tangents.get_offsets()) == len(range(0, path.n_frames, 8))
    assert np.allclose(np.hypot(tangents.U, tangents.V), 0.5)


def test_path_vectors_rejects_other_inputs():
    with pytest.raises(TypeError, match="MotionPath"):
        plot.path_vectors(np.zeros((5, 2)))
    with pytest.raises(IndexError, match="frames"):
        plot.path_vectors(_arc(10), frames=[12])
    with pytest.raises(ValueError, match="every"):
        plot.path_vectors(_arc(10), every=0)


def test_time_warps_takes_results_and_plain_arrays(walk30):
    h = walk30.dt
    slow = edit(
        [walk30],
        [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, walk30.n_frames - 1, 2 * walk30.duration, hard=True)],
    )
    times = np.arange(walk30.n_frames) * h
    a1, a2 = plot.time_warps([slow, times], ["slow", "plain"], h=h, title="t")
    (slow_t, plain_t), (slow_s, plain_s) = a1.get_lines(), a2.get_lines()[:2]
    assert np.allclose(slow_t.get_ydata(), slow.times[0]) and np.allclose(plain_t.get_ydata(), times)
    assert np.allclose(slow_s.get_ydata(), 2.0) and np.allclose(plain_s.get_ydata(), 1.0), "steps in units of h"
    with pytest.raises(ValueError, match="one label per warp"):
        plot.time_warps([times], ["a", "b"], h=h)
    with pytest.raises(ValueError, match="shape"):
        plot.time_warps([np.zeros((3, 2))], ["a"], h=h)


@pytest.fixture(scope="module")
def walk30(cmu):
    return cmu("16_15").resample(30)
