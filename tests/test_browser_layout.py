"""The editors fit a laptop: JupyterLab at 1366x768 and 1440x900 with the file browser open (headless Chromium).

Issue #28: on a laptop with JupyterLab's default layout (the file browser
open on the left) the path editor's 3D view covered the plot and cut its
status line, and the staggered explorer pushed its controls past the right
edge, its toggle and Undo/Redo/Reset squeezed to "...".  This test opens a
notebook (written here, building each widget the way its lesson does:
03's path editor with a 3D view, 04's time tracks, 10's touch-up stepper,
13's staggered explorer, 01's 3D viewer) in the real JupyterLab of ``test_browser.py``,
opens the file browser, and measures in the DOM at both window sizes:

* overflow: how far (CSS px) any visible element of a widget reaches past
  the right edge of the notebook's content box (its cell's output area);
* squeezed controls: buttons, toggles, text boxes and labels whose text is
  cut (``scrollWidth > clientWidth``, the "..." a person sees), and any
  control narrower than :data:`MIN_CONTROL_PX`;
* overlap: the area shared by the plot, the 3D view and every control,
  status line or legend outside them (a 3D view drawn over the plot);
* the touch-up stepper's schedule: one line per adjustment under the
  column headings (its rows wrapped onto two lines each at 1366 px).

Everything must be 0.  The figures are printed (``-s`` shows them).

Run: ``pytest -m browser tests/test_browser_layout.py``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_support import LessonPage, wait_until

# the lab, the browser and the screenshots folder live there
from test_browser import browser, lab, shots_dir  # noqa: F401 - fixtures are used by name

pytestmark = [pytest.mark.browser, pytest.mark.timeout(420)]

#: Window sizes of the laptops the course is taught on (CSS px).
SIZES = ((1366, 768), (1440, 900))

#: No button, toggle or slider may be narrower than this (CSS px).
MIN_CONTROL_PX = 28

#: Overlaps smaller than this on either side are borders touching, not one element over another (CSS px).
TOUCH_PX = 2

# One cell per widget, built as its lesson builds it; each root gets a class the measurement finds.
CELLS = {
    "setup": """
import numpy as np
from mocaplab import data
from mocaplab.contacts import foot_contacts
from mocaplab.editing import AbsoluteTime, PinPosition, Sync
from mocaplab.physics import Body
from mocaplab.widgets import PathEditor, StaggeredExplorer, TimeTrackEditor, TouchUpStepper

walk = data.cmu("16_15").resample(30)
P = walk.pelvis_positions[:, [0, 2]]
F = walk.n_frames
""",
    "path": """
path_editor = PathEditor(walk, [PinPosition(0, 0, P[0], hard=True), PinPosition(0, F - 1, P[-1], hard=True)],
                         viewer_options={"window_size": (420, 340)})
path_editor.widget.add_class("layout-path")
path_editor
""",
    "time": """
other = data.cmu("02_01").resample(30)
h = walk.dt
time_editor = TimeTrackEditor([walk, other], [AbsoluteTime(0, 90, 90 * h), AbsoluteTime(0, 0, 0.0, hard=True),
                                              AbsoluteTime(1, 0, 0.5, hard=True), Sync(1, 60, 0, 90, hard=True)])
time_editor.widget.add_class("layout-time")
time_editor
""",
    "stepper": """
jump = data.cmu("16_05").resample(30)
stepper = TouchUpStepper(jump, body=Body.from_skeleton(jump), contacts=foot_contacts(jump),
                         viewer_options={"window_size": (640, 400)})
stepper.widget.add_class("layout-stepper")
stepper.widget
""",
    "viewer": """
from mocaplab.widgets import MotionViewer

viewer = MotionViewer(walk, window_size=(480, 300))
viewer.widget.add_class("layout-viewer")
viewer
""",
    "explorer": """
