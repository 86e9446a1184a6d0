"""StaggeredExplorer driven headless: every control forwards to the core editor."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("ipywidgets")


@pytest.fixture()
def explorer(cmu, monkeypatch):
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    x = StaggeredExplorer(cmu("16_05"), max_poses=8, backend="agg", viewer_backend="none", optimize=False)
    yield x
    x.close()


def info(x) -> dict:
    return json.loads(x.curves_info.value)


def test_toggle_switches_to_non_staggered_curves(explorer) -> None:
    x = explorer
    assert "mocaplab-staggered-toggle" in x.toggle._dom_classes
    assert "mocaplab-staggered-explorer" in x.widget._dom_classes
    before = info(x)
    png = x.image.value
    x.toggle.value = False
    after = info(x)
    assert x.editor.staggered is False and after["staggered"] is False
    assert after["checksum"] != pytest.approx(before["checksum"], rel=1e-9)
    assert x.image.value != png
    x.toggle.value = True
    assert info(x)["checksum"] == pytest.approx(before["checksum"], rel=1e-12)


def test_sliders_forward_to_the_editor(explorer) -> None:
    x = explorer
    r0 = np.array(x.editor.current.refinements)
    x.s_slider.value = 0.02
    x.l_slider.value = 2.0
    assert x.editor.s == 0.02 and x.editor.l == 2.0
    assert not np.array_equal(x.editor.current.refinements, r0)
    x.tau_slider.value = 0.03
    assert x.editor.tau == 0.03
    per_variable = np.array(x.editor.current.refinements)
    x.limb_check.value = True
    assert x.editor.random_by == "limb" and not np.array_equal(x.editor.current.refinements, per_variable)
    x.wr_slider.value = 0.3
    assert x.editor.w_r == 0.3
    x.succession_dropdown.value = "LeftArm"
    assert x.editor.joint == "LeftArm"
    x.count_slider.value = 5
    assert x.editor.current.n_poses == 5 and len(x.pose_list.options) == 5
    assert info(x)["n_poses"] == 5


def test_pose_list_and_curve_joint(explorer) -> None:
    x = explorer
    x.pose_list.value = 3
    assert x.editor.selected == 3
    x.joint_dropdown.value = "root_position"
    assert info(x)["variable"] == "root_position"
    label = x.pose_list.options[1][0]
    assert "w=" in label and "refined" in label


def test_errors_show_in_the_status_line(explorer) -> None:
    x = explorer
    x.editor.set_curve_joint = lambda name: (_ for _ in ()).throw(KeyError(name))  # type: ignore[method-assign]
    x.joint_dropdown.value = "Head"
    assert "KeyError" in x.status.value


def test_3d_view_with_static_backend(cmu, monkeypatch) -> None:
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    x = StaggeredExplorer(cmu("16_05"), max_poses=6, backend="agg", optimize=False)
    try:
        v = x.viewer
        labels = [c.label for c in v.characters]
        assert labels == ["original", "played", "non-staggered pose", "true pose at t_k"]
        x.pose_list.value = 2
        assert x.viewer is v  # updated in place
        assert "pose 2" in v.characters[3].motion.name
        assert v.time == pytest.approx(x.editor.current.times[2], abs=1.0 / v.fps)
        x.toggle.value = False
        assert v.characters[1].label == "played, non-staggered"
    finally:
        x.close()


def test_rejects_wrong_input() -> None:
    from mocaplab.widgets import StaggeredExplorer

    with pytest.raises(TypeError, match="Motion or a StaggeredEditor"):
        StaggeredExplorer("16_05")  # type: ignore[arg-type]


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
def test_defaults_come_from_the_roles_below_a_static_root(cmu, monkeypatch) -> None:
    """A pelvis travelling below a static joint 0: the explorer's defaults are the pelvis, its curves the travel."""
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer
    from test_staggered_invariance import static_root

    m = static_root(cmu("16_15")[:360])
    pelvis = m.skeleton.roles["pelvis"]
    x = StaggeredExplorer(m, max_poses=6, backend="agg", optimize=False)
    try:
        ed = x.editor
        assert m.skeleton.names[0] != pelvis
        assert ed.joint == pelvis and x.succession_dropdown.value == pelvis
        assert x.editor.curve_joint in m.skeleton.names  # a joint rotation, never a translation
        assert ed.current.constraints is None and ed.analysis.event_joints == m.skeleton.roles.foot_joints()
        x.joint_dropdown.value = pelvis + ".position"
        assert info(x)["variable"] == pelvis + ".position" and x.ax.get_ylabel() == "m"
        c = ed.curves()
        assert c["kind"] == "translation"
        assert np.abs(c["original"] - m.translations[:, 1]).max() == 0.0
        assert np.abs(c["values"] - m.translations[:, 1]).max() < 1e-9
        # the overlaid poses stand where the pelvis has travelled to
        x.pose_list.value = 3
        ns, true = ed.overlay()
        assert ns.translations is not None
        t3 = ed.current.times[3]
        f = int(round(t3 * m.fps))
        assert np.abs(true.global_positions()[0] - m.global_positions()[f]).max() < 1e-9
        assert np.abs(x.viewer.characters[3].motion.global_positions()[0] - m.global_positions()[f]).max() < 1e-9
    finally:
        x.close()
