"""The staggered-pose explorer: a thin view over :class:`mocaplab.staggered.StaggeredEditor`.

Coleman et al. 2008 represent a motion as staggered poses whose knots carry
timing refinements.  :class:`StaggeredExplorer` shows, for one clip (any
skeleton: the defaults come from its joint roles, ``roles=`` overrides them):

* **joint curves** of a chosen control variable (rotation vector
  components of a joint, the root position or a joint's animated
  translation) as played, over the original
  clip (grey), with the pose times (vertical lines, the selected pose bold)
  and the refined knots (dots) drawn on them;
* a **toggle** (CSS class ``mocaplab-staggered-toggle``) between staggered
  playback and non-staggered playback (every refinement zeroed);
* a **feet planted** box (class ``mocaplab-staggered-constraints``), on by
  default: the contact constraint layer holds the feet where the clip
  planted them; unticked, the edit plays without it;
* sliders for the **succession** offset ``s`` and exponent ``l``
  (``r + s d(i)^l``, depth measured from a chosen joint, by default the
  pelvis of the skeleton's joint roles), the **random**
  timing bound ``tau`` (seeded; per variable, or per limb with the
  *random per limb* box), relative **exaggeration** ``w_r`` against
  the average pose, and the **pose count** (culling by priority);
* the **pose list** with the priorities ``w_k`` and number of refined knots;
* **Undo**, **Redo** and **Reset** (:class:`~mocaplab.widgets._controls.HistoryButtons`
  over the editor's history; each slider release is one step) and
  **Export BVH** of the motion being played;
* one 3D view (:class:`~mocaplab.widgets.MotionViewer`) playing the current
  motion (purple) over the original (pale blue), with the selected pose's
  non-staggered pose (orange) and true pose at ``t_k`` (yellow) standing
  where they happen (Figure 6).  Selecting a pose moves the clock to
  ``t_k``; every other change keeps the time the 3D view was scrubbed to.

Every control forwards its value in one line to the core editor; the widget
only draws, and after every action (an error included) each control is set
back from the editor, so they never disagree.  Messages (timing warnings,
rejected edits, errors) appear, HTML-escaped, in a status line (class
``mocaplab-staggered-status``).  The current curve statistics are published
as JSON in a hidden HTML widget (class ``mocaplab-staggered-curves``) for
browser tests.

Examples
--------
>>> from mocaplab import cmu                                # doctest: +SKIP
>>> from mocaplab.widgets import StaggeredExplorer          # doctest: +SKIP
>>> StaggeredExplorer(cmu("16_15"), max_poses=12)           # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import html
import io
import json
from collections.abc import Callable, Mapping
from typing import Any

import ipywidgets as W
import numpy as np
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine

from mocaplab.motion import Motion
from mocaplab.plot import literal
from mocaplab.staggered import StaggeredEditor

from ._controls import (
    ExportControl,
    HistoryButtons,
    bind_keys,
    error_html,
    export_name,
    history_status,
    row,
    viewer_shortcuts,
)
from ._drag import TOOLBAR_PX, make_canvas

__all__ = ["StaggeredExplorer", "params_change"]

#: What the explorer's controls call each edit parameter (``EditorParams`` field -> words).
_PARAM_NAMES = {
    "max_poses": "poses",
    "s": "succession s",
    "l": "exponent l",
    "joint": "depth from",
    "tau": "random tau",
    "seed": "random seed",
    "random_by": "random by",
    "w_r": "exaggerate w_r",
    "exaggerate_joints": "exaggerated joints",
    "staggered": "staggered",
    "constraints": "feet planted",
    "selected": "selected pose",
}


def params_change(old: Any, new: Any) -> str:
    """What an edit from explorer parameters ``old`` to ``new`` (``EditorParams``) did, in words.

    >>> from mocaplab.staggered.editor import EditorParams
    >>> params_change(EditorParams(12), EditorParams(12, s=0.02, staggered=False))
    'succession s 0 -> 0.02, staggered on -> off'
    """

    def shown(value: Any) -> str:
        if isinstance(value, bool):
            return "on" if value else "off"
        if isinstance(value, float):
            return f"{value:.4g}"
        return "all" if value is None else str(value)

    changed = [
        f"{_PARAM_NAMES.get(f.name, f.name)} {shown(getattr(old, f.name))} -> {shown(getattr(new, f.name))}"
        for f in dataclasses.fields(new)
        if getattr(old, f.name) != getattr(new, f.name)
    ]
    return ", ".join(changed) if changed else "no parameter changed"

_COMPONENT_COLORS = ("#d62728", "#2ca02c", "#1f77b4")
NON_STAGGERED_COLOR = "#ff7f0e"  # orange, as in Figure 6
TRUE_POSE_COLOR = "#e6c700"  # yellow
_FIGSIZE = (7.5, 3.6)
_DPI = 100  # one figure pixel per CSS pixel, as TOOLBAR_PX counts them


class StaggeredExplorer:
    """Explore the staggered poses of a clip and edit their timing.

    Parameters
    ----------
    motion : Motion or StaggeredEditor
        The clip (any skeleton; an editor is built for it), or an existing
        editor.
    max_poses : int, optional
        Initial pose count (culling by priority); default every candidate.
    curve_joint : str, optional
        Variable whose curves are drawn (a joint name, ``"root_position"``
        or ``"<joint>.position"``); default the joint rotation with the
        largest signal weight.
    joint : str, optional
        Joint the succession depth is measured from (default the pelvis of
        the joint roles, :func:`mocaplab.staggered.default_joint`).
    roles : mapping, optional
        Joint-role overrides (:func:`mocaplab.roles.resolve_roles`) for the
        defaults (pelvis, contact joints, constraint layer), passed to the
        editor.
    viewer : bool
        Build the 3D views (:class:`~mocaplab.widgets.MotionViewer`).
    backend : str, optional
        ``"auto"``, ``"ipympl"`` or ``"agg"`` for the curve canvas.
    viewer_backend : str, optional
        MotionViewer backend (default ``MOCAPLAB_JUPYTER_BACKEND``).
    **extract_options
        Passed to :func:`mocaplab.staggered.extract`.

    Attributes
    ----------
    editor : StaggeredEditor
    toggle : ipywidgets.ToggleButton
        Staggered (pressed) or non-staggered playback.
    s_slider, l_slider, tau_slider, wr_slider : ipywidgets.FloatSlider
    limb_check : ipywidgets.Checkbox
        Random timing per limb (checked) or per variable.
    count_slider : ipywidgets.IntSlider
    pose_list : ipywidgets.Select
    joint_dropdown, succession_dropdown : ipywidgets.Dropdown
    history : HistoryButtons
        ``.undo``, ``.redo``, ``.reset`` buttons (CSS ``mocaplab-undo`` ...).
    export : ExportControl
        Writes :meth:`StaggeredEditor.evaluate` (the motion played) as BVH.
    figure : matplotlib.figure.Figure
    """

    def __init__(
        self,
        motion: Motion | StaggeredEditor,
        *,
        max_poses: int | None = None,
        curve_joint: str | None = None,
        joint: str | None = None,
        viewer: bool = True,
        backend: str = "auto",
        viewer_backend: str | None = None,
        roles: Mapping[str, Any] | None = None,
        **extract_options: Any,
    ) -> None:
        if isinstance(motion, StaggeredEditor):
            self.editor = motion
        elif isinstance(motion, Motion):
            self.editor = StaggeredEditor(motion, max_poses=max_poses, joint=joint, roles=roles, **extract_options)
        else:
            raise TypeError(f"Expected `motion` to be a Motion or a StaggeredEditor, got {type(motion).__name__}")
        ed = self.editor
        if curve_joint is None:
            # the joint rotation (variables 1 .. J) with the largest signal weight
            w = ed.analysis.weights[1 : ed.motion.n_joints + 1]
            curve_joint = ed.analysis.variables[1 + int(np.argmax(w))]
        ed.set_curve_joint(curve_joint)
        self._viewer_enabled = bool(viewer)
        self._syncing = False
        self._viewer_backend = viewer_backend
        self.status = W.HTML(value="")
        self.status.add_class("mocaplab-staggered-status")
        self._build_controls()
        self._build_figure(backend)
        self.view_box = W.Box(layout=W.Layout(min_height="40px"))
        self.viewer: Any = None
        # ctrl+z / ctrl+y undo and redo, space and the arrows play and step the 3D view
        shortcuts = self.history.shortcuts() + viewer_shortcuts(lambda: self.viewer)
        self.keys_help = bind_keys(self.canvas, shortcuts, guard=self._run)
        self.help = W.HTML(f"<span style='color:#555; font-size:0.9em'>{html.escape(self.keys_help)}</span>")
        self.help.add_class("mocaplab-keys-help")
        self.curves_info = W.HTML(value="", layout=W.Layout(display="none"))
        self.curves_info.add_class("mocaplab-staggered-curves")
        self._refresh_all(move_clock=True)

    # ------------------------------------------------------------ controls
    def _build_controls(self) -> None:
        ed = self.editor
        sk = ed.motion.skeleton
        self.toggle = W.ToggleButton(
            value=ed.staggered,
            description="staggered",
            tooltip="staggered playback: the refinements on (off: they are zeroed, every joint keys at t_k)",
        )
        self.toggle.add_class("mocaplab-staggered-toggle")
        slider = dict(continuous_update=False, style={"description_width": "110px"}, layout=W.Layout(width="330px"))
        self.s_slider = W.FloatSlider(
            value=ed.s,
            min=-0.06,
            max=0.06,
            step=0.005,
            readout_format=".3f",
            description="succession s",
            tooltip="timing offset per level of depth, s (positive: the extremities follow; negative: they lead)",
            **slider,
        )
        self.s_slider.add_class("mocaplab-staggered-s")
        self.l_slider = W.FloatSlider(
            value=ed.l,
            min=0.5,
            max=4.0,
            step=0.1,
            description="exponent l",
            tooltip="succession's nonlinearity (1: linear in the depth; larger loosens the extremities)",
            **slider,
        )
        self.tau_slider = W.FloatSlider(
            value=ed.tau,
            min=0.0,
            max=0.1,
            step=0.005,
            readout_format=".3f",
            description="random tau",
            tooltip="bound of the random timing offsets, s (0: none)",
            **slider,
        )
        self.limb_check = W.Checkbox(
            value=ed.random_by == "limb",
            description="random per limb",
            indent=False,
            tooltip="one random offset per limb (off: one per joint variable)",
        )
        self.constraints_check = W.Checkbox(
            value=ed.constraints,
            description="feet planted",
            indent=False,
            tooltip="hold the feet where the input planted them (the contact constraint layer)",
        )
        self.constraints_check.add_class("mocaplab-staggered-constraints")
        self.wr_slider = W.FloatSlider(
            value=ed.w_r,
            min=-0.5,
            max=1.0,
            step=0.05,
            description="exaggerate w_r",
            tooltip="exaggeration away from the average pose (0: none; negative moves toward it)",
            **slider,
        )
        self.count_slider = W.IntSlider(
            value=ed.current.n_poses,
            min=2,
            max=ed.n_candidates,
            step=1,
            description="poses",
            tooltip="how many staggered poses represent the clip (fewer: the least needed are culled)",
            **slider,
        )
        self.joint_dropdown = W.Dropdown(
            options=list(ed.current.variables),
            value=ed.curve_joint,
            description="curves",
            tooltip="the joint variable whose curves the plot shows",
            layout=W.Layout(width="260px"),
        )
        self.succession_dropdown = W.Dropdown(
            options=list(sk.names),
            value=ed.joint,
            description="depth from",
            tooltip="the joint the succession's depth is counted from (only its subtree moves)",
            layout=W.Layout(width="260px"),
        )
        self.pose_list = W.Select(
            options=[],
            rows=8,
            description="poses",
            tooltip="pick a pose: the 3D view jumps to its time t_k and overlays its non-staggered and true poses",
            layout=W.Layout(width="400px"),
        )
        edit = self._observer
        self.toggle.observe(edit(lambda v: self.editor.set_staggered(v)), names="value")
        self.s_slider.observe(edit(lambda v: self.editor.set_succession(s=v)), names="value")
        self.l_slider.observe(edit(lambda v: self.editor.set_succession(l=v)), names="value")
        self.tau_slider.observe(edit(lambda v: self.editor.set_random(tau=v)), names="value")
        self.limb_check.observe(edit(lambda v: self.editor.set_random(by="limb" if v else "variable")), names="value")
        self.constraints_check.observe(edit(lambda v: self.editor.set_constraints(v)), names="value")
        self.wr_slider.observe(edit(lambda v: self.editor.set_exaggeration(v)), names="value")
        self.count_slider.observe(edit(lambda v: self.editor.set_pose_count(v)), names="value")
        self.succession_dropdown.observe(edit(lambda v: self.editor.set_succession(joint=v)), names="value")
        self.joint_dropdown.observe(edit(lambda v: self.editor.set_curve_joint(v), viewers=False), names="value")
        # selections merge into one undo step (no checkpoint); they move the 3D clock to t_k
        self.pose_list.observe(edit(self._select, checkpoint=False, move_clock=True), names="value")
        self.history = HistoryButtons(
            self.editor, self._after_history, guard=self._run, snapshot=lambda: self.editor.params
        )
        self.export = ExportControl(
            self.editor.evaluate, default=export_name(self.editor.motion.name, "staggered"), guard=self._run
        )

    def _run(self, action: Callable[[], object]) -> None:
        """Run a widget action; an error goes to the status line, and the controls show the editor's values."""
        try:
            action()
        except Exception as err:  # show it in the widget instead of losing it in the log
            self.status.value = error_html(err, trace=True)
        finally:
            self._sync_controls()

    def _observer(
        self,
        action: Callable[[Any], None],
        *,
        viewers: bool = True,
        checkpoint: bool = True,
        move_clock: bool = False,
    ) -> Callable[[dict[str, Any]], None]:
        """An observer forwarding the new value to ``action``, then redrawing.

        With ``continuous_update=False`` every slider event is a whole
        gesture (a release), so it ends an undo step (``checkpoint``).
        """

        def observer(change: dict[str, Any]) -> None:
            if self._syncing:
                return

            def act() -> None:
                action(change["new"])
                if checkpoint:
                    self.editor.checkpoint()
                self._refresh_all(viewers=viewers, move_clock=move_clock)

            self._run(act)

        return observer

    def _select(self, value: Any) -> None:
        if value is not None:
            self.editor.select(int(value))

    def _after_history(self) -> None:
        """After undo, redo or reset: redraw and say what changed; the clock moves only when the selected pose did."""
        self._refresh_all(move_clock=self.editor.selected != self._shown_pose)
        if self.history.last is not None:
            text = history_status(*self.history.last, params_change)
            note = f" · {self.editor.message}" if self.editor.message else ""
            self.status.value = html.escape(text + note)

    @staticmethod
    def _put(control: W.Widget, value: Any) -> None:
        """Set a control's value, widening a slider's range rather than letting it clamp the value."""
        if isinstance(control, (W.FloatSlider, W.IntSlider)):
            if value > control.max:
                control.max = value
            if value < control.min:
                control.min = value
        if control.value != value:
            control.value = value

    def _sync_controls(self) -> None:
        """Show the editor's values on every control (without echoing them back)."""
        ed = self.editor
        self._syncing = True
        try:
            self._put(self.toggle, ed.staggered)
            self._put(self.constraints_check, ed.constraints)
            self._put(self.s_slider, ed.s)
            self._put(self.l_slider, ed.l)
            self._put(self.tau_slider, ed.tau)
            self._put(self.limb_check, ed.random_by == "limb")
            self._put(self.wr_slider, ed.w_r)
            self._put(self.count_slider, ed.current.n_poses)
            self._put(self.succession_dropdown, ed.joint)
            if ed.curve_joint in self.joint_dropdown.options:
                self._put(self.joint_dropdown, ed.curve_joint)
            opts = [
                (f"{k:3d}  t={t:6.3f} s  w={w if np.isfinite(w) else float('inf'):7.4f}  refined {n:2d}", k)
                for k, t, w, n in ed.pose_table()
            ]
            if list(self.pose_list.options) != opts:
                self.pose_list.options = opts
            self._put(self.pose_list, ed.selected)
            self.history.sync()
        finally:
            self._syncing = False

    # -------------------------------------------------------------- figure
    def _build_figure(self, backend: str) -> None:
        self.figure = Figure(figsize=_FIGSIZE, dpi=_DPI, layout="constrained")
        self.ax = self.figure.add_subplot(1, 1, 1)
        self.canvas = make_canvas(self.figure, backend=backend)  # type: ignore[arg-type]
        self.interactive = isinstance(self.canvas, W.DOMWidget)
        self.image = None if self.interactive else W.Image(format="png")
        if self.interactive:
            # ipympl's toolbar floats over the canvas' left edge: lay the axes out to its right
            free = min(TOOLBAR_PX / (_FIGSIZE[0] * _DPI), 0.2)
            self.figure.set_layout_engine(ConstrainedLayoutEngine(rect=(free, 0.0, 1.0 - free, 1.0)))
            # as wide as the figure: a growing canvas box pushed the controls 450 px to the right
            self.canvas.layout.flex = "0 0 auto"

    def _draw_curves(self) -> None:
        ed = self.editor
        c = ed.curves()
        ax = self.ax
        ax.clear()
        name = ed.curve_joint
        for d in range(3):
            ax.plot(c["t0"], c["original"][:, d], color="0.75", lw=1.0)
            ax.plot(c["t"], c["values"][:, d], color=_COMPONENT_COLORS[d], lw=1.4, label="xyz"[d])
            ax.plot(c["knot_times"], c["knot_values"][:, d], "o", ms=3.5, color=_COMPONENT_COLORS[d])
        sel = ed.selected
        for k, t in enumerate(c["pose_times"]):
            ax.axvline(t, color="k", lw=1.6 if k == sel else 0.5, alpha=0.8 if k == sel else 0.35)
        unit = "m" if c["kind"] == "translation" else "rad (rotation vector)"
        mode = "staggered" if ed.staggered else "non-staggered (refinements zeroed)"
        ax.set_title(literal(f"{name}: {mode}"), fontsize=10)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(unit)
        ax.legend(loc="upper right", fontsize=8, ncols=3)
        if self.interactive:
            self.canvas.draw_idle()
        else:
            buf = io.BytesIO()
            self.figure.savefig(buf, format="png")
            self.image.value = buf.getvalue()  # type: ignore[union-attr]
        info = {
            "variable": name,
            "staggered": ed.staggered,
            "n_poses": int(c["pose_times"].size),
            "mean": float(np.mean(c["values"])),
            "checksum": float(np.sum(np.abs(c["values"]))),
        }
        self.curves_info.value = html.escape(json.dumps(info))  # joint names from a file are text, not markup

    # --------------------------------------------------------------- views
    def _refresh_view(self, *, move_clock: bool = False) -> None:
        """One 3D view: original and played motion, and the selected pose's
        non-staggered (orange) and true (yellow) poses standing where they
        happen (Figure 6).  The viewer keeps its time (the frame a student
        scrubbed to) unless ``move_clock``: then it goes to ``t_k``."""
        if not self._viewer_enabled:
            return
        ed = self.editor
        ns, true = ed.overlay()
        motions = [ed.motion, ed.evaluate(), ns, true]
        labels = [
            "original",
            "played" if ed.staggered else "played, non-staggered",
            "non-staggered pose",
            "true pose at t_k",
        ]
        if self.viewer is None:
            from .viewer import MotionViewer

            # a single viewer: several trame views in one output are fragile
            self.viewer = MotionViewer(
                motions,
                colors=["#c6dbef", "#6a3d9a", NON_STAGGERED_COLOR, TRUE_POSE_COLOR],
                labels=labels,
                backend=self._viewer_backend,
                window_size=(640, 360),
            )
            self.view_box.children = [self.viewer.widget]
            move_clock = True
        else:
            self.viewer.set_motions(motions, labels=labels)  # keeps the viewer's time
        if move_clock:
            self.viewer.set_time(float(ed.current.times[ed.selected]))

    def _refresh_all(self, *, viewers: bool = True, move_clock: bool = False) -> None:
        ed = self.editor
        self.status.value = html.escape(ed.message) if ed.message else ""
        self._sync_controls()
        self._draw_curves()
        if viewers:
            self._refresh_view(move_clock=move_clock)
        self._shown_pose = ed.selected
        self._shown_params = ed.params

    # --------------------------------------------------------------- layout
    @property
    def widget(self) -> W.Widget:
        """The whole explorer as one ipywidgets box (class ``mocaplab-staggered-explorer``).

        Edits made on :attr:`editor` directly since the last redraw are drawn first.
        """
        if self.editor.params != self._shown_params:
            self._run(self._refresh_all)
        if getattr(self, "_box", None) is None:
            canvas = self.canvas if self.interactive else self.image
            controls = W.VBox(
                [
                    row([self.toggle, self.constraints_check, self.joint_dropdown]),
                    self.s_slider,
                    self.l_slider,
                    self.succession_dropdown,
                    self.tau_slider,
                    self.limb_check,
                    self.wr_slider,
                    self.count_slider,
                    self.pose_list,
                    self.history.box,
                ]
            )
            # the controls drop below the curves when the notebook has no room beside them
            self._box = W.VBox(
                [
                    row([canvas, controls], align="flex-start"),
                    self.help,
                    self.view_box,
                    self.status,
                    self.export.box,
                    self.curves_info,
                ]
            )
            self._box.add_class("mocaplab-staggered-explorer")
        return self._box

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    def close(self) -> None:
        """Release the 3D render window."""
        if self.viewer is not None:
            self.viewer.close()

    def __repr__(self) -> str:
        ed = self.editor
        return f"<StaggeredExplorer {ed.motion.name!r}: {ed.current.n_poses} poses, staggered={ed.staggered}>"
