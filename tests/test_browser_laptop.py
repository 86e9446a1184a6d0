"""A new student's laptop: lessons 01, 03, 10, 13, 14 and 15 at 1366x768 with the file browser open (issue #28).

The "done when" of issue #28: on a 1366x768 laptop with JupyterLab's file
browser open, lessons 01, 03, 10, 13, 14 and 15 run on the CMU clip and on a
studio file with a static root, and everything fits, plays and edits
correctly.  One JupyterLab server (``test_browser.py``'s) and one browser
window of that size open each lesson in turn, run all its cells and check:

* **fits**: every widget the lesson shows, measured in the DOM as
  ``test_browser_layout.py`` measures the editors: nothing past the right
  edge of its output, no control squeezed to "...", no overlap;
* **plays**: the lesson's 3D view plays (its play button, then the kernel's
  frame moves on) and pauses;
* **edits**: the lesson's widget answers a student's action: lesson 01's
  viewer steps with the arrow keys, 03's path editor drags a handle (the
  handle lands under the mouse), 10's stepper steps (the kernel's step and
  the mean label change), 13's explorer toggles its refinements (the curves'
  data change), 14's and 15's viewers step.

The studio variant runs the same lesson after one added first cell:
``conventions.read_clips_as_studio_files`` makes ``mocaplab.cmu`` hand out
each clip as a BVH file with a static ``joint_Root`` above the travelling
pelvis, read back with ``mocaplab.load`` (lesson 14 is itself about such a
file: it runs once).  There the path editor's pins must lie on the pelvis'
path (issue #28: from a static root they all landed at (0, 0)).

Run: ``pytest -m browser tests/test_browser_laptop.py`` (11 lesson runs, about 260 s).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from browser_support import LessonPage, wait_until
from conventions import STUDIO_CELL
from test_browser import (  # noqa: F401 - fixtures are used by name
    _assert_handle_under_mouse,
    _drag_handle,
    _press_toggle,
    browser,
    lab,
    lesson_or_skip,
    shots_dir,
)
from test_browser_layout import _kernel_value, _open_file_browser, measure

pytestmark = [pytest.mark.browser, pytest.mark.timeout(420)]

#: The laptop: CSS px of the browser window.
LAPTOP = (1366, 768)

#: Per lesson: its widget classes and the kernel name of the 3D viewer that plays.
LESSONS = {
    "01": ("MotionViewer", "viewer"),
    "03": ("PathEditor", "path_editor.viewer"),
    "10": ("TouchUpStepper", "stepper.viewer"),
    "13": ("StaggeredExplorer", "explorer.viewer"),
    "14": ("MotionViewer", "three"),
    "15": ("MotionViewer", "pipeline"),
}


# Tag each widget output of the notebook (its first element) so measure() finds it by class.
_TAG_OUTPUTS_JS = """
() => {
  const roots = Array.from(document.querySelectorAll('.jp-OutputArea-output'))
    .map((out) => out.querySelector('.jupyter-widgets'))  // the outermost: first in document order
    .filter((el) => el);
  roots.forEach((el, k) => el.classList.add('laptop-widget-' + k));
  return roots.length;
}
"""


def _studio_copy(server: Any, notebook: Path) -> str:
    """The lesson with the studio cell first, written beside it in the server's folder; returns its name."""
    nb = json.loads(notebook.read_text())
    cell = {"cell_type": "code", "execution_count": None, "metadata": {}, "outputs": [], "source": ""}
    cell["source"] = STUDIO_CELL
    nb["cells"].insert(0, cell)
    name = f"{notebook.stem}_studio.ipynb"
    (server.root_dir / name).write_text(json.dumps(nb))
    return name


@pytest.fixture(scope="module")
def laptop(browser: Any) -> Iterator[Any]:  # noqa: F811
    context = browser.new_context(viewport={"width": LAPTOP[0], "height": LAPTOP[1]})
    yield context
    context.close()


def _open(server: Any, laptop: Any, shots: Path, number: str, studio: bool) -> LessonPage:
    widget, _ = LESSONS[number]
    notebook = lesson_or_skip(number, widget)
    name = _studio_copy(server, notebook) if studio else notebook.name
    if not studio:
        (server.root_dir / name).write_text(notebook.read_text())  # the lesson as it is now
    lesson = LessonPage(laptop, server, name, shots)
    lesson.open()
    _open_file_browser(lesson)  # open() closes it; a student's JupyterLab has it open
    return lesson


