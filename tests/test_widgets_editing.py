"""PathEditor and TimeTrackEditor driven headless with matplotlib mouse events.

The widgets are thin views over :class:`mocaplab.editing.SceneEditor`: every
test feeds events through ``canvas.callbacks.process`` (as the browser would
through ipympl) and checks what reached the editor and what the view shows.
"""

from __future__ import annotations

import html
import json

import ipywidgets
import numpy as np
import pytest
from matplotlib.backend_bases import MouseEvent
from mocaplab.widgets.path_editor import PathEditor
from mocaplab.widgets.time_track import TimeTrackEditor

from mocaplab.editing import AbsoluteTime, Duration, PinDirection, PinPosition, Relative, SceneEditor, Sync


# --------------------------------------------------------------------------- fixtures and helpers
@pytest.fixture(scope="module")
def walks(cmu):
    """Two 30 fps CMU walks side by side (16_15 and 02_01 shifted 1.5 m in x)."""
    a = cmu("16_15").resample(30)
    b = cmu("02_01").resample(30).transformed(translation=(1.5, 0.0, 0.0))
    return [a, b]


class Spy:
    """A SceneEditor that records the calls the widget makes."""

    def __init__(self, editor: SceneEditor) -> None:
        self._editor = editor
        self.calls: list[tuple] = []

    def __getattr__(self, name):
        return getattr(self._editor, name)

    def drag(self, index, target):
        self.calls.append(("drag", index, np.array(target, dtype=float)))
        return self._editor.drag(index, target)

    def add(self, constraint):
        self.calls.append(("add", constraint))
        return self._editor.add(constraint)

    def remove(self, index):
        self.calls.append(("remove", index))
        return self._editor.remove(index)


class ViewerStub:
    """Stands in for MotionViewer: records the motions and times it was given."""

    def __init__(self, motions, **options) -> None:
        self.motions = list(motions)
        self.updates: list[list] = []
        self.times: list[float] = []
        self.widget = ipywidgets.HTML("3D")
        self.closed = False

    def set_motions(self, motions) -> None:
        self.motions = list(motions)
        self.updates.append(self.motions)

    def set_time(self, t: float) -> None:
        self.times.append(float(t))

    def close(self) -> None:
        self.closed = True


def _event(view, name, xy, *, data=True, key=None, modifiers=None, button=1):
    """Feed one mouse event at data (or display) coordinates ``xy``."""
    x, y = view.ax.transData.transform(xy) if data else xy
    event = MouseEvent(name, view.canvas, x, y, button=button, key=key, modifiers=modifiers)
    view.canvas.callbacks.process(name, event)
    return event


def _drag(view, start, stop, *, steps=5, **kw):
    """Press at ``start``, move in ``steps`` to ``stop`` (data coordinates), release."""
    _event(view, "button_press_event", start, **kw)
    for s in np.linspace(0.0, 1.0, steps + 1)[1:]:
        _event(view, "motion_notify_event", (1 - s) * np.asarray(start) + s * np.asarray(stop), **kw)
    _event(view, "button_release_event", stop, **kw)


def _status(view) -> str:
    return view.status.value


# --------------------------------------------------------------------------- PathEditor
def test_press_on_path_pins_and_drag_moves_the_pin(walks):
    spy = Spy(SceneEditor(walks, [PinPosition(0, 0, walks[0].root_positions[0, [0, 2]], hard=True)]))
    pe = PathEditor(spy, viewer=False)
    pe.figure.canvas.draw()
    before = np.array(pe.result.paths[0])
    start = before[60]
    stop = start + np.array([0.8, 0.3])
    _drag(pe, start, stop)

    kinds = [c[0] for c in spy.calls]
    assert kinds[0] == "add" and isinstance(spy.calls[0][1], PinPosition)
    assert spy.calls[0][1].character == 0 and spy.calls[0][1].frame == 60
    assert kinds.count("drag") == 5, "one solve per motion event"
    assert all(c[1] == 1 for c in spy.calls if c[0] == "drag"), "drags go to the new pin, constraint 1"
    pin = pe.editor.constraints[1]
    assert np.allclose(pin.position, stop, atol=1e-9), "the pin sits under the mouse"
    after = np.array(pe.result.paths[0])
    assert np.linalg.norm(after[60] - stop) < 0.1, "the path follows the soft pin"
    assert np.linalg.norm(after[0] - before[0]) < 1e-6, "the hard pin at frame 0 holds"
    assert np.allclose(pe._lines[0].get_xydata(), after), "the drawn path is the edited path"
    assert "PinPosition #1" in _status(pe) and "residual" in _status(pe)
    assert f"{stop[0]:.3f}" in _status(pe) and f"{stop[1]:.3f}" in _status(pe)
    handles = json.loads(pe.handles_info.value.replace("&quot;", '"'))
    assert [h["index"] for h in handles] == [0, 1]
    assert np.allclose(handles[1]["data"], stop)


def test_drag_existing_pin_then_click_unpins(walks):
    end = walks[0].n_frames - 1
    target = walks[0].root_positions[end, [0, 2]]
    spy = Spy(SceneEditor([walks[0]], [PinPosition(0, end, target, hard=True)]))
    pe = PathEditor(spy, viewer=False)
    pe.figure.canvas.draw()
    moved = target + np.array([1.0, 0.0])
    _drag(pe, target, moved)
    assert [c[0] for c in spy.calls] == ["drag"] * 5
    assert np.allclose(pe.result.paths[0][end], moved, atol=1e-6), "hard pin: exact"
    assert "moved PinPosition #0" in _status(pe)
    residual = float(_status(pe).split("residual")[1].split()[0])
    assert residual < 1e-6, "the status reports the hard pin's residual"

    # press and release on the handle without moving: unpin
    _event(pe, "button_press_event", moved)
    _event(pe, "button_release_event", moved)
    assert spy.calls[-1] == ("remove", 0)
    assert len(pe.editor.constraints) == 0
    assert "removed PinPosition #0" in _status(pe)
    assert np.allclose(pe.result.paths[0], walks[0].root_positions[:, [0, 2]], atol=1e-6), (
        "no constraint: original path"
    )


def test_click_on_path_pins_in_place_without_changing_it(walks):
    pe = PathEditor([walks[0]], viewer=False)
    pe.figure.canvas.draw()
    p = np.array(pe.result.paths[0][30])
    _event(pe, "button_press_event", p)
    _event(pe, "button_release_event", p)
    (pin,) = pe.editor.constraints
    assert isinstance(pin, PinPosition) and pin.frame == 30
    assert np.allclose(pe.result.paths[0], walks[0].root_positions[:, [0, 2]], atol=1e-6)
    assert "pinned PinPosition #0" in _status(pe)


