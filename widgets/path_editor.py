"""Drag motion paths with the mouse: a thin view over :class:`mocaplab.editing.SceneEditor`.

Kim et al. 2009 (section 3.1, Figure 3) edit synchronized characters by
pinning points of their motion paths and dragging them.  :class:`PathEditor`
draws every character's path from above (ground coordinates ``(x, z)``,
metres) and turns mouse gestures into constraint edits:

=====================================  ===========================================
gesture                                 edit
=====================================  ===========================================
press on a path point, drag             ``add(PinPosition(k, frame, p))`` then
                                        ``drag(i, (x, z))`` on every motion event
press on a path point, release          pin it where it is
press on a pin handle, drag             ``drag(i, (x, z))`` on every motion event
press on a handle, release unmoved      ``remove(i)`` (unpin)
shift + press on a path point or pin,   ``add(PinDirection(k, frame, d))`` then
drag                                    ``drag(i, d)`` with ``d`` the tangent
                                        ``p[frame + 1] - p[frame - 1]`` pointing
                                        at the mouse
press on a direction arrow tip, drag    ``drag(i, d)``
=====================================  ===========================================

``Relative`` constraints are drawn as dashed links between the two characters.
All the mathematics happens in the core editor; the widget only draws its
result.  Beside the plot, a 3D :class:`~mocaplab.widgets.MotionViewer` shows the
edited scene, synced to the time slider; it receives the edited motions
(:meth:`~mocaplab.widgets.MotionViewer.set_motions`, in place: same plotter,
same widget) when the mouse is released, since redrawing the 3D scene on every
motion event would slow a live drag.

Drawing conventions
-------------------
The view looks down the vertical axis from above: ground ``x`` to the right
and ground ``z`` down the page (the z axis is inverted), so a character's left
is on its left on screen.  Pins are
circles drawn at their target position, direction pins are arrows from the
pinned path point whose tip is the handle, the current time is a triangle on
every path.  Handle positions, in data and in canvas pixels, are published in
the hidden HTML widget ``handles_info`` (CSS class ``mocaplab-path-handles``) as
JSON, for browser tests.

Examples
--------
>>> from mocaplab import data, editing                  # doctest: +SKIP
>>> walk = data.cmu("16_15").resample(30)              # doctest: +SKIP
>>> PathEditor([walk], [editing.PinPosition(0, 0, walk.root_positions[0, [0, 2]], hard=True)])  # doctest: +SKIP
"""

from __future__ import annotations

import functools
import html
import json
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import ipywidgets as W
import numpy as np
from matplotlib.figure import Figure
from numpy.typing import NDArray

from mocaplab import editing

__all__ = ["PathEditor", "make_canvas", "character_colors"]

Backend = Literal["auto", "ipympl", "agg"]

#: Colours of characters 0, 1, ... (matplotlib's tab10 cycle).
_TAB10 = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)


def character_colors(n: int) -> list[str]:
    """Colours for ``n`` characters (the tab10 cycle, repeated)."""
    return [_TAB10[k % len(_TAB10)] for k in range(n)]


# --------------------------------------------------------------------------- canvas
class _CanvasView:
    """A matplotlib figure with an ipywidgets face.

    With ipympl the canvas itself is a DOM widget (interactive in JupyterLab,
    and its mouse events can also be fed by hand).  Without it, the figure is
    drawn with Agg into an :class:`ipywidgets.Image` refreshed on request.
    """

    def __init__(self, figure: Figure, backend: Backend) -> None:
        self.figure = figure
        self.canvas = make_canvas(figure, backend=backend)
        self.interactive = isinstance(self.canvas, W.DOMWidget)
        if self.interactive:
            self.widget: W.DOMWidget = self.canvas
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
        import io

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