def _assert_fits(lesson: LessonPage) -> int:
    """Every widget output: no overflow, no squeezed control, no overlap (test_browser_layout.measure)."""
    page = lesson.page
    count = page.evaluate(_TAG_OUTPUTS_JS)
    assert count > 0, f"{lesson.notebook}: no widget shown"
    failures = []
    for k in range(count):
        root = page.locator(f".laptop-widget-{k}").first
        root.scroll_into_view_if_needed()
        page.wait_for_timeout(200)
        m = measure(lesson, f"laptop-widget-{k}")
        if m["overflow"] or m["squeezed"] or m["overlap_px2"]:
            lesson.screenshot(f"widget-{k}-does-not-fit", root)
            failures.append(
                f"widget {k}: overflow {m['overflow']} px {m['past_examples']}; squeezed {m['squeezed'][:6]}; "
                f"overlap {m['overlap_px2']} px2 {m['overlaps']}"
            )
    assert not failures, f"{lesson.notebook} at {LAPTOP} with the file browser open:\n" + "\n".join(failures)
    return count


def _edit(lesson: LessonPage, number: str, studio: bool) -> None:
    """The lesson's widget answers a student's action (see the module docstring)."""
    page = lesson.page
    if number in ("01", "14", "15"):
        viewer = LESSONS[number][1]
        lesson.kernel_eval(f"{viewer}.set_frame(0)")
        box = page.locator(".mocaplab-viewer").nth(_viewer_position(lesson, viewer))
        box.scroll_into_view_if_needed()
        box.locator(".widget-button").nth(2).click()  # one frame forward; the keys go to the viewer now
        page.keyboard.press("ArrowRight")
        wait_until(lambda: _kernel_value(lesson, f"{viewer}.frame") == 2, timeout=20, what="the step and the key")
    elif number == "03":
        if studio:  # the pins lie on the pelvis' path, not at the static root
            off = _kernel_value(
                lesson,
                "max(float(np.linalg.norm(np.asarray(c.position) - walk.pelvis_positions[c.frame, [0, 2]]))"
                " for c in path_editor.editor.constraints)",
            )
            assert off < 1e-6, f"the path editor's pins lie {off:.3f} m from the pelvis' path"
        result = _drag_handle(lesson, "path", "PathEditor", (30.0, -20.0))
        _assert_handle_under_mouse(lesson, result, (0, 1))
    elif number == "10":
        mean = page.locator(".mocaplab-touchup-mean").first
        before = mean.text_content()
        page.locator(".mocaplab-touchup-step").first.click()
        wait_until(lambda: _kernel_value(lesson, "stepper.session.index") == 1, timeout=60, what="a step")
        wait_until(lambda: mean.text_content() != before, timeout=30, what="the mean label to change")
    elif number == "13":
        explorer = page.locator(".mocaplab-staggered-explorer").first
        info = explorer.locator(".mocaplab-staggered-curves").first
        before = info.text_content()
        _press_toggle(explorer.locator(".mocaplab-staggered-toggle").first)
        wait_until(lambda: info.text_content() != before, timeout=60, what="the curves to change")


def _viewer_position(lesson: LessonPage, viewer: str) -> int:
    """Index of the kernel's ``viewer`` among the page's ``.mocaplab-viewer`` boxes (tagged from the kernel)."""
    lesson.kernel_eval(f"{viewer}.widget.add_class('laptop-this-viewer')")
    lesson.page.locator(".laptop-this-viewer").first.wait_for(timeout=20000)
    return int(
        lesson.page.evaluate(
            "() => Array.from(document.querySelectorAll('.mocaplab-viewer'))"
            ".indexOf(document.querySelector('.laptop-this-viewer'))"
        )
    )


CASES = [(n, False) for n in LESSONS] + [(n, True) for n in LESSONS if n != "14"]


@pytest.mark.parametrize(("number", "studio"), CASES, ids=[f"{n}-{'studio' if s else 'cmu'}" for n, s in CASES])
def test_lesson_fits_plays_and_edits_on_a_laptop(
    lab: Any,  # noqa: F811
    laptop: Any,
    shots_dir: Path,  # noqa: F811
    number: str,
    studio: bool,
) -> None:
    lesson = _open(lab, laptop, shots_dir, number, studio)
    try:
        seconds = lesson.run_all(timeout=240)
        lesson.wait_idle(settle=1.0)
        widgets = _assert_fits(lesson)
        viewer = LESSONS[number][1]
        index = _viewer_position(lesson, viewer)
        play = lesson.page.locator(".mocaplab-viewer").nth(index).locator(".mocaplab-viewer-play").first
        play.scroll_into_view_if_needed()
        lesson.kernel_eval(f"{viewer}.set_frame(0)")
        play.click()
        wait_until(lambda: _kernel_value(lesson, f"{viewer}.frame") > 5, timeout=30, what=f"{viewer} to play")
        play.click()
        wait_until(lambda: not _kernel_value(lesson, f"{viewer}.playing"), timeout=30, what=f"{viewer} to pause")
        _edit(lesson, number, studio)
        lesson.screenshot("laptop-done")
        assert not lesson.stderr_tracebacks(), lesson.stderr_tracebacks()
        print(f"\n{lesson.notebook} at {LAPTOP[0]}x{LAPTOP[1]}: ran in {seconds:.0f} s, {widgets} widgets fit, plays, edits")
    finally:
        lesson.close()