def test_shift_drag_sets_a_direction(walks):
    spy = Spy(SceneEditor([walks[0]], [PinPosition(0, 0, walks[0].root_positions[0, [0, 2]], hard=True)]))
    pe = PathEditor(spy, viewer=False)
    pe.figure.canvas.draw()
    f = 60
    base = np.array(pe.result.paths[0][f])
    tangent = pe.result.paths[0][f + 1] - pe.result.paths[0][f - 1]
    u = tangent / np.linalg.norm(tangent)
    left = np.array([u[1], -u[0]])
    goal = base + 0.5 * (u + left)  # 45 degrees to the left of the walking direction
    _drag(pe, base, goal, modifiers=["shift"])
    adds = [c[1] for c in spy.calls if c[0] == "add"]
    assert len(adds) == 1 and isinstance(adds[0], PinDirection) and adds[0].frame == f
    c = pe.editor.constraints[1]
    want = (u + left) / np.linalg.norm(u + left)
    got = np.asarray(c.direction, dtype=float)
    assert np.allclose(got / np.linalg.norm(got), want, atol=0.05)
    path = np.asarray(pe.result.paths[0])
    new_t = path[f + 1] - path[f - 1]
    angle = np.degrees(np.arccos(np.clip(new_t @ want / np.linalg.norm(new_t), -1, 1)))
    assert angle < 10.0, "the path turned towards the dragged direction"
    assert "PinDirection #1" in _status(pe)
    kinds = [h["kind"] for h in pe.handle_positions()]
    assert kinds == ["pin", "direction"]


def test_relative_constraints_are_drawn_as_links(walks):
    a, b = walks
    cs = [Relative(1, 40, 0, 40, (0.0, -1.5))]
    pe = PathEditor(walks, cs, viewer=False)
    link = pe._links.get_xydata()
    assert link.shape == (3, 2)
    assert np.allclose(link[0], pe.result.paths[1][40]) and np.allclose(link[1], pe.result.paths[0][40])


def test_errors_are_shown_in_the_status_not_raised(walks):
    pe = PathEditor([walks[0]], [PinPosition(0, 10, walks[0].root_positions[10, [0, 2]])], viewer=False)
    pe.figure.canvas.draw()

    def broken(index, target):
        raise ValueError("solver exploded")

    pe.editor.drag = broken  # type: ignore[method-assign]
    p = np.asarray(pe.editor.constraints[0].position)
    _drag(pe, p, p + 0.5)  # must not raise
    assert "ValueError" in _status(pe) and "solver exploded" in _status(pe)
    assert isinstance(pe.last_error, ValueError)
    assert "mocaplab-error" in _status(pe)


def test_toolbar_zoom_mode_and_other_buttons_do_not_edit(walks):
    pe = PathEditor([walks[0]], viewer=False)
    pe.figure.canvas.draw()
    p = np.array(pe.result.paths[0][20])
    _drag(pe, p, p + 0.5, button=3)
    assert len(pe.editor.constraints) == 0
    pe.canvas.toolbar.zoom()
    _drag(pe, p, p + 0.5)
    pe.canvas.toolbar.zoom()
    assert len(pe.editor.constraints) == 0


def test_viewer_gets_new_motions_on_release_and_follows_time(walks, monkeypatch):
    pe = PathEditor(walks, viewer=ViewerStub([]))
    first = pe.viewer
    pe.figure.canvas.draw()
    start = np.array(pe.result.paths[0][50])
    _drag(pe, start, start + 0.6)
    assert pe.viewer is first and not first.closed, "the same viewer is updated, not replaced"
    assert pe.viewer_updates == 1 and len(first.updates) == 1, "one update per release, none per motion event"
    assert pe._viewer_box.children[0] is first.widget
    assert pe.viewer.motions[0] is pe.result.refined()[0], "the 3D view shows the refined motion"
    assert _status(pe).rstrip("</span>").endswith("refined")
    moved_root = pe.viewer.motions[0].root_positions[:, [0, 2]]
    assert not np.allclose(moved_root, walks[0].root_positions[: len(moved_root), [0, 2]], atol=1e-3), (
        "edited motion shown"
    )
    t0 = float(pe.result.clock[0])
    pe.time.value = pe.time.min + 1.0
    assert pe.viewer.times[-1] == pytest.approx(pe.time.value - t0)
    marker = pe._now[0].get_xydata()[0]
    times = np.asarray(pe.result.times[0])
    expect = [np.interp(pe.time.value, times, pe.result.paths[0][:, i]) for i in (0, 1)]
    assert np.allclose(marker, expect), "the time marker sits on the path at the slider's time"


def test_real_motion_viewer_is_updated_in_place_after_a_drag(walks, monkeypatch):
    pytest.importorskip("pyvista")
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets.viewer import MotionViewer

    pe = PathEditor([walks[0]], viewer_options={"window_size": (160, 120), "backend": "static"})
    assert isinstance(pe.viewer, MotionViewer)
    first, plotter, widget = pe.viewer, pe.viewer.plotter, pe.viewer.widget
    meshes = (first.characters[0].bones, first.characters[0].joints)
    image = first._view.value
    pe.figure.canvas.draw()
    start = np.array(pe.result.paths[0][50])
    _drag(pe, start, start + np.array([0.5, 0.0]))
    assert pe.viewer is first and pe.viewer.plotter is plotter and pe.viewer.widget is widget
    assert (first.characters[0].bones, first.characters[0].joints) == meshes, "the meshes were updated in place"
    assert pe._viewer_box.children[0] is widget
    shown = pe.viewer.characters[0].positions[:, 0, [0, 2]]
    edited = pe.result.refined()[0].global_positions()
    assert np.allclose(shown, edited[:, 0, [0, 2]]), "the 3D view shows the edited (refined) motion"
    assert not np.allclose(edited[:, 0, [0, 2]], walks[0].global_positions()[:, 0, [0, 2]], atol=1e-3)
    f = pe.viewer.character_frames()[0]
    n = walks[0].n_joints
    centres = (
        np.asarray(first.characters[0].joints.points).reshape(-1, len(first._spheres.template), 3)
        - first._spheres.template[None]
    ).mean(axis=1)
    assert np.allclose(centres[:n], edited[f], atol=1e-9), "the drawn spheres are the edited pose"
    assert first._view.value != image, "the static image was re-rendered"
    first.close()


