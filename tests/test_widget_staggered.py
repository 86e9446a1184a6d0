"""StaggeredExplorer driven headless: every control forwards to the core editor."""

from __future__ import annotations

import html
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
    """The published curve statistics, as the browser reads them (the text of the HTML widget)."""
    return json.loads(html.unescape(x.curves_info.value))


def no_error(x) -> bool:
    """No exception shown in the status line (timing warnings may be)."""
    return "color:#b00" not in x.status.value


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
        assert ed.constraints and ed.current.constraints is not None  # feet planted by default
        assert ed.analysis.event_joints == m.skeleton.roles.foot_joints()
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


# ------------------------------------------------------------ history, export, sync
def test_undo_redo_reset_buttons_restore_the_sliders(explorer) -> None:
    x = explorer
    h = x.history
    assert "mocaplab-undo" in h.undo._dom_classes and h.undo.disabled and h.redo.disabled
    x.s_slider.value = 0.02
    at_002 = info(x)["checksum"]
    x.s_slider.value = 0.04  # a second release of the same slider is a step of its own
    x.wr_slider.value = 0.3
    assert not h.undo.disabled
    h.undo.click()
    assert x.wr_slider.value == x.editor.w_r == 0.0 and x.s_slider.value == 0.04
    h.undo.click()
    assert x.s_slider.value == x.editor.s == 0.02
    assert info(x)["checksum"] == pytest.approx(at_002, rel=1e-12)
    assert not h.redo.disabled
    h.redo.click()
    assert x.s_slider.value == 0.04 and no_error(x)
    x.toggle.value = False
    x.count_slider.value = 5
    h.reset.click()
    assert (x.s_slider.value, x.wr_slider.value, x.toggle.value, x.count_slider.value) == (0.0, 0.0, True, 8)
    assert len(x.pose_list.options) == 8
    h.undo.click()  # the reset is undoable
    assert (x.s_slider.value, x.toggle.value, x.count_slider.value) == (0.04, False, 5)


def test_controls_show_the_editors_values_after_an_error(explorer, monkeypatch) -> None:
    """The issue's case: an unexpected error left the slider at 0.8 while the editor kept 0.0."""
    from mocaplab.staggered import editor

    x = explorer
    monkeypatch.setattr(x.editor, "set_exaggeration", lambda w: (_ for _ in ()).throw(RuntimeError("boom")))
    x.wr_slider.value = 0.8
    assert "RuntimeError" in x.status.value and "boom" in x.status.value
    assert x.wr_slider.value == x.editor.w_r == 0.0
    monkeypatch.undo()
    # the editor accepted the value, the drawing failed: the slider keeps the editor's 0.8
    monkeypatch.setattr(x, "_draw_curves", lambda: (_ for _ in ()).throw(RuntimeError("draw")))
    x.wr_slider.value = 0.8
    assert "RuntimeError" in x.status.value and x.wr_slider.value == x.editor.w_r == 0.8
    monkeypatch.undo()
    # an edit the editor rejects: its reason in the status line, the slider back at the editor's value
    monkeypatch.setattr(editor, "succession", lambda *a, **k: (_ for _ in ()).throw(ValueError("<crossing>")))
    x.s_slider.value = 0.03
    assert "edit rejected" in x.status.value and "&lt;crossing&gt;" in x.status.value
    assert x.s_slider.value == x.editor.s == 0.0
    # a value set on the editor directly (beyond a slider's range) is shown, not clamped
    monkeypatch.undo()
    x.editor.set_succession(s=0.1)
    x._refresh_all()
    assert x.s_slider.value == 0.1 and x.s_slider.max >= 0.1


def test_export_writes_the_motion_being_played(explorer, tmp_path) -> None:
    from mocaplab.io import load_bvh

    x = explorer
    x.s_slider.value = 0.03
    x.toggle.value = False
    x.export.path.value = str(tmp_path / "edited.bvh")
    x.export.button.click()
    assert "mocaplab-export" in x.export.button._dom_classes and no_error(x)
    back = load_bvh(tmp_path / "edited.bvh", scale=0.01)  # save_bvh writes centimetres
    played = x.editor.evaluate()
    assert back.n_frames == played.n_frames and back.skeleton.names == played.skeleton.names
    assert np.abs(back.global_positions() - played.global_positions()).max() < 1e-3
    staggered = x.editor.current.evaluate(staggered=True)
    assert np.abs(back.global_positions() - staggered.global_positions()).max() > 1e-2  # the non-staggered one


