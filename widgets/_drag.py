"""Drag machinery shared by the editing widgets (:mod:`.path_editor`, :mod:`.time_track`).

Both editors are thin views over one :class:`mocaplab.editing.SceneEditor`:
a matplotlib figure whose handles the mouse drags, a status line and a hidden
HTML widget publishing where the handles are drawn.  :class:`DragView` holds
everything they share; a subclass supplies only what is specific to it:

=========================  ===================================================
subclass method             what it does
=========================  ===================================================
``_press(event, press)``    pick what the press is on: :meth:`DragView._grab`
                            an existing handle, or :meth:`DragView._create` a
                            constraint there
``_drag_target(drag, xy)``  the editor's ``drag`` target for the mouse at
                            data coordinates ``xy`` (None: skip this event)
``_collect_handles()``      draw the constraints (:class:`Marks`), set
                            ``self._handles``
``_draw_result(final=)``    draw the current result (paths, tracks)
``_fit_view(grow_only=)``   axis limits that show the result and the handles
``_describe(index, ...)``   the status text of constraint ``index``
``_edited()``               optional: after a gesture (e.g. update a 3D view)
=========================  ===================================================

The gesture itself is the same in both widgets: a press on a handle grabs it,
a press elsewhere may create a constraint; the drag starts once the mouse has
moved more than ``click_tolerance`` pixels and calls ``editor.drag`` on every
motion event; the release applies its own position too (front ends may drop
motion events); a press and release without moving on an existing handle
removes it.  Every callback is :func:`guarded`: an exception is shown in the
status line (CSS class ``mocaplab-error``) and kept in ``last_error`` instead
of being lost in the kernel log, and the view is then redrawn from the
editor (:meth:`DragView.resync`), so what it shows is what the editor holds
(a failed edit changes nothing in the editor).

History and export: every view shows Undo / Redo / Reset buttons
(:class:`~mocaplab.widgets._controls.HistoryButtons` over the editor's own
``undo``/``redo``/``reset``) and an "Export BVH" control writing the current
edited motions (one file per character: the motion shown, cut to the
character's own span ``result.active[k]``, see :func:`own_spans`).  The release
of the mouse ends a gesture: the view calls ``editor.checkpoint()``, so one
drag is one undo step.

Refined where a person looks: the path editing moves whole bodies rigidly,
so feet slide until full-body refinement (Kim et al. 2009, section 4.3;
:meth:`mocaplab.editing.EditResult.refined`) plants them again.  With the
"refine on release" box ticked (the default) the view refines the edit when
the mouse is released (and after undo, redo, reset or a refresh); the 3D
view shows and the export writes those refined motions
(:meth:`DragView.shown_motions`) and the status line ends with
``refined``.  The editor refines only the characters that changed
(:class:`mocaplab.editing.RefineCache`).  During a drag the plain edit is
drawn (the paths); unticked, the view shows and writes the plain edit.
"""

from __future__ import annotations

import functools
import html
import io
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import ipywidgets as W
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from numpy.typing import NDArray

from mocaplab import editing

from ._constraints import constraint_change, frame_of, kind_of
from ._controls import (
    ExportControl,
    HistoryButtons,
    Shortcut,
    bind_keys,
    error_html,
    export_name,
    history_status,
    row,
)

Backend = Literal["auto", "ipympl", "agg"]

#: CSS pixels kept free along the left edge of an interactive figure: ipympl lays
#: its toolbar (vertical, on the left) over the canvas, where it hid the tick labels.
TOOLBAR_PX = 44

#: Status lines wrap at the figure's width: the whole text is always shown (never cut by an ellipsis).
_STATUS_STYLE = "display:block; max-width:{px}px; white-space:normal; overflow-wrap:anywhere"

#: One draggable handle: (constraint index, kind, position in data coordinates, shape (2,)).
Handle = tuple[int, str, NDArray[np.float64]]

