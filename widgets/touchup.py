"""Step through a physical touch-up (Shin et al. 2003) and watch the ZMP settle.

>>> from mocaplab.widgets import TouchUpStepper          # doctest: +SKIP
>>> TouchUpStepper(bent_walk, body=fit.body)             # doctest: +SKIP

The widget is a thin view over :class:`mocaplab.physics.TouchUpSession`:

* **step** / **back** buttons move through the adjustments (a step already
  computed is reused), **reset** goes back to the input (step 0, the
  schedule the stepper started with); the forward button carries the CSS
  class ``mocaplab-touchup-step``, the reset button ``mocaplab-reset``;
* a header with the measures of the step shown: on the **ground**, the mean
  ZMP distance over the ground frames (class ``mocaplab-touchup-mean``; a
  flight step may raise it: the frames next to a flight take the flight's
  change of velocity), and the same without the frames at each end of the
  clip that no step corrects (:attr:`~mocaplab.physics.TouchUpState.edge_frames`);
  for each **flight** (class
  ``mocaplab-touchup-flight``), the gravity fitted to the centre of mass
  (9.81 m/s^2 when it flies a parabola; "too short to fit" for a flight of
  fewer than 3 frames) and the spread of the angular
  momentum about its mean (0 when constant), computed by the core
  (:attr:`mocaplab.physics.TouchUpState.flights`);
* a **schedule table** edits each adjustment's link sets (joint names or
  presets, comma separated; presets come from the skeleton's joint roles,
  so they work on any naming convention), ``sigma`` (seconds), ``rho`` and
  stage; an edit applies from the current step on;
* **Figure 8**: the ZMP's distance outside the support polygon on every
  frame, for the input and for the current step;
* **Figure 9**: the mean distance after each step so far (the mean label
  also names the best complete pass so far and counts ground frames
  without a ZMP, which the means leave out);
* a **3D view** (:class:`~mocaplab.widgets.MotionViewer`) of the input (grey)
  and the current motion with its centre of mass, its ZMP and its support
  polygon drawn under it;
* **Export BVH** of the motion of the step shown.

The stepper takes any Motion (the presets and contacts come from the
skeleton's joint roles; ``roles=`` overrides them).  Callbacks show their
exceptions, HTML-escaped, in the widget's status line, and every control is
then set back from the session, so none disagrees with it.
"""

from __future__ import annotations

import html
import io
from collections.abc import Sequence
from typing import Any

import ipywidgets as W
import numpy as np
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine

from mocaplab.motion import Motion
from mocaplab.physics import Adjustment, TouchUpSession
from mocaplab.plot import literal

from ._controls import ExportControl, Shortcut, bind_keys, error_html, export_name, row, viewer_shortcuts
from ._drag import TOOLBAR_PX

__all__ = ["TouchUpStepper", "plot_zmp_distance", "plot_mean_distance", "plot_balance_top"]

STEP_CLASS = "mocaplab-touchup-step"
BACK_CLASS = "mocaplab-touchup-back"
MEAN_CLASS = "mocaplab-touchup-mean"
FLIGHT_CLASS = "mocaplab-touchup-flight"
RESET_CLASSES = ("mocaplab-reset", "mocaplab-touchup-reset")
INPUT_COLOR = "#9a9a9a"
CURRENT_COLOR = "#1f77b4"


def _canvas(figure: Figure) -> tuple[Any, Any]:
    """(canvas, widget): an ipympl canvas widget, or Agg drawn into an Image."""
    try:
        from .path_editor import make_canvas
    except ImportError:  # pragma: no cover - the path editor ships with the package
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        canvas: Any = FigureCanvasAgg(figure)
    else:
        canvas = make_canvas(figure)
    if isinstance(canvas, W.DOMWidget):
        return canvas, canvas
    return canvas, W.Image(format="png")