def test_shares_a_scene_editor_with_the_time_track(walks):
    editor = SceneEditor(walks, [])
    pe = PathEditor(editor, viewer=False)
    tt = TimeTrackEditor(editor)
    pe.on_edit(lambda result: tt.refresh())
    pe.figure.canvas.draw()
    p = np.array(pe.result.paths[1][20])
    _drag(pe, p, p + 0.4)
    assert tt.result is editor.result and pe.result is editor.result
    # re-time character 1 in the time track: the path editor's slider follows the new clock
    tt.on_edit(lambda result: pe.refresh())
    tt.figure.canvas.draw()
    last = float(tt.result.times[1][-1])
    _drag(tt, (last, 1.0), (last + 1.5, 1.0))
    assert pe.time.max == pytest.approx(max(float(t[-1]) for t in editor.result.times))
    assert pe.time.max > last + 1.0


def test_inputs_are_not_mutated(walks):
    before = [np.array(m.root_positions) for m in walks]
    pe = PathEditor(walks, viewer=False)
    pe.figure.canvas.draw()
    p = np.array(pe.result.paths[0][40])
    _drag(pe, p, p + 1.0)
    for m, b in zip(walks, before, strict=True):
        assert np.array_equal(m.root_positions, b)


def test_layout_and_dom_classes(walks):
    pe = PathEditor([walks[0]], viewer=False)
    assert "mocaplab-path-editor" in pe.widget._dom_classes
    assert "mocaplab-path-status" in pe.status._dom_classes
    assert "mocaplab-path-handles" in pe.handles_info._dom_classes
    assert "mocaplab-path-time" in pe.time._dom_classes
    assert "mocaplab-path-canvas" in pe.canvas._dom_classes
    assert pe.ax.get_title() == "mocaplab path editor"
    assert pe.ax.yaxis_inverted(), "seen from above: z grows down the page"


def test_agg_backend_shows_a_png(walks):
    import ipywidgets as W

    pe = PathEditor([walks[0]], viewer=False, backend="agg")
    image = pe.widget.children[0].children[0]
    assert isinstance(image, W.Image) and image.value[:4] == b"\x89PNG"
    first = image.value
    pe.figure.canvas.draw()
    p = np.array(pe.result.paths[0][40])
    _drag(pe, p, p + 1.0)
    assert image.value != first, "redrawn on release"


def test_bad_arguments(walks):
    editor = SceneEditor([walks[0]], [])
    with pytest.raises(ValueError, match="pick_radius"):
        PathEditor(editor, pick_radius=0, viewer=False)
    with pytest.raises(ValueError, match="constraints"):
        PathEditor(editor, [], viewer=False)
    with pytest.raises(ValueError, match="backend"):
        PathEditor(editor, backend="qt", viewer=False)
    with pytest.raises(TypeError, match="set_motions"):
        PathEditor(editor, viewer=ipywidgets.HTML("not a viewer"))
    with pytest.raises(ValueError, match="labels"):
        TimeTrackEditor(editor, labels=["a", "b"])


# --------------------------------------------------------------------------- TimeTrackEditor
def test_press_on_tick_adds_absolute_time_and_drag_moves_it(walks):
    spy = Spy(SceneEditor(walks, [AbsoluteTime(0, 0, 0.0, hard=True)]))
    tt = TimeTrackEditor(spy)
    tt.figure.canvas.draw()
    f = 60
    t = float(tt.result.times[0][f])
    _drag(tt, (t, 0.0), (t + 0.8, 0.0))
    assert spy.calls[0][0] == "add" and isinstance(spy.calls[0][1], AbsoluteTime)
    assert spy.calls[0][1].frame == f
    assert [c[0] for c in spy.calls[1:]] == ["drag"] * 5
    times = np.asarray(tt.result.times[0])
    assert abs(times[f] - (t + 0.8)) < 0.05, "frame 60 now plays about 0.8 s later"
    assert abs(times[0]) < 1e-6
    assert np.all(np.diff(times) > 0), "time warps stay monotone"
    assert "AbsoluteTime #1" in _status(tt) and "min step" in _status(tt)
    ticks = tt._tracks[0].get_segments()
    assert np.allclose([s[0, 0] for s in ticks], times), "ticks at the warped reference times"
    # click on the handle: removed
    _event(tt, "button_press_event", (float(tt.editor.constraints[1].time), -0.25))
    _event(tt, "button_release_event", (float(tt.editor.constraints[1].time), -0.25))
    assert spy.calls[-1] == ("remove", 1)
    assert "removed AbsoluteTime #1" in _status(tt)


def test_duration_handle_drag(walks):
    a = walks[0]
    d0 = 60 / a.fps
    spy = Spy(SceneEditor([a], [Duration(0, 0, 60, d0, hard=True)]))
    tt = TimeTrackEditor(spy)
    tt.figure.canvas.draw()
    (h,) = tt.handle_positions()
    assert h["kind"] == "duration"
    end = np.array(h["data"])
    _drag(tt, end, end + np.array([1.0, 0.0]))
    assert all(c[0] == "drag" for c in spy.calls)
    assert tt.editor.constraints[0].duration == pytest.approx(d0 + 1.0, abs=1e-9)
    times = np.asarray(tt.result.times[0])
    assert times[60] - times[0] == pytest.approx(d0 + 1.0, abs=1e-6), "hard duration: exact"
    assert "Duration #0" in _status(tt)


def test_sync_links_are_drawn_and_follow_the_warp(walks):
    tt = TimeTrackEditor(walks, [Sync(1, 30, 0, 50, hard=True)])
    link = tt._syncs.get_xydata()
    assert link.shape == (3, 2)
    assert link[0][0] == pytest.approx(link[1][0], abs=1e-6), "synchronized frames share a reference time"
    assert tuple(link[0]) != tuple(link[1])


def test_time_track_errors_are_shown(walks):
    tt = TimeTrackEditor([walks[0]], [AbsoluteTime(0, 20, 20 / 30)])
    tt.figure.canvas.draw()

    def broken(index, target):
        raise RuntimeError("no time")

    tt.editor.drag = broken  # type: ignore[method-assign]
    x = float(tt.editor.constraints[0].time)
    _drag(tt, (x, -0.25), (x + 0.5, -0.25))
    assert "RuntimeError" in _status(tt) and "no time" in _status(tt)


def test_time_track_dom_classes(walks):
    tt = TimeTrackEditor(walks)
    assert "mocaplab-time-editor" in tt.widget._dom_classes
    assert "mocaplab-time-status" in tt.status._dom_classes
    assert "mocaplab-time-handles" in tt.handles_info._dom_classes
    assert tt.ax.get_title() == "mocaplab time tracks"
    assert [t.get_text() for t in tt.ax.get_yticklabels()] == ["0: 16_15", "1: 02_01"]


