"""Every control of the editors and the viewer says what it does when the mouse rests on it (issue #28).

A student met "random tau", "exponent l", "+1 iteration" with no hint.  Each
widget is built headless (static 3D views) and its tree walked: every button,
toggle, checkbox, slider, dropdown, list and text box must carry a non-empty
``tooltip`` (ipywidgets 8 shows it as the element's title).
"""

from __future__ import annotations

from collections.abc import Iterator

import ipywidgets as W
import pytest

from mocaplab.contacts import foot_contacts
from mocaplab.physics import Body

CONTROLS = (
    W.Button,
    W.ToggleButton,
    W.Checkbox,
    W.FloatSlider,
    W.IntSlider,
    W.Dropdown,
    W.Select,
    W.Text,
    W.BoundedFloatText,
)


def controls(widget: W.Widget) -> Iterator[W.Widget]:
    """Every control in ``widget``'s tree (each once)."""
    seen: set[int] = set()
    stack = [widget]
    while stack:
        w = stack.pop()
        if id(w) in seen:
            continue
        seen.add(id(w))
        if isinstance(w, CONTROLS):
            yield w
        stack.extend(getattr(w, "children", ()) or ())


@pytest.fixture(scope="module")
def widgets(cmu):
    from mocaplab.widgets import MotionViewer, PathEditor, StaggeredExplorer, TimeTrackEditor, TouchUpStepper

    walk = cmu("16_15").resample(30)[:60]
    jump = cmu("16_05").resample(30)
    static = {"backend": "static", "window_size": (160, 120)}
    built = {
        "path editor": PathEditor(walk, viewer_options=static),
        "time tracks": TimeTrackEditor([walk, walk]),
        "touch-up stepper": TouchUpStepper(
            jump, body=Body.from_skeleton(jump), contacts=foot_contacts(jump), viewer_options=static
        ),
        "staggered explorer": StaggeredExplorer(cmu("16_05"), max_poses=8, viewer_backend="static", optimize=False),
        "viewer": MotionViewer([walk, walk], **static),
    }
    yield {name: w.widget for name, w in built.items()}
    for w in built.values():
        close = getattr(w, "close", None) or getattr(getattr(w, "viewer", None), "close", None)
        if close is not None:
            close()


@pytest.mark.parametrize("name", ["path editor", "time tracks", "touch-up stepper", "staggered explorer", "viewer"])
def test_every_control_has_a_tooltip(widgets, name):
    found = list(controls(widgets[name]))
    assert len(found) >= 3, f"the {name} shows controls"
    missing = [f"{type(c).__name__} {getattr(c, 'description', '')!r}" for c in found if not (c.tooltip or "").strip()]
    assert not missing, f"{name}: controls without a tooltip: {missing}"


def test_the_check_sees_a_control_without_a_tooltip():
    box = W.VBox([W.HBox([W.Button(description="go", tooltip="go on")]), W.FloatSlider(description="x")])
    assert [c.description for c in controls(box) if not c.tooltip] == ["x"]