# --------------------------------------------------------------------------- canvas
class CanvasView:
    """A matplotlib figure with an ipywidgets face.

    With ipympl the canvas itself is a DOM widget (interactive in JupyterLab,
    and its mouse events can also be fed by hand).  Without it, the figure is
    drawn with Agg into an :class:`ipywidgets.Image` refreshed on request.
    """

    def __init__(self, figure: Figure, backend: Backend) -> None:
        self.figure = figure
        self.canvas = make_canvas(figure, backend=backend)
        self.interactive = isinstance(self.canvas, W.DOMWidget)
        self.widget: W.DOMWidget
        if self.interactive:
            self.widget = self.canvas
        else:
            self.widget = W.Image(format="png")
            self.render()

    def draw(self, *, final: bool = False) -> None:
        """Redraw: ipympl draws lazily on the front end's request; Agg renders a PNG when ``final``."""
        if self.interactive:
            self.canvas.draw_idle()
        elif final:
            self.render()

    def render(self) -> None:
        buf = io.BytesIO()
        self.figure.savefig(buf, format="png")
        self.widget.value = buf.getvalue()


def make_canvas(figure: Figure, *, backend: Backend = "auto") -> Any:
    """Attach a canvas to ``figure``: an ipympl widget canvas, or Agg.

    ``backend="auto"`` uses ipympl when it is installed (the canvas works with
    or without a running front end, and independently of ``%matplotlib``),
    else Agg.  The figure is not registered with pyplot, so it is never shown
    twice and never needs ``plt.close``.
    """
    if backend not in ("auto", "ipympl", "agg"):
        raise ValueError(f"Expected `backend` to be 'auto', 'ipympl' or 'agg', got {backend!r}")
    if backend in ("auto", "ipympl"):
        try:
            from ipympl.backend_nbagg import Canvas, FigureManager
        except ImportError:
            if backend == "ipympl":
                raise
        else:
            canvas = Canvas(figure)
            FigureManager(canvas, id(figure) % 100_000)
            canvas.header_visible = False
            canvas.footer_visible = False
            canvas.resizable = False
            canvas.toolbar_position = "left"
            canvas.toolbar_visible = "fade-in-fade-out"  # do not hide the tick labels
            return canvas
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    return FigureCanvasAgg(figure)


# --------------------------------------------------------------------------- gesture
@dataclass
class Drag:
    """State of one mouse gesture."""

    index: int  # constraint index in the editor
    kind: str  # "pin", "direction", "time", "duration"
    press_px: tuple[float, float]
    created: bool  # the press added the constraint
    moved: bool = False
    anchor: Any = None  # kind-specific data fixed at press time
    last_px: tuple[float, float] | None = None  # where the last update put the handle