def test_release_lands_the_handle_under_the_mouse_when_motion_events_were_dropped(walks):
    """Browsers may drop motion events: the release position is applied too."""
    end = walks[0].n_frames - 1
    target = walks[0].root_positions[end, [0, 2]]
    pe = PathEditor([walks[0]], [PinPosition(0, end, target, hard=True)], viewer=False)
    pe.figure.canvas.draw()
    goal = target + np.array([0.7, -0.4])
    _event(pe, "button_press_event", target)
    _event(pe, "motion_notify_event", target + np.array([0.2, -0.1]))  # only one motion event arrives
    _event(pe, "button_release_event", goal)
    assert np.allclose(pe.editor.constraints[0].position, goal, atol=1e-9)
    assert np.allclose(pe.result.paths[0][end], goal, atol=1e-6)
    (h,) = pe.handle_positions()
    x, y = pe.ax.transData.transform(goal)
    assert np.allclose(h["pixel"], [x, y], atol=1e-6)


def test_dragging_beyond_the_axes_keeps_following_the_mouse(walks):
    pe = PathEditor([walks[0]], [PinPosition(0, 0, walks[0].root_positions[0, [0, 2]], hard=True)], viewer=False)
    pe.figure.canvas.draw()
    start = np.asarray(pe.editor.constraints[0].position)
    bbox = pe.ax.get_window_extent()
    x0, y0 = pe.ax.transData.transform(start)
    _event(pe, "button_press_event", (x0, y0), data=False)
    outside = (x0, bbox.y1 + 15.0)  # above the axes, on the title
    event = _event(pe, "motion_notify_event", outside, data=False)
    assert event.inaxes is None
    want = pe.ax.transData.inverted().transform((event.x, event.y))  # matplotlib rounds pixels
    assert np.allclose(pe.editor.constraints[0].position, want, atol=1e-9)
    _event(pe, "button_release_event", outside, data=False)
    assert np.allclose(pe.editor.constraints[0].position, want, atol=1e-9)
    assert pe.ax.get_window_extent().contains(*pe.ax.transData.transform(want)), "the view grew to show the handle"
    assert pe.last_error is None


def test_handle_pixels_match_the_drawn_figure(walks):
    """Published handle pixels are those of the laid-out figure (what the browser shows)."""
    pe = PathEditor([walks[0]], [PinPosition(0, 30, walks[0].root_positions[30, [0, 2]])], viewer=False)
    published = json.loads(pe.handles_info.value.replace("&quot;", '"'))
    pe.figure.canvas.draw()
    assert np.allclose(published[0]["pixel"], pe.handle_positions()[0]["pixel"], atol=0.5)
    css = published[0]["css"]
    assert css[1] == pytest.approx(pe.figure.bbox.height - published[0]["pixel"][1])


def test_press_away_from_the_tracks_does_nothing(walks):
    tt = TimeTrackEditor(walks)
    tt.figure.canvas.draw()
    _drag(tt, (1.0, 0.5), (1.5, 0.5))  # between the two tracks
    assert len(tt.editor.constraints) == 0


# --------------------------------------------------------------------------- any skeleton
def _same_gestures(make):
    """Pin a path point and drag it in a PathEditor, re-time a frame in a TimeTrackEditor, on ``make()``."""
    motions = make()
    p0 = motions[0].pelvis_positions[0, [0, 2]]
    pe = PathEditor(motions, [PinPosition(0, 0, p0, hard=True)], viewer=ViewerStub([]))
    pe.figure.canvas.draw()
    start = np.array(pe.result.paths[0][60])
    _drag(pe, start, start + np.array([0.8, 0.3]), steps=2)
    tt = TimeTrackEditor(pe.editor)
    tt.figure.canvas.draw()
    t = float(tt.result.times[0][40])
    _drag(tt, (t, 0.0), (t + 0.6, 0.0), steps=2)
    pe.refresh()
    return pe, tt


@pytest.fixture(scope="module")
def cmu_gestures(walks):
    return _same_gestures(lambda: [walks[0]])


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
@pytest.mark.parametrize("convention", ["renamed", "static_root"])
def test_editors_work_on_any_skeleton_with_no_joint_name(walks, cmu_gestures, convention):
    """The same gestures on a re-expressed CMU walk give the CMU answer (no joint name passed)."""
    from test_editing_conventions import CONVENTIONS, body

    cmu_pe, cmu_tt = cmu_gestures
    pe, tt = _same_gestures(lambda: [CONVENTIONS[convention](walks[0])])
    assert pe.last_error is None and tt.last_error is None, (pe.last_error, tt.last_error)
    assert [type(c).__name__ for c in pe.editor.constraints] == ["PinPosition", "PinPosition", "AbsoluteTime"]
    path = np.asarray(pe.result.paths[0])
    assert np.linalg.norm(path[60] - cmu_pe.result.paths[0][60]) < 1e-9
    assert np.linalg.norm(path[60] - walks[0].root_positions[60, [0, 2]]) > 0.3, "the path was dragged"
    assert np.allclose(tt.result.times[0], cmu_tt.result.times[0], atol=1e-9), "the same re-timing"
    assert np.allclose(pe._lines[0].get_xydata(), path), "the drawn path is the pelvis path"
    shown = pe.viewer.motions[0]
    assert shown is pe.result.refined()[0]
    assert np.abs(body(shown) - body(cmu_pe.viewer.motions[0])).max() < 1e-3, "the 3D view gets the same motion"


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
def test_roles_reach_the_scene_editor(walks):
    from test_editing_conventions import renamed

    m = renamed(walks[0])
    spine = m.skeleton.index("Spine_02")
    pe = PathEditor([m], viewer=False, roles={"pelvis": "Spine_02"})
    assert pe.editor.options["roles"] == {"pelvis": "Spine_02"}
    assert np.allclose(pe.result.paths[0], m.global_positions()[:, spine][:, [0, 2]], atol=1e-9)
    tt = TimeTrackEditor([m], roles={"pelvis": "Spine_02"})
    assert tt.editor.characters[0].path_joint == spine
    with pytest.raises(ValueError, match="`roles` only with characters"):
        PathEditor(pe.editor, viewer=False, roles={"pelvis": "Hips"})
    with pytest.raises(ValueError, match="once"):
        TimeTrackEditor([m], roles={"pelvis": "Hips"}, editor_options={"roles": {"pelvis": "Hips"}})


