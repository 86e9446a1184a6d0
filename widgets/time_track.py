"""Drag time handles on per-character tracks (Kim et al. 2009, section 4.4, Figure 5).

Each character has one horizontal track.  Its frames are ticks placed at their
*reference times* (``EditResult.times[k]``): evenly spaced before any edit,
squeezed where the character is sped up and spread where it is slowed down.
The original, uniform ticks are drawn faintly just above each track, as in the
top half of Figure 5.

=====================================  ===========================================
gesture                                 edit
=====================================  ===========================================
press on a frame tick, drag             ``add(AbsoluteTime(k, frame, t))`` then
                                        ``drag(i, t)`` on every motion event
press on a tick, release                pin that frame at its current time
press on a time handle, drag            ``drag(i, t)`` (AbsoluteTime: new time)
press on a duration's end handle, drag  ``drag(i, d)`` with ``d`` = mouse time
                                        minus the start frame's time at press
press on any handle, release unmoved    ``remove(i)``
=====================================  ===========================================

``Sync`` constraints are drawn as links between the two tracks.  All the
mathematics is in :class:`mocaplab.editing.SceneEditor`; this view only draws its
result.  Handle positions (data: ``(time, track)``; pixels) are published as
JSON in the hidden HTML widget ``handles_info`` (CSS class
``mocaplab-time-handles``) for browser tests.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from typing import Any

import ipywidgets as W
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from numpy.typing import NDArray

from mocaplab import editing

from .path_editor import (
    Backend,
    _CanvasView,
    _core_residual,
    _current_result,
    _Drag,
    _DragView,
    _event_data,
    _frame_of,
    _guarded,
    _is,
    _kind_of,
    _other_frame_of,
    _plain_ticks,
    character_colors,
)

__all__ = ["TimeTrackEditor"]


class TimeTrackEditor(_DragView):
    """Per-character time tracks with draggable time handles (Figure 5 of Kim et al. 2009).

    Parameters
    ----------
    editor_or_characters : SceneEditor or Motion or sequence of Motion
        An existing :class:`mocaplab.editing.SceneEditor` (shared) or the
        characters to build one from.
    constraints : sequence of constraints, optional
        Initial constraints when characters are given.
    labels : sequence of str, optional
        Track names (default ``"character k"`` or the motion's name).
    figsize : tuple of float, optional
        Inches (100 dpi); default width 8, height 1.2 + 0.9 per track.
    pick_radius : float
        How close (pixels) a press must be to a handle or tick.
    backend : {"auto", "ipympl", "agg"}
        Canvas: ipympl widget (default when installed) or Agg image.
    title : str
        Figure title.
    editor_options : dict, optional
        Options for the SceneEditor built from characters.

    Attributes
    ----------
    editor, result, figure, ax, canvas
        As for :class:`~mocaplab.widgets.PathEditor`; the x axis is reference
        time in seconds and track ``k`` lies on ``y = k`` (track 0 on top).
    status : ipywidgets.HTML
        Time and residual of the dragged handle, the minimum time step, or the
        last error (CSS class ``mocaplab-time-status``).
    widget : ipywidgets.VBox
        The layout (CSS class ``mocaplab-time-editor``).
    """

    status_class = "mocaplab-time-status"
    handles_class = "mocaplab-time-handles"

    def __init__(
        self,
        editor_or_characters: Any,
        constraints: Sequence[Any] | None = None,
        *,
        labels: Sequence[str] | None = None,
        figsize: tuple[float, float] | None = None,
        pick_radius: float = 8.0,
        backend: Backend = "auto",
        title: str = "mocaplab time tracks",
        editor_options: dict[str, Any] | None = None,
    ) -> None:
        super().__init__(editor_or_characters, constraints, pick_radius=pick_radius, editor_options=editor_options)
        self.original_times = [np.array(t, dtype=float) for t in self.result.times]
        n = len(self.original_times)
        if labels is None:
            motions = getattr(self.editor, "characters", None)
            names = [getattr(m, "name", "") for m in motions] if motions is not None else [""] * n
            labels = [f"{k}: {name}" if name else f"character {k}" for k, name in enumerate(names)]
        if len(labels) != n:
            raise ValueError(f"Expected {n} `labels` (one per character), got {len(labels)}")
        self.labels = list(labels)
        self.colors = character_colors(n)

        if figsize is None:
            figsize = (8.0, 1.2 + 0.9 * n)
        self.figure = Figure(figsize=figsize, dpi=100, layout="constrained")
        self._view = _CanvasView(self.figure, backend)
        self.canvas = self._view.canvas
        if self._view.interactive:
            self.canvas.add_class("mocaplab-time-canvas")
        self.ax = self.figure.add_subplot()
        self.ax.set_title(title)
        self.ax.set_xlabel("reference time (s)")
        _plain_ticks(self.ax)
        self.ax.set_yticks(range(n), self.labels)
        self.ax.set_ylim(n - 0.4, -0.7)  # track 0 on top
        self.ax.grid(True, axis="x", alpha=0.3)
        for k, (t, c) in enumerate(zip(self.original_times, self.colors, strict=True)):
            self.ax.add_collection(_ticks(t, k - 0.42, k - 0.3, color=c, alpha=0.35, lw=0.6))
            self.ax.plot([t[0], t[-1]], [k, k], color=c, lw=1.0, alpha=0.6)
        self._tracks = [_ticks(t, k - 0.2, k + 0.2, color=c, lw=0.8) for k, (t, c) in enumerate(zip(self.original_times, self.colors, strict=True))]
        for coll in self._tracks:
            self.ax.add_collection(coll)
        (self._abs,) = self.ax.plot([], [], "v", ms=11, mfc="white", mec="k", mew=2.0, zorder=5)
        (self._abs_hard,) = self.ax.plot([], [], "v", ms=11, mfc="k", mec="k", mew=2.0, zorder=5)
        (self._dur_bars,) = self.ax.plot([], [], "-", color="k", lw=2.5, alpha=0.7, zorder=4)
        (self._dur_ends,) = self.ax.plot([], [], "s", ms=9, mfc="gold", mec="k", zorder=6)
        (self._syncs,) = self.ax.plot([], [], "-", color="crimson", lw=1.5, zorder=3)

        self._handles: list[tuple[int, str, NDArray[np.float64]]] = []
        self._connect(self.canvas)
        self.widget = W.VBox([self._view.widget, self.status, self.handles_info])
        self.widget.add_class("mocaplab-time-editor")
        self._fit_view()
        self._redraw(final=True)
        self._set_status("press a frame tick to pin its time; drag a handle to move it; click a handle to remove it")

    # ------------------------------------------------------------------ public
    def refresh(self) -> None:
        """Redraw from the editor's current result (after editing it in code)."""
        self._apply(_current_result(self.editor))
        self._fit_view(grow_only=True)
        self._redraw(final=True)

    def handle_positions(self) -> list[dict[str, Any]]:
        """Where each handle is drawn: ``{"index", "kind", "data": [time, track], "pixel", "css"}``.

        ``pixel`` is in matplotlib display coordinates (figure pixels from the
        bottom-left), ``css`` in CSS pixels from the canvas' top-left corner.
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
    def _fit_view(self, *, grow_only: bool = False) -> None:
        times = [np.asarray(t, dtype=float) for t in [*self.result.times, *self.original_times]]
        lo = min(float(t.min()) for t in times)
        hi = max(float(t.max()) for t in times)
        for _, _, xy in self._handles:
            lo, hi = min(lo, float(xy[0])), max(hi, float(xy[0]))
        pad = 0.05 * max(hi - lo, 0.5)
        lo, hi = lo - pad, hi + pad
        if grow_only:
            x0, x1 = self.ax.get_xlim()
            if lo >= x0 and hi <= x1:
                return
            lo, hi = min(lo, x0), max(hi, x1)
        self.ax.set_xlim(lo, hi)
        self.figure.draw_without_rendering()  # settle the layout: handle pixels as drawn

    def _redraw(self, *, final: bool = False) -> None:
        for k, (coll, times) in enumerate(zip(self._tracks, self.result.times, strict=True)):
            coll.set_segments(_segments(np.asarray(times, dtype=float), k - 0.2, k + 0.2))
        self._collect_handles()
        self.handles_info.value = html.escape(json.dumps(self.handle_positions()))
        self._view.draw(final=final)

    def _collect_handles(self) -> None:
        times = [np.asarray(t, dtype=float) for t in self.result.times]
        handles: list[tuple[int, str, NDArray[np.float64]]] = []
        soft, hard, bars, ends, syncs = [], [], [], [], []
        nan = np.full(2, np.nan)
        for i, c in enumerate(self.editor.constraints):
            if _is(c, "AbsoluteTime"):
                k = int(c.character)
                xy = np.array([float(c.time), k - 0.25])
                (hard if getattr(c, "hard", False) else soft).append(xy)
                handles.append((i, "time", xy))
            elif _is(c, "Duration"):
                k, f = int(c.character), int(c.frame)
                start = times[k][f]
                end = np.array([start + float(c.duration), k + 0.3])
                bars += [np.array([start, k + 0.3]), end, nan]
                ends.append(end)
                handles.append((i, "duration", end))
            elif _is(c, "Sync"):
                a, fa = int(c.character), _frame_of(c)
                b, fb = int(c.other), _other_frame_of(c)
                syncs += [np.array([times[a][fa], a]), np.array([times[b][fb], b]), nan]
        self._handles = handles

        def put(line: Any, pts: list[NDArray[np.float64]]) -> None:
            arr = np.asarray(pts, dtype=float).reshape(-1, 2)
            line.set_data(arr[:, 0], arr[:, 1])

        put(self._abs, soft)
        put(self._abs_hard, hard)
        put(self._dur_bars, bars)
        put(self._dur_ends, ends)
        put(self._syncs, syncs)

    # ------------------------------------------------------------------ picking
    def _pick_handle(self, event: Any) -> tuple[int, str, NDArray[np.float64]] | None:
        if not self._handles:
            return None
        px = self.ax.transData.transform(np.array([h[2] for h in self._handles]))
        d = np.hypot(px[:, 0] - event.x, px[:, 1] - event.y)
        j = int(np.argmin(d))
        return self._handles[j] if d[j] <= self.pick_radius else None

    def _pick_tick(self, event: Any) -> tuple[int, int] | None:
        # the track under the mouse, then the nearest tick in time (pixels)
        k = int(round(event.ydata))
        if not 0 <= k < len(self.result.times) or abs(event.ydata - k) > 0.35:
            return None
        t = np.asarray(self.result.times[k], dtype=float)
        px = self.ax.transData.transform(np.column_stack([t, np.full(t.shape, float(k))]))
        d = np.abs(px[:, 0] - event.x)
        i = int(np.argmin(d))
        return (k, i) if d[i] <= self.pick_radius else None

    # ------------------------------------------------------------------ events
    @_guarded
    def _on_press(self, event: Any) -> None:
        if event.inaxes is not self.ax or event.button != 1 or self._toolbar_busy(self.canvas):
            return
        self.last_error = None
        press = (float(event.x), float(event.y))
        handle = self._pick_handle(event)
        if handle is not None:
            index, kind, _ = handle
            c = self.editor.constraints[index]
            anchor = float(np.asarray(self.result.times[int(c.character)])[int(c.frame)]) if kind == "duration" else None
            self._drag = _Drag(index, kind, press, created=False, anchor=anchor)
            self._describe(index, prefix="picked")
            return
        tick = self._pick_tick(event)
        if tick is None:
            return
        k, f = tick
        t = float(np.asarray(self.result.times[k])[f])
        index = self._add(editing.AbsoluteTime(k, f, t))
        self._drag = _Drag(index, "time", press, created=True)
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
        """Solve with the dragged handle at the time under the mouse (also outside the axes)."""
        drag = self._drag
        assert drag is not None  # internal invariant
        drag.last_px = (float(event.x), float(event.y))
        x = float(_event_data(self.ax, event)[0])
        target = x if drag.kind == "time" else x - drag.anchor
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
            self._set_status(f"removed {_kind_of(c)} #{drag.index} (character {int(c.character)}, frame {_frame_of(c)})")
        elif drag.moved:
            self._describe(drag.index, prefix="moved")
        self.result = _current_result(self.editor)
        self._fit_view(grow_only=True)
        self._redraw(final=True)

    # ------------------------------------------------------------------ status
    def _describe(self, index: int, *, prefix: str) -> None:
        c = self.editor.constraints[index]
        k, f = int(c.character), _frame_of(c)
        t = np.asarray(self.result.times[k], dtype=float)
        steps = [np.diff(np.asarray(tt, dtype=float)) for tt in self.result.times if len(tt) > 1]
        min_step = min(float(s.min()) for s in steps) if steps else float("nan")
        if _is(c, "AbsoluteTime"):
            residual = abs(t[f] - float(c.time))
            text = f"{prefix} AbsoluteTime #{index} · character {k} frame {f} · t = {float(c.time):.3f} s"
        elif _is(c, "Duration"):
            e = int(c.end_frame)
            residual = abs(t[e] - t[f] - float(c.duration))
            text = f"{prefix} Duration #{index} · character {k} frames {f}-{e} · duration {float(c.duration):.3f} s"
        else:
            residual = float("nan")
            text = f"{prefix} {_kind_of(c)} #{index} · character {k} frame {f}"
        core = _core_residual(self.result, index)
        residual = residual if core is None else core
        self._set_status(f"{text} · residual {residual:.2e} s · min step {min_step:.4f} s")


def _segments(times: NDArray[np.float64], y0: float, y1: float) -> NDArray[np.float64]:
    """Vertical tick segments at ``times`` from ``y0`` to ``y1``, shape (F, 2, 2)."""
    seg = np.empty((len(times), 2, 2))
    seg[:, :, 0] = times[:, None]
    seg[:, 0, 1] = y0
    seg[:, 1, 1] = y1
    return seg


def _ticks(times: NDArray[np.float64], y0: float, y1: float, **style: Any) -> LineCollection:
    return LineCollection(_segments(times, y0, y1), **style)
