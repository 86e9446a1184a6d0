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
circles drawn at their target position (filled: hard, white: soft, with a
red line to the path point a soft pin pulls on), direction pins are arrows
from the pinned path point whose tip is the handle, the current time is a
triangle on every path; the legend under the plot names every mark.  The
footplants of the edited motions are small footprints on the ground: the
foot contacts the core detects on each clip
(:func:`mocaplab.contacts.foot_contacts` of the editor's
:meth:`~mocaplab.editing.SceneEditor.contact_joints`, so any skeleton's feet
through its joint roles), each drawn where the edited motion plants that
foot, heel to toe.  They follow the drag live for small scenes and are
updated on release for large ones (``live_footplant_frames``).  With
discrete editing (:class:`~mocaplab.editing.DiscreteEditor`) the frames the
last applied transformation changed are highlighted on the path and the
status line names it (the core's own description, e.g. ``character 0:
duplicate frames 40..75 (1.20 s)``).

Undo, Redo and Reset buttons, a "refine on release" box and an "Export BVH"
control sit under the status line (:mod:`widgets._drag`): each drag is one
undo step; on release the edit is refined (feet planted, only the characters
that changed) and the 3D view shows and export writes the refined motions,
one BVH file per character.  Handle positions, in data and in canvas pixels, are published in
the hidden HTML widget ``handles_info`` (CSS class ``mocaplab-path-handles``) as
JSON, for browser tests.  The gesture itself (press, drag, release, click to
remove, errors shown in the status line) is shared with
:class:`~mocaplab.widgets.TimeTrackEditor` in ``widgets/_drag.py``.

Examples
--------
>>> from mocaplab import data, editing                  # doctest: +SKIP
>>> walk = data.cmu("16_15").resample(30)              # doctest: +SKIP
>>> PathEditor([walk], [editing.PinPosition(0, 0, walk.pelvis_positions[0, [0, 2]], hard=True)])  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import ipywidgets as W
import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from mocaplab import editing
from mocaplab.contacts import foot_contacts, intervals_from_mask
from mocaplab.plot import literal

from ._constraints import core_residual, frame_of, is_a, kind_of, other_frame_of
from ._controls import Shortcut, row, viewer_shortcuts
from ._drag import (
    Backend,
    Drag,
    DragView,
    Handle,
    Marks,
    guarded,
    make_canvas,
)
from .scene import character_colors

__all__ = ["PathEditor", "make_canvas"]


def _tangent(path: NDArray[np.float64], i: int) -> NDArray[np.float64]:
    """Central-difference tangent ``p[i+1] - p[i-1]`` (one-sided at the ends), shape (2,)."""
    n = len(path)
    a, b = max(i - 1, 0), min(i + 1, n - 1)
    return np.asarray(path[b] - path[a], dtype=float)


def _fmt_vec(v: Any) -> str:
    v = np.asarray(v, dtype=float)
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


