"""mocaplab.plot with the Agg backend: what is drawn is the data."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mocaplab import plot, quat  # noqa: E402
from mocaplab.contacts import Contacts, foot_contacts  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")


def test_skeleton_3d_draws_every_bone_at_its_fk_position(walk):
    ax = plot.skeleton(walk, 40, highlight=["LeftFoot"])
    assert ax.name == "3d"
    sk = walk.skeleton
    (bones,) = [c for c in ax.collections if type(c).__name__ == "Line3DCollection"]
    segs = np.asarray(bones._segments3d)
    assert segs.shape == (sk.n_joints - 1 + len(sk.end_site_parents), 2, 3)
    pos = walk.global_positions()[40]
    # matplotlib (X, Y, Z) = world (z, x, y); bone j goes from parent to joint
    assert np.allclose(segs[: sk.n_joints - 1, 1], pos[1:, [2, 0, 1]])
    assert np.allclose(segs[: sk.n_joints - 1, 0], pos[sk.parents[1:]][:, [2, 0, 1]])
    assert "frame 40" in ax.get_title()
    ax.figure.canvas.draw()


@pytest.mark.parametrize(("projection", "axes"), [("front", (0, 1)), ("side", (2, 1)), ("top", (0, 2))])
def test_skeleton_projections(walk, projection, axes):
    fig, ax = plt.subplots()
    out = plot.skeleton(walk, -1, ax=ax, projection=projection, end_sites=False)
    assert out is ax
    segs = ax.collections[0].get_segments()
    pos = walk.global_positions()[-1]
    assert np.allclose(np.array(segs)[:, 1], pos[1:][:, list(axes)])
    assert f"frame {walk.n_frames - 1}" in ax.get_title()
    fig.canvas.draw()


def test_skeleton_bad_arguments(walk):
    with pytest.raises(IndexError, match="frame"):
        plot.skeleton(walk, walk.n_frames)
    with pytest.raises(ValueError, match="projection"):
        plot.skeleton(walk, 0, projection="oblique")
    _, ax2d = plt.subplots()
    with pytest.raises(ValueError, match="3D Axes"):
        plot.skeleton(walk, 0, ax=ax2d)
    with pytest.raises(TypeError, match="Motion"):
        plot.skeleton(np.zeros((3, 3)), 0)
    with pytest.raises(KeyError, match="Tail"):
        plot.skeleton(walk, 0, highlight=["Tail"])


def test_root_path_motions_and_arrays(walk, cmu):
    other = cmu("02_01")
    ax = plot.root_path([walk, other, np.zeros((5, 2))])
    lines = [ln for ln in ax.get_lines() if ln.get_linestyle() == "-"]
    assert len(lines) == 3
    assert np.allclose(lines[0].get_xydata(), walk.root_positions[:, [0, 2]])
    assert np.allclose(lines[1].get_xydata(), other.root_positions[:, [0, 2]])
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["16_15", "02_01", "path 2"]
    single = plot.root_path(walk.root_positions)
    assert np.allclose(single.get_lines()[0].get_xydata(), walk.root_positions[:, [0, 2]])
    with pytest.raises(ValueError, match=r"\(F, 2\)"):
        plot.root_path([np.zeros((4, 4))])
    with pytest.raises(ValueError, match="at least one"):
        plot.root_path([])


def _screen_turning(ax, xz: np.ndarray) -> float:
    """Total signed turning (radians, counter-clockwise > 0) of a path as drawn on the screen."""
    d = np.diff(ax.transData.transform(xz), axis=0)
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    return float(np.sum(np.arctan2(cross, np.sum(d[:-1] * d[1:], axis=1))))


def test_top_views_look_down_from_above_with_z_down_the_page(walk):
    # a left turn, seen from above (+Y) in a right-handed scene, turns counter-clockwise:
    # heading +z, then +x (a positive rotation about +y)
    s = np.linspace(0.0, np.pi / 2, 30)
    left_turn = np.c_[1.0 - np.cos(s), np.sin(s)]
    ax = plot.root_path(left_turn)
    assert ax.yaxis_inverted() and not ax.xaxis_inverted()
    ax.figure.canvas.draw()  # settle the equal aspect: screen angles are true angles
    assert _screen_turning(ax, left_turn) == pytest.approx(np.pi / 2 * 28 / 29, abs=1e-3)  # 29 chords
    lo, hi = ax.transData.transform([[0.0, 0.0], [0.0, 1.0]])
    assert hi[1] < lo[1], "+z points down the page"
    plot.root_path(left_turn, ax=ax)  # a second path in the same Axes does not flip it back
    assert ax.yaxis_inverted()
    plot.skeleton(walk, 0, ax=ax, projection="top")
    assert ax.yaxis_inverted()
    assert plot.skeleton(walk, 0, projection="top").yaxis_inverted()
    assert not plot.skeleton(walk, 0, projection="front").yaxis_inverted()
    assert not plot.skeleton(walk, 0, projection="side").yaxis_inverted()


def test_a_real_left_turn_turns_left_on_the_page(cmu):
    turn = cmu("16_17")  # walk, 90-degree left turn
    yaw = np.unwrap(quat.yaw(turn.rotations[:, 0]))
    assert np.degrees(yaw[-1] - yaw[0]) > 60, "the root yaws left (counter-clockwise about +y)"
    ax = plot.root_path(turn)
    assert _screen_turning(ax, turn.root_positions[::10, [0, 2]]) > np.radians(60)


def test_joint_curves_components(walk):
    contacts = foot_contacts(walk)
    ax = plot.joint_curves(walk, ["LeftFoot", "RightFoot"], contacts=contacts)
    j = walk.skeleton.index("RightFoot")
    assert np.allclose(ax.get_lines()[1].get_ydata(), walk.global_positions()[:, j, 1])
    assert np.allclose(ax.get_lines()[1].get_xdata(), walk.times)
    n_spans = len(contacts.intervals("LeftFoot")) + len(contacts.intervals("RightFoot"))
    assert len(ax.patches) == n_spans
    k = walk.skeleton.index("LeftLeg")
    angle = plot.joint_curves(walk, "LeftLeg", component="angle").get_lines()[0].get_ydata()
    assert np.allclose(angle, np.degrees(quat.angle(walk.rotations[:, k])))
    speed = plot.joint_curves(walk, "Head", component="speed").get_lines()[0].get_ydata()
    assert np.allclose(speed, walk.joint_speeds()[:, walk.skeleton.index("Head")])
    with pytest.raises(ValueError, match="component"):
        plot.joint_curves(walk, "Head", component="torque")
    with pytest.raises(ValueError, match="contacts"):
        plot.joint_curves(walk[:10], "LeftFoot", contacts=contacts)


def test_contact_timeline_bars_are_the_intervals():
    mask = np.zeros((120, 2), dtype=bool)
    mask[10:40, 0] = True
    mask[60:90, 0] = True
    mask[30:70, 1] = True
    c = Contacts(("LeftFoot", "RightFoot"), mask, 120.0)
    ax = plot.contact_timeline(c, frame=50)
    bars = ax.collections
    assert len(bars) == 2
    left = [(v[:, 0].min(), np.ptp(v[:, 0])) for v in (path.vertices for path in bars[0].get_paths())]
    assert np.allclose(left, [(10 / 120, 30 / 120), (60 / 120, 30 / 120)])
    assert [t.get_text() for t in ax.get_yticklabels()] == ["LeftFoot", "RightFoot"]
    with pytest.raises(TypeError, match="Contacts"):
        plot.contact_timeline(mask)


def test_plot_is_not_imported_by_the_core():
    import subprocess
    import sys

    code = "import sys, mocaplab, mocaplab.contacts; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_any_skeleton_layout_and_naming(walk):
    """A static joint 0 above the pelvis and ``_L``/``_R`` names: the pelvis path, the sides from the names."""
    import warnings

    from test_editing_conventions import static_root

    clip = walk[:200].transformed(translation=(8.0, 0.0, 6.0))  # far from the origin, where joint 0 stays
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The motion path follows joint")
        m = static_root(clip)
        ax = plot.root_path(m)
        assert np.allclose(ax.get_lines()[0].get_xydata(), clip.root_positions[:, [0, 2]])
        ax3 = plot.skeleton(m, 0)
    # the body is drawn, not joint 0 at the origin nor its "bone" to the pelvis: the view frames the character
    (bones,) = [c for c in ax3.collections if type(c).__name__ == "Line3DCollection"]
    n = clip.n_joints - 1 + len(clip.skeleton.end_site_parents)
    assert np.asarray(bones._segments3d).shape == (n, 2, 3)
    assert ax3.get_xlim()[0] > 3.0 and ax3.get_ylim()[0] > 3.0  # matplotlib X, Y = world z, x
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="The motion path follows joint")
        ax2 = plot.skeleton(m, 0, projection="top", ax=plt.subplots()[1])
    assert ax2.get_xlim()[0] > 3.0, "the top view frames the character"
    c = Contacts(("Foot_L", "Toes_R", "Spine_01", "LowerBack"), np.ones((10, 4), bool), 30.0)
    colors = [tuple(b.get_facecolor()[0][:3]) for b in plot.contact_timeline(c).collections]
    rgb = [matplotlib.colors.to_rgb(plot.COLORS[k]) for k in (0, 1, 7, 7)]
    assert np.allclose(colors, rgb), "left blue, right orange, the spine grey"