def guarded(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run a callback; show its exception in the widget's status instead of losing it."""

    @functools.wraps(method)
    def wrapper(self: DragView, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - shown to the user, kept in .last_error
            self._fail(exc)
            return None

    return wrapper


class DragView:
    """Common parts of the path and time-track editors: editor, canvas, status, gestures.

    Subclasses set the CSS classes below, call :meth:`_build_figure` and
    :meth:`_open` from their constructor and implement the methods listed in
    the module docstring.
    """

    status_class = "mocaplab-status"
    handles_class = "mocaplab-handles"
    canvas_class = "mocaplab-canvas"
    editor_class = "mocaplab-editor"

    figure: Figure
    ax: Axes
    canvas: Any
    widget: W.Box

    def __init__(
        self,
        editor_or_characters: Any,
        constraints: Sequence[Any] | None,
        *,
        pick_radius: float,
        editor_options: dict[str, Any] | None = None,
        roles: Any = None,
        refine: bool = True,
    ) -> None:
        if not pick_radius > 0:
            raise ValueError(f"Expected `pick_radius` > 0 pixels, got {pick_radius!r}")
        self.editor = as_scene_editor(editor_or_characters, constraints, editor_options, roles=roles)
        self.pick_radius = float(pick_radius)
        self.click_tolerance = 3.0  # pixels a press may move and still count as a click
        self.status = W.HTML(value="")
        self.status.add_class(self.status_class)
        self.handles_info = W.HTML(value="[]", layout=W.Layout(display="none"))
        self.handles_info.add_class(self.handles_class)
        self.last_error: BaseException | None = None
        self._drag: Drag | None = None
        self._handles: list[Handle] = []
        self._listeners: list[Callable[[Any], None]] = []
        self.result = current_result(self.editor)
        self._refined_for: Any = None  # the result whose motions _refined_motions holds
        self._refined_motions: list[Any] | None = None
        self._refine_note = ""
        self.refine = W.Checkbox(
            value=bool(refine),
            description="refine on release",
            indent=False,
            tooltip="Plant the feet (full-body refinement) of the edited motions the 3D view shows and export writes",
            layout=W.Layout(width="auto"),
        )
        self.refine.add_class("mocaplab-refine")
        self.refine.observe(self._on_refine_toggle, names="value")
        self.history_buttons = HistoryButtons(
            self.editor, self._after_history, guard=self._guard, snapshot=lambda: tuple(self.editor.constraints)
        )
        self.export_control = ExportControl(
            self._export_motions, default=export_name(_first_clip_name(self.editor), "edited"), guard=self._guard
        )
        # a row that wraps: the "wrote ..." note goes under the button when it does not fit beside it
        self.controls = row([self.history_buttons.box, self.refine, self.export_control.box])
        self.controls.add_class("mocaplab-edit-controls")

    # -- public
    def on_edit(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(result)`` after every edit made through this view."""
        self._listeners.append(callback)

    @property
    def constraints(self) -> tuple[Any, ...]:
        """The editor's constraints (a tuple)."""
        return tuple(self.editor.constraints)

    def _drawn_constraints(self) -> tuple[Any, ...]:
        """Constraints with frames on the current result's (possibly transformed) clips.

        After discrete editing inserts or deletes frames, ``result.constraints``
        holds the same constraints, in the same order, re-indexed onto the
        transformed clips; the editor's own list keeps the input clips' frames.
        """
        current = getattr(self.result, "constraints", None)
        mine = tuple(self.editor.constraints)
        if current is not None and len(current) == len(mine):
            return tuple(current)
        return mine

    def handle_positions(self) -> list[dict[str, Any]]:
        """Where each handle is drawn.

        Returns
        -------
        list of dict
            ``{"index": constraint index, "kind": handle kind, "data": [x, y]
            in the axes' data coordinates, "pixel": [px, py] in figure pixels
            from the bottom-left (matplotlib display coordinates),
            "css": [cx, cy] in CSS pixels from the canvas' top-left corner}``.
        """
        out = []
        ratio = float(getattr(self.canvas, "device_pixel_ratio", 1.0) or 1.0)
        height = self.figure.bbox.height
        for index, kind, xy in self._handles:
            px, py = self.ax.transData.transform(xy)
            out.append(
                {
                    "index": index,
                    "kind": kind,
                    "data": [float(xy[0]), float(xy[1])],
                    "pixel": [float(px), float(py)],
                    "css": [float(px / ratio), float((height - py) / ratio)],
                }
            )
        return out

    def refresh(self) -> None:
        """Redraw from the editor's current result (after editing it in code)."""
        self._apply(current_result(self.editor))
        self._settle(grow_only=self._refresh_grows_view)

    def shown_motions(self) -> list[Any]:
        """The motions the 3D view shows and export writes (on the shared clock), one per character.

        The current result's refined motions
        (:meth:`~mocaplab.editing.EditResult.refined`) while "refine on
        release" is ticked, refined on first call for each result; its plain
        ``motions`` otherwise, or when refinement failed (the status line
        says why).
        """
        if self._refined_for is not self.result:
            self._refined_for = self.result
            self._refined_motions, self._refine_note = self._refine_result(self.result)
        return list(self._refined_motions) if self._refined_motions is not None else list(self.result.motions)

    def _refine_result(self, result: Any) -> tuple[list[Any] | None, str]:
        """``(refined motions or None, status note)`` for ``result``."""
        if not self.refine.value:
            return None, " · not refined (refine on release is off)"
        refined = getattr(result, "refined", None)
        if not callable(refined):
            return None, ""
        try:
            motions = list(refined())
        except Exception as exc:  # noqa: BLE001 - the plain edit is still shown; the status says why
            return None, f" · not refined ({type(exc).__name__}: {exc})"
        return motions, " · refined"

    @guarded
    def _on_refine_toggle(self, change: dict[str, Any]) -> None:
        self._refined_for = None
        self._settle()
        self._set_status(("refine on release: on" if change["new"] else "refine on release: off") + self._refine_note)

    def resync(self) -> None:
        """Make every control and drawing show the editor's state (after an error; the status is kept).

        The listeners (:meth:`on_edit`) and the subclass hook (the 3D view,
        the time slider) are brought up to date too, each on its own: one
        that raises does not keep the others on the old state.
        """
        self.result = current_result(self.editor)
        self.history_buttons.sync()
        self._notify(self.result)
        try:
            self._edited()
        except Exception:  # noqa: BLE001 - resync runs after an error, which is the one shown
            pass
        self._redraw(final=True)

    def export(self, path: Any = None) -> list[Any]:
        """Write the current edited motions as BVH (to ``path`` or the export box's name); returns the files."""
        return self.export_control.export(path)

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    # -- construction
    _refresh_grows_view = True  # refresh() only widens the view (False: fit it anew)

    def _build_figure(self, figsize: tuple[float, float], backend: Backend, title: str) -> None:
        """The figure, its canvas (CSS class ``canvas_class`` when interactive) and titled axes."""
        self.figure = Figure(figsize=figsize, dpi=100, layout="constrained")
        self._view = CanvasView(self.figure, backend)
        self.canvas = self._view.canvas
        width_px = int(round(figsize[0] * 100))
        if self._view.interactive:
            self.canvas.add_class(self.canvas_class)
            # the toolbar floats over the canvas' left edge: lay the axes out to its right
            free = min(TOOLBAR_PX / width_px, 0.2)
            self.figure.set_layout_engine(ConstrainedLayoutEngine(rect=(free, 0.0, 1.0 - free, 1.0)))
        # a status as wide as the figure: a long message wraps onto more lines instead of
        # widening the layout and pushing the 3D view sideways
        self._status_px = width_px
        self.status.layout.width = f"{width_px}px"
        self.controls.layout.width = f"{width_px}px"
        self.ax = self.figure.add_subplot()
        self.ax.set_title(title)
        plain_ticks(self.ax)

    def _open(self, widget: W.Box, hint: str) -> None:
        """Finish construction: lay out ``widget``, listen to the mouse, draw, show ``hint``."""
        self.widget = widget
        self.widget.add_class(self.editor_class)
        self.canvas.mpl_connect("button_press_event", self._on_press)
        self.canvas.mpl_connect("motion_notify_event", self._on_motion)
        self.canvas.mpl_connect("button_release_event", self._on_release)
        self.keys_help = bind_keys(self.canvas, self._shortcuts(), guard=self._guard)
        self._fit_view()
        self._redraw(final=True)
        self._set_status(f"{hint} · {self.keys_help}" if self.keys_help else hint)

    def _shortcuts(self) -> list[Shortcut]:
        """The keyboard shortcuts of the plot (:func:`bind_keys`): ctrl+z undo, ctrl+y redo; subclasses add."""
        return self.history_buttons.shortcuts()

    # -- editing
    def _apply(self, result: Any) -> None:
        """Show ``result``: every listener is called (each on its own); then the first listener error is raised."""
        self.result = result
        self.last_error = None
        self.history_buttons.sync()
        error = self._notify(result)
        if error is not None:
            raise error

    def _notify(self, result: Any) -> BaseException | None:
        """Call every listener with ``result``, each under its own guard; returns the first error (or None)."""
        first: BaseException | None = None
        for callback in self._listeners:
            try:
                callback(result)
            except Exception as exc:  # noqa: BLE001 - the others still run; the caller shows it
                first = first or exc
        return first

    def _export_motions(self) -> list[Any]:
        """The motions the Export button writes: each character's own retimed span (:func:`own_spans`).

        Refined while "refine on release" is ticked (:meth:`shown_motions`).
        """
        self.result = current_result(self.editor)
        return own_spans(self.result, self.shown_motions())

    def _after_history(self) -> None:
        """After Undo, Redo or Reset: redraw everything (handles, paths, 3D view) from the editor."""
        self._drag = None
        self._apply(current_result(self.editor))
        self._settle(grow_only=self._refresh_grows_view)
        last = self.history_buttons.last
        text = history_status(*last, self._constraint_change) if last is not None else "history"
        self._set_status(text + self._history_note() + self._refine_note)

    def _constraint_change(self, old: Sequence[Any], new: Sequence[Any]) -> str:
        """What an edit from constraints ``old`` to ``new`` did, in words (:func:`constraint_change`)."""
        return constraint_change(old, new, who=self._character)

    def _history_note(self) -> str:
        """Extra status text after an undo, redo or reset (subclasses add to it)."""
        return ""

    def _guard(self, action: Callable[[], object]) -> None:
        """Run a button's action; an exception is shown and the view resynced (as :func:`guarded`)."""
        try:
            action()
        except Exception as exc:  # noqa: BLE001 - shown to the user, kept in .last_error
            self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        """Show ``exc`` and redraw from the editor, so nothing shows a state the editor does not hold."""
        self._show_error(exc)
        try:
            self.resync()
        except Exception:  # noqa: BLE001 - the first error is the one to show
            pass

    def _add(self, constraint: Any) -> int:
        out = self.editor.add(constraint)
        index = len(self.editor.constraints) - 1 if not isinstance(out, (int, np.integer)) else int(out)
        self._apply(current_result(self.editor, out))
        return index

    def _remove(self, index: int) -> None:
        out = self.editor.remove(index)
        self._apply(current_result(self.editor, out))

    def _settle(self, *, grow_only: bool = True) -> None:
        """After a gesture or a refresh: refinement (if on), the subclass hook, the view fitted, a final redraw."""
        self.shown_motions()
        self._edited()
        self._fit_view(grow_only=grow_only)
        self._redraw(final=True)

    # -- drawing
    def _redraw(self, *, final: bool = False) -> None:
        self._draw_result(final=final)
        self._collect_handles()
        self.handles_info.value = html.escape(json.dumps(self.handle_positions()))
        self._view.draw(final=final)

    # -- status
    def _show_error(self, exc: BaseException) -> None:
        """``Type: message (function, line N)`` in the status line (:func:`error_html`: escaped, never raises)."""
        self.last_error = exc
        style = "color:#b00020; " + _STATUS_STYLE.format(px=self._status_width())
        self.status.value = error_html(exc, where=True, tag="span", style=style)

    def _set_status(self, text: str) -> None:
        """The status text, wrapped at the figure's width (all of it shown), html-escaped."""
        self._status_text = text
        style = _STATUS_STYLE.format(px=self._status_width())
        self.status.value = (
            f'<span class="mocaplab-ok" style="{style}" title="{html.escape(text)}">{html.escape(text)}</span>'
        )

    def _character(self, k: int) -> str:
        """``character k`` with the clip's name when it has one (escaped later, with the status)."""
        characters = getattr(self.editor, "characters", None)
        name = getattr(characters[k], "name", "") if characters is not None and k < len(characters) else ""
        return f"character {k} ({name})" if name else f"character {k}"

    def _status_width(self) -> int:
        return int(getattr(self, "_status_px", 600))

    # -- picking
    def _pick_handle(self, event: Any) -> Handle | None:
        """The handle within ``pick_radius`` pixels of the mouse (the nearest), or None."""
        if not self._handles:
            return None
        px = self.ax.transData.transform(np.array([h[2] for h in self._handles]))
        d = np.hypot(px[:, 0] - event.x, px[:, 1] - event.y)
        j = int(np.argmin(d))
        return self._handles[j] if d[j] <= self.pick_radius else None

    def _toolbar_busy(self) -> bool:
        """Whether the toolbar is zooming or panning (then the mouse is not for editing)."""
        toolbar = getattr(self.canvas, "toolbar", None)
        return bool(toolbar is not None and str(getattr(toolbar, "mode", "")))

    def _moved(self, event: Any) -> bool:
        assert self._drag is not None  # internal invariant, not input validation
        dx = event.x - self._drag.press_px[0]
        dy = event.y - self._drag.press_px[1]
        return bool(np.hypot(dx, dy) > self.click_tolerance)

    # -- gesture
    def _grab(self, index: int, kind: str, press: tuple[float, float], anchor: Any = None) -> None:
        """Start dragging the existing handle of constraint ``index``."""
        self._drag = Drag(index, kind, press, created=False, anchor=anchor)
        self._describe(index, prefix="picked")

    def _create(self, constraint: Any, kind: str, press: tuple[float, float], anchor: Any = None) -> None:
        """Add ``constraint`` where the mouse pressed and start dragging its handle."""
        index = self._add(constraint)
        self._drag = Drag(index, kind, press, created=True, anchor=anchor)
        self._redraw()
        self._describe(index, prefix="pinned")

    @guarded
    def _on_press(self, event: Any) -> None:
        if event.inaxes is not self.ax or event.button != 1 or self._toolbar_busy():
            return
        self.last_error = None
        self.editor.checkpoint()  # a gesture starts: edits made before (in code, say) stay a step of their own
        self._press(event, (float(event.x), float(event.y)))

    @guarded
    def _on_motion(self, event: Any) -> None:
        drag = self._drag
        if drag is None or event.x is None or event.y is None:
            return
        if not drag.moved and not self._moved(event):
            return
        drag.moved = True
        self._move_to(event)

    def _move_to(self, event: Any) -> None:
        """Solve with the dragged handle under the mouse position of ``event`` (also outside the axes)."""
        drag = self._drag
        assert drag is not None  # internal invariant
        drag.last_px = (float(event.x), float(event.y))
        target = self._drag_target(drag, event_data(self.ax, event))
        if target is None:
            return
        self._apply(current_result(self.editor, self.editor.drag(drag.index, target)))
        self._redraw()
        self._describe(drag.index, prefix="drag")

    @guarded
    def _on_release(self, event: Any) -> None:
        drag = self._drag
        if drag is None:
            return
        try:
            if self.last_error is None and event.x is not None and (drag.moved or self._moved(event)):
                if drag.last_px != (float(event.x), float(event.y)):
                    drag.moved = True
                    self._move_to(event)  # the front end may drop motion events: end under the mouse
        finally:
            self._drag = None
            self.editor.checkpoint()  # the gesture ends: the next edit is a new undo step
        if self.last_error is not None:
            pass  # keep the error of the failed update on show
        elif not drag.moved and not drag.created:
            c = self.editor.constraints[drag.index]
            self._remove(drag.index)
            self._set_status(
                f"removed {kind_of(c)} #{drag.index} ({self._character(int(c.character))}, frame {frame_of(c)})"
            )
        elif drag.moved:
            self._describe(drag.index, prefix="moved")
        self.result = current_result(self.editor)
        self._settle()
        if self.last_error is None:
            self._set_status(getattr(self, "_status_text", "") + self._refine_note)
        self.history_buttons.sync()

    # -- subclasses implement
    def _press(self, event: Any, press: tuple[float, float]) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _drag_target(self, drag: Drag, mouse: NDArray[np.float64]) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def _collect_handles(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _draw_result(self, *, final: bool) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _fit_view(self, *, grow_only: bool = False) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _describe(self, index: int, *, prefix: str) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _edited(self) -> None:
        """Called after each gesture and refresh, before the view is fitted and redrawn."""


# --------------------------------------------------------------------------- helpers
def as_scene_editor(
    editor_or_characters: Any, constraints: Sequence[Any] | None, options: dict[str, Any] | None, *, roles: Any = None
) -> Any:
    """Accept a SceneEditor (used as is) or characters (+ constraints, options, roles) to build one.

    ``roles`` (joint roles fixed by hand, see :func:`mocaplab.roles.resolve_roles`)
    becomes the editor's ``roles`` option.
    """
    if hasattr(editor_or_characters, "drag") and hasattr(editor_or_characters, "constraints"):
        if constraints is not None or options or roles is not None:
            raise ValueError(
                "Pass `constraints`, `editor_options` and `roles` only with characters, not with a SceneEditor "
                "(it has its own: SceneEditor(characters, constraints, roles=..., ...))"
            )
        return editor_or_characters  # a SceneEditor, or any object with its interface (tests use spies)
    if roles is not None:
        if options and options.get("roles") is not None:
            raise ValueError("Pass `roles` once: as `roles=` or in `editor_options`, not both")
        options = {**(options or {}), "roles": roles}
    characters = list(editor_or_characters) if isinstance(editor_or_characters, Sequence) else [editor_or_characters]
    # a SceneEditor, or a DiscreteEditor with editor_options={"discrete": True or DiscreteOptions(...)}
    return editing.make_editor(characters, list(constraints or ()), **(options or {}))


def _first_clip_name(editor: Any) -> str:
    """The first character's clip name (the default export is named after it), or ``""``."""
    characters: Sequence[Any] = getattr(editor, "characters", None) or ()
    return str(getattr(characters[0], "name", "") or "") if len(characters) else ""


def own_spans(result: Any, motions: Sequence[Any] | None = None) -> list[Any]:
    """Each character's motion on the shared clock cut to its own time span (``result.active[k]``).

    ``result.motions`` (or ``motions``, the same characters on the same
    clock: the refined ones) hold the first / last pose outside each
    character's span so that all play on one clock; a file gets only the
    character's retimed motion (a character starting 3 s late is not written
    with 3 s of frozen first pose).
    """
    motions = list(result.motions if motions is None else motions)
    active = getattr(result, "active", None)
    if active is None:
        return motions
    out = []
    for m, on in zip(motions, active, strict=True):
        ticks = np.flatnonzero(np.asarray(on))
        if ticks.size == 0 or ticks.size == m.n_frames:
            out.append(m)
        else:
            out.append(m[int(ticks[0]) : int(ticks[-1]) + 1])
    return out


def current_result(editor: Any, returned: Any = None) -> Any:
    """The editor's current EditResult (what an editor call returned, or its ``result``)."""
    if returned is not None and hasattr(returned, "paths"):
        return returned
    result = getattr(editor, "result", None)
    if callable(result):
        result = result()
    if result is None:
        raise AttributeError(f"{type(editor).__name__} exposes no current `result`")
    return result


def event_data(ax: Any, event: Any) -> NDArray[np.float64]:
    """Data coordinates of a mouse event, also outside the axes (where ``xdata`` is None)."""
    if event.inaxes is ax and event.xdata is not None and event.ydata is not None:
        return np.array([event.xdata, event.ydata], dtype=float)
    return np.asarray(ax.transData.inverted().transform((float(event.x), float(event.y))), dtype=float)


def plain_ticks(ax: Any) -> None:
    """Tick labels with an ASCII minus sign (some browser fonts drop the Unicode one)."""
    from matplotlib.ticker import FuncFormatter

    plain = FuncFormatter(lambda value, _pos: f"{value:g}")
    ax.xaxis.set_major_formatter(plain)
    ax.yaxis.set_major_formatter(plain)


class Marks:
    """Points gathered per matplotlib ``Line2D`` while walking the constraints, then drawn at once.

    Parameters
    ----------
    lines : sequence of Line2D
        The lines to fill; :meth:`draw` empties those that received no point.
    """

    def __init__(self, lines: Sequence[Any]) -> None:
        self._points: dict[Any, list[NDArray[np.float64]]] = {line: [] for line in lines}

    def point(self, line: Any, xy: Any) -> None:
        """Add a marker at ``xy``, shape (2,)."""
        self._points[line].append(np.asarray(xy, dtype=float))

    def segment(self, line: Any, a: Any, b: Any) -> None:
        """Add a segment from ``a`` to ``b`` (each shape (2,)), apart from the others (a NaN break)."""
        self._points[line] += [np.asarray(a, dtype=float), np.asarray(b, dtype=float), np.full(2, np.nan)]

    def draw(self) -> None:
        for line, points in self._points.items():
            arr = np.asarray(points, dtype=float).reshape(-1, 2)
            line.set_data(arr[:, 0], arr[:, 1])