class _Plot:
    def __init__(self, figure: Figure) -> None:
        self.figure = figure
        self.canvas, self.widget = _canvas(figure)
        if self.widget is self.canvas:
            # ipympl's toolbar floats over the canvas' left edge: lay the axes out to its right
            free = min(TOOLBAR_PX / (figure.get_figwidth() * figure.dpi), 0.2)
            figure.set_layout_engine(ConstrainedLayoutEngine(rect=(free, 0.0, 1.0 - free, 1.0)))
            self.canvas.layout.flex = "0 0 auto"  # as wide as the figure

    def draw(self) -> None:
        if self.widget is self.canvas:
            self.canvas.draw_idle()
        else:
            buf = io.BytesIO()
            self.figure.savefig(buf, format="png")
            self.widget.value = buf.getvalue()


def _names(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.replace(";", ",").split(",") if t.strip())


#: The schedule's columns: heading, what its tooltip says, CSS grid track.  The headings are written once
#: above the rows (not as a description on every control), so a row fits on one line of a laptop's notebook.
SCHEDULE_COLUMNS = (
    ("", "", "max-content"),
    ("S2 (rotated)", "the links rotated: joint names (each with its descendants) or presets", "minmax(120px, 2fr)"),
    ("S3 (kept global)", "links carried by S2 keeping their global orientation (none in flight)", "minmax(100px, 2fr)"),
    ("sigma (s)", "width of the smoothing kernel of the displacement map, in seconds", "86px"),
    ("rho", "damping: the share of the computed adjustment applied", "minmax(150px, 1.5fr)"),
    ("stage", "which frames the adjustment corrects: ground (ZMP, s3.3) or flight (s3.4)", "92px"),
)


class _Row:
    """Controls of one adjustment of the schedule: one line of the schedule's grid (:data:`SCHEDULE_COLUMNS`)."""

    def __init__(self, k: int, adj: Adjustment) -> None:
        self.k = k
        fill = {"width": "auto", "min_width": "0"}  # each control fills its column of the grid
        # sent on Enter or leaving the box, not per keystroke (a half-typed name is no joint)
        self.s2 = W.Text(
            value=", ".join(adj.s2),
            tooltip="S2, the links rotated: joint names (each with its descendants) or presets such as lower_body, "
            "comma-separated; Enter applies",
            continuous_update=False,
            layout=W.Layout(**fill),
        )
        self.s3 = W.Text(
            value=", ".join(adj.s3),
            tooltip="S3, links carried by S2 that keep their global orientation (empty in flight); Enter applies",
            continuous_update=False,
            layout=W.Layout(**fill),
        )
        self.sigma = W.BoundedFloatText(
            value=round(adj.sigma, 4),
            min=0.0,
            max=10.0,
            step=1 / 30,
            tooltip="sigma, the width of the smoothing kernel of this adjustment's displacement map, in seconds",
            layout=W.Layout(**fill),
        )
        self.rho = W.FloatSlider(
            value=adj.rho,
            min=0.05,
            max=1.0,
            step=0.05,
            tooltip="rho, the damping: the share of the computed adjustment applied (1: all of it)",
            continuous_update=False,
            layout=W.Layout(**fill),
        )
        self.stage = W.Dropdown(
            options=["ground", "flight"],
            value=adj.stage,
            tooltip="which frames this adjustment corrects: ground (ZMP balance, s3.3) or flight (s3.4)",
            layout=W.Layout(**fill),
        )
        self.cells: list[W.Widget] = [W.Label(f"{k + 1}."), self.s2, self.s3, self.sigma, self.rho, self.stage]

    def set(self, adj: Adjustment) -> None:
        self.s2.value = ", ".join(adj.s2)
        self.s3.value = ", ".join(adj.s3)
        self.sigma.value = round(adj.sigma, 4)
        self.rho.value = adj.rho
        self.stage.value = adj.stage

    def changes(self, adj: Adjustment) -> dict[str, Any]:
        """Fields whose control differs from ``adj``."""
        out: dict[str, Any] = {}
        if _names(self.s2.value) != adj.s2:
            out["s2"] = _names(self.s2.value)
        if _names(self.s3.value) != adj.s3:
            out["s3"] = _names(self.s3.value)
        if abs(float(self.sigma.value) - round(adj.sigma, 4)) > 1e-9:
            out["sigma"] = float(self.sigma.value)
        if abs(float(self.rho.value) - adj.rho) > 1e-9:
            out["rho"] = float(self.rho.value)
        if self.stage.value != adj.stage:
            out["stage"] = self.stage.value
        return out


