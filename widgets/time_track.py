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
``mocaplab-time-handles``) for browser tests.  The gesture machinery is shared
with :class:`~mocaplab.widgets.PathEditor` (``widgets/_drag.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import ipywidgets as W
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from mocaplab import editing
from mocaplab.plot import literal

from ._constraints import core_residual, frame_of, is_a, kind_of, other_frame_of
from ._drag import (
    Backend,
    Drag,
    DragView,
    Handle,
    Marks,
)
from .scene import character_colors

__all__ = ["TimeTrackEditor"]


class TimeTrackEditor(DragView):
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
    roles : mapping of role name to joint name, or one per character, optional
        Joint roles fixed by hand (the editor's ``roles`` option), for
        skeletons whose roles cannot be inferred; not needed otherwise.
    refine : bool
        Initial state of the "refine on release" box: export writes the
        refined motions (as :class:`~mocaplab.widgets.PathEditor`).

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
    handles_info : ipywidgets.HTML
        Hidden; :meth:`handle_positions` as JSON (CSS class
        ``mocaplab-time-handles``): kinds ``"time"`` and ``"duration"``,
        ``data`` is ``[time, track]``.
    """

    status_class = "mocaplab-time-status"
    handles_class = "mocaplab-time-handles"
    canvas_class = "mocaplab-time-canvas"
    editor_class = "mocaplab-time-editor"

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
        roles: Any = None,
        refine: bool = True,
    ) -> None:
        super().__init__(
            editor_or_characters,
            constraints,
            pick_radius=pick_radius,
            editor_options=editor_options,
            roles=roles,
            refine=refine,
        )
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
        self._build_figure(figsize, backend, literal(title))
        self.ax.set_xlabel("reference time (s)")
        self.ax.set_yticks(range(n), [literal(label) for label in self.labels])
        self.ax.set_ylim(n - 0.4, -0.7)  # track 0 on top
        self.ax.grid(True, axis="x", alpha=0.3)
        for k, (t, c) in enumerate(zip(self.original_times, self.colors, strict=True)):
            self.ax.add_collection(_ticks(t, k - 0.42, k - 0.3, color=c, alpha=0.35, lw=0.6))
            self.ax.plot([t[0], t[-1]], [k, k], color=c, lw=1.0, alpha=0.6)
        self._tracks = [
            _ticks(t, k - 0.2, k + 0.2, color=c, lw=0.8)
            for k, (t, c) in enumerate(zip(self.original_times, self.colors, strict=True))
        ]
        for coll in self._tracks:
            self.ax.add_collection(coll)
        (self._abs,) = self.ax.plot([], [], "v", ms=11, mfc="white", mec="k", mew=2.0, zorder=5)
        (self._abs_hard,) = self.ax.plot([], [], "v", ms=11, mfc="k", mec="k", mew=2.0, zorder=5)
        (self._dur_bars,) = self.ax.plot([], [], "-", color="k", lw=2.5, alpha=0.7, zorder=4)
        (self._dur_ends,) = self.ax.plot([], [], "s", ms=9, mfc="gold", mec="k", zorder=6)
        (self._syncs,) = self.ax.plot([], [], "-", color="crimson", lw=1.5, zorder=3)
        self._legend()
        self._open(
            W.VBox([self._view.widget, self.status, self.controls, self.handles_info]),
            "press a frame tick to pin its time; drag a handle to move it; click a handle to remove it",
        )

    # ------------------------------------------------------------------ drawing
    def _legend(self) -> None:
        """A legend right of the tracks naming the handle kinds (hard and soft times apart)."""
        entries = [
            (Line2D([], [], marker="v", ms=9, mfc="k", mec="k", mew=2.0, ls="none"), "hard time"),
            (Line2D([], [], marker="v", ms=9, mfc="white", mec="k", mew=2.0, ls="none"), "soft time"),
            (
                Line2D([], [], color="k", lw=2.5, alpha=0.7, marker="s", ms=7, mfc="gold", mec="k", markevery=[1]),
                "duration",
            ),
            (Line2D([], [], color="crimson", lw=1.5), "sync"),
        ]
        handles, labels = zip(*entries, strict=True)
        self.figure.legend(handles, labels, loc="outside right upper", fontsize="x-small", frameon=False)

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

    def _draw_result(self, *, final: bool) -> None:
        for k, (coll, times) in enumerate(zip(self._tracks, self.result.times, strict=True)):
            coll.set_segments(list(_segments(np.asarray(times, dtype=float), k - 0.2, k + 0.2)))

    def _collect_handles(self) -> None:
        times = [np.asarray(t, dtype=float) for t in self.result.times]
        handles: list[Handle] = []
        marks = Marks([self._abs, self._abs_hard, self._dur_bars, self._dur_ends, self._syncs])
        for i, c in enumerate(self._drawn_constraints()):
            if is_a(c, "AbsoluteTime"):
                k = int(c.character)
                xy = np.array([float(c.time), k - 0.25])
                marks.point(self._abs_hard if getattr(c, "hard", False) else self._abs, xy)
                handles.append((i, "time", xy))
            elif is_a(c, "Duration"):
                k, f = int(c.character), int(c.frame)
                start = times[k][f]
                end = np.array([start + float(c.duration), k + 0.3])
                marks.segment(self._dur_bars, (start, k + 0.3), end)
                marks.point(self._dur_ends, end)
                handles.append((i, "duration", end))
            elif is_a(c, "Sync"):
                a, fa = int(c.character), frame_of(c)
                b, fb = int(c.other), other_frame_of(c)
                marks.segment(self._syncs, (times[a][fa], a), (times[b][fb], b))
        self._handles = handles
        marks.draw()

    # ------------------------------------------------------------------ picking
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
    def _press(self, event: Any, press: tuple[float, float]) -> None:
        handle = self._pick_handle(event)
        if handle is not None:
            index, kind, _ = handle
            anchor = None
            if kind == "duration":  # the start frame's time at press time
                c = self.editor.constraints[index]
                anchor = float(np.asarray(self.result.times[int(c.character)])[int(c.frame)])
            self._grab(index, kind, press, anchor)
            return
        tick = self._pick_tick(event)
        if tick is None:
            return
        k, f = tick
        self._create(editing.AbsoluteTime(k, f, float(np.asarray(self.result.times[k])[f])), "time", press)

    def _drag_target(self, drag: Drag, mouse: NDArray[np.float64]) -> float:
        """The time under the mouse (an AbsoluteTime's target), minus the start's time for a Duration."""
        x = float(mouse[0])
        return x if drag.kind == "time" else x - drag.anchor

    # ------------------------------------------------------------------ status
    def _describe(self, index: int, *, prefix: str) -> None:
        c = self._drawn_constraints()[index]
        k, f = int(c.character), frame_of(c)
        who = self._character(k)
        t = np.asarray(self.result.times[k], dtype=float)
        steps = [np.diff(np.asarray(tt, dtype=float)) for tt in self.result.times if len(tt) > 1]
        min_step = min(float(s.min()) for s in steps) if steps else float("nan")
        if is_a(c, "AbsoluteTime"):
            residual = abs(t[f] - float(c.time))
            text = f"{prefix} AbsoluteTime #{index} · {who} frame {f} · t = {float(c.time):.3f} s"
        elif is_a(c, "Duration"):
            e = int(c.end_frame)
            residual = abs(t[e] - t[f] - float(c.duration))
            text = f"{prefix} Duration #{index} · {who} frames {f}-{e} · duration {float(c.duration):.3f} s"
        else:
            residual = float("nan")
            text = f"{prefix} {kind_of(c)} #{index} · {who} frame {f}"
        core = core_residual(self.result, index)
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
    return LineCollection(list(_segments(times, y0, y1)), **style)