def test_discrete_editing_from_editor_options_drives_a_discrete_editor(walks):
    # editor_options={"discrete": True} builds a DiscreteEditor behind the same view; dragging the
    # end pin of a walk far enough adds steps, and the drawn path is the transformed one
    from mocaplab.editing import DiscreteEditor

    walk = walks[0]
    P = walk.root_positions[:, [0, 2]]
    end = walk.n_frames - 1
    cons = [PinPosition(0, 0, P[0], hard=True), PinPosition(0, end, P[-1], hard=True)]
    pe = PathEditor([walk], cons, editor_options={"discrete": True}, viewer=False)
    assert isinstance(pe.editor, DiscreteEditor)
    pe.figure.canvas.draw()
    _drag(pe, P[-1], P[0] + 1.5 * (P[-1] - P[0]), steps=10)
    res = pe.result
    assert res.transformations and len(res.paths[0]) > walk.n_frames
    assert np.allclose(pe._lines[0].get_xydata(), res.paths[0]), "the drawn path is the transformed one"
    pin = pe.editor.constraints[1]
    assert pin.frame == end, "the editor keeps the input clip's frames"
    assert res.constraints[1].frame == len(res.paths[0]) - 1, "the result maps them onto the transformed clip"
    assert np.linalg.norm(np.asarray(pin.position) - (P[0] + 1.5 * (P[-1] - P[0]))) < 0.05, "the pin followed the mouse"
    handles = json.loads(pe.handles_info.value.replace("&quot;", '"'))
    assert np.allclose(handles[1]["data"], pin.position), "and is drawn at its target"
    assert np.allclose(res.paths[0][-1], pin.position, atol=1e-6), "which the transformed path reaches"


# --------------------------------------------------------------------------- undo, redo, reset, export
def _handles(view):
    return [(h["index"], h["kind"], h["data"]) for h in view.handle_positions()]


def _published(view):
    return json.loads(view.handles_info.value.replace("&quot;", '"'))


def test_undo_redo_reset_buttons_restore_the_drawn_paths_handles_and_3d_view(walks):
    P = walks[0].root_positions[:, [0, 2]]
    F = walks[0].n_frames
    pe = PathEditor(walks, [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])], viewer=ViewerStub([]))
    pe.figure.canvas.draw()
    undo, redo, reset = pe.history_buttons.undo, pe.history_buttons.redo, pe.history_buttons.reset
    assert undo.disabled and redo.disabled, "nothing to undo or redo yet"
    first_paths = [np.array(p) for p in pe.result.paths]
    first_handles, first_result = _handles(pe), pe.result
    _drag(pe, P[-1], P[-1] + np.array([1.0, -0.5]))  # gesture 1: five drags of pin 1
    dragged_paths = [np.array(p) for p in pe.result.paths]
    dragged_handles = _handles(pe)
    start = np.array(pe.result.paths[1][40])
    _drag(pe, start, start + 0.6)  # gesture 2: a new pin on character 1, dragged
    assert not undo.disabled and len(pe.editor.undo_stack) == 3, "one undo step per gesture"
    _drag(pe, start + 0.6, start + 0.9)  # gesture 3: the same pin again, a step of its own (checkpoint on release)
    assert len(pe.editor.undo_stack) == 4
    undo.click()

    undo.click()
    assert pe.last_error is None
    assert _handles(pe) == dragged_handles and len(pe.editor.constraints) == 2
    assert all(np.array_equal(a, b) for a, b in zip(pe.result.paths, dragged_paths, strict=True))
    undo.click()
    assert pe.result is first_result and _handles(pe) == first_handles
    assert [h["data"] for h in _published(pe)] == [h[2] for h in first_handles], "the page gets the first handles"
    for line, path in zip(pe._lines, first_paths, strict=True):
        assert np.array_equal(line.get_xydata(), path), "the drawn paths are the first ones, bitwise"
    assert pe.viewer.motions[0] is first_result.refined()[0], "the 3D view shows the restored motions"
    assert undo.disabled and not redo.disabled
    assert f"undid: moved pin at frame {F - 1} of character 0" in _status(pe), "says which step it took back"

    redo.click()
    assert _handles(pe) == dragged_handles
    reset.click()
    assert pe.result is first_result and not undo.disabled, "reset is an undoable step"
    undo.click()
    assert _handles(pe) == dragged_handles


def test_time_track_undo_after_a_drag(walks):
    tt = TimeTrackEditor(walks, [AbsoluteTime(0, 0, 0.0, hard=True)])
    tt.figure.canvas.draw()
    first = [np.array(t) for t in tt.result.times]
    t = float(tt.result.times[0][60])
    _drag(tt, (t, 0.0), (t + 0.8, 0.0))
    assert not np.allclose(tt.result.times[0], first[0])
    tt.history_buttons.undo.click()
    assert len(tt.editor.constraints) == 1, "the pressed and dragged handle was one step"
    assert all(np.array_equal(a, b) for a, b in zip(tt.result.times, first, strict=True))
    ticks = tt._tracks[0].get_segments()
    assert np.array_equal([s[0, 0] for s in ticks], first[0]), "the ticks are back"


def test_export_writes_the_edited_motions_as_bvh(walks, tmp_path):
    from mocaplab.io import load_bvh

    pe = PathEditor(walks, viewer=False)
    pe.figure.canvas.draw()
    start = np.array(pe.result.paths[0][50])
    _drag(pe, start, start + np.array([0.7, 0.4]))
    assert pe.export_control.path.value == "16_15_edited.bvh", "named after the first clip"
    pe.export_control.path.value = str(tmp_path / "scene.bvh")
    pe.export_control.button.click()
    assert pe.last_error is None, pe.last_error
    files = pe.export_control.written
    assert [f.name for f in files] == ["scene_1.bvh", "scene_2.bvh"], "one file per character"
    for k, f in enumerate(files):
        back = load_bvh(f, scale=0.01)
        on = np.asarray(pe.result.active[k])  # the character's own span on the shared clock
        edited = pe.result.refined()[k]
        assert back.n_frames == int(on.sum())
        np.testing.assert_allclose(back.pelvis_positions[:, [0, 2]], edited.pelvis_positions[on][:, [0, 2]], atol=1e-5)
    back = load_bvh(files[0], scale=0.01)
    moved = np.linalg.norm(back.pelvis_positions[:, [0, 2]] - walks[0].root_positions[: back.n_frames, [0, 2]], axis=1)
    assert moved.max() > 0.3, "the file holds the edited path, not the input"
    assert "wrote" in pe.export_control.label.value


def _skate(before, after):
    from mocaplab import quality

    report = quality.compare(before, after)
    return report["skate"].after