explorer = StaggeredExplorer(data.cmu("16_15")[3:], max_poses=12, curve_joint="LeftForeArm", joint="LeftArm")
explorer.widget.add_class("layout-explorer")
explorer.widget
""",
}

_MEASURE_JS = """
([cls, minControl, touch]) => {
  const root = document.querySelector('.' + cls);
  if (!root) return {found: false};
  const area = root.closest('.jp-OutputArea-output') || root.closest('.jp-Cell') || root.parentElement;
  const box = area.getBoundingClientRect();
  const visible = (el) => {
    const s = getComputedStyle(el);
    if (s.display === 'none' || s.visibility === 'hidden') return false;
    const r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0;
  };
  const label = (el) => {
    const text = (el.textContent || el.getAttribute('title') || '').trim().replace(/\\s+/g, ' ').slice(0, 40);
    return (el.className && typeof el.className === 'string' ? el.className.split(' ')[0] : el.tagName) +
      (text ? ' "' + text + '"' : '');
  };
  const all = Array.from(root.querySelectorAll('*')).filter(visible);
  // 1. overflow past the right edge of the output area
  let overflow = 0;
  const past = [];
  for (const el of all) {
    const over = el.getBoundingClientRect().right - box.right;
    if (over > 1) { past.push(label(el) + ' +' + Math.round(over)); }
    overflow = Math.max(overflow, over);
  }
  // 2. squeezed controls: cut text, or narrower than minControl
  const controls = all.filter((el) => el.matches(
    'button, input[type=text], select, .widget-readout, .widget-label, .widget-toggle-button, .widget-slider'));
  const squeezed = [];
  for (const el of controls) {
    const r = el.getBoundingClientRect();
    const cut = el.scrollWidth > el.clientWidth + 1 && getComputedStyle(el).overflowX !== 'visible';
    const thin = el.matches('button, .widget-toggle-button, .widget-slider') && r.width < minControl;
    if (cut || thin) squeezed.push(label(el) + ' ' + Math.round(r.width) + 'px' + (cut ? ' cut' : ' thin'));
  }
  // 3. overlap of the plot, the 3D view and the controls / status / legend outside them
  const big = [];
  root.querySelectorAll('.jupyter-matplotlib-canvas-div, .widget-image').forEach((el) => {
    if (visible(el)) big.push(['plot', el]);
  });
  root.querySelectorAll('iframe').forEach((el) => { if (visible(el)) big.push(['3D view', el]); });
  const inside = (el) => big.some(([, b]) => b !== el && b.contains(el)) || el.closest('.jupyter-matplotlib');
  const small = all.filter((el) => !inside(el) && el.matches(
    'button, .widget-slider, .widget-dropdown, .widget-checkbox, .widget-toggle-button, .widget-text, ' +
    '.widget-html, .widget-select'));
  const overlaps = [];
  let shared = 0;
  const meet = (a, b) => {
    const ra = a.getBoundingClientRect(), rb = b.getBoundingClientRect();
    const w = Math.min(ra.right, rb.right) - Math.max(ra.left, rb.left);
    const h = Math.min(ra.bottom, rb.bottom) - Math.max(ra.top, rb.top);
    return (w > touch && h > touch) ? w * h : 0;
  };
  for (let i = 0; i < big.length; i++) {
    for (let j = i + 1; j < big.length; j++) {
      const a = meet(big[i][1], big[j][1]);
      if (a > 0) { overlaps.push(big[i][0] + ' x ' + big[j][0] + ' ' + Math.round(a) + 'px2'); shared += a; }
    }
    for (const el of small) {
      if (big[i][1].contains(el) || el.contains(big[i][1])) continue;
      const a = meet(big[i][1], el);
      if (a > 0) { overlaps.push(big[i][0] + ' x ' + label(el) + ' ' + Math.round(a) + 'px2'); shared += a; }
    }
  }
  return {found: true, overflow: Math.max(0, Math.round(overflow)), past: past.length, past_examples: past.slice(0, 8),
          squeezed, overlap_px2: Math.round(shared), overlaps: overlaps.slice(0, 8), area_width: Math.round(box.width),
          big: big.map(([n, el]) => n + ' ' + JSON.stringify(el.getBoundingClientRect()))};
}
"""

# The touch-up stepper's schedule: how many lines its controls take, and how many adjustments (a stage each).
_SCHEDULE_LINES_JS = """
() => {
  const schedule = document.querySelector('.layout-stepper .mocaplab-touchup-schedule');
  if (!schedule) return {rows: -1, lines: -1, found: false};
  const controls = Array.from(schedule.querySelectorAll('.widget-text, .widget-slider, .widget-dropdown'));
  const middles = controls.map((el) => { const r = el.getBoundingClientRect(); return (r.top + r.bottom) / 2; });
  middles.sort((a, b) => a - b);
  const lines = middles.filter((y, i) => i === 0 || y - middles[i - 1] > 8).length;  // a new line 8 px lower
  return {rows: schedule.querySelectorAll('.widget-dropdown').length, lines, found: true};
}
"""


def _notebook(path: Path) -> Path:
    cells = [
        {"cell_type": "code", "execution_count": None, "metadata": {}, "outputs": [], "source": src.strip()}
        for src in CELLS.values()
    ]
    nb = {
        "cells": cells,
        "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
        "nbformat": 4,
        "nbformat_minor": 5,
    }
    path.write_text(json.dumps(nb, indent=1) + "\n")
    return path


def _open_file_browser(lesson: LessonPage) -> float:
    """Open JupyterLab's file browser on the left (the default layout); returns its width in CSS px."""
    lesson.page.evaluate("() => window.jupyterapp.commands.execute('filebrowser:activate')")
    lesson.page.wait_for_timeout(800)
    width = lesson.page.evaluate(
        "() => { const b = document.querySelector('.jp-FileBrowser'); return b ? b.getBoundingClientRect().width : 0; }"
    )
    assert width > 150, f"the file browser did not open (width {width} px)"
    return float(width)