def test_the_3d_view_keeps_its_scrubbed_time(cmu, monkeypatch) -> None:
    """Toggles, sliders and undo keep the frame the 3D view was scrubbed to; selecting a pose moves it to t_k."""
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    x = StaggeredExplorer(cmu("16_05"), max_poses=6, backend="agg", optimize=False)
    try:
        v = x.viewer
        v.set_frame(40)
        for change in (
            lambda: setattr(x.toggle, "value", False),
            lambda: setattr(x.s_slider, "value", 0.02),
            lambda: setattr(x.wr_slider, "value", 0.3),
            lambda: setattr(x.count_slider, "value", 5),
            x.history.undo.click,
            x.history.reset.click,
        ):
            change()
            assert x.viewer is v and v.frame == 40 and no_error(x)
        x.pose_list.value = 3
        assert v.time == pytest.approx(x.editor.current.times[3], abs=1.0 / v.fps)
        v.set_frame(50)
        x.tau_slider.value = 0.02
        assert v.frame == 50
        x.history.undo.click()  # the random timing: the selection stays, so does the clock
        assert v.frame == 50
        x.history.undo.click()  # the selection: back to pose 0, and the clock to t_0
        assert x.editor.selected == 0 and v.frame == 0
    finally:
        x.close()


def test_the_toolbar_leaves_the_y_label_clear(cmu) -> None:
    """ipympl's toolbar floats over the canvas' left edge: the axes (y label included) start to its right."""
    pytest.importorskip("ipympl")
    from mocaplab.widgets import StaggeredExplorer
    from mocaplab.widgets._drag import TOOLBAR_PX

    x = StaggeredExplorer(cmu("16_05"), max_poses=6, backend="ipympl", viewer=False, optimize=False)
    assert x.interactive
    renderer = x.figure.canvas.get_renderer()
    x.figure.draw(renderer)
    # ipympl shows one figure pixel per CSS pixel, the unit of TOOLBAR_PX
    assert x.ax.yaxis.label.get_window_extent(renderer).x0 >= TOOLBAR_PX
    assert x.ax.get_tightbbox(renderer).x0 >= TOOLBAR_PX


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
@pytest.mark.parametrize("convention", ["mixamo", "game_studio"])
def test_any_skeleton_and_roles(converted, convention, monkeypatch) -> None:
    """A clip with other joint names (and a static root above the pelvis): defaults from its roles; ``roles=`` reaches the editor."""
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    m, names = converted("16_15", convention)
    pelvis = m.skeleton.roles["pelvis"]
    x = StaggeredExplorer(m, max_poses=6, backend="agg", viewer=False, optimize=False)
    assert x.editor.joint == pelvis == names["Hips"] and x.succession_dropdown.value == pelvis
    x.s_slider.value = 0.02
    assert no_error(x) and "rejected" not in x.status.value
    assert not np.array_equal(x.editor.current.refinements, x.editor.base.refinements)
    x.history.undo.click()
    assert x.s_slider.value == 0.0
    spine = names["LowerBack"]
    y = StaggeredExplorer(m, max_poses=6, backend="agg", viewer=False, optimize=False, roles={"pelvis": spine})
    assert y.editor.joint == spine and y.editor.motion.skeleton.roles["pelvis"] == spine


def test_joint_names_and_messages_are_escaped(cmu, monkeypatch) -> None:
    import dataclasses

    from mocaplab.widgets import StaggeredExplorer

    m = cmu("16_05")
    sk = m.skeleton
    evil = "<b>LeftArm</b>"
    m = m.replace(skeleton=dataclasses.replace(sk, names=tuple(evil if n == "LeftArm" else n for n in sk.names)))
    x = StaggeredExplorer(m, max_poses=6, backend="agg", viewer=False, optimize=False, curve_joint=evil)
    assert "&lt;b&gt;LeftArm&lt;/b&gt;" in x.curves_info.value and "<b>" not in x.curves_info.value
    assert info(x)["variable"] == evil
    x.editor.message = f"a warning naming {evil}"
    x._refresh_all(viewers=False)
    assert "&lt;b&gt;" in x.status.value and "<b>" not in x.status.value


def test_edits_on_the_editor_show_when_the_widget_is_displayed(explorer) -> None:
    x = explorer
    x.editor.set_succession(s=0.02, l=2.0)  # as lesson 13 does before showing the explorer
    x.editor.set_staggered(False)
    assert x.s_slider.value == 0.0
    assert x.widget is not None  # displaying it (reading the box) draws the edits
    assert (x.s_slider.value, x.l_slider.value, x.toggle.value) == (0.02, 2.0, False)
    assert info(x)["staggered"] is False and not x.history.undo.disabled


def test_feet_planted_box_turns_the_constraint_layer_off_and_on(explorer) -> None:
    x = explorer
    assert "mocaplab-staggered-constraints" in x.constraints_check._dom_classes
    assert x.constraints_check.value is True and x.editor.constraints
    x.s_slider.value = 0.02
    held = x.editor.evaluate()
    x.constraints_check.value = False
    assert no_error(x) and x.editor.constraints is False
    free = x.editor.evaluate()
    assert np.abs(held.global_positions() - free.global_positions()).max() > 1e-3
    x.history.undo.click()
    assert x.editor.constraints and x.constraints_check.value is True