# --------------------------------------------------------------------------- shared drag machinery
@dataclass
class _Drag:
    """State of one mouse gesture."""

    index: int  # constraint index in the editor
    kind: str  # "pin", "direction", "time", "duration"
    press_px: tuple[float, float]
    created: bool  # the press added the constraint
    moved: bool = False
    anchor: Any = None  # kind-specific data fixed at press time
    last_px: tuple[float, float] | None = None  # where the last update put the handle


def _guarded(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run a callback; show its exception in the widget's status instead of losing it."""

    @functools.wraps(method)
    def wrapper(self: _DragView, *args: Any, **kwargs: Any) -> Any:
        try:
            return method(self, *args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - shown to the user, kept in .last_error
            self._show_error(exc)
            return None

    return wrapper


class _DragView:
    """Common parts of the path and time-track editors: editor, status, events."""

    status_class = "mocaplab-status"
    handles_class = "mocaplab-handles"

    def __init__(
        self,
        editor_or_characters: Any,
        constraints: Sequence[Any] | None,
        *,
        pick_radius: float,
        editor_options: dict[str, Any] | None = None,
    ) -> None:
        if not pick_radius > 0:
            raise ValueError(f"Expected `pick_radius` > 0 pixels, got {pick_radius!r}")
        self.editor = _as_scene_editor(editor_or_characters, constraints, editor_options)
        self.pick_radius = float(pick_radius)
        self.click_tolerance = 3.0  # pixels a press may move and still count as a click
        self.status = W.HTML(value="")
        self.status.add_class(self.status_class)
        self.handles_info = W.HTML(value="[]", layout=W.Layout(display="none"))
        self.handles_info.add_class(self.handles_class)
        self.last_error: BaseException | None = None
        self._drag: _Drag | None = None
        self._listeners: list[Callable[[Any], None]] = []
        self.result = _current_result(self.editor)

    # -- public
    def on_edit(self, callback: Callable[[Any], None]) -> None:
        """Call ``callback(result)`` after every edit made through this view."""
        self._listeners.append(callback)

    @property
    def constraints(self) -> tuple[Any, ...]:
        """The editor's constraints (a tuple)."""
        return tuple(self.editor.constraints)

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    # -- events
    def _connect(self, canvas: Any) -> None:
        canvas.mpl_connect("button_press_event", self._on_press)
        canvas.mpl_connect("motion_notify_event", self._on_motion)
        canvas.mpl_connect("button_release_event", self._on_release)

    def _toolbar_busy(self, canvas: Any) -> bool:
        toolbar = getattr(canvas, "toolbar", None)
        return bool(toolbar is not None and str(getattr(toolbar, "mode", "")))

    def _moved(self, event: Any) -> bool:
        assert self._drag is not None  # internal invariant, not input validation
        dx = event.x - self._drag.press_px[0]
        dy = event.y - self._drag.press_px[1]
        return bool(np.hypot(dx, dy) > self.click_tolerance)

    def _apply(self, result: Any) -> None:
        self.result = result
        self.last_error = None
        for callback in self._listeners:
            callback(result)

    def _add(self, constraint: Any) -> int:
        out = self.editor.add(constraint)
        index = len(self.editor.constraints) - 1 if not isinstance(out, (int, np.integer)) else int(out)
        self._apply(_current_result(self.editor, out))
        return index

    def _remove(self, index: int) -> None:
        out = self.editor.remove(index)
        self._apply(_current_result(self.editor, out))

    def _show_error(self, exc: BaseException) -> None:
        self.last_error = exc
        where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        loc = f" ({where.name}, line {where.lineno})" if where else ""
        self.status.value = (
            f'<span class="mocaplab-error" style="color:#b00020">'
            f"{html.escape(type(exc).__name__)}: {html.escape(str(exc))}{html.escape(loc)}</span>"
        )

    def _set_status(self, text: str) -> None:
        self.status.value = f'<span class="mocaplab-ok">{html.escape(text)}</span>'

    # subclasses implement
    def _on_press(self, event: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _on_motion(self, event: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _on_release(self, event: Any) -> None:  # pragma: no cover - abstract
        raise NotImplementedError


def _as_scene_editor(
    editor_or_characters: Any, constraints: Sequence[Any] | None, options: dict[str, Any] | None
) -> Any:
    """Accept a SceneEditor (used as is) or characters (+ constraints, options) to build one."""
    if hasattr(editor_or_characters, "drag") and hasattr(editor_or_characters, "constraints"):
        if constraints is not None or options:
            raise ValueError(
                "Pass `constraints` and `editor_options` only with characters, not with a SceneEditor (it has its own)"
            )
        return editor_or_characters  # a SceneEditor, or any object with its interface (tests use spies)
    scene_editor = getattr(editing, "SceneEditor", None)
    if scene_editor is None:
        raise ImportError("mocaplab.editing.SceneEditor is not available")
    characters = list(editor_or_characters) if isinstance(editor_or_characters, Sequence) else [editor_or_characters]
    return scene_editor(characters, list(constraints or ()), **(options or {}))


def _current_result(editor: Any, returned: Any = None) -> Any:
    """The editor's current EditResult (what an editor call returned, or its ``result``)."""
    if returned is not None and hasattr(returned, "paths"):
        return returned
    result = getattr(editor, "result", None)
    if callable(result):
        result = result()
    if result is None:
        raise AttributeError(f"{type(editor).__name__} exposes no current `result`")
    return result


def _kind_of(constraint: Any) -> str:
    return type(constraint).__name__


def _is(constraint: Any, name: str) -> bool:
    cls = getattr(editing, name, None)
    return isinstance(constraint, cls) if cls is not None else _kind_of(constraint) == name


def _frame_of(constraint: Any) -> int:
    """The constraint's frame (the first frame of a variational constraint)."""
    frame = getattr(constraint, "frame", None)
    if frame is None:
        frame = constraint.frames[0]
    return int(frame)


def _other_frame_of(constraint: Any) -> int:
    """The other character's frame of a Relative or Sync constraint (first of a variational one)."""
    frame = getattr(constraint, "other_frame", None)
    if frame is None:
        frame = constraint.other_frames[0]
    return int(frame)


def _tangent(path: NDArray[np.float64], i: int) -> NDArray[np.float64]:
    """Central-difference tangent ``p[i+1] - p[i-1]`` (one-sided at the ends), shape (2,)."""
    n = len(path)
    a, b = max(i - 1, 0), min(i + 1, n - 1)
    return np.asarray(path[b] - path[a], dtype=float)


def _event_data(ax: Any, event: Any) -> NDArray[np.float64]:
    """Data coordinates of a mouse event, also outside the axes (where ``xdata`` is None)."""
    if event.inaxes is ax and event.xdata is not None and event.ydata is not None:
        return np.array([event.xdata, event.ydata], dtype=float)
    return np.asarray(ax.transData.inverted().transform((float(event.x), float(event.y))), dtype=float)


def _plain_ticks(ax: Any) -> None:
    """Tick labels with an ASCII minus sign (some browser fonts drop the Unicode one)."""
    from matplotlib.ticker import FuncFormatter

    plain = FuncFormatter(lambda value, _pos: f"{value:g}")
    ax.xaxis.set_major_formatter(plain)
    ax.yaxis.set_major_formatter(plain)


def _fmt_vec(v: Any) -> str:
    v = np.asarray(v, dtype=float)
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


# --------------------------------------------------------------------------- path editor
class PathEditor(_DragView):
    """Top-down editor of motion paths with draggable pins (Kim et al. 2009, Figure 3).

    Parameters
    ----------
    editor_or_characters : SceneEditor or Motion or sequence of Motion
        An existing :class:`mocaplab.editing.SceneEditor` (shared, not copied),
        or the characters to build one from.
    constraints : sequence of constraints, optional
        Initial constraints when characters are given.
    viewer : bool or MotionViewer
        ``True`` builds a 3D :class:`~mocaplab.widgets.MotionViewer` of the
        edited scene beside the plot (skipped if unavailable), ``False`` none,
        or pass a viewer to use (any object with ``set_motions(motions)``,
        ``set_time(t)`` and a ``widget``).
    figsize : tuple of float
        Figure size in inches (100 dpi).
    pick_radius : float
        How close (pixels) a press must be to a handle or path point.
    backend : {"auto", "ipympl", "agg"}
        Canvas: ipympl widget (default when installed) or Agg image.
    title : str
        Figure title.
    arrow_length : float, optional
        Length (metres) of direction-pin arrows; default 8% of the view diagonal.
    editor_options : dict, optional
        Options for the :class:`~mocaplab.editing.SceneEditor` built from characters.
    viewer_options : dict, optional
        Keyword options for the :class:`~mocaplab.widgets.MotionViewer` (e.g.
        ``{"window_size": (480, 360), "backend": "static"}``).

    Attributes
    ----------
    editor : SceneEditor
    result : EditResult
        The current edit.
    figure, ax, canvas
        The matplotlib figure, its axes and canvas (feed mouse events to
        ``canvas.callbacks.process``).
    status : ipywidgets.HTML
        Position and residual of the dragged handle, or the last error
        (CSS class ``mocaplab-path-status``).
    time : ipywidgets.FloatSlider
        Reference time shown by the markers and the 3D viewer
        (CSS class ``mocaplab-path-time``).
    viewer : MotionViewer or None
        Given the edited motions with ``set_motions`` when the mouse is
        released after an edit (the same viewer and 3D view are kept);
        ``viewer_updates`` counts these updates.
    widget : ipywidgets.Box
        The whole layout (CSS class ``mocaplab-path-editor``).
    """

    status_class = "mocaplab-path-status"
    handles_class = "mocaplab-path-handles"

    def __init__(
        self,
        editor_or_characters: Any,
        constraints: Sequence[Any] | None = None,
        *,
        viewer: Any = True,
        figsize: tuple[float, float] = (6.0, 5.0),
        pick_radius: float = 10.0,
        backend: Backend = "auto",
        title: str = "mocaplab path editor",
        arrow_length: float | None = None,
        editor_options: dict[str, Any] | None = None,
        viewer_options: dict[str, Any] | None = None,
    ) -> None:
        super().__init__(editor_or_characters, constraints, pick_radius=pick_radius, editor_options=editor_options)
        self.title = title
        self.arrow_length = arrow_length
        self.original_paths = [np.array(p, dtype=float) for p in self.result.paths]
        n = len(self.original_paths)
        self.colors = character_colors(n)

        self.figure = Figure(figsize=figsize, dpi=100, layout="constrained")
        self._view = _CanvasView(self.figure, backend)
        self.canvas = self._view.canvas
        if self._view.interactive:
            self.canvas.add_class("mocaplab-path-canvas")
        self.ax = self.figure.add_subplot()
        self.ax.set_title(title)
        self.ax.set_xlabel("x (m)")
        self.ax.set_ylabel("z (m)")
        self.ax.set_aspect("equal", adjustable="datalim")
        _plain_ticks(self.ax)
        self.ax.grid(True, alpha=0.3)

        self._ghosts = [
            self.ax.plot(p[:, 0], p[:, 1], color=c, lw=1.0, ls=":", alpha=0.6)[0]
            for p, c in zip(self.original_paths, self.colors, strict=True)
        ]
        self._lines = [
            self.ax.plot(p[:, 0], p[:, 1], color=c, lw=2.0, label=f"character {k}")[0]
            for k, (p, c) in enumerate(zip(self.original_paths, self.colors, strict=True))
        ]
        self._now = [self.ax.plot([], [], marker="^", ms=9, color=c, mec="k", ls="none")[0] for c in self.colors]
        (self._pins,) = self.ax.plot([], [], "o", ms=11, mfc="white", mec="k", mew=2.0, zorder=5)
        (self._hard_pins,) = self.ax.plot([], [], "o", ms=11, mfc="k", mec="k", mew=2.0, zorder=5)
        (self._arrows,) = self.ax.plot([], [], "-", color="k", lw=1.5, zorder=4)
        (self._tips,) = self.ax.plot([], [], "D", ms=8, mfc="gold", mec="k", zorder=6)
        (self._links,) = self.ax.plot([], [], "--", color="0.3", lw=1.2, zorder=3)
        (self._misses,) = self.ax.plot([], [], "-", color="crimson", lw=1.0, zorder=4)  # soft pin -> path point
        if n > 1:
            self.ax.legend(loc="best", fontsize="small")

        t0, t1 = self._time_range()
        self.time = W.FloatSlider(
            value=t0,
            min=t0,
            max=max(t1, t0 + 1e-6),
            step=self._time_step(),
            description="time (s)",
            readout_format=".2f",
            continuous_update=True,
            layout=W.Layout(width="95%"),
        )
        self.time.add_class("mocaplab-path-time")
        self.time.observe(self._on_time, names="value")

        self.viewer_options = dict(viewer_options or {})
        self.viewer_updates = 0  # how many times the 3D viewer received new motions
        self.viewer = self._make_viewer(viewer)
        self._viewer_box = W.Box([self._viewer_widget()] if self.viewer is not None else [])
        left = W.VBox([self._view.widget, self.time, self.status, self.handles_info])
        self.widget = W.HBox([left, self._viewer_box])
        self.widget.add_class("mocaplab-path-editor")

        self._handles: list[tuple[int, str, NDArray[np.float64]]] = []
        self._connect(self.canvas)
        self._fit_view()
        self._redraw(final=True)
        self._set_status(
            "press a path to pin it; drag a pin to move it; click a pin to unpin; shift-drag for a direction"
        )

    # ------------------------------------------------------------------ public
    def refresh(self) -> None:
        """Redraw from the editor's current result (after editing it in code)."""
        self._apply(_current_result(self.editor))
        self._update_viewer()
        self._fit_view()
        self._redraw(final=True)

    def handle_positions(self) -> list[dict[str, Any]]:
        """Where each handle is drawn.

        Returns
        -------
        list of dict
            ``{"index": constraint index, "kind": "pin" | "direction",
            "data": [x, z] in metres, "pixel": [px, py] in figure pixels from
            the bottom-left (matplotlib display coordinates),
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

    # ------------------------------------------------------------------ drawing
    def _time_range(self) -> tuple[float, float]:
        times = [np.asarray(t, dtype=float) for t in self.result.times]
        return float(min(t[0] for t in times)), float(max(t[-1] for t in times))

    def _update_time_range(self) -> None:
        """Fit the time slider to the (possibly re-timed) reference clock."""
        t0, t1 = self._time_range()
        t1 = max(t1, t0 + 1e-6)
        if (self.time.min, self.time.max) != (t0, t1):
            with self.time.hold_trait_notifications():
                if t0 > self.time.max:
                    self.time.max = t1
                    self.time.min = t0
                else:
                    self.time.min = t0
                    self.time.max = t1

    def _time_step(self) -> float:
        steps = [np.median(np.diff(t)) for t in self.result.times if len(t) > 1]
        return float(min(steps)) if steps else 0.01

    def _make_viewer(self, viewer: Any) -> Any:
        if viewer is False or viewer is None:
            return None
        if viewer is not True:
            if not callable(getattr(viewer, "set_motions", None)):
                raise TypeError(
                    f"Expected `viewer` to be a bool or a viewer with a set_motions(motions) method "
                    f"(a MotionViewer), got {type(viewer).__name__}"
                )
            return viewer
        try:
            from .viewer import MotionViewer
        except ImportError:
            return None
        return MotionViewer(list(self.result.motions), colors=self.colors, **self.viewer_options)

    def _update_viewer(self) -> None:
        """Show the edited motions in the 3D viewer, in place (same viewer, same 3D view)."""
        if self.viewer is None:
            return
        self.viewer.set_motions(list(self.result.motions))
        self.viewer_updates += 1
        self._sync_viewer_time()

    def _viewer_widget(self) -> Any:
        return getattr(self.viewer, "widget", self.viewer)

    def _sync_viewer_time(self) -> None:
        """Move the viewer to the slider's reference time (its clock starts at ``result.clock[0]``)."""
        if self.viewer is None:
            return
        t = float(self.time.value)
        clock = getattr(self.result, "clock", None)
        t0 = float(clock[0]) if clock is not None and len(clock) else self._time_range()[0]
        setter = getattr(self.viewer, "set_time", None)
        if callable(setter):
            setter(t - t0)

    def _collect_handles(self) -> None:
        paths = self.result.paths
        handles: list[tuple[int, str, NDArray[np.float64]]] = []
        pins, hard, arrows, tips, links, misses = [], [], [], [], [], []
        length = self._arrow_len()
        for i, c in enumerate(self.editor.constraints):
            if _is(c, "PinPosition"):
                xy = np.asarray(c.position, dtype=float).reshape(2)
                (hard if getattr(c, "hard", False) else pins).append(xy)
                handles.append((i, "pin", xy))
                k = int(c.character)
                for f in _frames(c):
                    misses += [xy, np.asarray(paths[k][f], dtype=float), np.full(2, np.nan)]
            elif _is(c, "PinDirection"):
                k, f = int(c.character), _frame_of(c)
                base = np.asarray(paths[k][f], dtype=float)
                d = np.asarray(c.direction, dtype=float).reshape(2)
                norm = np.linalg.norm(d)
                tip = base + (d / norm if norm > 0 else d) * length
                arrows += [base, tip, np.full(2, np.nan)]
                tips.append(tip)
                handles.append((i, "direction", tip))
            elif _is(c, "Relative"):
                a, fa = int(c.character), _frame_of(c)
                b, fb = int(c.other), _other_frame_of(c)
                links += [np.asarray(paths[a][fa], float), np.asarray(paths[b][fb], float), np.full(2, np.nan)]
        self._handles = handles

        def put(line: Any, pts: list[NDArray[np.float64]]) -> None:
            arr = np.asarray(pts, dtype=float).reshape(-1, 2)
            line.set_data(arr[:, 0], arr[:, 1])

        put(self._pins, pins)
        put(self._hard_pins, hard)
        put(self._arrows, arrows)
        put(self._tips, tips)
        put(self._links, links)
        put(self._misses, misses)

    def _arrow_len(self) -> float:
        if self.arrow_length is not None:
            return float(self.arrow_length)
        x0, x1 = self.ax.get_xlim()
        y0, y1 = self.ax.get_ylim()
        return 0.08 * float(np.hypot(x1 - x0, y1 - y0))

    def _redraw(self, *, final: bool = False) -> None:
        if final:
            self._update_time_range()
        for line, path in zip(self._lines, self.result.paths, strict=True):
            p = np.asarray(path, dtype=float)
            line.set_data(p[:, 0], p[:, 1])
        self._draw_now()
        self._collect_handles()
        self.handles_info.value = html.escape(json.dumps(self.handle_positions()))
        self._view.draw(final=final)

    def _draw_now(self) -> None:
        t = float(self.time.value)
        for marker, path, times in zip(self._now, self.result.paths, self.result.times, strict=True):
            p = np.asarray(path, dtype=float)
            tt = np.asarray(times, dtype=float)
            if tt[0] - 1e-9 <= t <= tt[-1] + 1e-9:
                marker.set_data([np.interp(t, tt, p[:, 0])], [np.interp(t, tt, p[:, 1])])
            else:
                marker.set_data([], [])

    def _fit_view(self, *, grow_only: bool = False) -> None:
        pts = np.concatenate([np.asarray(p, dtype=float) for p in [*self.result.paths, *self.original_paths]])
        for _, _, xy in self._handles:
            pts = np.vstack([pts, xy])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        pad = 0.15 * max(float(np.max(hi - lo)), 1.0) + 0.25  # room to drag handles near the edges
        lo, hi = lo - pad, hi + pad
        if grow_only:
            (x0, x1), (y0, y1) = sorted(self.ax.get_xlim()), sorted(self.ax.get_ylim())
            if lo[0] >= x0 and hi[0] <= x1 and lo[1] >= y0 and hi[1] <= y1:
                return
            lo = np.minimum(lo, [x0, y0])
            hi = np.maximum(hi, [x1, y1])
        # auto=True only lets the equal aspect widen one range without a warning;
        # set_*lim cancels any pending autoscale, and set_data never requests one
        self.ax.set_xlim(lo[0], hi[0], auto=True)
        self.ax.set_ylim(hi[1], lo[1], auto=True)  # z grows down the page: the scene seen from above
        # settle the layout and the equal aspect now, so that published handle
        # pixels match what the front end will draw
        self.figure.draw_without_rendering()

    # ------------------------------------------------------------------ picking
    def _pick_handle(self, event: Any) -> tuple[int, str, NDArray[np.float64]] | None:
        if not self._handles:
            return None
        xy = np.array([h[2] for h in self._handles])
        px = self.ax.transData.transform(xy)
        d = np.hypot(px[:, 0] - event.x, px[:, 1] - event.y)
        j = int(np.argmin(d))
        return self._handles[j] if d[j] <= self.pick_radius else None

    def _pick_path(self, event: Any) -> tuple[int, int] | None:
        best: tuple[float, int, int] | None = None
        for k, path in enumerate(self.result.paths):
            px = self.ax.transData.transform(np.asarray(path, dtype=float))
            d = np.hypot(px[:, 0] - event.x, px[:, 1] - event.y)
            i = int(np.argmin(d))
            if best is None or d[i] < best[0]:
                best = (float(d[i]), k, i)
        if best is None or best[0] > self.pick_radius:
            return None
        return best[1], best[2]

    # ------------------------------------------------------------------ events
    @_guarded
    def _on_press(self, event: Any) -> None:
        if event.inaxes is not self.ax or event.button != 1 or self._toolbar_busy(self.canvas):
            return
        self.last_error = None
        shift = "shift" in getattr(event, "modifiers", ()) or event.key == "shift"
        press = (float(event.x), float(event.y))
        handle = self._pick_handle(event)
        if handle is not None and not (shift and handle[1] == "pin"):
            index, kind, _ = handle
            c = self.editor.constraints[index]
            anchor = None
            if kind == "direction":
                k, f = int(c.character), _frame_of(c)
                anchor = (k, f, np.array(self.result.paths[k][f], dtype=float))
            self._drag = _Drag(index, kind, press, created=False, anchor=anchor)
            self._describe(index, prefix="picked")
            return
        if handle is not None:  # shift on a pin: a direction at the pinned frame
            c = self.editor.constraints[handle[0]]
            target = (int(c.character), _frame_of(c))
        else:
            target = self._pick_path(event)
            if target is None:
                return
        k, f = target
        path = np.asarray(self.result.paths[k], dtype=float)
        if shift:
            index = self._add(editing.PinDirection(k, f, _tangent(path, f)))
            self._drag = _Drag(index, "direction", press, created=True, anchor=(k, f, path[f].copy()))
        else:
            index = self._add(editing.PinPosition(k, f, path[f].copy()))
            self._drag = _Drag(index, "pin", press, created=True)
        self._redraw()
        self._describe(index, prefix="pinned")

    @_guarded
    def _on_motion(self, event: Any) -> None:
        drag = self._drag
        if drag is None or event.x is None or event.y is None:
            return
        if not drag.moved and not self._moved(event):
            return
        drag.moved = True
        self._move_to(event)

    def _move_to(self, event: Any) -> None:
        """Solve with the dragged handle under the mouse position of ``event``."""
        drag = self._drag
        assert drag is not None  # internal invariant
        drag.last_px = (float(event.x), float(event.y))
        mouse = _event_data(self.ax, event)
        if drag.kind == "pin":
            target = mouse
        else:
            # the direction from where the pinned point was at press time to the mouse
            # (the point itself may move while its direction turns)
            k, f, base = drag.anchor
            d = mouse - base
            if np.linalg.norm(d) < 1e-12:
                return
            target = d
        self._apply(_current_result(self.editor, self.editor.drag(drag.index, target)))
        self._redraw()
        self._describe(drag.index, prefix="drag")

    @_guarded
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
        if self.last_error is not None:
            pass  # keep the error of the failed update on show
        elif not drag.moved and not drag.created:
            c = self.editor.constraints[drag.index]
            self._remove(drag.index)
            self._set_status(
                f"removed {_kind_of(c)} #{drag.index} (character {int(c.character)}, frame {_frame_of(c)})"
            )
        elif drag.moved:
            self._describe(drag.index, prefix="moved")
        self.result = _current_result(self.editor)
        self._update_viewer()
        self._fit_view(grow_only=True)
        self._redraw(final=True)

    @_guarded
    def _on_time(self, change: dict[str, Any]) -> None:
        self._draw_now()
        self._sync_viewer_time()
        self._view.draw(final=True)

    # ------------------------------------------------------------------ status
    def _describe(self, index: int, *, prefix: str) -> None:
        c = self.editor.constraints[index]
        k, f = int(c.character), _frame_of(c)
        p = np.asarray(self.result.paths[k], dtype=float)
        if _is(c, "PinPosition"):
            target = np.asarray(c.position, dtype=float).reshape(2)
            residual = _core_residual(self.result, index)
            if residual is None:
                residual = float(np.max(np.linalg.norm(p[_frames(c)] - target, axis=-1)))
            text = (
                f"{prefix} PinPosition #{index} · character {k} frame {f} · "
                f"target (x, z) = {_fmt_vec(target)} m · path {_fmt_vec(p[f])} m · residual {residual:.2e} m"
            )
        elif _is(c, "PinDirection"):
            d = np.asarray(c.direction, dtype=float).reshape(2)
            t = _tangent(p, f)
            angle = abs(float(np.degrees(np.arctan2(d[0] * t[1] - d[1] * t[0], d @ t))))
            text = (
                f"{prefix} PinDirection #{index} · character {k} frame {f} · "
                f"direction {_fmt_vec(d / max(np.linalg.norm(d), 1e-12))} · tangent off by {angle:.2f} deg"
            )
            residual = _core_residual(self.result, index)
            if residual is not None:
                text += f" · residual {residual:.2e} m"
        else:
            text = f"{prefix} {_kind_of(c)} #{index} · character {k} frame {f}"
        self._set_status(text)


def _core_residual(result: Any, index: int) -> float | None:
    """The editor's own residual of constraint ``index`` (``EditResult.residuals()``), if it reports one."""
    residuals = getattr(result, "residuals", None)
    if not callable(residuals):
        return None
    value = residuals().get(index)
    return None if value is None else float(value)


def _frames(c: Any) -> NDArray[np.int64]:
    """Frames a constraint holds on (one for instant, its sample for variational ones)."""
    frames = getattr(c, "frames", None)
    if frames is None or getattr(c, "frame", None) is not None:
        return np.array([int(c.frame)])
    a, b = int(frames[0]), int(frames[1])
    return np.arange(a, b + 1)  # inclusive, as in mocaplab.editing