def test_refined_on_release_plants_the_feet_in_the_view_and_the_file(walks, tmp_path):
    """The default view refines on release: the 3D view and the BVH file skate no more than the input."""
    from mocaplab.io import load_bvh

    pe = PathEditor([walks[0]], viewer=ViewerStub([]))
    assert pe.refine.value and "mocaplab-refine" in pe.refine._dom_classes
    pe.figure.canvas.draw()
    start = np.array(pe.result.paths[0][50])
    _drag(pe, start, start + np.array([0.8, 0.5]))
    assert pe.last_error is None, pe.last_error
    assert "· refined" in _status(pe), "the status line says the shown motion is refined"
    shown = pe.viewer.motions[0]
    plain = pe.result.motions[0]
    assert shown is pe.result.refined()[0] and shown is not plain
    input_skate = _skate(walks[0], walks[0])
    assert _skate(walks[0], shown) <= input_skate, "the refined view skates no more than the input"
    assert _skate(walks[0], plain) > 1.5 * _skate(walks[0], shown), "the plain edit skates: refinement mattered"
    (written,) = pe.export(tmp_path / "refined.bvh")
    back = load_bvh(written, scale=0.01)
    np.testing.assert_allclose(back.global_positions(), shown.global_positions(), atol=1e-4)

    # unticked: the view and the file hold the plain edit, and the status says so
    pe.refine.value = False
    assert pe.viewer.motions[0] is plain and "not refined" in _status(pe)
    (written,) = pe.export(tmp_path / "plain.bvh")
    np.testing.assert_allclose(load_bvh(written, scale=0.01).global_positions(), plain.global_positions(), atol=1e-4)
    pe.refine.value = True
    assert pe.viewer.motions[0] is shown, "ticked again: the refinement of this edit, not computed again"


def test_time_track_refines_on_release(walks, tmp_path):
    tt = TimeTrackEditor(walks, [AbsoluteTime(0, 0, 0.0, hard=True)])
    tt.figure.canvas.draw()
    t = float(tt.result.times[0][60])
    _drag(tt, (t, 0.0), (t + 0.5, 0.0))
    assert tt.last_error is None and "· refined" in _status(tt)
    files = tt.export(tmp_path / "timed.bvh")
    on = np.asarray(tt.result.active[0])
    refined = tt.result.refined()[0]
    assert np.abs(refined.pelvis_positions - tt.result.motions[0].pelvis_positions).max() > 1e-3
    np.testing.assert_allclose(load_pelvis(files[0]), refined.pelvis_positions[on], atol=1e-5)


def load_pelvis(path):
    from mocaplab.io import load_bvh

    return load_bvh(path, scale=0.01).pelvis_positions


def test_export_error_is_shown_and_the_view_stays_in_sync(walks, tmp_path):
    pe = PathEditor([walks[0]], viewer=False)
    pe.export_control.path.value = str(tmp_path / "missing-folder" / "x.bvh")
    pe.export_control.button.click()
    assert pe.last_error is not None and "mocaplab-error" in _status(pe)


def test_export_writes_each_characters_own_span_not_the_padded_clock(walks, tmp_path):
    """A character starting 3 s late is written as its own retimed motion, without the held first pose."""
    from mocaplab.io import load_bvh

    cons = [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(1, 0, 3.0, hard=True)]
    tt = TimeTrackEditor(walks, cons, refine=False)  # the plain edit: the late character's file is its clip
    result = tt.result
    assert result.motions[1].n_frames > walks[1].n_frames, "on the shared clock the late character is padded"
    files = tt.export(tmp_path / "late.bvh")
    for k, f in enumerate(files):
        back = load_bvh(f, scale=0.01)
        on = np.asarray(result.active[k])
        assert back.n_frames == int(on.sum()) == walks[k].n_frames, "exactly the character's own frames"
        np.testing.assert_allclose(back.pelvis_positions, result.motions[k].pelvis_positions[on], atol=1e-5)
    late = load_bvh(files[1], scale=0.01)
    np.testing.assert_allclose(late.pelvis_positions, walks[1].pelvis_positions, atol=1e-5)


def test_export_failure_says_which_files_were_written(walks, tmp_path):
    from mocaplab.widgets._controls import ExportControl

    folder = tmp_path / "<b>folder"
    folder.mkdir()
    (folder / "scene_2.bvh").mkdir()  # the second file cannot be written: a directory has its name
    control = ExportControl(lambda: walks)
    with pytest.raises(OSError):
        control.export(folder / "scene.bvh", overwrite=True)  # else the numbered scene_2_*.bvh would be free
    assert control.written == [folder / "scene_1.bvh"], "written holds the file written before the failure"
    label = control.label.value
    assert "mocaplab-error" in label and "scene_1.bvh" in label and "scene_2.bvh not written" in label
    assert "&lt;b&gt;folder" in label and "<b>" not in label
    with pytest.raises(OSError):
        control.export(tmp_path / "missing-folder" / "x.bvh")
    assert control.written == [] and "scene_1" not in control.label.value, "nothing of the earlier export is kept"
    assert "wrote no file" in control.label.value


def test_a_failing_listener_does_not_keep_the_others_on_the_old_state(walks):
    P = walks[0].root_positions[:, [0, 2]]
    F = walks[0].n_frames
    pe = PathEditor(
        [walks[0]], [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])], viewer=ViewerStub([])
    )
    pe.figure.canvas.draw()
    seen = []

    def broken(result):
        raise RuntimeError("listener <i>broke</i>")

    pe.on_edit(broken)
    pe.on_edit(seen.append)
    _drag(pe, P[-1], P[-1] + np.array([1.0, 0.5]))
    assert seen and seen[-1] is pe.editor.result, "the second listener ran although the first raised"
    dragged = pe.editor.result
    pe.history_buttons.undo.click()
    assert "RuntimeError" in _status(pe) and "&lt;i&gt;broke&lt;/i&gt;" in _status(pe)
    restored = pe.editor.result
    assert restored is not dragged and pe.result is restored
    assert seen[-1] is restored, "the later listener shows the undone state"
    assert pe.viewer.motions[0] is restored.refined()[0], "the 3D view shows the undone state"
    assert np.array_equal(pe._lines[0].get_xydata(), restored.paths[0])


class FailingEditor(Spy):
    """A SceneEditor whose drag fails from the ``fail_at``-th call on, and whose undo crashes after undoing."""

    def __init__(self, editor, fail_at=3):
        super().__init__(editor)
        self.fail_at = fail_at

    def drag(self, index, target):
        if sum(c[0] == "drag" for c in self.calls) + 1 >= self.fail_at:
            self.calls.append(("failed drag", index))
            raise ValueError("engine rejected the target <b>bold</b>")
        return super().drag(index, target)

    def undo(self):
        self._editor.undo()
        raise RuntimeError("crashed after undoing")