def measure(lesson: LessonPage, cls: str) -> dict[str, Any]:
    """Overflow, squeezed controls and overlap of the widget with class ``cls`` (see the module docstring)."""
    return lesson.page.evaluate(_MEASURE_JS, [cls, MIN_CONTROL_PX, TOUCH_PX])


@pytest.fixture(scope="module")
def layout_page(lab: Any, browser: Any, shots_dir: Path) -> Iterator[LessonPage]:  # noqa: F811
    """The layout notebook opened at the first size, all its cells run; closed after the module."""
    notebook = _notebook(lab.root_dir / "layout_check.ipynb")
    width, height = SIZES[0]
    context = browser.new_context(viewport={"width": width, "height": height})
    lesson = LessonPage(context, lab, notebook.name, shots_dir)
    try:
        lesson.open()
        lesson.run_all(timeout=300)
        lesson.wait_idle(settle=2.0)
        yield lesson
    finally:
        lesson.close()
        context.close()


def test_editors_fit_a_laptop_with_the_file_browser_open(layout_page: LessonPage) -> None:
    lesson = layout_page
    failures: list[str] = []
    for width, height in SIZES:
        lesson.page.set_viewport_size({"width": width, "height": height})
        browser_px = _open_file_browser(lesson)
        lesson.page.wait_for_timeout(2000)  # JupyterLab lays the panels out again
        for name in ("path", "time", "stepper", "explorer", "viewer"):
            cls = f"layout-{name}"
            root = lesson.page.locator(f".{cls}").first
            root.wait_for(timeout=60000)
            root.scroll_into_view_if_needed()
            lesson.page.wait_for_timeout(500)
            m = measure(lesson, cls)
            assert m["found"], f"{name}: no element with class {cls}"
            lesson.screenshot(f"{width}x{height}-{name}")
            print(
                f"\n{width}x{height} (file browser {browser_px:.0f} px, output {m['area_width']} px) {name}: "
                f"overflow {m['overflow']} px ({m['past']} elements past the edge), "
                f"squeezed {len(m['squeezed'])}, overlap {m['overlap_px2']} px2"
            )
            if name == "stepper":
                lines = lesson.page.evaluate(_SCHEDULE_LINES_JS)
                print(f"  schedule: {lines['rows']} adjustments on {lines['lines']} lines")
                if lines["lines"] != lines["rows"] or not lines["found"]:  # one line per adjustment
                    failures.append(f"{width}x{height} stepper: the schedule's {lines['rows']} rows wrap: {lines}")
            if m["overflow"] or m["squeezed"] or m["overlap_px2"]:
                failures.append(
                    f"{width}x{height} {name}: overflow {m['overflow']} px over {m['past']} elements "
                    f"{m['past_examples']}; squeezed {m['squeezed'][:8]}; overlap {m['overlap_px2']} px2 "
                    f"{m['overlaps']}"
                )
    assert not failures, "widgets do not fit a laptop with the file browser open:\n" + "\n".join(failures)


def _kernel_value(lesson: LessonPage, expression: str) -> Any:
    out = lesson.kernel_eval(f"import json as _j; print('@@json@@' + _j.dumps({expression})); del _j")
    found = [line[8:] for line in out.splitlines() if line.startswith("@@json@@")]
    assert found, f"kernel said {out!r} to {expression}"
    return json.loads(found[-1])


