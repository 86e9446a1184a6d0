"""Keyboard shortcuts over the editors' plots (issue #28): ctrl+z / ctrl+y, space, the arrows.

Keys are pressed as ipympl delivers them, matplotlib ``key_press_event``\\ s
on the plot's canvas (``canvas.callbacks.process``).  Each shortcut must do
what its button does (undo and redo keep the status that says what changed),
matplotlib's own keys (``l`` turns the y axis logarithmic) are off, and the
help line lists the keys.
"""

from __future__ import annotations

import html
import re

import ipywidgets
import numpy as np
import pytest
from matplotlib.backend_bases import KeyEvent
from mocaplab.widgets.path_editor import PathEditor
from mocaplab.widgets.time_track import TimeTrackEditor

from mocaplab.contacts import foot_contacts
from mocaplab.editing import AbsoluteTime, PinPosition
from mocaplab.physics import Body


def press(canvas, key: str) -> None:
    """Press ``key`` with the mouse over the middle of the figure's first axes (where ipympl sends it from)."""
    ax = canvas.figure.axes[0]
    x, y = ax.bbox.x0 + 0.5 * ax.bbox.width, ax.bbox.y0 + 0.5 * ax.bbox.height
    canvas.callbacks.process("key_press_event", KeyEvent("key_press_event", canvas, key=key, x=x, y=y))


def _text(widget) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", widget.value))


class PlayableStub:
    """A 3D view with the viewer's play / back / forward buttons, counting their clicks."""

    def __init__(self) -> None:
        self.widget = ipywidgets.HTML("3D")
        self.clicks: list[str] = []
        for name in ("play", "back", "forward"):
            button = ipywidgets.Button(description=name)
            button.on_click(lambda _b, name=name: self.clicks.append(name))
            setattr(self, name, button)

    def set_motions(self, motions) -> None:
        pass

    def set_time(self, t: float) -> None:
        pass


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15").resample(30)


def test_path_editor_keys_undo_redo_play_and_step(walk):
    P = walk.pelvis_positions[:, [0, 2]]
    F = walk.n_frames
    view = PlayableStub()
    pe = PathEditor(walk, [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])], viewer=view)
    assert "ctrl+z undo" in _text(pe.status) and "space play/pause" in _text(pe.status), "the help line names the keys"
    pe.editor.drag(1, P[-1] + np.array([0.6, 0.2]))
    pe.editor.checkpoint()
    pe.refresh()
    moved = np.array(pe.editor.constraints[1].position)
    press(pe.canvas, "ctrl+z")
    assert np.allclose(pe.editor.constraints[1].position, P[-1]), "ctrl+z undid the drag"
    assert _text(pe.status).startswith(f"undid: moved pin at frame {F - 1}"), _text(pe.status)
    press(pe.canvas, "ctrl+y")
    assert np.allclose(pe.editor.constraints[1].position, moved), "ctrl+y redid it"
    press(pe.canvas, "ctrl+y")  # nothing to redo: the disabled button is not pressed
    assert pe.last_error is None
    t0 = pe.time.value
    press(pe.canvas, "right")
    press(pe.canvas, "right")
    press(pe.canvas, "left")
    assert pe.time.value == pytest.approx(t0 + pe.time.step), "the arrows move the time one frame"
    press(pe.canvas, " ")
    assert view.clicks == ["play"], "space presses the 3D view's play button"
    press(pe.canvas, "q")  # a key with no shortcut does nothing
    assert view.clicks == ["play"] and pe.last_error is None


def test_matplotlib_keys_are_off_over_the_plot(walk):
    tt = TimeTrackEditor([walk], [AbsoluteTime(0, 0, 0.0, hard=True)])
    before = (tt.ax.get_xscale(), tt.ax.get_yscale())
    for key in ("l", "k", "g"):
        press(tt.canvas, key)
    assert (tt.ax.get_xscale(), tt.ax.get_yscale()) == before == ("linear", "linear")
    assert "space" not in _text(tt.status), "no 3D view: the help line does not promise play"


def test_explorer_keys(cmu, monkeypatch):
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    x = StaggeredExplorer(cmu("16_05"), max_poses=8, viewer_backend="static", optimize=False)
    try:
        x.widget  # noqa: B018 - displayed: the 3D view exists
        assert "ctrl+z undo" in _text(x.help) and x.help in x.widget.children
        x.s_slider.value = 0.02
        press(x.canvas, "ctrl+z")
        assert x.editor.s == 0.0 and x.s_slider.value == 0.0
        assert _text(x.status).startswith("undid: succession s 0 -> 0.02")
        press(x.canvas, "ctrl+Z")  # ctrl+shift+z redoes too
        assert x.editor.s == pytest.approx(0.02)
        frame = x.viewer.frame
        press(x.canvas, "right")
        assert x.viewer.frame == frame + 1, "the arrow steps the 3D view"
    finally:
        x.close()


def test_stepper_keys_step_and_go_back(cmu):
    from mocaplab.widgets import TouchUpStepper

    jump = cmu("16_05").resample(30)
    stepper = TouchUpStepper(jump, body=Body.from_skeleton(jump), contacts=foot_contacts(jump), viewer=False)
    canvas = stepper._plot8.canvas
    assert "step" in _text(stepper.help) and "back" in _text(stepper.help)
    press(canvas, "right")
    press(canvas, "right")
    assert stepper.session.index == 2, "the right arrow steps"
    press(stepper._plot9.canvas, "ctrl+z")
    press(canvas, "left")
    assert stepper.session.index == 0, "left and ctrl+z go back"
    press(canvas, "left")  # at the input: the disabled back button is not pressed
    assert stepper.session.index == 0


def test_viewer_keys_play_pause_and_step(walk):
    """The standalone 3D viewer: space plays and pauses, the arrows step, as its buttons; the help line says so."""
    import asyncio

    from mocaplab.widgets import MotionViewer

    async def scenario() -> None:
        v = MotionViewer(walk, backend="none")
        box = v.widget
        assert v.keys in box.children, "the help line is in the viewer's box"
        assert "space play/pause" in v.keys.help and "\u2192 frame forward" in v.keys.help
        assert v.keys.scope in box._dom_classes, "the keys are taken from the viewer's own box"
        v.keys._handle_custom_msg({"key": " "}, [])  # as the browser sends a key
        assert v.playing and v.play.description == "pause", "space plays"
        v.keys.press(" ")
        assert not v.playing and v.play.description == "play", "space again pauses"
        frame = v.frame
        for key in ("right", "right", "left"):
            v.keys.press(key)
        assert v.frame == frame + 1 and v.slider.value == frame + 1, "the arrows step one frame"
        assert not v.keys.press("q") and v.frame == frame + 1, "a key with no shortcut does nothing"
        v.keys.press(" ")
        v.keys.press("right")
        assert not v.playing and v.frame == frame + 2, "an arrow while playing pauses and steps"
        v.close()

    asyncio.run(scenario())