def test_after_a_callback_error_the_view_shows_the_editors_state(walks):
    P = walks[0].root_positions[:, [0, 2]]
    F = walks[0].n_frames
    spy = FailingEditor(SceneEditor([walks[0]], [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])]))
    pe = PathEditor(spy, viewer=ViewerStub([]))
    pe.figure.canvas.draw()
    _drag(pe, P[-1], P[-1] + np.array([1.5, 0.0]), steps=6)  # the third motion event fails
    assert "ValueError" in _status(pe) and "&lt;b&gt;bold&lt;/b&gt;" in _status(pe) and "<b>" not in _status(pe)
    accepted = np.asarray(spy.constraints[1].position)
    assert not np.allclose(accepted, P[-1] + np.array([1.5, 0.0])), "the engine kept its last accepted target"
    assert np.allclose(_published(pe)[1]["data"], accepted), "the handle is drawn where the engine has it"
    assert pe.result is spy.result
    assert np.array_equal(pe._lines[0].get_xydata(), spy.result.paths[0]), "the drawn path is the engine's"
    assert not pe.history_buttons.undo.disabled

    # undo changes the engine, then crashes: the view follows the engine, not its own last picture
    pe.history_buttons.undo.click()
    assert "crashed after undoing" in _status(pe)
    assert np.allclose(_published(pe)[1]["data"], P[-1]), "the handle is back where the engine put it"
    assert np.array_equal(pe._lines[0].get_xydata(), spy.result.paths[0])
    assert pe.history_buttons.undo.disabled and not pe.history_buttons.redo.disabled


# --------------------------------------------------------------------------- ground view: legend, footplants, discrete
def test_legend_names_hard_and_soft_pins_and_every_mark(walks):
    pe = PathEditor([walks[0]], viewer=False)
    (legend,) = pe.figure.legends
    labels = [t.get_text() for t in legend.get_texts()]
    for name in ("hard pin", "soft pin", "direction pin", "relative offset", "footplant", "input path"):
        assert name in labels, labels
    hard, soft = (legend.legend_handles[labels.index(n)] for n in ("hard pin", "soft pin"))
    assert hard.get_markerfacecolor() == pe._hard_pins.get_markerfacecolor() != soft.get_markerfacecolor()
    assert soft.get_markerfacecolor() == pe._pins.get_markerfacecolor()
    assert "last discrete change" not in labels, "continuous editing draws no transformation"
    box = legend.get_window_extent(pe.figure.canvas.get_renderer())
    assert box.y1 <= pe.ax.get_window_extent().y0 + 1, "the legend sits under the plot, not over the paths"


def _expected_plants(motion, edited, joints):
    """Mid frames of each foot's contacts (ankle or toe planted), and the edited ankle-toe midpoints there."""
    from mocaplab.contacts import foot_contacts, intervals_from_mask

    c = foot_contacts(motion, joints=joints)
    g = edited.global_positions()
    out = []
    for ankle, toe in motion.skeleton.roles.feet():
        mask = c.of(ankle) | c.of(toe)
        for a, b in intervals_from_mask(mask):
            m = (a + b - 1) // 2
            out.append(0.5 * (g[m, motion.skeleton.index(ankle), [0, 2]] + g[m, motion.skeleton.index(toe), [0, 2]]))
    return np.array(out)


def test_footplants_are_drawn_where_the_edited_motion_plants_its_feet(walks):
    P = walks[0].root_positions[:, [0, 2]]
    F = walks[0].n_frames
    pe = PathEditor(
        [walks[0]], [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1], hard=True)], viewer=False
    )
    pe.figure.canvas.draw()
    before = pe.footplants[0].copy()
    assert len(before) >= 4, "a 4 s walk plants its feet several times"
    want = _expected_plants(walks[0], pe.result.edited_motions[0], pe.editor.contact_joints(0))
    assert np.allclose(np.sort(before[:, :2], axis=0), np.sort(want, axis=0), atol=1e-9)
    assert len(pe._feet.get_paths()) == len(before), "one footprint drawn per plant"
    _drag(pe, P[-1], P[-1] + np.array([2.0, 0.0]))
    after = pe.footplants[0]
    want = _expected_plants(walks[0], pe.result.edited_motions[0], pe.editor.contact_joints(0))
    assert np.allclose(np.sort(after[:, :2], axis=0), np.sort(want, axis=0), atol=1e-9), "they follow the edit"
    assert np.abs(after[:, 0] - before[:, 0]).max() > 0.5, "the footprints moved with the dragged path"
    # a footprint lies heel to toe: along the walking direction, within 35 degrees
    tangent = np.asarray(pe.result.tangents[0])
    walking = np.arctan2(tangent[:, 1], tangent[:, 0]).mean()
    assert np.all(np.abs(np.angle(np.exp(1j * (after[:, 2] - walking)))) < np.radians(35))

    # a large scene updates them on release only
    pe.live_footplant_frames = 0
    handle = np.asarray(pe.editor.constraints[1].position)
    _event(pe, "button_press_event", handle)
    _event(pe, "motion_notify_event", handle + np.array([-1.0, 0.0]))
    assert np.array_equal(pe.footplants[0], after), "not during the drag"
    _event(pe, "button_release_event", handle + np.array([-1.0, 0.0]))
    assert not np.allclose(pe.footplants[0], after), "on release"


def test_discrete_transformation_is_highlighted_and_named_then_undone(walks):
    walk = walks[0]
    P = walk.root_positions[:, [0, 2]]
    end = walk.n_frames - 1
    cons = [PinPosition(0, 0, P[0], hard=True), PinPosition(0, end, P[-1], hard=True)]
    pe = PathEditor([walk], cons, editor_options={"discrete": True}, viewer=False)
    labels = [t.get_text() for t in pe.figure.legends[0].get_texts()]
    assert "last discrete change" in labels
    assert pe.highlighted is None and len(pe._changed.get_xydata()) == 0
    pe.figure.canvas.draw()
    _drag(pe, P[-1], P[0] + 1.5 * (P[-1] - P[0]), steps=10)
    res = pe.result
    assert res.transformations
    last = res.transformations[-1]
    a, b = last.frames
    k, first, final = pe.highlighted
    assert (k, first, final) == (0, a - 1, min(b, len(res.paths[0]) - 1))
    assert np.array_equal(pe._changed.get_xydata(), res.paths[0][first : final + 1]), "those frames are highlighted"
    assert f"applied {last} (frames {first}-{final} highlighted)" in html.unescape(_status(pe)), _status(pe)
    assert "moved PinPosition #1" in _status(pe)

    pe.history_buttons.undo.click()  # the whole drag was one step: the inserted steps go
    assert pe.result.transformations == () and len(pe.result.paths[0]) == walk.n_frames
    assert pe.highlighted is None and len(pe._changed.get_xydata()) == 0
    assert np.array_equal(pe._lines[0].get_xydata(), pe.editor.result.paths[0])
    pe.history_buttons.redo.click()
    assert pe.result.transformations == res.transformations and f"applied {last}" in html.unescape(_status(pe))