def test_keys_reach_the_editor_from_the_plot(layout_page: LessonPage) -> None:
    """After a click on the path editor's plot (ipympl gives it the focus), the arrows move its time, ctrl+z undoes."""
    lesson = layout_page
    page = lesson.page
    root = page.locator(".layout-path").first
    root.scroll_into_view_if_needed()
    canvas = root.locator(".jupyter-matplotlib-canvas-div canvas").last
    canvas.scroll_into_view_if_needed()
    page.wait_for_timeout(300)
    box = canvas.bounding_box()
    assert box is not None
    n = _kernel_value(lesson, "len(path_editor.editor.constraints)")
    page.mouse.click(box["x"] + 0.85 * box["width"], box["y"] + 0.12 * box["height"])  # the focus: an empty spot
    lesson.wait_idle()
    focused = page.evaluate("() => document.activeElement ? document.activeElement.className : ''")
    assert "jupyter-matplotlib-canvas-div" in focused, f"the click gave the focus to {focused!r}, not the plot"
    assert _kernel_value(lesson, "len(path_editor.editor.constraints)") == n, "the click added no pin"
    t0 = _kernel_value(lesson, "path_editor.time.value")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    wait_until(lambda: _kernel_value(lesson, "path_editor.time.value") > t0, timeout=20, what="the time to move")
    step = _kernel_value(lesson, "path_editor.time.step")
    assert _kernel_value(lesson, "path_editor.time.value") == pytest.approx(t0 + 2 * step)
    lesson.kernel_eval(
        "path_editor.editor.drag(1, path_editor.editor.constraints[1].position + np.array([0.5, 0.0]));"
        " path_editor.editor.checkpoint(); path_editor.refresh(); path_editor.history_buttons.sync()"
    )
    page.keyboard.press("Control+z")
    wait_until(lambda: _kernel_value(lesson, "path_editor.editor.can_undo") is False, timeout=20, what="ctrl+z to undo")
    status = root.locator(".mocaplab-path-status").first.text_content() or ""
    assert status.startswith("undid: moved hard pin at frame"), status


def test_keys_reach_the_viewer_from_its_picture(layout_page: LessonPage) -> None:
    """After a click on the 3D picture the browser draws (a page of the kernel's trame server in an iframe), the
    arrows step and space plays and pauses: the picture's page posts its keys to the viewer's KeyCapture."""
    lesson = layout_page
    page = lesson.page
    root = page.locator(".layout-viewer").first
    root.scroll_into_view_if_needed()
    assert "click the picture" in (root.locator(".mocaplab-keys-help").first.text_content() or ""), "the help line"
    lesson.kernel_eval("viewer.stop_playback(); viewer.set_frame(0)")
    frame = root.locator("iframe").first
    box = frame.bounding_box()
    assert box is not None
    page.mouse.click(box["x"] + 0.5 * box["width"], box["y"] + 0.6 * box["height"])
    focused = page.evaluate("() => document.activeElement ? document.activeElement.tagName : ''")
    assert focused == "IFRAME", f"the click gave the focus to {focused!r}, not the picture's page"
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    wait_until(lambda: _kernel_value(lesson, "viewer.frame") == 2, timeout=20, what="the arrows pressed on the picture")
    page.keyboard.press(" ")
    wait_until(lambda: _kernel_value(lesson, "viewer.playing"), timeout=20, what="space on the picture to play")
    page.keyboard.press(" ")
    wait_until(lambda: not _kernel_value(lesson, "viewer.playing"), timeout=20, what="space on the picture to pause")


def test_keys_reach_the_viewer_from_its_controls(layout_page: LessonPage) -> None:
    """After a click on the 3D viewer's step button, the arrows step and space plays and pauses (issue #28)."""
    lesson = layout_page
    page = lesson.page
    root = page.locator(".layout-viewer").first
    root.scroll_into_view_if_needed()
    assert "space play/pause" in (root.locator(".mocaplab-keys-help").first.text_content() or ""), "the help line"
    lesson.kernel_eval("viewer.set_frame(0)")
    forward = root.locator(".widget-button").nth(2)
    forward.click()  # steps one frame, and the focus is now in the viewer
    wait_until(lambda: _kernel_value(lesson, "viewer.frame") == 1, timeout=20, what="the step button")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowRight")
    page.keyboard.press("ArrowLeft")
    wait_until(lambda: _kernel_value(lesson, "viewer.frame") == 2, timeout=20, what="the arrows to step")
    lesson.wait_idle(settle=0.5)
    assert _kernel_value(lesson, "viewer.frame") == 2, "each arrow stepped one frame, once"
    page.keyboard.press(" ")  # on the focused step button: plays, and does not click the button as well
    wait_until(lambda: _kernel_value(lesson, "viewer.playing"), timeout=20, what="space to play")
    wait_until(lambda: _kernel_value(lesson, "viewer.frame") > 10, timeout=20, what="the frames to move")
    page.keyboard.press(" ")
    wait_until(lambda: not _kernel_value(lesson, "viewer.playing"), timeout=20, what="space to pause")
    frame = _kernel_value(lesson, "viewer.frame")
    lesson.wait_idle(settle=0.5)
    assert _kernel_value(lesson, "viewer.frame") == frame, "paused"
    slider = root.locator(".mocaplab-viewer-slider").first
    text = slider.locator(".widget-label").first.text_content() or ""
    assert text.strip() == f"{frame / 30:.3f} s", f"the slider shows the frame: {text!r} for frame {frame}"
