"""The staggered explorer in JupyterLab, as a student uses it (headless Chromium, marker ``browser``).

Lesson 13 is opened and run in a real JupyterLab (the fixtures of
``test_browser.py``: one server on a copy of ``lessons/``, Debian's
Chromium through Playwright).  The explorer is found by its CSS class (the
lessons gain cells), and the kernel's explorer is tied to it by a class the
kernel adds to its box.  The student scrubs the 3D view's slider to a frame,
toggles the staggered playback and moves the succession slider: the 3D
view stays on the scrubbed frame (the issue: "the staggered explorer
resets the 3D clock to t_k on every toggle or slider change").  Undo then
brings the slider back to its previous value, in the page and in the
kernel's editor.  No error may reach the browser console.

Run: ``pytest -m browser tests/test_browser_widgets.py``.
"""

from __future__ import annotations

import json
import re
import secrets
from typing import Any

import pytest
from browser_support import LessonPage, wait_until

# the lab, the browser and open_lesson (a lesson opened in a fresh page, closed after the test) live there
from test_browser import (  # noqa: F401 - fixtures are used by name
    assert_no_console_errors,
    browser,
    lab,
    open_lesson,
    set_slider,
    shots_dir,
)

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]

_FIND_EXPLORER = """
import json as _j
_x = [_o for _n, _o in list(globals().items()) if type(_o).__name__ == "StaggeredExplorer" and not _n.startswith("_")]
if _x:
    _x[-1].widget.add_class({marker!r})
    globals()[{var!r}] = _x[-1]
print("@@json@@" + _j.dumps(len(_x)))
del _j, _x
"""

_STATE = """
import json as _j
_x = {var}
print("@@json@@" + _j.dumps({{"frame": _x.viewer.frame, "time": _x.viewer.time, "s": _x.editor.s,
    "staggered": _x.editor.staggered, "selected": _x.editor.selected,
    "t_k": float(_x.editor.current.times[_x.editor.selected]), "n_frames": _x.viewer.n_frames, "fps": _x.viewer.fps,
    "can_undo": _x.editor.can_undo}}))
del _j, _x
"""


def _kernel(lesson: LessonPage, code: str) -> Any:
    out = lesson.kernel_eval(code)
    found = [line[len("@@json@@") :] for line in out.splitlines() if line.startswith("@@json@@")]
    assert found, f"kernel said {out!r} to:\n{code}"
    return json.loads(found[-1])


def _readout(slider: Any) -> str:
    return (slider.locator(".widget-readout").first.text_content() or "").strip()


def test_staggered_explorer_keeps_the_scrubbed_frame_and_undoes(open_lesson: Any) -> None:  # noqa: F811
    lesson = open_lesson("13", "StaggeredExplorer")
    lesson.run_all()
    page = lesson.page
    marker = f"mocaplab-tested-{secrets.token_hex(3)}"
    var = f"_explorer_{secrets.token_hex(3)}"
    assert _kernel(lesson, _FIND_EXPLORER.format(marker=marker, var=var)) >= 1, "no StaggeredExplorer in the kernel"
    explorer = page.locator(f".mocaplab-staggered-explorer.{marker}").first
    explorer.wait_for(timeout=60000)
    view_slider = explorer.locator(".mocaplab-viewer-slider").first
    view_slider.wait_for(timeout=60000)
    view_slider.scroll_into_view_if_needed()
    lesson.wait_idle()
    state = _kernel(lesson, _STATE.format(var=var))
    t_k_frame = round(state["t_k"] * state["fps"])
    target = state["n_frames"] // 3 if abs(state["n_frames"] // 3 - t_k_frame) > 5 else state["n_frames"] // 2

    def frame_is(want: int) -> bool:
        return _kernel(lesson, _STATE.format(var=var))["frame"] == want and _readout(view_slider) == str(want)

    # scrub the 3D view, as a student does (typing into the slider's readout)
    set_slider(view_slider, target)
    wait_until(lambda: frame_is(target), timeout=30, what=f"the 3D view at frame {target}")
    lesson.screenshot("staggered-scrubbed", explorer)

    # toggle the staggered playback: the curves change, the 3D frame does not
    info = explorer.locator(".mocaplab-staggered-curves").first
    before = info.text_content()
    explorer.locator(".mocaplab-staggered-toggle").first.click()
    page.wait_for_function("([el, b]) => el.textContent !== b", arg=[info.element_handle(), before], timeout=60000)
    lesson.wait_idle()
    state = _kernel(lesson, _STATE.format(var=var))
    assert state["staggered"] is False, "the toggle did not reach the editor"
    assert state["frame"] == target and _readout(view_slider) == str(target), (
        f"toggling moved the 3D view from frame {target} to {state['frame']} (readout {_readout(view_slider)!r})"
    )
    lesson.screenshot("staggered-toggled-same-frame", explorer)

    # move the succession slider: the 3D frame stays, and Undo brings the slider back
    s_slider = explorer.locator(".mocaplab-staggered-s").first
    s_before = state["s"]
    shown_before = _readout(s_slider)
    s_new = 0.035 if abs(s_before - 0.035) > 1e-9 else -0.02
    set_slider(s_slider, s_new)
    wait_until(
        lambda: abs(_kernel(lesson, _STATE.format(var=var))["s"] - s_new) < 1e-9,
        timeout=60,
        what=f"the editor's s at {s_new}",
    )
    lesson.wait_idle()
    assert _kernel(lesson, _STATE.format(var=var))["frame"] == target, "the succession slider moved the 3D view"
    assert _readout(view_slider) == str(target)
    undo = explorer.locator(".mocaplab-undo").first
    assert not undo.is_disabled(), "Undo is disabled after an edit"
    undo.click()
    wait_until(lambda: _readout(s_slider) == shown_before, timeout=60, what=f"the s slider back at {shown_before}")
    lesson.wait_idle()
    state = _kernel(lesson, _STATE.format(var=var))
    assert state["s"] == pytest.approx(s_before, abs=1e-12), "Undo did not restore the editor's s"
    assert float(re.sub(r"[^\d.eE+-]", "", _readout(s_slider))) == pytest.approx(s_before, abs=5e-4)
    assert state["staggered"] is False, "one Undo undid more than the slider change"
    assert state["frame"] == target and _readout(view_slider) == str(target), "Undo moved the 3D view"
    lesson.screenshot("staggered-undone", explorer)
    assert_no_console_errors(lesson)
