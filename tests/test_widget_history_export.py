"""What the editors say after Undo / Redo / Reset, and how Export names its files (issue #28).

* The status after Undo names the step taken back ("undid: moved pin at
  frame 40 of character 0"), after Redo the step made again, in every editor
  (path, time tracks, staggered explorer); the words come from a diff of the
  constraint lists (or of the explorer's parameters), so a removal in the
  middle of the list is one removal, not every later constraint "moved".
* Export defaults to ``<clip>_<method>.bvh`` (path editor ``edited``,
  touch-up ``touched_up``, explorer ``staggered``), never overwrites an
  existing file without being asked (``_2``, ``_3`` ...), and shows the full
  path of what it wrote.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

import numpy as np
import pytest
from mocaplab.widgets._constraints import constraint_change
from mocaplab.widgets._controls import ExportControl, export_name, free_paths, history_status
from mocaplab.widgets.path_editor import PathEditor
from mocaplab.widgets.staggered import params_change
from mocaplab.widgets.time_track import TimeTrackEditor

from mocaplab.editing import AbsoluteTime, Duration, PinDirection, PinPosition
from mocaplab.staggered.editor import EditorParams


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15").resample(30)


def _status(view) -> str:
    """The status line as a person reads it (tags dropped, entities decoded)."""
    return html.unescape(re.sub(r"<[^>]+>", "", view.status.value))


# --------------------------------------------------------------------------- undo / redo status
def test_constraint_change_names_what_an_edit_did():
    a = PinPosition(0, 40, (0.0, 1.0))
    moved = PinPosition(0, 40, (0.5, 1.0))
    d = PinDirection(1, 10, (1.0, 0.0))
    t = AbsoluteTime(0, 90, 3.0, hard=True)
    assert constraint_change([a], [moved]) == "moved pin at frame 40 of character 0"
    assert constraint_change([a, d], [a]) == "removed direction pin at frame 10 of character 1"
    assert constraint_change([a], [a, t]) == "added time handle at frame 90 of character 0"
    # a removal in the middle is one removal: the constraints after it did not move
    b, c = PinPosition(0, 50, (1.0, 1.0)), PinPosition(0, 60, (2.0, 1.0), hard=True)
    assert constraint_change([a, b, c], [a, c]) == "removed pin at frame 50 of character 0"
    assert constraint_change([a, c], [a, b, c]) == "added pin at frame 50 of character 0"
    assert constraint_change([c], [PinPosition(0, 60, (2.0, 3.0), hard=True)]) == (
        "moved hard pin at frame 60 of character 0"
    )
    assert constraint_change([a], [PinPosition(1, 40, (0.0, 1.0))]).startswith("replaced pin at frame 40 of character 0")
    assert constraint_change([a, b], [a, b]) == "no constraint changed"
    assert constraint_change([], [a, b, c]) == "added 3 pins"
    named = constraint_change([Duration(0, 10, 30, 1.0)], [], who=lambda k: f"character {k} (16_15)")
    assert named == "removed duration at frame 10 of character 0 (16_15)"


def test_history_status_names_the_step_undone_and_redone():
    describe = lambda old, new: f"{old} -> {new}"  # noqa: E731
    assert history_status("undo", "B", "A", describe) == "undid: A -> B", "undo names the edit it took back"
    assert history_status("redo", "A", "B", describe) == "redid: A -> B"
    assert history_status("reset", "B", "A", describe) == "reset: B -> A"
    with pytest.raises(ValueError, match="`action`"):
        history_status("again", "A", "B", describe)


def test_path_editor_says_what_undo_and_redo_changed(walk):
    P = walk.pelvis_positions[:, [0, 2]]
    F = walk.n_frames
    pe = PathEditor(walk, [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1])], viewer=False)
    pe.editor.drag(1, P[-1] + np.array([0.8, -0.3]))
    pe.editor.checkpoint()
    pe.editor.add(PinPosition(0, 40, P[40] + 0.2))
    pe.editor.checkpoint()
    pe.refresh()
    buttons = pe.history_buttons
    buttons.undo.click()
    assert pe.last_error is None, pe.last_error
    assert _status(pe).startswith("undid: added pin at frame 40 of character 0"), _status(pe)
    buttons.undo.click()
    assert _status(pe).startswith(f"undid: moved pin at frame {F - 1} of character 0"), _status(pe)
    assert "restored" not in _status(pe)
    buttons.redo.click()
    assert _status(pe).startswith(f"redid: moved pin at frame {F - 1} of character 0"), _status(pe)
    buttons.redo.click()
    buttons.reset.click()
    assert _status(pe).startswith(
        f"reset: moved pin at frame {F - 1} of character 0 (16_15); removed pin at frame 40 of character 0 (16_15)"
    ), _status(pe)


def test_time_tracks_say_what_undo_changed(walk):
    tt = TimeTrackEditor([walk], [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, 60, 60 * walk.dt)])
    tt.editor.drag(1, 60 * walk.dt + 0.4)
    tt.editor.checkpoint()
    tt.refresh()
    tt.history_buttons.undo.click()
    assert tt.last_error is None, tt.last_error
    assert _status(tt).startswith("undid: moved time handle at frame 60 of character 0"), _status(tt)


def test_params_change_names_the_explorer_controls():
    old = EditorParams(12)
    assert params_change(old, EditorParams(12, s=0.02)) == "succession s 0 -> 0.02"
    assert params_change(old, EditorParams(12, constraints=False, selected=3)) == (
        "feet planted on -> off, selected pose 0 -> 3"
    )
    assert params_change(old, EditorParams(None)) == "poses 12 -> all"
    assert params_change(old, old) == "no parameter changed"


def test_explorer_says_what_undo_changed(cmu, monkeypatch):
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "static")
    from mocaplab.widgets import StaggeredExplorer

    x = StaggeredExplorer(cmu("16_05"), max_poses=8, backend="agg", viewer_backend="none", optimize=False)
    try:
        x.s_slider.value = 0.02
        x.history.undo.click()
        assert x.editor.s == 0.0
        assert html.unescape(x.status.value).startswith("undid: succession s 0 -> 0.02"), x.status.value
        x.history.redo.click()
        assert html.unescape(x.status.value).startswith("redid: succession s 0 -> 0.02"), x.status.value
        assert x.export.path.value == "16_05_staggered.bvh"
    finally:
        x.close()


# --------------------------------------------------------------------------- export names
def test_export_name_is_the_clip_and_the_method():
    assert export_name("16_15", "edited") == "16_15_edited.bvh"
    assert export_name("studio walk/take 2", "touched_up") == "studio_walk_take_2_touched_up.bvh"
    assert export_name(None, "staggered") == "motion_staggered.bvh"


def test_default_export_names_of_the_editors(walk, cmu):
    from mocaplab.widgets import TouchUpStepper

    from mocaplab.contacts import foot_contacts
    from mocaplab.physics import Body

    assert PathEditor(walk, viewer=False).export_control.path.value == "16_15_edited.bvh"
    assert TimeTrackEditor([walk]).export_control.path.value == "16_15_edited.bvh"
    jump = cmu("16_05").resample(30)
    stepper = TouchUpStepper(jump, body=Body.from_skeleton(jump), contacts=foot_contacts(jump), viewer=False)
    assert stepper.export.path.value == "16_05_touched_up.bvh", "two steppers on two clips do not share a file"


def test_export_never_overwrites_silently_and_shows_the_full_path(walk, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    control = ExportControl(lambda: walk[:20], default=export_name(walk.name, "touched_up"))
    (first,) = control.export()
    assert first == tmp_path / "16_15_touched_up.bvh" and first.is_absolute() and first.exists()
    assert str(first) in html.unescape(control.label.value), "the label shows the full path"
    before = first.read_bytes()
    (second,) = control.export()
    assert second == tmp_path / "16_15_touched_up_2.bvh", "a second export gets a numbered name"
    assert first.read_bytes() == before
    label = html.unescape(control.label.value)
    assert str(second) in label and "16_15_touched_up.bvh already there: kept, not overwritten" in label
    (third,) = control.export()
    assert third.name == "16_15_touched_up_3.bvh"
    (again,) = control.export(first, overwrite=True)
    assert again == first and "already there" not in control.label.value, "overwrite=True writes the name asked"


def test_free_paths_numbers_a_group_of_files(tmp_path):
    (tmp_path / "scene_2.bvh").write_text("")
    assert [f.name for f in free_paths(tmp_path / "scene.bvh", 2)] == ["scene_2_1.bvh", "scene_2_2.bvh"]
    assert [f.name for f in free_paths(tmp_path / "walk", 1)] == ["walk.bvh"]
    assert free_paths(Path("~/x.bvh"), 1)[0] == Path("~/x.bvh").expanduser()
