"""The lessons work for a person in JupyterLab: end-to-end tests in headless Chromium.

One JupyterLab server (127.0.0.1, random port, random token) serves a
temporary copy of ``lessons/``; Debian's Chromium, driven by Playwright, opens
each widget lesson, runs all its cells, waits for the widget, interacts with
the mouse as a student would, and checks that the kernel received the edit
(labels that only the kernel updates, and the widget's state read back from
the kernel) and that the 3D view changed.  Every state is screenshotted into
``browser-screenshots/`` at the repository root (or ``$MOCAPLAB_SCREENSHOTS``);
the folder is named in the test output.  Console errors mentioning a widget,
the widget manager or a comm fail the test.  The viewer lessons (01 and 05)
also play their 3D view for 3 s and count the distinct pictures it shows
with Chromium's screencast (it must keep changing, at least 3 per second;
15 for one character and 8 for the eight-character relay are aimed at and
printed, the rates are benchmarks/bench_viewer.py's), check the slider's time and frame agree and keep
up with the wall clock, check the layout (a 300 px slider track, toolbar
icons apart, the legend outside the view), and fail on any console error.
Lesson 03's path editor is also undone (Undo brings back the first path and
handles exactly), redone and exported (the BVH file the Export button writes
holds the edited root path, read back with ``mocaplab.io.load_bvh``).

The server is started with ``MOCAPLAB_JUPYTER_BACKEND=client`` so the 3D
view is the one a student gets (drawn by the browser in a trame iframe), not
the static image of the nbval runs; lesson 01 also shows its walk with the
server-rendering fallback (``backend="server"``).  A lesson (or widget) that has not landed yet is skipped with
a reason naming the missing piece.

Run: ``pytest -m browser tests/test_browser.py`` (needs ``/usr/bin/chromium``;
outside CI the module is skipped when it is missing).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from browser_support import (
    CHROMIUM,
    JupyterLabServer,
    LessonPage,
    copy_lessons,
    image_change,
    image_std,
    kernel_pid,
    launch_chromium,
    play_viewer,
    png_to_grey,
    server_env,
    traced_pictures,
    wait_until,
)

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[1]
# MOCAPLAB_BROWSER_LESSONS points the suite at another lesson folder (to debug a draft).
LESSONS = Path(os.environ.get("MOCAPLAB_BROWSER_LESSONS", ROOT / "lessons")).resolve()
WIDGETS = ROOT / "widgets"

# A rendered 3D view "is not blank" when its grey levels vary at least this much.
MIN_VIEW_STD = 4.0
# A view "changed" when the mean absolute grey difference of two screenshots exceeds this.
MIN_CHANGE = 0.3

if not Path(CHROMIUM).exists():
    if os.environ.get("CI"):
        raise RuntimeError(f"browser tests need Chromium at {CHROMIUM} (apt-get install chromium)")
    pytest.skip(f"Chromium not found at {CHROMIUM} (apt-get install chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright Python package is not installed")


# ---------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def shots_dir(pytestconfig: pytest.Config) -> Iterator[Path]:
    """Folder for the screenshots, named in the test output (each lesson's old ones are removed when it opens)."""
    folder = Path(os.environ.get("MOCAPLAB_SCREENSHOTS", ROOT / "browser-screenshots")).resolve()
    if folder in (ROOT, LESSONS, ROOT / "tests"):
        raise ValueError(f"MOCAPLAB_SCREENSHOTS must be a folder of its own, got {folder}")
    folder.mkdir(parents=True, exist_ok=True)
    reporter = pytestconfig.pluginmanager.get_plugin("terminalreporter")

    capture = pytestconfig.pluginmanager.get_plugin("capturemanager")

    def say(text: str) -> None:
        if reporter is None or capture is None:  # pragma: no cover - pytest without its terminal
            print(text)
            return
        with capture.global_and_fixture_disabled():
            reporter.write_line(text)

    say(f"\nbrowser screenshots: {folder}")
    yield folder
    say(f"\nbrowser screenshots written to {folder}: {len(list(folder.glob('*.png')))} files")


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[JupyterLabServer]:
    """A JupyterLab server on a copy of lessons/, always stopped by process id afterwards."""
    if not LESSONS.is_dir():
        pytest.skip("no lessons/ folder")
    base = tmp_path_factory.mktemp("browser")
    root = copy_lessons(LESSONS, base / "lessons")
    server = JupyterLabServer(root, env=server_env(os.environ.get("MOCAPLAB_DATA_DIR")), state_dir=base / "state")
    try:
        server.start()
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_api.sync_playwright() as playwright:
        chromium = launch_chromium(playwright)
        try:
            yield chromium
        finally:
            chromium.close()


_TRACEBACKS: dict[str, list[str]] = {}


@pytest.fixture
def open_lesson(request: pytest.FixtureRequest) -> Iterator[Any]:
    """``open_lesson("03", "PathEditor")`` opens that lesson in a fresh page, or skips naming what is missing.

    The server and browser start only once a lesson is found. The page is
    screenshotted and closed (its kernel shut down) after the test, and any
    traceback printed in a cell's output is recorded for
    :func:`test_no_tracebacks_in_lesson_outputs`.
    """
    pages: list[LessonPage] = []
    contexts: list[Any] = []

    def opener(number: str, *needs: str) -> LessonPage:
        notebook = lesson_or_skip(number, *needs)
        lab = request.getfixturevalue("lab")
        shutil.copy2(notebook, lab.root_dir / notebook.name)  # the lesson as it is now (it may have landed late)
        browser = request.getfixturevalue("browser")
        shots = request.getfixturevalue("shots_dir")
        context = browser.new_context(viewport={"width": 1800, "height": 1100})
        contexts.append(context)
        for old in shots.glob(f"{notebook.stem}-*.png"):  # this lesson's screenshots of an earlier run
            old.unlink()
        page = LessonPage(context, lab, notebook.name, shots)
        pages.append(page)
        page.open()
        return page

    yield opener
    for page in pages:
        try:
            page.screenshot("final")
            _TRACEBACKS[page.notebook] = page.stderr_tracebacks()
        except Exception:  # noqa: BLE001 - evidence only; the page may be gone
            pass
        page.close()
    for context in contexts:
        context.close()


def lesson_or_skip(number: str, *needs: str) -> Path:
    """The lesson ``NN_*.ipynb``; skip naming the missing piece if it or a needed widget is absent.

    ``needs`` are widget class names the lesson must display (their module
    must exist in ``widgets/`` and the notebook must mention the class).
    """
    found = sorted(LESSONS.glob(f"{number}_*.ipynb"))
    modules = {
        "MotionViewer": "viewer.py",
        "PathEditor": "path_editor.py",
        "TimeTrackEditor": "time_track.py",
        "TouchUpStepper": "touchup.py",
        "StaggeredExplorer": "staggered.py",
    }
    for name in needs:
        if not (WIDGETS / modules[name]).exists():
            pytest.skip(f"widget {name} (widgets/{modules[name]}) has not landed yet")
    if not found:
        pytest.skip(f"lesson {number} (lessons/{number}_*.ipynb) has not landed yet")
    text = found[0].read_text()
    for name in needs:
        if name not in text:
            pytest.skip(f"lesson {found[0].name} does not display {name} yet")
    return found[0]


# ---------------------------------------------------------------- 3D view
def trame_frame(scope: Any) -> Any:
    """The first pyvista trame iframe inside ``scope`` (a locator or page)."""
    return scope.locator("iframe.pyvista").first


def rendered_view(lesson: LessonPage, iframe: Any, *, timeout: float = 60.0) -> tuple[Any, bytes]:
    """Wait until the trame view in ``iframe`` shows a finished, non-blank render.

    Returns the locator of the render surface (the largest visible ``img`` or
    ``canvas`` in the iframe) and its pixels (:func:`view_pixels`), once two
    polls in a row agree and :func:`looks_rendered` accepts them (varied grey
    levels below the toolbar band, not a mostly black frame).
    """
    iframe.wait_for(state="attached", timeout=timeout * 1000)
    iframe.scroll_into_view_if_needed()
    frame = iframe.content_frame
    deadline = time.monotonic() + timeout
    png, previous = b"", None
    while time.monotonic() < deadline:
        surface = _largest_surface(frame)
        if surface is not None:
            png = view_pixels(surface)
            if previous is not None and looks_rendered(png) and view_change(previous, png) < 0.05:
                return surface, png
            previous = png
        lesson.page.wait_for_timeout(400)
    path = lesson.screenshot("unrendered-3d-view", iframe)
    detail = ""
    if png:
        grey = png_to_grey(png)
        detail = f" (last frame: {100 * float((grey < 16).mean()):.0f}% black, grey std {float(grey.std()):.1f})"
    raise AssertionError(f"the 3D view did not show a finished render within {timeout:.0f} s{detail}; see {path}")


def view_pixels(surface: Any) -> bytes:
    """A screenshot of a 3D view's render surface (what the student sees)."""
    return surface.screenshot()


def view_change(before: bytes, after: bytes) -> float:
    """Mean grey change of two view screenshots below the toolbar band (top 20%) overlaid on the view."""
    a, b = png_to_grey(before), png_to_grey(after)
    h, w = min(a.shape[0], b.shape[0]), min(a.shape[1], b.shape[1])
    top = h // 5
    return float(np.abs(a[top:h, :w] - b[top:h, :w]).mean())


def _largest_surface(frame: Any) -> Any:
    best, area = None, 0.0
    for selector in ("img", "canvas"):
        items = frame.locator(selector)
        for i in range(items.count()):
            item = items.nth(i)
            try:
                if not item.is_visible():
                    continue
                box = item.bounding_box()
            except Exception:  # noqa: BLE001 - element replaced while we look
                continue
            if box and box["x"] > -box["width"] and box["width"] * box["height"] > area:
                best, area = item, box["width"] * box["height"]
    return best if area > 100 * 100 else None


def looks_rendered(png: bytes) -> bool:
    """A finished render: varied grey levels (below the toolbar band), not a black loading frame."""
    grey = png_to_grey(png)
    body = grey[grey.shape[0] // 5 :]
    return float(body.std()) > MIN_VIEW_STD and float((grey < 16).mean()) < 0.5


def wait_view_change(
    lesson: LessonPage, surface_of: Any, before: bytes, *, timeout: float = 30.0
) -> tuple[bytes, float]:
    """Poll the pixels of ``surface_of()`` until they show a finished render different from ``before``.

    A frame counts once it looks rendered (:func:`looks_rendered`) and the
    next poll shows the same image (the view has settled: no loading or
    low-resolution interactive frame). Returns the last pixels and their
    change (0 when no settled, rendered frame was seen; the last frame is then
    saved as ``<lesson>-NN-unrendered-view.png`` for the report).
    """
    deadline = time.monotonic() + timeout
    png, previous = before, None
    while time.monotonic() < deadline:
        lesson.page.wait_for_timeout(400)
        try:
            png = view_pixels(surface_of())
        except Exception:  # noqa: BLE001 - the view may be rebuilding
            previous = None
            continue
        settled = previous is not None and view_change(previous, png) < 0.05
        previous = png
        if not looks_rendered(png) or not settled:
            continue
        change = view_change(before, png)
        if change > MIN_CHANGE:
            return png, change
    if not looks_rendered(png):
        lesson._n_shots += 1
        path = lesson.shots / f"{Path(lesson.notebook).stem}-{lesson._n_shots:02d}-unrendered-view.png"
        path.write_bytes(png)
        grey = png_to_grey(png)
        raise AssertionError(
            f"the 3D view never showed a finished render within {timeout:.0f} s "
            f"(last frame: {100 * float((grey < 16).mean()):.0f}% black, grey std {float(grey.std()):.1f}; saved {path})"
        )
    return png, view_change(before, png)


def mouse_drag(page: Any, start: tuple[float, float], end: tuple[float, float], *, steps: int = 12) -> None:
    """Press at ``start``, move in ``steps`` to ``end``, release (page CSS pixels)."""
    page.mouse.move(*start)
    page.mouse.down()
    for k in range(1, steps + 1):
        s = k / steps
        page.mouse.move(start[0] + s * (end[0] - start[0]), start[1] + s * (end[1] - start[1]))
        page.wait_for_timeout(30)
    page.mouse.up()


def assert_no_widget_errors(lesson: LessonPage) -> None:
    errors = lesson.widget_errors()
    assert not errors, f"{lesson.notebook}: widget-manager errors in the browser console: {errors}"


def set_slider(slider: Any, value: float | int) -> None:
    """Type a value into an ipywidgets slider's editable readout (as a person can)."""
    readout = slider.locator(".widget-readout")
    readout.click()
    readout.press("Control+a")
    readout.type(str(value))
    readout.press("Enter")


def text_of(locator: Any) -> str:
    return (locator.text_content() or "").strip()


# ---------------------------------------------------------------- lessons
def test_lesson_01_viewer_renders_and_is_interactive(open_lesson: Any) -> None:
    lesson = open_lesson("01", "MotionViewer")
    seconds = lesson.run_all()
    page = lesson.page
    iframe = trame_frame(page)
    surface, first = rendered_view(lesson, iframe)
    lesson.screenshot("viewer", iframe)
    assert image_std(first) > MIN_VIEW_STD

    # rotate the camera with the mouse: the kernel re-renders and streams a new image
    box = surface.bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] * 0.6
    mouse_drag(page, (cx, cy), (cx + 0.3 * box["width"], cy - 0.1 * box["height"]))
    rotated, change = wait_view_change(lesson, lambda: _largest_surface(iframe.content_frame), first)
    lesson.screenshot("viewer-rotated", iframe)
    print(f"3D view mean grey change after rotating: {change:.2f}")
    assert change > MIN_CHANGE, f"dragging in the 3D view did not change it (mean change {change:.3f})"

    # move the frame slider: the kernel moves the skeleton and shows the frame's time on the slider
    viewer_box = page.locator(".mocaplab-viewer").last
    slider = viewer_box.locator(".mocaplab-viewer-slider").first
    time_shown = slider.locator(".widget-label").first
    before = text_of(time_shown)
    set_slider(slider, 40)
    page.wait_for_function(
        "([el, before]) => el.textContent.trim() !== before",
        arg=[time_shown.element_handle(), before],
        timeout=30000,
    )
    moved, change = wait_view_change(lesson, lambda: _largest_surface(iframe.content_frame), rotated)
    lesson.screenshot("viewer-frame-40", viewer_box)
    print(f"3D view mean grey change after moving the frame slider: {change:.2f}")
    assert change > MIN_CHANGE, f"moving the frame slider did not change the 3D view (mean change {change:.3f})"
    assert text_of(time_shown) == f"{40 / 120:.3f} s", f"the slider's time did not follow it: {text_of(time_shown)!r}"
    assert_viewer_layout(viewer_box)

    # play: real time, as many distinct pictures as the target, slider and time in agreement
    played = play_measured(lesson, "viewer", PLAY_TARGETS["01"])
    lesson.screenshot("viewer-played", viewer_box)
    assert_plays_in_real_time(played, PLAY_TARGETS["01"])
    assert_no_console_errors(lesson)
    print(f"lesson 01 ran in {seconds:.1f} s in JupyterLab")


def test_lesson_05_relay_plays_in_real_time(open_lesson: Any) -> None:
    """Eight characters: the relay viewer plays at the target rate; the path editor's narrow view fits its toolbar."""
    lesson = open_lesson("05", "MotionViewer")
    lesson.run_all()
    page = lesson.page
    views = page.locator(".mocaplab-viewer")
    for i in range(views.count()):
        view = views.nth(i)
        rendered_view(lesson, trame_frame(view))
        lesson.screenshot(f"viewer-{i}", view)
        assert_viewer_layout(view)
    played = play_measured(lesson, "relay_viewer", PLAY_TARGETS["05"])
    lesson.screenshot("relay-played", played["box"])
    legend = played["box"].locator(".mocaplab-viewer-legend").first
    # the legend is grouped: each clip once, after its characters' dots, with their count
    assert legend.is_visible() and "16_15 ×4" in text_of(legend) and text_of(legend).count("●") == 8, (
        f"legend: {text_of(legend)!r}"
    )
    assert_plays_in_real_time(played, PLAY_TARGETS["05"])
    assert_no_console_errors(lesson)


@pytest.mark.parametrize("backend", ["client", "server"])
def test_lesson_01_viewer_with_each_backend(open_lesson: Any, backend: str) -> None:
    """Drawn by the browser ("client": the kernel draws no picture) or by the kernel ("server", the fallback):
    rotating, the slider and play change the picture and the slider follows the play."""
    lesson = open_lesson("01", "MotionViewer")
    lesson.run_all()
    page = lesson.page
    lesson.run_cell(
        f"client_viewer = MotionViewer(walk, backend={backend!r})\n"
        "client_viewer.add_lines('root path', walk.root_positions * [1, 0, 1], color='gray')\n"
        "client_viewer.widget.add_class('mocaplab-client-viewer')\n"
        "client_viewer"
    )
    box = page.locator(".mocaplab-client-viewer").first
    box.scroll_into_view_if_needed()
    iframe = trame_frame(box)
    assert "secret=" in (iframe.get_attribute("src") or ""), "the page gets the kernel's trame secret"
    surface, first = rendered_view(lesson, iframe)
    tag = surface.evaluate("(el) => el.tagName")
    assert tag == ("CANVAS" if backend == "client" else "IMG"), f"the view's surface is a {tag}"
    lesson.screenshot(f"{backend}-viewer", box)
    assert image_std(first) > MIN_VIEW_STD

    rect = surface.bounding_box()
    cx, cy = rect["x"] + rect["width"] / 2, rect["y"] + rect["height"] * 0.6
    mouse_drag(page, (cx, cy), (cx + 0.3 * rect["width"], cy - 0.1 * rect["height"]))
    rotated, change = wait_view_change(lesson, lambda: _largest_surface(iframe.content_frame), first)
    lesson.screenshot(f"{backend}-viewer-rotated", box)
    assert change > MIN_CHANGE, f"dragging in the browser-drawn view did not change it (mean change {change:.3f})"

    slider = box.locator(".mocaplab-viewer-slider").first
    set_slider(slider, 200)
    moved, change = wait_view_change(lesson, lambda: _largest_surface(iframe.content_frame), rotated)
    lesson.screenshot(f"{backend}-viewer-frame-200", box)
    assert change > MIN_CHANGE, f"moving the frame slider did not change the browser-drawn view ({change:.3f})"

    pid = kernel_pid(lesson)
    played = play_viewer(lesson, "client_viewer", seconds=PLAY_SECONDS, pid=pid)
    print(
        f"{backend}: {played['pictures_per_s']:.1f} pictures/s, kernel {played['kernel_cpu_percent']:.1f} % "
        f"of a core, {played['kernel_pictures_per_s']:.1f} kernel pictures/s"
    )
    assert played["pictures_per_s"] >= MIN_PLAY_RATE, f"the picture hardly changed while playing: {played}"
    if backend == "client":
        assert played["kernel_pictures_per_s"] == 0, "the kernel drew pictures while the browser played"
    else:
        assert played["kernel_pictures_per_s"] > 3, "the kernel drew no pictures while playing"
    pairs = played["label_slider"]
    assert len(pairs) >= 3 and all(a == b for a, b in pairs), f"slider time and frame during play: {pairs}"
    assert len({b for _, b in pairs}) >= 3, f"the slider did not follow the play: {pairs}"
    assert played["max_lag_s"] < 0.6, f"the time shown lagged the wall clock by {played['max_lag_s']:.2f} s"
    if backend == "client":
        # the trace's count of new pictures on the display (bench_viewer judges its targets on it): pictures
        # reach the display while the browser plays, none while it is stopped
        traced = traced_pictures(lesson, "client_viewer", seconds=1.5)
        assert traced["pictures_per_s"] is not None and traced["pictures_per_s"] >= MIN_PLAY_RATE, traced
        lesson.kernel_eval("client_viewer.stop_playback(); client_viewer.set_frame(0)")
        still = traced_pictures(lesson, "client_viewer", seconds=1.0, play=False)
        assert still["new_pictures"] == 0, f"pictures drawn while stopped: {still}"
    if backend == "client":  # cylinders and spheres for a few characters, stick figures for a crowd
        page_frame = iframe.element_handle().content_frame()
        assert _drawn_sets(page_frame) == ["mocaplab-bones", "mocaplab-joints"], _drawn_sets(page_frame)
        lesson.kernel_eval("client_viewer.set_motions([walk] * 9)")
        wait_until(
            lambda: _drawn_sets(page_frame) == ["mocaplab-sticks"], timeout=30, what="nine walkers drawn as sticks"
        )
        sticks, change = wait_view_change(lesson, lambda: _largest_surface(iframe.content_frame), moved)
        lesson.screenshot(f"{backend}-viewer-sticks", box)
        assert change > MIN_CHANGE and image_std(sticks) > MIN_VIEW_STD, f"nine walkers' sticks not shown ({change:.3f})"
        lesson.kernel_eval("client_viewer.set_motions([walk])")  # and back: every set was kept mounted
        wait_until(
            lambda: _drawn_sets(page_frame) == ["mocaplab-bones", "mocaplab-joints"],
            timeout=30,
            what="one walker drawn with cylinders and spheres again",
        )
        # a browser that cannot draw the play fast enough draws it with fewer pixels, sharp again when stopped
        # (asked for an impossible rate here, as a slow one would see it)
        full = _canvas_sizes(page_frame)
        page_frame.evaluate("() => { window.trame.utils.mocaplab.targetRate = 1e6; }")
        lesson.kernel_eval("client_viewer.set_frame(0); client_viewer.toggle_playback()")
        reduced = wait_until(
            lambda: (lambda now: now if now[0][0] < 0.6 * full[0][0] else None)(_canvas_sizes(page_frame)),
            timeout=20,
            what="the play drawn with fewer pixels",
        )
        lesson.kernel_eval("client_viewer.stop_playback()")
        wait_until(lambda: _canvas_sizes(page_frame) == full, timeout=20, what="full resolution once stopped")
        page_frame.evaluate("() => { window.trame.utils.mocaplab.targetRate = 30; }")
        assert reduced[0][0] >= 0.5 * full[0][0] - 1, (reduced, full)  # never below PLAY_MIN_RATIO
    assert_no_console_errors(lesson)
    lesson.kernel_eval("client_viewer.close()")


def _canvas_sizes(frame: Any) -> list[list[int]]:
    """The drawing size (canvas pixels) of each vtk.js view of the browser-drawn page."""
    return frame.evaluate(
        """() => Object.values(window.trame.refs)
                 .map((ref) => ref && ref.$ && ref.$.provides && ref.$.provides.view)
                 .filter((view) => view && view.openglRenderWindow)
                 .map((view) => view.openglRenderWindow.getSize().slice())"""
    )


def _drawn_sets(frame: Any) -> list[str]:
    """The ids of the crowd's sets the browser-drawn view draws (bones, joints, sticks: visible, with points
    and, for the sticks, lines), sorted."""
    return sorted(
        frame.evaluate(
            """() => {
                 const out = [];
                 for (const ref of Object.values(window.trame.refs)) {
                   const view = ref && ref.$ && ref.$.provides && ref.$.provides.view;
                   if (!view) continue;
                   for (const actor of view.renderer.getActors()) {
                     const id = String(actor.get("representationId").representationId || "");
                     const data = actor.getMapper() && actor.getMapper().getInputData(0);
                     const drawn = actor.getVisibility() && data && data.getNumberOfPoints() > 0
                       && (id !== "mocaplab-sticks" || data.getLines().getNumberOfCells() > 0);
                     if (drawn && id.indexOf("mocaplab-") === 0 && id.indexOf("overlay") < 0) out.push(id);
                   }
                 }
                 return out;
               }"""
        )
    )


# Distinct pictures per second of play aimed at in headless Chromium with software GL: a second try is
# made below them (printed; the rates themselves are measured by benchmarks/bench_viewer.py).  The tests
# check behaviour: the picture keeps changing while playing (MIN_PLAY_RATE; a view stuck on one picture,
# or updated only by the 0.5 s re-send of trame's server rendering, shows 0-2 per second).
PLAY_TARGETS = {"01": 15.0, "05": 8.0}
MIN_PLAY_RATE = 3.0
PLAY_SECONDS = 3.0


def play_measured(lesson: LessonPage, var: str, target: float) -> dict[str, Any]:
    """Play the viewer ``var`` for 3 s (:func:`browser_support.play_viewer`); once more if below ``target``.

    The second try is for a machine busy with other work during the first
    (the CI machine is shared by the whole suite); the viewer before this
    test showed 0-2 pictures per second, far from any try.
    """
    played = play_viewer(lesson, var, seconds=PLAY_SECONDS)
    cost = played["kernel_cost_ms"]  # None when the browser draws
    print(
        f"{var}: {played['pictures_per_s']:.1f} pictures/s (kernel {played['kernel_pictures_per_s']:.1f}/s"
        f"{'' if cost is None else f' at {cost:.1f} ms'}), largest label lag {played['max_lag_s']:.3f} s"
    )
    if played["pictures_per_s"] < target:
        again = play_viewer(lesson, var, seconds=PLAY_SECONDS)
        print(f"{var} again: {again['pictures_per_s']:.1f} pictures/s")
        if again["pictures_per_s"] > played["pictures_per_s"]:
            played = again
    return played


def assert_plays_in_real_time(played: dict[str, Any], target: float) -> None:
    rate = played["pictures_per_s"]
    assert rate >= MIN_PLAY_RATE, (
        f"the 3D view showed {rate:.1f} distinct pictures per second of play (aim {target:g}): it hardly changed"
    )
    pairs = played["label_slider"]
    assert len(pairs) >= 3, f"too few reads of the slider during play: {pairs}"
    assert all(a == b for a, b in pairs), f"the slider's time and frame disagreed during play: {pairs}"
    # the time shown trails the wall clock by the click's trip to the kernel and one slider update (1/8 s)
    assert played["max_lag_s"] < 0.6, f"the time shown lagged the wall clock by {played['max_lag_s']:.2f} s"
    state = played["state"]  # read in the kernel right after the 3 s
    expected = min(PLAY_SECONDS, (state["n_frames"] - 1) / state["fps"])
    assert state["time"] >= expected - 0.5, (
        f"after {PLAY_SECONDS:g} s of play the viewer is at {state['time']:.2f} s, behind the wall clock ({expected:.2f} s)"
    )


def assert_viewer_layout(view: Any) -> None:
    """A slider track of at least 300 px, the toolbar's icons apart, the legend outside the 3D view."""
    track = view.locator(".mocaplab-viewer-slider .slider-container").first
    width = track.bounding_box()["width"]
    assert width >= 300, f"the frame slider's track is {width:.0f} px wide"
    iframe = trame_frame(view)
    frame = iframe.content_frame
    buttons = frame.locator(".v-card .v-btn:visible, .v-card .v-selection-control:visible")
    boxes = [b for b in (buttons.nth(i).bounding_box() for i in range(buttons.count())) if b]
    for a, b in zip(boxes, boxes[1:], strict=False):
        assert a["x"] + a["width"] <= b["x"] + 1 or abs(a["y"] - b["y"]) > a["height"] / 2, (
            f"toolbar icons overlap: {a} and {b}"
        )
    view_box = iframe.bounding_box()  # the iframe's items are measured in the page's viewport too
    for b in boxes:
        assert b["x"] + b["width"] <= view_box["x"] + view_box["width"] + 1, f"a toolbar icon sticks out: {b}"
    legend = view.locator(".mocaplab-viewer-legend").first
    if legend.is_visible():
        lb = legend.bounding_box()
        assert lb["y"] >= view_box["y"] + view_box["height"] - 1, "the legend overlaps the 3D view"


def assert_no_console_errors(lesson: LessonPage) -> None:
    """No error at all in the browser console (the trame page's POST to .../paraview/ used to log a 405)."""
    assert not lesson.console and not lesson.page_errors, f"{lesson.notebook}: console errors {lesson.console}"


# The kernel side of a drag view: find the displayed instance by its handles, map pixels to data.
_KERNEL_FIND = """
import json as _j
_found = None
for _name, _obj in list(globals().items()):
    if type(_obj).__name__ == {cls!r} and not _name.startswith("_"):
        if [h["data"] for h in _obj.handle_positions()] == _j.loads({data!r}):
            _found = _name
            break
print("@@json@@" + _j.dumps(_found))
del _j, _found
"""

_KERNEL_PIXEL_TO_DATA = """
import json as _j
_w = {name}
_ratio = float(getattr(_w.canvas, "device_pixel_ratio", 1.0) or 1.0)
_h = _w.figure.bbox.height
_inv = _w.ax.transData.inverted()
_px = [({x} * _ratio, _h - {y} * _ratio), ({x} + 1.0) * _ratio, _h - ({y} + 1.0) * _ratio]
_a = _inv.transform(_px[0])
_b = _inv.transform((_px[1], _px[2]))
print("@@json@@" + _j.dumps({{"data": [float(v) for v in _a], "per_px": [abs(float(v)) for v in (_b - _a)]}}))
del _j, _w, _ratio, _h, _inv, _px, _a, _b
"""

_KERNEL_HANDLES = """
import json as _j
print("@@json@@" + _j.dumps({name}.handle_positions()))
del _j
"""


def _kernel_json(lesson: LessonPage, code: str) -> Any:
    """Run ``code`` in the kernel and decode the line it prints after the ``@@json@@`` marker.

    The marker keeps the answer apart from anything a background task of the
    kernel (a trame server, say) prints meanwhile.
    """
    out = lesson.kernel_eval(code)
    found = [line[len("@@json@@") :] for line in out.splitlines() if line.startswith("@@json@@")]
    assert found, f"kernel said {out!r} to:\n{code}"
    return json.loads(found[-1])


def _drag_handle(lesson: LessonPage, prefix: str, class_name: str, offset: tuple[float, float]) -> dict[str, Any]:
    """Drag the first handle of the ``mocaplab-{prefix}-*`` editor by ``offset`` CSS pixels.

    Before the drag, the kernel names the displayed instance (the one whose
    handles are those published in the page) and tells which data point lies
    under the release pixel. Returns the instance name, the handle before, the
    expected data under the release point (with data units per pixel), and the
    status text before and after.
    """
    page = lesson.page
    editor = page.locator(f".mocaplab-{prefix}-editor").first
    editor.wait_for(timeout=60000)
    canvas = editor.locator(f".mocaplab-{prefix}-canvas").first.locator(".jupyter-matplotlib-canvas-div canvas").last
    canvas.wait_for(timeout=60000)
    canvas.scroll_into_view_if_needed()
    status = editor.locator(f".mocaplab-{prefix}-status").first
    info = editor.locator(f".mocaplab-{prefix}-handles").first
    handles = json.loads(info.text_content() or "[]")
    if not handles:
        raise AssertionError(f"the {prefix} editor of {lesson.notebook} shows no handle to drag")
    handle = handles[0]
    name = _kernel_json(lesson, _KERNEL_FIND.format(cls=class_name, data=json.dumps([h["data"] for h in handles])))
    assert name, f"no {class_name} in the kernel has the handles shown in the page: {handles}"
    release = (handle["css"][0] + offset[0], handle["css"][1] + offset[1])
    expected = _kernel_json(lesson, _KERNEL_PIXEL_TO_DATA.format(name=name, x=release[0], y=release[1]))
    before = text_of(status)

    box = canvas.bounding_box()
    page.mouse.move(box["x"] + handle["css"][0], box["y"] + handle["css"][1])
    page.wait_for_timeout(200)
    box = canvas.bounding_box()  # measured again once the page is still under the mouse
    start = (box["x"] + handle["css"][0], box["y"] + handle["css"][1])
    mouse_drag(page, start, (box["x"] + release[0], box["y"] + release[1]))
    page.wait_for_function(
        "([el, before]) => el.textContent.trim() !== before && /moved/.test(el.textContent)",
        arg=[status.element_handle(), before],
        timeout=60000,
    )
    page.wait_for_timeout(300)
    return {
        "name": name,
        "handle": handle,
        "expected": expected,
        "before": before,
        "after": text_of(status),
        "handles_after": json.loads(info.text_content() or "[]"),
    }


def _assert_handle_under_mouse(lesson: LessonPage, result: dict[str, Any], axes: tuple[int, ...]) -> dict[str, Any]:
    """The kernel's handle lies (within 4 px) on the data point that was under the mouse at release."""
    kernel = _kernel_json(lesson, _KERNEL_HANDLES.format(name=result["name"]))
    moved = next(h for h in kernel if h["index"] == result["handle"]["index"])
    for axis in axes:
        miss_px = abs(moved["data"][axis] - result["expected"]["data"][axis]) / result["expected"]["per_px"][axis]
        assert miss_px < 4, (
            f"kernel handle at {moved['data']}, the mouse was released over {result['expected']['data']} "
            f"(axis {axis} off by {miss_px:.1f} px)"
        )
    # the page shows the handles the kernel has
    page_handles = {h["index"]: h["data"] for h in result["handles_after"]}
    assert page_handles.get(moved["index"]) == moved["data"], (page_handles, moved)
    return moved


def test_lesson_03_drag_a_path_handle(open_lesson: Any) -> None:
    lesson = open_lesson("03", "PathEditor")
    lesson.run_all()
    page = lesson.page
    editor = page.locator(".mocaplab-path-editor").first
    editor.wait_for(timeout=60000)
    iframe = trame_frame(editor)
    _, view_before = rendered_view(lesson, iframe)
    src_before = iframe.get_attribute("src")
    lesson.screenshot("path-editor-before", editor)

    result = _drag_handle(lesson, "path", "PathEditor", (70.0, -45.0))
    lesson.screenshot("path-editor-dragged", editor)
    after = result["after"]
    target = re.search(r"target \(x, z\) = \(([-\d.]+), ([-\d.]+)\)", after)
    assert target, f"status label shows no target position after the drag: {after!r}"
    residual = re.search(r"residual ([-+\d.e]+)", after)
    assert residual, f"status label shows no residual after the drag: {after!r}"

    # the kernel holds the handle where the mouse let go, and the label reports it
    moved = _assert_handle_under_mouse(lesson, result, axes=(0, 1))
    assert [float(target.group(1)), float(target.group(2))] == pytest.approx(moved["data"], abs=2e-3)
    assert moved["data"] != result["handle"]["data"]

    # the 3D view shows the edited motion (the viewer may be rebuilt on release)
    def surface() -> Any:
        return _largest_surface(trame_frame(page.locator(".mocaplab-path-editor").first).content_frame)

    rendered_view(lesson, trame_frame(editor))
    _, change = wait_view_change(lesson, surface, view_before, timeout=45)
    lesson.screenshot("path-editor-3d-after", editor)
    print(f"3D view mean grey change after the path edit: {change:.2f}")
    assert change > MIN_CHANGE, (
        f"the 3D view did not change after the path edit (mean change {change:.3f}; "
        f"iframe src {src_before} -> {trame_frame(editor).get_attribute('src')})"
    )
    assert_no_widget_errors(lesson)


_KERNEL_PATHS = """
import json as _j
_r = {name}.editor.result
print("@@json@@" + _j.dumps({{"paths": [_p.tolist() for _p in _r.paths],
    "motion": [_m.pelvis_positions[:, [0, 2]].tolist() for _m in _r.motions],
    "n": len({name}.editor.constraints)}}))
del _j, _r
"""


def _published_handles(info: Any) -> list[Any]:
    return [h["data"] for h in json.loads(info.text_content() or "[]")]


def _wait_handles(page: Any, info: Any, want: list[Any], what: str) -> None:
    """Wait until the page publishes handles at ``want`` (data coordinates, exactly)."""
    page.wait_for_function(
        "([el, want]) => JSON.stringify(JSON.parse(el.textContent || '[]').map(h => h.data)) === want",
        arg=[info.element_handle(), json.dumps(want, separators=(",", ":"))],
        timeout=60000,
    )
    assert _published_handles(info) == want, what


def test_lesson_03_undo_and_export_in_the_path_editor(open_lesson: Any, tmp_path: Path) -> None:
    """Drag, then Undo restores the first path and handles; Redo, then Export writes the edited walk as BVH."""
    from mocaplab.io import load_bvh

    lesson = open_lesson("03", "PathEditor")
    lesson.run_all()
    page = lesson.page
    editor = page.locator(".mocaplab-path-editor").first  # by its class: lessons gain cells
    editor.wait_for(timeout=60000)
    info = editor.locator(".mocaplab-path-handles").first
    first_handles = _published_handles(info)
    name = _kernel_json(lesson, _KERNEL_FIND.format(cls="PathEditor", data=json.dumps(first_handles)))
    assert name, f"no PathEditor in the kernel has the handles shown: {first_handles}"
    first = _kernel_json(lesson, _KERNEL_PATHS.format(name=name))
    undo = editor.locator(".mocaplab-undo").first
    redo = editor.locator(".mocaplab-redo").first
    assert undo.is_disabled() and redo.is_disabled(), "nothing to undo before any edit"

    result = _drag_handle(lesson, "path", "PathEditor", (70.0, -45.0))
    assert result["name"] == name
    dragged_handles = _published_handles(info)
    dragged = _kernel_json(lesson, _KERNEL_PATHS.format(name=name))
    assert dragged_handles != first_handles and dragged["paths"] != first["paths"]
    lesson.screenshot("path-editor-before-undo", editor)

    page.wait_for_function("(el) => !el.disabled", arg=undo.element_handle(), timeout=30000)
    undo.click()
    _wait_handles(page, info, first_handles, "Undo did not bring the handles back")
    lesson.wait_idle()
    lesson.screenshot("path-editor-undone", editor)
    back = _kernel_json(lesson, _KERNEL_PATHS.format(name=name))
    assert back["paths"] == first["paths"], "Undo did not restore the first path exactly"
    assert back["n"] == first["n"]
    status = text_of(editor.locator(".mocaplab-path-status").first)
    assert status.startswith("undid: ") and " at frame " in status, f"status after Undo: {status!r}"
    page.wait_for_function("(el) => el.disabled", arg=undo.element_handle(), timeout=30000)

    redo.click()
    _wait_handles(page, info, dragged_handles, "Redo did not bring the dragged handles back")
    lesson.wait_idle()
    target = tmp_path / "edited_walk.bvh"
    box = editor.locator(".mocaplab-export-path input").first
    box.fill(str(target))
    box.press("Tab")
    page.wait_for_timeout(300)
    editor.locator(".mocaplab-export").first.click()
    label = editor.locator(".mocaplab-export-status").first
    page.wait_for_function("(el) => /wrote/.test(el.textContent)", arg=label.element_handle(), timeout=60000)
    lesson.screenshot("path-editor-exported", editor)
    assert target.exists(), f"Export did not write {target}; label {text_of(label)!r}"
    written = load_bvh(target, scale=0.01)
    edited = np.asarray(_kernel_json(lesson, _KERNEL_PATHS.format(name=name))["motion"][0])
    path = written.pelvis_positions[:, [0, 2]]
    assert path.shape == edited.shape
    assert np.abs(path - edited).max() < 1e-4, "the file's root path is not the edited one"
    original = np.asarray(first["motion"][0])
    assert np.abs(path - original).max() > 0.05, "the file holds the input walk, not the edited one"
    assert_no_widget_errors(lesson)
    assert_no_console_errors(lesson)


def test_lesson_04_drag_a_time_handle(open_lesson: Any) -> None:
    lesson = open_lesson("04", "TimeTrackEditor")
    lesson.run_all()
    editor = lesson.page.locator(".mocaplab-time-editor").first
    editor.wait_for(timeout=60000)
    editor.scroll_into_view_if_needed()
    lesson.screenshot("time-editor-before", editor)
    result = _drag_handle(lesson, "time", "TimeTrackEditor", (60.0, 0.0))
    lesson.screenshot("time-editor-dragged", editor)
    assert result["after"] != result["before"]
    moved = _assert_handle_under_mouse(lesson, result, axes=(0,))
    assert moved["data"][0] > result["handle"]["data"][0], "dragging right did not make the time later"
    assert_no_widget_errors(lesson)


def _number(text: str) -> float:
    found = re.findall(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", text)
    if not found:
        raise AssertionError(f"no number in label {text!r}")
    return float(found[0])


def test_lesson_09_touchup_step_lowers_mean_zmp_distance(open_lesson: Any) -> None:
    lesson = open_lesson("09", "TouchUpStepper")
    lesson.run_all()
    page = lesson.page
    widget = page.locator(".mocaplab-touchup").first
    button = page.locator(".mocaplab-touchup-step").first
    button.wait_for(timeout=60000)
    button.scroll_into_view_if_needed()
    scope = widget if widget.count() else page.locator(".jp-OutputArea-output", has=button).first
    mean = page.locator(".mocaplab-touchup-mean").first
    before_text = text_of(mean)
    before = _number(before_text)
    lesson.screenshot("touchup-before", scope)
    button.click()
    page.wait_for_function(
        "([el, before]) => el.textContent.trim() !== before",
        arg=[mean.element_handle(), before_text],
        timeout=90000,
    )
    lesson.wait_idle()
    after = _number(text_of(mean))
    views = scope.locator("iframe.pyvista")
    for i in range(views.count()):  # the 3D views still show a proper render after the kernel's update
        rendered_view(lesson, views.nth(i), timeout=30)
    lesson.screenshot("touchup-after-step", scope)
    assert after < before, f"mean ZMP distance did not fall: {before_text!r} -> {text_of(mean)!r}"
    assert_no_widget_errors(lesson)


@pytest.mark.parametrize("number", ["11", "13"])
def test_staggered_toggle_changes_curves(open_lesson: Any, number: str) -> None:
    lesson = open_lesson(number, "StaggeredExplorer")
    lesson.run_all()
    page = lesson.page
    explorer = page.locator(".mocaplab-staggered-explorer").first
    explorer.wait_for(timeout=60000)
    toggle = explorer.locator(".mocaplab-staggered-toggle").first
    info = explorer.locator(".mocaplab-staggered-curves").first
    canvas = explorer.locator(".jupyter-matplotlib-canvas-div canvas").first
    canvas.scroll_into_view_if_needed()
    lesson.wait_idle()
    before = canvas.screenshot()
    info_before = info.text_content()
    pressed_before = "mod-active" in (toggle.get_attribute("class") or "")
    lesson.screenshot("staggered-before", explorer)
    _press_toggle(toggle)
    page.wait_for_function(
        "([el, before]) => el.textContent !== before", arg=[info.element_handle(), info_before], timeout=60000
    )
    lesson.wait_idle()
    deadline = time.monotonic() + 30
    change = 0.0
    while time.monotonic() < deadline and change <= MIN_CHANGE:
        page.wait_for_timeout(300)
        change = image_change(before, canvas.screenshot())
    views = explorer.locator("iframe.pyvista")
    for i in range(views.count()):  # the 3D views still show a proper render after the kernel's update
        rendered_view(lesson, views.nth(i), timeout=30)
    lesson.screenshot("staggered-toggled", explorer)
    assert ("mod-active" in (toggle.get_attribute("class") or "")) != pressed_before, "the toggle did not switch"
    assert change > MIN_CHANGE, f"toggling the refinements did not change the curves (mean change {change:.3f})"
    assert json.loads(info.text_content() or "{}") != json.loads(info_before or "{}")
    assert_no_widget_errors(lesson)


def _press_toggle(toggle: Any) -> None:
    """Click a ToggleButton, a Checkbox, or the first option of ToggleButtons."""
    for selector in ("button", "input[type=checkbox]"):
        inner = toggle.locator(selector)
        if inner.count():
            inner.first.click()
            return
    toggle.click()


def test_no_tracebacks_in_lesson_outputs() -> None:
    """No lesson opened above printed a traceback into a cell output (runs last: file order)."""
    if not _TRACEBACKS:
        pytest.skip("no lesson was opened in the browser")
    bad = {name: found for name, found in _TRACEBACKS.items() if found}
    assert not bad, f"tracebacks printed in lesson outputs in JupyterLab: {bad}"