def test_status_lines_wrap_and_show_the_whole_text(walks):
    pe = PathEditor([walks[0]], viewer=False)
    long = "word " * 80
    pe._set_status(long)
    assert "ellipsis" not in pe.status.value and "nowrap" not in pe.status.value
    assert "white-space:normal" in pe.status.value and long.strip() in pe.status.value
    assert pe.status.layout.overflow in (None, "", "visible"), "nothing is clipped"


# --------------------------------------------------------------------------- any Motion, escaped text
EVIL = "<img src=x onerror=alert(1)>"


def _evil(motion):
    """``motion`` named EVIL, with its left toe joint named EVIL."""
    import dataclasses

    sk = motion.skeleton
    names = tuple(EVIL if n == "LeftToeBase" else n for n in sk.names)
    return motion.replace(skeleton=dataclasses.replace(sk, names=names), name=EVIL)


def test_text_from_data_and_exceptions_is_escaped(walks, tmp_path):
    m = _evil(walks[0])
    P = m.root_positions[:, [0, 2]]
    pe = PathEditor([m], [PinPosition(0, 0, P[0], hard=True)], viewer=False)
    tt = TimeTrackEditor(pe.editor)
    pe.figure.canvas.draw()
    assert len(pe.footplants[0]) >= 4, "the roles still find the renamed toe"
    _drag(pe, P[-1], P[-1] + 0.5)  # a new pin: the status names the character and its clip
    assert "&lt;img src=x onerror=alert(1)&gt;" in _status(pe) and "<img" not in _status(pe)
    tt.refresh()
    tt.figure.canvas.draw()
    t = float(tt.result.times[0][30])
    _drag(tt, (t, 0.0), (t + 0.3, 0.0))
    assert "&lt;img" in _status(tt) and "<img" not in _status(tt)

    def broken(index, target):
        raise ValueError(f"joint {EVIL!r} is not allowed")

    pe.editor.drag = broken  # type: ignore[method-assign]
    _drag(pe, P[-1] + 0.5, P[-1] + 1.0)
    assert "mocaplab-error" in _status(pe) and "<img" not in _status(pe) and "&lt;img" in _status(pe)
    assert "<" not in pe.export_control.path.value, "the default export name keeps only safe characters"
    pe.export(tmp_path / "evil.bvh")
    assert "<img" not in pe.export_control.label.value


@pytest.fixture(scope="module")
def converted(walks, tmp_path_factory):
    from conventions import load_converted

    folder = tmp_path_factory.mktemp("conventions")
    return {c: load_converted(walks[0], c, folder)[0] for c in ("mixamo", "game_studio")}


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
@pytest.mark.parametrize("convention", ["mixamo", "game_studio"])
def test_converted_clip_drag_undo_export(walks, converted, convention, tmp_path):
    """A mixamo file, and a static root above a travelling pelvis: footplants, drag, undo and export all work."""
    from mocaplab.io import load_bvh

    m = converted[convention]
    P = m.pelvis_positions[:, [0, 2]]
    pe = PathEditor([m], [PinPosition(0, 0, P[0], hard=True)], viewer=ViewerStub([]))
    pe.figure.canvas.draw()
    assert len(pe.footplants[0]) >= 4, "feet found through the joint roles"
    first = np.array(pe.result.paths[0])
    assert np.allclose(first, P, atol=1e-6), "the path is the pelvis' (not the static root's)"
    start = np.array(pe.result.paths[0][60])
    _drag(pe, start, start + np.array([0.8, 0.3]))
    assert pe.last_error is None, pe.last_error
    dragged = np.array(pe.result.paths[0])
    assert np.linalg.norm(dragged[60] - first[60]) > 0.3
    (f,) = pe.export(tmp_path / f"{convention}.bvh")
    back = load_bvh(f, scale=0.01)
    np.testing.assert_allclose(
        back.pelvis_positions[:, [0, 2]], pe.result.motions[0].pelvis_positions[:, [0, 2]], atol=1e-5
    )
    pe.history_buttons.undo.click()
    assert np.array_equal(pe.result.paths[0], first) and len(pe.editor.constraints) == 1
    tt = TimeTrackEditor([m], roles=None)
    tt.figure.canvas.draw()
    times = np.array(tt.result.times[0])
    _drag(tt, (times[40], 0.0), (times[40] + 0.5, 0.0))
    assert tt.last_error is None and abs(tt.result.times[0][40] - times[40] - 0.5) < 0.05
    tt.history_buttons.undo.click()
    assert np.array_equal(tt.result.times[0], times)


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_roles_reach_the_editor_and_the_footplants(walks):
    import dataclasses

    feet = {"LeftFoot": "knob_a", "LeftToeBase": "knob_b", "RightFoot": "knob_c", "RightToeBase": "knob_d"}
    sk = walks[0].skeleton
    m = walks[0].replace(skeleton=dataclasses.replace(sk, names=tuple(feet.get(n, n) for n in sk.names)))
    roles = {"left_ankle": "knob_a", "left_toe": "knob_b", "right_ankle": "knob_c", "right_toe": "knob_d"}
    pe = PathEditor([m], viewer=False, roles=roles)
    assert pe.editor.options["roles"] == roles
    assert pe.editor.contact_joints(0) == ("knob_a", "knob_b", "knob_c", "knob_d")
    reference = PathEditor([walks[0]], viewer=False)
    assert np.allclose(pe.footplants[0], reference.footplants[0], atol=1e-9), "the named feet are the CMU feet"


def test_an_edit_in_code_and_a_gesture_are_two_undo_steps(walks):
    P = walks[0].root_positions[:, [0, 2]]
    F = walks[0].n_frames
    pe = PathEditor([walks[0]], [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])], viewer=False)
    pe.editor.drag(1, P[-1] + np.array([0.5, 0.0]))  # in code, as lesson cells do
    pe.refresh()
    in_code = pe.result
    pe.figure.canvas.draw()
    handle = np.asarray(pe.editor.constraints[1].position)
    _drag(pe, handle, handle + np.array([0.0, 0.6]))  # then the mouse, on the same pin
    pe.history_buttons.undo.click()
    assert pe.result is in_code, "undo goes back to the code edit, not before it"