def _schedule_grid(rows: Sequence[_Row]) -> W.GridBox:
    """The schedule as a grid: the column headings (with tooltips) over one line per adjustment."""
    headings = [
        W.HTML(f"<span title='{html.escape(tip, quote=True)}'>{html.escape(name)}</span>")
        for name, tip, _ in SCHEDULE_COLUMNS
    ]
    grid = W.GridBox(
        headings + [cell for r in rows for cell in r.cells],
        layout=W.Layout(
            grid_template_columns=" ".join(track for _, _, track in SCHEDULE_COLUMNS),
            grid_gap="2px 8px",
            align_items="center",
            max_width="860px",
            overflow="auto",  # narrower than the columns' minimum (about 620 px): scrolls, never overlaps
        ),
    )
    return grid


# --------------------------------------------------------------------------- static figures
def _axes(ax: Any, size: tuple[float, float]) -> Any:
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=size, layout="constrained")[1]


def plot_zmp_distance(curves: dict[str, Any], *, fps: float, ax: Any = None) -> Any:
    """Figure 8: distance of the ZMP outside the support polygon per frame (mm).

    ``curves`` maps a label to distances in metres, shape (F,) (NaN in
    flight, drawn as gaps).  Returns the axes.
    """
    ax = _axes(ax, (9, 3))
    for k, (label, d) in enumerate(curves.items()):
        d = np.asarray(d, dtype=float)
        color = INPUT_COLOR if k == 0 else f"C{k - 1}"
        ax.plot(
            np.arange(len(d)) / fps, 1000 * d, color=color, lw=1.2, label=literal(f"{label}: mean {1000 * np.nanmean(d):.1f} mm")
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("ZMP distance (mm)")
    ax.set_title("Distance of the ZMP from the support polygon (Shin et al., Fig. 8)")
    ax.legend()
    return ax


def plot_mean_distance(history: Any, *, ax: Any = None, error: bool = False) -> Any:
    """Figure 9: mean ZMP distance after each step of a touch-up history (mm).

    With ``error=True`` the touch-up's error measure instead
    (:attr:`mocaplab.physics.TouchUpState.error`: the ZMP distance on ground
    frames and the distance of the centre of mass from its parabola on
    flight frames, averaged); the ring marks the best pass, the result.
    """
    ax = _axes(ax, (6, 3))
    mean = 1000 * np.asarray(history.errors if error else history.mean_zmp_distance)
    ax.plot(np.arange(len(mean)), mean, "o-", color=CURRENT_COLOR, ms=4)
    n = len(history.states[0].schedule)
    for k in range(n, len(mean), n):
        ax.axvline(k + 0.5, color="0.85", lw=0.8, zorder=0)
    best = getattr(history, "best", None)
    if best is not None:
        ax.plot([best], [mean[best]], "o", mfc="none", mec="#d62728", ms=9, mew=1.5, label="best pass (the result)")
        ax.legend(fontsize="small", loc="upper right")
    ax.set_xlabel("step (one adjustment each; grey lines end a pass)")
    ax.set_ylabel("mean error (mm)" if error else "mean distance (mm)")
    ax.set_title("Touch-up error at each step" if error else "Average distance at each step (Shin et al., Fig. 9)")
    ax.set_ylim(0, None)
    return ax


def plot_balance_top(balance: Any, *, frames: Sequence[int] | None = None, ax: Any = None) -> Any:
    """Top-down view: support polygons at some frames, the ZMP and the ground track of the COM.

    The ground axis along which the clip travels furthest is drawn horizontally.
    """
    ax = _axes(ax, (9, 3.5))
    n = len(balance.com)
    frames = list(range(0, n, max(1, n // 12))) if frames is None else list(frames)
    span = np.ptp(balance.com[:, [0, 2]], axis=0)
    h, v = (0, 2) if span[0] >= span[1] else (2, 0)
    for f in frames:
        poly = balance.polygon(f)
        if len(poly) >= 2:
            closed = np.vstack([poly, poly[:1]])
            ax.fill(closed[:, h], closed[:, v], color="#2ca02c", alpha=0.15, lw=0)
            ax.plot(closed[:, h], closed[:, v], color="#2ca02c", lw=0.8)
    ax.plot(balance.com[:, h], balance.com[:, v], color="#ff7f0e", lw=1.2, label="centre of mass (ground track)")
    ax.plot(balance.zmp[:, h], balance.zmp[:, v], ".", color="#d62728", ms=3, label="ZMP")
    ax.plot(balance.zmp[frames, h], balance.zmp[frames, v], "o", mfc="none", color="#d62728", ms=6)
    ax.set_aspect("equal")
    ax.set_xlabel("xyz"[h] + " (m)")
    ax.set_ylabel("xyz"[v] + " (m)")
    ax.set_title("Support polygons (green) at the circled frames, seen from above")
    ax.legend(loc="best", fontsize="small")
    return ax


class TouchUpStepper:
    """Step a physical touch-up forward and back and edit its schedule.

    Parameters
    ----------
    motion : Motion or TouchUpSession
        The motion to touch up (a new session is started with ``options``),
        or an existing session.
    viewer : bool
        Show the 3D view (a :class:`~mocaplab.widgets.MotionViewer`).
    viewer_options : dict, optional
        Keyword options of the viewer (``window_size``, ``backend`` ...).
    **options
        Options of :class:`mocaplab.physics.TouchUpSession` (``body``,
        ``schedule``, ``contacts``, ``flight_window``, ``footplants``,
        ``roles``: joint-role overrides for skeletons whose roles are not
        inferred right).

    Attributes
    ----------
    session : TouchUpSession
        The core stepper every control forwards to.
    step_button, back_button, reset_button : ipywidgets.Button
    mean_label : ipywidgets.HTML
        "mean ZMP distance over ground frames ... mm" of the current step, whole and without the end frames.
    flight_label : ipywidgets.HTML
        Fitted gravity and angular-momentum spread of each flight (hidden without flights).
    export : ExportControl
        Writes the motion of the step shown as BVH.
    rows : list
        One set of schedule controls per adjustment (``.s2``, ``.s3``,
        ``.sigma``, ``.rho``, ``.stage`` widgets).
    figure8, figure9 : matplotlib.figure.Figure
    viewer : MotionViewer or None
    widget : ipywidgets.VBox
    """

    def __init__(
        self,
        motion: Motion | TouchUpSession,
        *,
        viewer: bool = True,
        viewer_options: dict[str, Any] | None = None,
        **options: Any,
    ) -> None:
        if isinstance(motion, TouchUpSession):
            if options:
                raise ValueError(f"Expected no session options with an existing TouchUpSession, got {sorted(options)}")
            self.session = motion
        elif isinstance(motion, Motion):
            self.session = TouchUpSession(motion, **options)
        else:
            raise TypeError(f"Expected `motion` to be a Motion or a TouchUpSession, got {type(motion).__name__}")
        self.viewer_options = dict(viewer_options or {})
        self.viewer_updates = 0

        self.back_button = W.Button(
            description="back",
            icon="step-backward",
            tooltip="Show the step before (the steps are kept: nothing is recomputed)",
            layout=W.Layout(width="90px"),
        )
        self.back_button.add_class(BACK_CLASS)
        self.step_button = W.Button(
            description="step",
            icon="step-forward",
            button_style="primary",
            tooltip="Apply the schedule's next adjustment (one step of the touch-up)",
            layout=W.Layout(width="90px"),
        )
        self.step_button.add_class(STEP_CLASS)
        self.iteration_button = W.Button(
            description="+1 iteration",
            tooltip="Run the whole schedule once more (one more pass of every adjustment)",
            layout=W.Layout(width="110px"),
        )
        self.reset_button = W.Button(
            description="reset",
            icon="refresh",
            tooltip="Back to the input and the first schedule",
            layout=W.Layout(width="90px"),
        )
        for name in RESET_CLASSES:
            self.reset_button.add_class(name)
        self._initial_schedule = self.session.input.schedule
        self.mean_label = W.HTML()
        self.mean_label.add_class(MEAN_CLASS)
        self.flight_label = W.HTML()
        self.flight_label.add_class(FLIGHT_CLASS)
        self.step_label = W.HTML()
        self.status = W.HTML()
        self.back_button.on_click(lambda _: self._guard(self.back))
        self.step_button.on_click(lambda _: self._guard(self.forward))
        self.iteration_button.on_click(lambda _: self._guard(self.forward_iteration))
        self.reset_button.on_click(lambda _: self._guard(self.reset))
        self.export = ExportControl(
            lambda: self.session.current.motion,
            default=export_name(self.session.input.motion.name, "touched_up"),
            guard=self._guard,
        )

        self.rows = [_Row(k, adj) for k, adj in enumerate(self.session.schedule)]
        for line in self.rows:
            for ctl in (line.s2, line.s3, line.sigma, line.rho, line.stage):
                ctl.observe(lambda change, r=line: self._on_row(r), names="value")
        self._syncing = False

        self.figure8, self._ax8 = self._figure(4.6, 2.6)
        self.figure9, self._ax9 = self._figure(3.2, 2.6)
        self._plot8 = _Plot(self.figure8)
        self._plot9 = _Plot(self.figure9)
        self._init_plots()

        self.viewer: Any = self._make_viewer() if viewer else None
        self._viewer_box = W.Box([self.viewer.widget] if self.viewer is not None else [])
        controls = row([self.back_button, self.step_button, self.iteration_button, self.reset_button, self.mean_label])
        schedule = W.VBox(
            [
                W.HTML("<b>schedule</b> (S1 = the other joints; an edit applies from the current step on)"),
                _schedule_grid(self.rows),
            ]
        )
        schedule.add_class("mocaplab-touchup-schedule")
        plots = row([self._plot8.widget, self._plot9.widget], align="flex-start")
        shortcuts = [
            Shortcut(("right",), "\u2192", "step", self._press(self.step_button)),
            Shortcut(("left", "ctrl+z"), "\u2190 or ctrl+z", "back", self._press(self.back_button)),
            *viewer_shortcuts(lambda: self.viewer)[:1],
        ]
        for plot in (self._plot8, self._plot9):
            self.keys_help = bind_keys(plot.canvas, shortcuts)
        self.help = W.HTML(f"<span style='color:#555; font-size:0.9em'>{html.escape(self.keys_help)}</span>")
        self.help.add_class("mocaplab-keys-help")
        self.widget = W.VBox(
            [
                controls,
                self.flight_label,
                self.step_label,
                schedule,
                plots,
                self.help,
                self._viewer_box,
                self.status,
                self.export.box,
            ]
        )
        self.widget.add_class("mocaplab-touchup")
        self._refresh(viewer=False)

    # ------------------------------------------------------------ actions
    def forward(self) -> None:
        """Apply the next adjustment (what the step button does)."""
        self.session.forward()
        self._refresh()

    def back(self) -> None:
        """Go back one step (what the back button does)."""
        self.session.back()
        self._refresh()

    def forward_iteration(self) -> None:
        """Run the rest of the schedule's current pass, or a whole pass."""
        self.session.finish_pass()
        self._refresh()

    def reset(self) -> None:
        """Back to the input: step 0 with the schedule the stepper started with (what the reset button does).

        The steps already computed are kept when the schedule is unchanged.
        """
        while self.session.index > 0:
            self.session.back()
        if self.session.schedule != self._initial_schedule:
            self.session.set_schedule(self._initial_schedule)
        self._refresh()

    def _on_row(self, row: _Row) -> None:
        if not self._syncing:  # a value the stepper set itself is no edit
            self._guard(lambda: self._edit(row))

    def _edit(self, row: _Row) -> None:
        changes = row.changes(self.session.schedule[row.k])
        if changes:
            self.session.set_adjustment(row.k, **changes)
            self._refresh(viewer=False)

    @staticmethod
    def _press(button: W.Button) -> Any:
        """An action clicking ``button`` when it is enabled (a keyboard shortcut; the button's handler guards)."""
        return lambda: None if button.disabled else button.click()

    def _guard(self, action: Any) -> None:
        try:
            action()
            self.status.value = ""
        except Exception as err:  # shown in the widget, not lost in the log
            self.status.value = error_html(err)
            self._sync_controls()  # every control shows the session again (the edit that failed is undone)

    def _sync_controls(self) -> None:
        """Set the schedule rows and the buttons from the session (without echoing the values back)."""
        s = self.session
        self.back_button.disabled = s.index == 0
        self.reset_button.disabled = s.index == 0 and s.schedule == self._initial_schedule
        self._syncing = True
        try:
            for row, adj in zip(self.rows, s.current.schedule, strict=False):
                row.set(adj)
        finally:
            self._syncing = False

    def _flight_text(self) -> str:
        """One line per flight: fitted gravity and angular-momentum spread, now and in the input."""
        lines = []
        for k, (f, f0) in enumerate(zip(self.session.current.flights, self.session.input.flights, strict=True)):
            fps = self.session.input.motion.fps
            lines.append(
                f"flight {k + 1} ({f.start / fps:.2f}-{f.stop / fps:.2f} s): fitted gravity "
                f"<b>{html.escape(f.gravity_text())}</b> (input {html.escape(f0.gravity_text())}, ballistic 9.81 m/s²)"
                " &nbsp;|&nbsp; angular momentum spread "
                f"<b>{f.momentum_spread:.3f}</b> kg m²/s (input {f0.momentum_spread:.3f}, ballistic 0)"
            )
        return "<br>".join(lines)

    # ------------------------------------------------------------ drawing
    @staticmethod
    def _figure(w: float, h: float) -> tuple[Figure, Any]:
        fig = Figure(figsize=(w, h), dpi=90, layout="constrained")
        return fig, fig.add_subplot(1, 1, 1)

    def _init_plots(self) -> None:
        first = self.session.input
        t = first.motion.times
        ax = self._ax8
        ax.set_title("ZMP distance per frame (Fig. 8)", fontsize=9)
        ax.set_xlabel("time (s)", fontsize=8)
        ax.set_ylabel("distance (mm)", fontsize=8)
        (self._line_in,) = ax.plot(t, 1000 * first.zmp_distance, color=INPUT_COLOR, lw=1.2, label="input")
        (self._line_now,) = ax.plot(t, 1000 * first.zmp_distance, color=CURRENT_COLOR, lw=1.2, label="current")
        ax.legend(fontsize=7, loc="upper right")
        ax.tick_params(labelsize=7)
        ax9 = self._ax9
        ax9.set_title("mean distance per step (Fig. 9)", fontsize=9)
        ax9.set_xlabel("step", fontsize=8)
        ax9.set_ylabel("mean (mm)", fontsize=8)
        ax9.tick_params(labelsize=7)
        (self._line_mean,) = ax9.plot([0], [1000 * first.mean_zmp_distance], "o-", color=CURRENT_COLOR, ms=3)
        (self._dot_mean,) = ax9.plot([0], [1000 * first.mean_zmp_distance], "o", color="#d62728", ms=6)

    def _refresh(self, *, viewer: bool = True) -> None:
        s = self.session
        cur = s.current
        mm = 1000.0 * cur.mean_zmp_distance
        mm0 = 1000.0 * s.input.mean_zmp_distance
        history = s.history
        best = history.best
        dropped = f"; {cur.dropped} ground frames without a ZMP left out" if cur.dropped else ""
        inner = 1000.0 * cur.mean_zmp_distance_interior
        self.mean_label.value = (
            f"mean ZMP distance over ground frames <b>{mm:.2f}</b> mm (input {mm0:.2f} mm{dropped}; "
            f"{inner:.2f} mm without the {cur.edge_frames} frames at each end, which no step corrects) "
            f"&nbsp;|&nbsp; best so far: step {best}, error {1000.0 * history.states[best].error:.2f} mm"
        )
        self.flight_label.value = self._flight_text()
        self.flight_label.layout.display = None if cur.flights else "none"
        nxt = cur.next_adjustment
        self.step_label.value = (
            f"step {cur.index} (pass {cur.iteration + 1}): <i>{html.escape(cur.label)}</i> &nbsp;|&nbsp; "
            f"next: {html.escape(nxt.label)}, sigma {nxt.sigma:.3g} s, rho {nxt.rho:.2g}"
        )
        self._sync_controls()
        self._line_now.set_ydata(1000 * cur.zmp_distance)
        top = np.nanmax(np.concatenate([1000 * s.input.zmp_distance, 1000 * cur.zmp_distance, [1.0]]))
        self._ax8.set_ylim(0, 1.08 * top)
        hist = history.mean_zmp_distance * 1000
        steps = np.arange(len(hist))
        self._line_mean.set_data(steps, hist)
        self._dot_mean.set_data([steps[-1]], [hist[-1]])
        self._ax9.set_xlim(-0.5, max(3, len(hist)) - 0.5)
        finite = hist[np.isfinite(hist)]
        self._ax9.set_ylim(0, 1.1 * max(float(finite.max()) if finite.size else 0.0, 1e-3))
        self._plot8.draw()
        self._plot9.draw()
        if viewer:
            self._update_viewer()

    # ------------------------------------------------------------ 3D view
    def _make_viewer(self) -> Any:
        from .viewer import MotionViewer

        s = self.session
        frame = getattr(self.viewer, "frame", None) if getattr(self, "viewer", None) is not None else None
        middle = s.input.motion.n_frames // 2 if frame is None else frame
        options: dict[str, Any] = {"window_size": (640, 360), "frame": middle} | self.viewer_options
        viewer = MotionViewer(
            [s.input.motion, s.current.motion],
            colors=[INPUT_COLOR, CURRENT_COLOR],
            labels=["input", "touched up"],
            **options,
        )
        self._add_overlays(viewer)
        return viewer

    def _add_overlays(self, viewer: Any) -> None:
        """COM, its shadow, ZMP and support polygon of the *current* step, as functions of time.

        The overlays read the session when the viewer asks for a time, so a
        step only needs the viewer to redraw (no actor is re-created).
        """
        lift = np.array([0.0, 0.003, 0.0])

        def now(t: float) -> tuple[Any, int]:
            bal = self.session.current.balance
            f = int(np.clip(round(t * self.session.input.motion.fps), 0, len(bal.com) - 1))
            return bal, f

        def com(t: float) -> np.ndarray:
            bal, f = now(t)
            return bal.com[f][None]

        def shadow(t: float) -> np.ndarray:
            bal, f = now(t)
            return (bal.com[f] * [1.0, 0.0, 1.0] + lift)[None]

        def zmp(t: float) -> np.ndarray:
            bal, f = now(t)
            return (bal.zmp[f] + lift)[None]

        def support(t: float) -> np.ndarray:
            bal, f = now(t)
            return bal.polygon(f) + lift

        viewer.add_points("com", com, color="#ff7f0e", radius=0.04)
        viewer.add_points("com_ground", shadow, color="#ff7f0e", radius=0.02)
        viewer.add_points("zmp", zmp, color="#d62728", radius=0.03)
        viewer.add_polygon("support", support, color="#2ca02c", opacity=0.35)

    def _update_viewer(self) -> None:
        if self.viewer is None:
            return
        s = self.session
        setter = getattr(self.viewer, "set_motions", None)
        if callable(setter):
            # redraws at the current time, and the overlays read the new step
            setter([s.input.motion, s.current.motion])
        else:
            old = self.viewer
            self.viewer = self._make_viewer()  # opens at the old viewer's frame
            self._viewer_box.children = [self.viewer.widget]
            old.close()
        self.viewer_updates += 1

    # ------------------------------------------------------------ display
    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    def show(self) -> Any:
        """Display the widget (and return it)."""
        from IPython.display import display

        display(self.widget)
        return self.widget