# --------------------------------------------------------------------------- path editor
class PathEditor(DragView):
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
    roles : mapping of role name to joint name, or one per character, optional
        Joint roles fixed by hand for skeletons whose roles cannot be
        inferred (the editor's ``roles`` option, see
        :mod:`mocaplab.editing.scene`): the paths follow their ``pelvis``.
        Not needed otherwise: no joint name is ever required.  The edited
        motions carry the roles to the 3D viewer.
    viewer_options : dict, optional
        Keyword options for the :class:`~mocaplab.widgets.MotionViewer` (e.g.
        ``{"window_size": (480, 360), "backend": "static"}``).
    refine : bool
        Initial state of the "refine on release" box (``refine``): the 3D
        view shows and export writes the full-body refined motions, feet
        planted (:meth:`shown_motions`); ``False``: the plain edit.

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
        Given the edited motions (:meth:`shown_motions`: refined while
        ``refine`` is ticked) with ``set_motions`` when the mouse is
        released after an edit (the same viewer and 3D view are kept);
        ``viewer_updates`` counts these updates.
    refine : ipywidgets.Checkbox
        "refine on release" (CSS class ``mocaplab-refine``).
    history_buttons : HistoryButtons
        Undo / Redo / Reset (CSS classes ``mocaplab-undo``, ``-redo``, ``-reset``).
    export_control : ExportControl
        File name box and "Export BVH" button (CSS ``mocaplab-export``);
        :meth:`export` does the same in code.
    footplants : list of ndarray, shape (n_k, 3)
        Drawn footplants of each character: ground ``(x, z)`` of the planted
        foot and its heel-to-toe angle (radians, from +x towards +z).
    highlighted : tuple (character, first, last) or None
        The frames (inclusive) of the last applied discrete transformation
        drawn highlighted.
    widget : ipywidgets.Box
        The whole layout (CSS class ``mocaplab-path-editor``).
    handles_info : ipywidgets.HTML
        Hidden; :meth:`handle_positions` as JSON (CSS class
        ``mocaplab-path-handles``): kinds ``"pin"`` and ``"direction"``,
        ``data`` is ``[x, z]`` in metres.
    """

    status_class = "mocaplab-path-status"
    handles_class = "mocaplab-path-handles"
    canvas_class = "mocaplab-path-canvas"
    editor_class = "mocaplab-path-editor"
    _refresh_grows_view = False  # refresh() fits the view anew
    #: Footplants follow a drag live up to this many frames in the scene; beyond, they update on release.
    live_footplant_frames = 3000
    #: Footprint size on the ground, metres (heel to toe, across).
    footprint_size = (0.24, 0.10)

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
        self.title = title
        self.arrow_length = arrow_length
        self.original_paths = [np.array(p, dtype=float) for p in self.result.paths]
        n = len(self.original_paths)
        self.colors = character_colors(n)

        self._build_figure(figsize, backend, literal(title))
        self.ax.set_xlabel("x (m)")
        self.ax.set_ylabel("z (m)")
        self.ax.set_aspect("equal", adjustable="datalim")
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
        self._changed = self.ax.plot(
            [], [], "-", color="orange", lw=8.0, alpha=0.45, solid_capstyle="round", zorder=1.5
        )[0]  # frames of the last discrete transformation
        self._feet = PolyCollection([], edgecolors="0.2", linewidths=0.6, alpha=0.7, zorder=2.5)
        self.ax.add_collection(self._feet)
        self._plant_cache: dict[int, tuple[Any, list[tuple[str, str | None, list[int]]]]] = {}
        self.footplants: list[NDArray[np.float64]] = [np.zeros((0, 3)) for _ in range(n)]
        self.highlighted: tuple[int, int, int] | None = None
        self._gesture_transformations = 0
        if 1 < n <= 10:
            self.ax.legend(loc="best", fontsize="small")
        self._legend()

        t0, t1 = self._time_range()
        self.time = W.FloatSlider(
            value=t0,
            min=t0,
            max=max(t1, t0 + 1e-6),
            step=self._time_step(),
            description="time (s)",
            tooltip="the time marked on the paths (triangles) and shown in the 3D view",
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
        left = W.VBox([self._view.widget, self.time, self.status, self.controls, self.handles_info])
        self._open(
            # the 3D view drops below the plot when the notebook has no room beside it (never over it)
            row([left, self._viewer_box], align="flex-start"),
            "press a path to pin it; drag a pin to move it; click a pin to unpin; shift-drag for a direction",
        )

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
        return MotionViewer(self.shown_motions(), colors=self.colors, **self.viewer_options)

    def _edited(self) -> None:
        """After a gesture or a refresh: show the edited motions in the 3D viewer, in place (same viewer, same 3D view)."""
        if self.viewer is None:
            return
        self.viewer.set_motions(self.shown_motions())
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
        handles: list[Handle] = []
        marks = Marks([self._pins, self._hard_pins, self._arrows, self._tips, self._links, self._misses])
        length = self._arrow_len()
        for i, c in enumerate(self._drawn_constraints()):
            if is_a(c, "PinPosition"):
                xy = np.asarray(c.position, dtype=float).reshape(2)
                marks.point(self._hard_pins if getattr(c, "hard", False) else self._pins, xy)
                handles.append((i, "pin", xy))
                k = int(c.character)
                for f in _frames(c):
                    marks.segment(self._misses, xy, paths[k][f])  # soft pin -> its path point
            elif is_a(c, "PinDirection"):
                k, f = int(c.character), frame_of(c)
                base = np.asarray(paths[k][f], dtype=float)
                d = np.asarray(c.direction, dtype=float).reshape(2)
                norm = np.linalg.norm(d)
                tip = base + (d / norm if norm > 0 else d) * length
                marks.segment(self._arrows, base, tip)
                marks.point(self._tips, tip)
                handles.append((i, "direction", tip))
            elif is_a(c, "Relative"):
                a, b = int(c.character), int(c.other)
                marks.segment(self._links, paths[a][frame_of(c)], paths[b][other_frame_of(c)])
        self._handles = handles
        marks.draw()

    def _arrow_len(self) -> float:
        if self.arrow_length is not None:
            return float(self.arrow_length)
        x0, x1 = self.ax.get_xlim()
        y0, y1 = self.ax.get_ylim()
        return 0.08 * float(np.hypot(x1 - x0, y1 - y0))

    def _legend(self) -> None:
        """One legend under the plot naming every kind of mark this view draws (fixed: no layout jump)."""
        entries = [
            (Line2D([], [], color="0.3", lw=1.0, ls=":"), "input path"),
            (Line2D([], [], marker="o", ms=9, mfc="k", mec="k", mew=2.0, ls="none"), "hard pin"),
            (Line2D([], [], marker="o", ms=9, mfc="white", mec="k", mew=2.0, ls="none"), "soft pin"),
            (Line2D([], [], color="crimson", lw=1.0), "soft pin to its path point"),
            (Line2D([], [], color="k", lw=1.5, marker="D", ms=6, mfc="gold", mec="k", markevery=[1]), "direction pin"),
            (Line2D([], [], color="0.3", lw=1.2, ls="--"), "relative offset"),
            (Line2D([], [], marker="^", ms=8, color="0.5", mec="k", ls="none"), "now (time slider)"),
            (Line2D([], [], marker="o", ms=6, mfc=self.colors[0], mec="0.2", alpha=0.7, ls="none"), "footplant"),
        ]
        if _is_discrete(self.editor):
            entries.append((Line2D([], [], color="orange", lw=6.0, alpha=0.45), "last discrete change"))
        handles, labels = zip(*entries, strict=True)
        self.figure.legend(
            handles, labels, loc="outside lower center", ncols=3, fontsize="x-small", frameon=False, handlelength=2.0
        )

    def _draw_result(self, *, final: bool) -> None:
        if final:
            self._update_time_range()
        for line, path in zip(self._lines, self.result.paths, strict=True):
            p = np.asarray(path, dtype=float)
            line.set_data(p[:, 0], p[:, 1])
        self._draw_now()
        self._draw_changed()
        frames = sum(len(p) for p in self.result.paths)
        if final or frames <= self.live_footplant_frames:
            self._draw_footplants()

    def _draw_changed(self) -> None:
        """Highlight the frames of the last discrete transformation (its new frames and seams)."""
        self.highlighted = _changed_frames(self.result)
        if self.highlighted is None:
            self._changed.set_data([], [])
            return
        k, a, b = self.highlighted
        p = np.asarray(self.result.paths[k], dtype=float)[a : b + 1]
        self._changed.set_data(p[:, 0], p[:, 1])

    def _plants(self, k: int) -> list[tuple[str, str | None, list[int]]]:
        """``(ankle, toe, mid frames of its contacts)`` per foot of character ``k``'s (transformed) clip, cached."""
        clip = self.result.characters[k]
        cached = self._plant_cache.get(k)
        if cached is not None and cached[0] is clip:
            return cached[1]
        out: list[tuple[str, str | None, list[int]]] = []
        try:
            contacts = foot_contacts(clip, joints=self.editor.contact_joints(k))
            feet = clip.skeleton.roles.feet()
        except ValueError:  # no feet the roles can name (RolesError): no footplants, the editing works
            feet = []
        for ankle, toe in feet:
            own = [j for j in (ankle, toe) if j is not None and j in contacts.joints]
            if not own:
                continue
            mask = np.any(np.stack([contacts.of(j) for j in own], axis=1), axis=1)
            mids = [(a + b - 1) // 2 for a, b in intervals_from_mask(mask)]
            out.append((ankle, toe if toe in clip.skeleton.names else None, mids))
        self._plant_cache[k] = (clip, out)
        return out

    def _draw_footplants(self) -> None:
        """Footprints where the edited motions plant their feet (heel to toe, on the ground view)."""
        polys, plants, colors = [], [], []
        length, width = self.footprint_size
        u = np.linspace(0.0, 2.0 * np.pi, 13)[:-1]
        outline = np.column_stack([0.5 * length * np.cos(u), 0.5 * width * np.sin(u)])
        for k in range(len(self.result.paths)):
            found = []
            feet = self._plants(k)
            if feet and any(mids for _, _, mids in feet):
                motion = self.result.edited_motions[k]
                g = motion.global_positions()
                names = motion.skeleton.names
                for ankle, toe, mids in feet:
                    if not mids:
                        continue
                    heel = g[mids, names.index(ankle)][:, [0, 2]]
                    if toe is not None:
                        tip = g[mids, names.index(toe)][:, [0, 2]]
                        centre, d = 0.5 * (heel + tip), tip - heel
                    else:
                        tangent = np.asarray(self.result.tangents[k], dtype=float)[mids]
                        centre, d = heel, tangent
                    angle = np.arctan2(d[:, 1], d[:, 0])
                    found.append(np.column_stack([centre, angle]))
            plants_k = np.concatenate(found) if found else np.zeros((0, 3))
            plants.append(plants_k)
            for x, z, a in plants_k:
                c, s_ = np.cos(a), np.sin(a)
                polys.append(outline @ np.array([[c, s_], [-s_, c]]) + (x, z))
                colors.append(self.colors[k])
        self.footplants = plants
        self._feet.set_verts(polys)
        self._feet.set_facecolor(colors or "none")

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
    def _press(self, event: Any, press: tuple[float, float]) -> None:
        self._gesture_transformations = len(getattr(self.result, "transformations", ()) or ())
        shift = "shift" in getattr(event, "modifiers", ()) or event.key == "shift"
        handle = self._pick_handle(event)
        if handle is not None and not (shift and handle[1] == "pin"):
            index, kind, _ = handle
            anchor = None
            if kind == "direction":  # the pinned point at press time
                c = self._drawn_constraints()[index]
                anchor = np.array(self.result.paths[int(c.character)][frame_of(c)], dtype=float)
            self._grab(index, kind, press, anchor)
            return
        target: tuple[int, int] | None
        if handle is not None:  # shift on a pin: a direction at the pinned frame
            c = self.editor.constraints[handle[0]]  # a new constraint lives in the editor's frames
            target = (int(c.character), frame_of(c))
        else:
            target = self._pick_path(event)
        if target is None:
            return
        k, f = target
        path = np.asarray(self.result.paths[k], dtype=float)
        if shift:
            self._create(editing.PinDirection(k, f, _tangent(path, f)), "direction", press, path[f].copy())
        else:
            self._create(editing.PinPosition(k, f, path[f].copy()), "pin", press)

    def _drag_target(self, drag: Drag, mouse: NDArray[np.float64]) -> NDArray[np.float64] | None:
        """A pin's target is the mouse; a direction's, the mouse minus the pinned point.

        The pinned point is taken where it was at press time (``drag.anchor``):
        the point itself may move while its direction turns.
        """
        if drag.kind == "pin":
            return mouse
        d = mouse - drag.anchor
        return None if np.linalg.norm(d) < 1e-12 else d

    @guarded
    def _shortcuts(self) -> list[Shortcut]:
        """Undo and redo, space plays the 3D view, the arrows move the time slider one frame."""
        keys = super()._shortcuts()
        if self.viewer is not None:
            keys += viewer_shortcuts(lambda: self.viewer)[:1]
        return keys + [
            Shortcut(("left",), "\u2190", "earlier", lambda: self._step_time(-1)),
            Shortcut(("right",), "\u2192", "later", lambda: self._step_time(+1)),
        ]

    def _step_time(self, steps: int) -> None:
        """Move the time slider by ``steps`` of its step (clipped to its range)."""
        slider = self.time
        slider.value = float(np.clip(slider.value + steps * slider.step, slider.min, slider.max))

    def _on_time(self, change: dict[str, Any]) -> None:
        self._draw_now()
        self._sync_viewer_time()
        self._view.draw(final=True)

    # ------------------------------------------------------------------ status
    def _transformation_note(self, *, new_only: bool) -> str:
        """`` · applied <the core's description> (frames a-b highlighted)`` for the last transformation."""
        done = tuple(getattr(self.result, "transformations", ()) or ())
        if not done or (new_only and len(done) <= self._gesture_transformations) or self.highlighted is None:
            return ""
        _, a, b = self.highlighted
        return f" · applied {done[-1]} (frames {a}-{b} highlighted)"

    def _history_note(self) -> str:
        return self._transformation_note(new_only=False)

    def _describe(self, index: int, *, prefix: str) -> None:
        self._set_status(self._description(index, prefix=prefix) + self._transformation_note(new_only=True))

    def _description(self, index: int, *, prefix: str) -> str:
        c = self._drawn_constraints()[index]
        k, f = int(c.character), frame_of(c)
        who = self._character(k)
        p = np.asarray(self.result.paths[k], dtype=float)
        if is_a(c, "PinPosition"):
            target = np.asarray(c.position, dtype=float).reshape(2)
            residual = core_residual(self.result, index)
            if residual is None:
                residual = float(np.max(np.linalg.norm(p[_frames(c)] - target, axis=-1)))
            text = (
                f"{prefix} PinPosition #{index} · {who} frame {f} · "
                f"target (x, z) = {_fmt_vec(target)} m · path {_fmt_vec(p[f])} m · residual {residual:.2e} m"
            )
        elif is_a(c, "PinDirection"):
            d = np.asarray(c.direction, dtype=float).reshape(2)
            t = _tangent(p, f)
            angle = abs(float(np.degrees(np.arctan2(d[0] * t[1] - d[1] * t[0], d @ t))))
            text = (
                f"{prefix} PinDirection #{index} · {who} frame {f} · "
                f"direction {_fmt_vec(d / max(np.linalg.norm(d), 1e-12))} · tangent off by {angle:.2f} deg"
            )
            residual = core_residual(self.result, index)
            if residual is not None:
                text += f" · residual {residual:.2e} m"
        else:
            text = f"{prefix} {kind_of(c)} #{index} · {who} frame {f}"
        return text


def _is_discrete(editor: Any) -> bool:
    """Whether the editor applies discrete transformations (a DiscreteEditor)."""
    return hasattr(editor, "discrete_options") or hasattr(editor, "applied")


def _changed_frames(result: Any) -> tuple[int, int, int] | None:
    """``(character, first, last)``: the frames (inclusive, seams included) of the last transformation.

    Its new frames ``Transformation.frames`` in the transformed clip, with the
    frame before and after (a deletion's seam is those two frames).
    """
    done = tuple(getattr(result, "transformations", ()) or ())
    if not done:
        return None
    t = done[-1]
    k = int(t.character)
    n = len(result.paths[k])
    a, b = (int(v) for v in t.frames)
    return k, max(a - 1, 0), min(b, n - 1)


def _frames(c: Any) -> NDArray[np.int64]:
    """Frames a constraint holds on (one for instant, its sample for variational ones)."""
    frames = getattr(c, "frames", None)
    if frames is None or getattr(c, "frame", None) is not None:
        return np.array([int(c.frame)])
    return np.arange(int(frames[0]), int(frames[1]))  # half-open, as in mocaplab.editing
