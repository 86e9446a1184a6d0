"""A 3D viewer of one or several motions: pyvista skeletons, a time slider, play.

>>> from mocaplab.data import cmu                      # doctest: +SKIP
>>> from mocaplab.widgets import MotionViewer          # doctest: +SKIP
>>> viewer = MotionViewer([cmu("16_15"), cmu("02_01")])  # doctest: +SKIP
>>> viewer                                             # doctest: +SKIP

This module is the widget: it builds the controls, keeps the clock and
forwards each event.  Its neighbours hold the rest, one job each:

========================================  =====================================================
:mod:`mocaplab.widgets.scene`             the scene as arrays: bones, joints, overlays, ground,
                                          camera framing (numpy only, tested without VTK)
:mod:`mocaplab.widgets.serving`           the trame server: its secret, its address behind a
                                          proxy, the iframe, the kernel's main thread
:mod:`mocaplab.widgets.vtkjs_page`        the ``client`` backend's page (vtk.js in the browser)
                                          and the state it reads
========================================  =====================================================

Longer than 800 lines because :class:`MotionViewer` is one object whose methods share one
mutable state (the clock, the kernel's meshes, the controls, the page's state and the
threads' queue): what does not need that state lives in the modules above.

What is drawn
-------------
Each character is two meshes whose topology never changes: its bones as
tubes and its joints (and end sites) as spheres.  Moving the slider writes new
point coordinates into those meshes **in place** (no actor is re-created),
then re-renders.  A ground grid lies at y = 0 under the whole scene.
:meth:`MotionViewer.set_motions` swaps in new motions (an edited scene) the
same way: same plotter, same widget, same meshes when the skeletons match.
The camera looks from the front-right and above, at the distance where the
whole clip of every character (from the ground to the top of the head, over
all frames) lies inside the picture.  With several characters a legend (an
HTML row under the view, not drawn into the picture) names them.

Time
----
Characters may have different lengths and frame rates.  The slider counts
frames of the viewer's clock, at ``fps`` frames per second (default: the
highest fps of the characters); slider frame ``i`` is time ``t = i / fps`` and
character ``k`` shows its frame ``round(t * fps_k)``, held at its last frame
once it has ended.  With one character the slider frame is its frame.

Playback
--------
The play button runs the clock in the kernel, against the wall clock: each
picture shows the frame ``start + floor(elapsed * fps)``, so a clip of 4 s
takes 4 s whatever the view costs to draw; frames that cannot be drawn in
time are skipped, never queued.  The kernel draws at most :attr:`play_rate`
pictures per second and rests between two pictures for ``play_rest`` times
the cost of the last one (the browser needs the CPU to show them).  The slider
shows the frame (its readout) and the time (its description), sent in one
message so that the two always agree; while playing it moves at most
:attr:`slider_rate` times per second (each move costs the JupyterLab page a
layout and paint that the 3D pictures need), always on the last frame and
when paused.  The line under the slider gives the clip's length and, for
characters of other frame rates, their own frames.  Moving the slider or pressing a step button while playing
continues from there (a step pauses).  After a click on a button or beside the controls, space
plays or pauses and the arrows step (:attr:`MotionViewer.keys`, listed on the help line).  Playing needs the kernel's asyncio loop
(it runs between cells, like the trame server); in a script it raises
``RuntimeError``, use :meth:`MotionViewer.set_frame`.

Overlays
--------
Extra named geometry updated with the time, for other lessons (centre of
mass, ZMP, support polygon, IK targets ...):
:meth:`MotionViewer.add_points` (spheres), :meth:`MotionViewer.add_lines`
(a polyline) and :meth:`MotionViewer.add_polygon` (a closed, optionally
filled polygon).  Their data is one of

* an array of shape ``(F, k, 3)``: ``k`` points on each of ``F`` frames,
  sampled at the overlay's ``fps`` (default: the first character's);
* a list of ``F`` arrays of shape ``(k_i, 3)``: the count may change per frame;
* an array of shape ``(k, 3)``: the same points on every frame;
* a callable ``f(t) -> (k, 3)`` of the time in seconds.

Rows containing NaN are left out on that frame.  An overlay that raises
leaves the viewer consistent: the characters, slider and label still move
to the new frame, and the error is shown in the status line (and raised to a
caller from Python).

Backends
--------
``MOCAPLAB_JUPYTER_BACKEND`` (default ``"client"``) selects how the 3D view
reaches the notebook:

* ``"trame"`` and ``"server"`` (the same): pyvista's trame view in its
  server-rendering mode, the fallback where the browser cannot draw
  (no WebGL).  The kernel renders (no multisampling: on Mesa's
  software rasteriser it costs five times the picture) and sends each picture
  as a JPEG; the mouse rotates and zooms.  Only the picture crosses the wire,
  never the geometry: pyvista's own ``"trame"`` mode also serialises the whole
  scene for its client-side toggle on every update (60-90 ms per frame for
  eight characters), which is the cost this viewer avoids.
* ``"client"``: the browser draws the 3D view with vtk.js
  (:mod:`mocaplab.widgets.vtkjs_page`).  The kernel sends the scene once and
  then only where to start and whether to play (on play, pause, a slider
  move or a step); it moves the slider :attr:`~MotionViewer.slider_rate`
  times per second from its own clock while the page plays and draws no
  picture.  :meth:`~MotionViewer.set_motions` and the overlay methods send
  the changed part again.  ``follow=True`` does not move this view's camera.
* ``"static"`` renders off-screen and shows a PNG image that is re-rendered
  when the slider moves (used by the tests and by nbval);
* ``"none"`` builds the controls without any 3D view.

The trame toolbar starts collapsed (one button that opens it) in views
narrower than :data:`TOOLBAR_WIDTH` pixels, where its icons would overlap.
The iframe's address, its secret and its route behind JupyterHub or another
proxy are :mod:`mocaplab.widgets.serving`'s.

Threads
-------
VTK renders only in the kernel's main thread, and JupyterLab may run a
widget's callback in another (a kernel subshell; see
:mod:`mocaplab.widgets.serving`).  The methods that touch the scene
(:meth:`~MotionViewer.set_frame`, :meth:`~MotionViewer.set_time`,
:meth:`~MotionViewer.set_motions`, the overlay methods, playback,
:meth:`~MotionViewer.close`, the slider's callback) called from another
thread are queued onto the main thread's asyncio loop, in call order, and
return at once.  Slider moves are coalesced: a burst of them draws the
newest frame once.  Calls made in the main thread, or when no loop was
running there (a script, the tests), run immediately, so the static
backend's image is re-rendered before the call returns.  An error in a
queued call is shown in the widget's status line.  Every text from data or
from an exception (labels, messages) is HTML-escaped before it goes into the
widget.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import html
import io
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mocaplab.motion import Motion

from . import vtkjs_page
from ._controls import KeyCapture, error_html, viewer_shortcuts
from .scene import (
    Character,
    Overlay,
    OverlayData,
    OverlayKind,
    SphereSet,
    as_motions,
    box_corners,
    character_colors,
    character_geometry,
    check_overlay_data,
    clock_of,
    fit_view,
    ground_grid,
    overlay_cells,
    scene_bounds,
    tube_faces,
    tube_points,
)
from .serving import (
    current_task,
    iframe_widget,
    main_thread_loop,
    on_main_thread,
    proxy_setting,
    quiet_vtk,
    secure_trame_server,
    without_vtklocal,
)

__all__ = [
    "MotionViewer",
    "PlayClock",
    "BACKENDS",
    "DEFAULT_BACKEND",
    "TOOLBAR_WIDTH",
    "default_backend",
    "sphere_set",
]

BACKENDS = ("trame", "server", "client", "static", "none")
ENV_VAR = "MOCAPLAB_JUPYTER_BACKEND"
# Width (px) the trame toolbar needs for its icons (it spans x = 20..510 px in server mode);
# narrower views start with it collapsed.
TOOLBAR_WIDTH = 540
# JPEG quality of the trame pictures while playing (paused: 100).  Measured in headless
# Chromium (lesson 01): 100 shows 10-12 pictures per second, 80 shows 17-21.
PLAY_QUALITY = 80
# Most slider updates per second while playing.  Each one costs the JupyterLab page a
# style, layout and paint pass (~30 ms of its main thread in headless Chromium): updating
# it with every picture halved the pictures shown (lesson 01: 10-13/s instead of 20).
SLIDER_RATE = 8.0
# Bottom edge (px) of the open toolbar: the camera keeps the characters below it.
_TOOLBAR_BOTTOM = 64
# pyvista's trame modes behind the viewer's backends.
_TRAME_MODES = {"trame": "server", "server": "server"}

_log = logging.getLogger(__name__)


DEFAULT_BACKEND = "client"


def default_backend() -> str:
    """The backend named by ``MOCAPLAB_JUPYTER_BACKEND`` (default :data:`DEFAULT_BACKEND`, the browser draws)."""
    return os.environ.get(ENV_VAR, DEFAULT_BACKEND).strip().lower() or DEFAULT_BACKEND


@dataclass
class PlayClock:
    """Playback against the wall clock: the frame to show at a moment.

    ``frame_at(now) = min(start_frame + floor((now - start_time) * fps), n_frames - 1)``:
    the frame follows the time that has passed, whatever was drawn before
    (frames that could not be drawn in time are skipped).

    Examples
    --------
    >>> clock = PlayClock(fps=30.0, n_frames=90)
    >>> clock.start(10, now=100.0)
    >>> clock.frame_at(100.5), clock.frame_at(200.0)
    (25, 89)
    """

    fps: float
    n_frames: int
    start_frame: int = 0
    start_time: float = 0.0

    def start(self, frame: int, *, now: float) -> None:
        """Play from ``frame`` at the moment ``now`` (seconds of the same clock as :meth:`frame_at`)."""
        self.start_frame, self.start_time = int(frame), float(now)

    def frame_at(self, now: float) -> int:
        elapsed = max(float(now) - self.start_time, 0.0)
        return int(min(self.start_frame + math.floor(elapsed * self.fps + 1e-9), self.n_frames - 1))

    def at_end(self, now: float) -> bool:
        return self.frame_at(now) >= self.n_frames - 1



# --------------------------------------------------------------------------
# the kernel's meshes (pyvista): the scene's arrays written into VTK
# --------------------------------------------------------------------------
def sphere_set(radius: float, resolution: int = 10) -> SphereSet:
    """Copies of pyvista's sphere of ``radius`` with ``resolution`` points around (the joints' and points' spheres)."""
    import pyvista as pv

    s = pv.Sphere(radius=1.0, theta_resolution=resolution, phi_resolution=max(4, resolution - 2))
    return SphereSet.from_unit(np.asarray(s.points, dtype=float), np.asarray(s.regular_faces, dtype=np.int64), radius)


def _mesh(points: NDArray[np.float64], faces: NDArray[np.int64], normals: NDArray[np.float64] | None = None) -> Any:
    import pyvista as pv

    mesh = pv.PolyData(np.array(points, dtype=float), faces=faces)
    if normals is not None:
        mesh.point_data["Normals"] = np.array(normals, dtype=float)
        mesh.point_data.active_normals_name = "Normals"
    return mesh


def _write_points(mesh: Any, points: NDArray[np.float64], normals: NDArray[np.float64] | None = None) -> None:
    """Overwrite a mesh's coordinates (and normals) in place; the actor keeps it."""
    target = mesh.points
    target[:] = points
    if normals is not None:
        mesh.point_data["Normals"][:] = normals
    mesh.Modified()




# --------------------------------------------------------------------------
class MotionViewer:
    """Play one or several motions in 3D with a time slider and a play button.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        The characters; lengths and frame rates may differ.
    colors : sequence of str, optional
        One colour per character, cycled (default
        :func:`~mocaplab.widgets.scene.character_colors`: tab20, then colours
        apart in CIELAB, distinct for at least 80 characters).
    labels : sequence of str, optional
        Names shown in the legend (default each motion's name).
    fps : float, optional
        Rate of the slider's clock (default the highest character fps).
    bone_radius, joint_radius : float
        Tube and sphere radii in metres.
    end_sites : bool
        Draw the bones to the BVH end sites (toe tips, head top, fingers).
    ground : bool
        Draw the ground grid at y = 0.
    follow : bool
        Move the camera with the first character's path joint (its pelvis,
        :attr:`~mocaplab.motion.Motion.path_joint`, whatever the layout).
    roles : mapping of role name to joint name, or one per character, optional
        Joint roles fixed by hand (:func:`mocaplab.roles.resolve_roles`) for
        skeletons whose roles cannot be inferred; the followed joint is
        their ``pelvis``.  Kept for :meth:`set_motions`.
    window_size : (int, int)
        Pixels of the 3D view (views narrower than :data:`TOOLBAR_WIDTH`
        start with the trame toolbar collapsed).
    backend : str, optional
        One of :data:`BACKENDS`; default ``MOCAPLAB_JUPYTER_BACKEND`` or ``"client"`` (drawn by the browser).
    frame : int
        Initial slider frame.
    play_rate : float
        Most pictures per second drawn while playing.

    Attributes
    ----------
    plotter : pyvista.Plotter
    slider : ipywidgets.IntSlider
        The frame of the viewer's clock (created with :attr:`widget`).
    play : ipywidgets.Button
        Starts and pauses real-time playback (:meth:`toggle_playback`).
    back, forward : ipywidgets.Button
        One frame back or forward (pause playback).
    keys : KeyCapture
        The keyboard shortcuts and their help line (created with
        :attr:`widget`): after a click on a button, on the viewer's box or
        on a 3D picture the browser draws (``client``; a picture drawn by
        the kernel keeps the keys for its own page), space plays or pauses
        and the left and right arrows step a frame, as the buttons do.
        ``viewer.keys.press(" ")`` presses a key from Python.
    play_rate : float
        Most pictures per second while playing.
    play_rest : float
        Pause after each picture while playing, in units of that picture's cost.
    play_quality : int
        JPEG quality (0-100) of the trame pictures while playing; paused
        pictures are sent at 100.
    slider_rate : float
        Most slider updates per second while playing (the slider's value and
        time always change together; the last frame and a pause always
        update it).
    pictures : int
        Pictures drawn by playback so far (for benchmarks).
    frame_cost : float
        Seconds the last played picture took to draw and send.
    play_log : collections.deque of (float, int, float)
        The last 2000 played pictures: clock reading when it began, frame, cost in seconds.

    Examples
    --------
    >>> v = MotionViewer(walk, backend="static")            # doctest: +SKIP
    >>> v.set_frame(60); image = v.screenshot()              # doctest: +SKIP
    >>> v.add_points("root", walk.root_positions[:, None])   # doctest: +SKIP
    """

    def __init__(
        self,
        motions: Motion | Sequence[Motion],
        *,
        colors: Sequence[str] | None = None,
        labels: Sequence[str] | None = None,
        fps: float | None = None,
        bone_radius: float = 0.018,
        joint_radius: float = 0.028,
        end_sites: bool = True,
        ground: bool = True,
        follow: bool = False,
        window_size: tuple[int, int] = (640, 400),
        backend: str | None = None,
        frame: int = 0,
        roles: Any = None,
        play_rate: float = 30.0,
    ) -> None:
        items = as_motions(motions)
        if roles is not None and not isinstance(roles, Mapping) and len(roles) != len(items):
            raise ValueError(f"Expected `roles` as one mapping or one per character ({len(items)}), got {len(roles)}")
        self.roles = roles
        backend = (backend or default_backend()).lower()
        if backend not in BACKENDS:
            raise ValueError(f"Expected `backend` (or ${ENV_VAR}) in {BACKENDS}, got {backend!r}")
        if colors is not None and len(colors) == 0:
            raise ValueError("Expected at least one colour in `colors`, got none")
        if labels is not None and len(labels) != len(items):
            raise ValueError(f"Expected {len(items)} `labels`, got {len(labels)}")
        if not (np.isfinite(float(play_rate)) and float(play_rate) > 0):
            raise ValueError(f"Expected `play_rate` > 0 pictures per second, got {play_rate!r}")
        self.backend = backend
        if fps is not None and not (np.isfinite(float(fps)) and float(fps) > 0):
            raise ValueError(f"Expected `fps` > 0, got {fps!r}")
        self._fps_option = None if fps is None else float(fps)
        self.fps, self.n_frames = self._clock(items)
        self.bone_radius = float(bone_radius)
        self.joint_radius = float(joint_radius)
        self.follow = bool(follow)
        self.end_sites = bool(end_sites)
        self._colors = tuple(colors) if colors is not None else ()
        self._sides = 8
        self._spheres = sphere_set(self.joint_radius)
        self._small_spheres = sphere_set(self.joint_radius * 0.6, resolution=8)
        self.characters = [self._character(k, m, None if labels is None else labels[k]) for k, m in enumerate(items)]
        self.overlays: dict[str, Overlay] = {}
        self._frame = int(np.clip(frame, 0, self.n_frames - 1))
        self._widget: Any = None
        self._view: Any = None  # the embedded pyvista view (trame) or ipywidgets.Image (static)
        self.slider: Any = None
        self.play: Any = None
        self.back: Any = None
        self.forward: Any = None
        self.keys: Any = None
        self._label: Any = None
        self._legend: Any = None
        self._status: Any = None
        self._quiet_thread: int | None = None  # the thread moving the controls itself (its echoes are ignored)
        self._loop = main_thread_loop()  # where calls from other threads are queued
        self._lock = threading.Lock()
        self._pending_frame: int | None = None  # newest slider frame not drawn yet (other threads)
        self._render_queued = False
        self.queued_calls = 0  # calls from other threads handed to the main thread's loop
        # playback
        self.play_rate = float(play_rate)
        self.play_rest = 0.5
        self.play_quality = PLAY_QUALITY
        self.slider_rate = SLIDER_RATE
        self._controls_at = -math.inf  # clock reading of the last slider update
        self.pictures = 0
        self.frame_cost = 0.0
        self.play_log: collections.deque[tuple[float, int, float]] = collections.deque(maxlen=2000)
        self._now: Callable[[], float] = time.perf_counter  # the wall clock (a fake one in tests)
        self._sleep: Callable[[float], Any] = asyncio.sleep
        self._play_clock = PlayClock(self.fps, self.n_frames)
        self._playing = False
        self._play_task: asyncio.Task[None] | None = None
        self._client: dict[str, Any] | None = None  # the "client" backend's page: server, state keys
        self._client_seq = 0
        self._build_scene(window_size, ground)
        self._apply_frame(self._frame)

    # ------------------------------------------------------------- scene
    def _build_scene(self, window_size: tuple[int, int], ground: bool) -> None:
        import pyvista as pv

        interactive = self.backend in ("trame", "server", "client")
        with quiet_vtk():
            self.plotter = pv.Plotter(off_screen=True, notebook=interactive, window_size=list(window_size))
        # no anti-aliasing: on Mesa's llvmpipe 8x MSAA makes a picture ~5x dearer (FXAA is as dear)
        self.plotter.disable_anti_aliasing()
        if self.plotter.render_window is not None:
            self.plotter.render_window.SetMultiSamples(0)
        self.plotter.theme.allow_empty_mesh = True  # overlays may be empty on some frames
        self.plotter.set_background("white")  # type: ignore[arg-type]  # pyvista's decorator hides `self`
        lo, hi = self._scene_bounds()
        self._bounds = (lo, hi)
        self._ground: Any = None
        self._ground_mesh: Any = None
        self._ground_extent: tuple[float, float, float, float] | None = None
        if ground:
            self._update_ground(lo, hi)
        for k, c in enumerate(self.characters):
            self._add_character_actors(k, c)
        self._frame_camera(self._frame)

    def _frame_camera(self, frame: int) -> None:
        """Fit the camera to the whole clip (or, following, to 1 m around the followed joint)."""
        lo, hi = self._bounds
        floor, top = min(float(lo[1]), 0.0), float(hi[1])
        if self.follow:
            root = self.characters[0].anchor(frame / self.fps)
            self._fit_camera(root - [1.0, 0.0, 1.0], root + [1.0, 0.0, 1.0], floor, top)
            self._camera_root = root.copy()
        else:
            self._fit_camera(lo, hi, floor, top)

    def _clock(self, items: Sequence[Motion]) -> tuple[float, int]:
        """The slider clock's rate and frame count for the characters ``items``."""
        return clock_of(items, self._fps_option)

    def _character(self, k: int, m: Motion, label: str | None) -> Character:
        """Character ``k``: its drawn points and bones (:func:`~mocaplab.widgets.scene.character_geometry`)."""
        roles = self.roles
        if roles is not None and not isinstance(roles, Mapping):  # one per character
            roles = roles[k] if k < len(roles) else None
        pos, segs, path_joint = character_geometry(m, roles, end_sites=self.end_sites)
        color = self._colors[k % len(self._colors)] if self._colors else character_colors(k + 1)[k]
        name = label if label is not None else (m.name or f"character {k}")
        return Character(m, color, str(name), pos, segs, path_joint)

    def _scene_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Box of every drawn point of every character over its whole clip, grown by the joint radius."""
        return scene_bounds(self.characters, max(self.joint_radius, self.bone_radius))

    def _update_ground(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> None:
        """Lay (or widen) the ground grid under the box ``[lo, hi]``; the actor is kept."""
        import pyvista as pv

        grid = ground_grid(lo, hi, self._ground_extent)
        if grid is None:
            return
        xs, zs, self._ground_extent = grid
        gx, gz = np.meshgrid(xs, zs, indexing="ij")
        plane = pv.StructuredGrid(gx, np.full_like(gx, -0.001), gz)
        if self._ground_mesh is None:
            self._ground_mesh = plane
            self._ground = self.plotter.add_mesh(
                plane, color="#f2f2f2", show_edges=True, edge_color="#bbbbbb", lighting=False, name="ground"
            )
        else:
            self._ground_mesh.copy_from(plane)

    def _add_character_actors(self, k: int, c: Character) -> None:
        """Make character ``k``'s two meshes (at its first frame) and their actors."""
        n_bones, n_pts = len(c.segments), c.positions.shape[1]
        p0 = c.positions[0]
        pts, normals = tube_points(p0[c.segments[:, 0]], p0[c.segments[:, 1]], self.bone_radius, self._sides)
        c.bones = _mesh(pts, tube_faces(n_bones, self._sides), normals)
        c.joints = _mesh(self._spheres.points(p0), self._spheres.faces(n_pts), self._spheres.normals(n_pts))
        a1 = self.plotter.add_mesh(c.bones, color=c.color, name=f"bones{k}", smooth_shading=False, reset_camera=False)
        a2 = self.plotter.add_mesh(c.joints, color=c.color, name=f"joints{k}", smooth_shading=False, reset_camera=False)
        c.actors = (a1, a2)
        for actor in c.actors:
            actor.prop.interpolation = "gouraud"

    def legend_html(self) -> str:
        """The legend, grouped by name: each name once, after the coloured dots of its characters; empty for one.

        Eight characters playing two clips read ``16_15 ●●●● 02_01 ●●●●``
        (each dot's tooltip says which character it is), not the two names
        eight times.  Names are HTML-escaped.
        """
        if len(self.characters) < 2:
            return ""
        groups: dict[str, list[tuple[int, str]]] = {}
        for k, c in enumerate(self.characters):
            groups.setdefault(c.label, []).append((k, c.color))
        items = []
        for label, members in groups.items():
            dots = "".join(
                f"<span title='character {k}' style='color:{html.escape(color, quote=True)};font-size:1.3em'>"
                "&#9679;</span>"
                for k, color in members
            )
            count = f" ×{len(members)}" if len(members) > 1 else ""
            wrap = "nowrap" if len(members) <= 10 else "normal"  # a long row of dots may wrap
            items.append(
                f"<span class='mocaplab-legend-group' style='white-space:{wrap};margin-right:14px'>"
                f"{dots} {html.escape(label)}{count}</span> "
            )
        return f"<div style='display:flex;flex-wrap:wrap;align-items:center;line-height:1.6'>{''.join(items)}</div>"

    def _update_legend(self) -> None:
        if self._legend is not None:
            self._legend.value = self.legend_html()
            self._legend.layout.display = "" if len(self.characters) > 1 else "none"

    def _fit_camera(self, lo: NDArray[np.float64], hi: NDArray[np.float64], floor: float, top: float) -> None:
        """Look from the front-right and above at the box [lo, hi] (x, z) x [floor, top] (y), all of it inside.

        In a trame view with its toolbar open, the picture's top band under
        the toolbar is kept free.
        """
        direction = np.array([1.0, 0.5, 0.9])
        up = np.array([0.0, 1.0, 0.0])
        corners = box_corners(lo, hi, floor, top)
        width, height = self.plotter.window_size
        focal, position = fit_view(
            corners,
            direction,
            up,
            view_angle=self.plotter.camera.view_angle,
            aspect=width / max(height, 1),
            top_band=self._toolbar_band(),
        )
        self.plotter.camera_position = [tuple(position), tuple(focal), tuple(up)]
        self.plotter.renderer.ResetCameraClippingRange()
        self._fitted = self._camera_pose()

    def _camera_pose(self) -> NDArray[np.float64]:
        """The camera as the viewer compares it: position relative to the focal point, view-up, and
        (without ``follow``, which moves it) the focal point."""
        cam = self.plotter.camera
        focal = np.asarray(cam.focal_point, dtype=float)
        parts = [np.asarray(cam.position, dtype=float) - focal, np.asarray(cam.up, dtype=float)]
        if not self.follow:
            parts.append(focal)
        return np.concatenate(parts)

    def camera_moved(self) -> bool:
        """Whether the camera is no longer where the viewer put it (the user rotated, panned or zoomed)."""
        return not np.allclose(self._camera_pose(), self._fitted, rtol=1e-6, atol=1e-6)

    def _toolbar_band(self) -> float:
        """Share of the view's height under the open trame toolbar (0 when collapsed or without trame)."""
        width, height = self.plotter.window_size
        if self.backend not in _TRAME_MODES or width < TOOLBAR_WIDTH:  # the "client" page has no toolbar
            return 0.0
        return min(_TOOLBAR_BOTTOM / max(height, 1), 0.3)

    def _frame_of(self, k: int, frame: int) -> int:
        return self.characters[k].frame_at(frame / self.fps)

    # ------------------------------------------------------------ updating
    @property
    def frame(self) -> int:
        """The current frame of the viewer's clock."""
        return self._frame

    @property
    def time(self) -> float:
        """The current time in seconds."""
        return self._frame / self.fps

    @property
    def playing(self) -> bool:
        """Whether real-time playback is running."""
        return self._playing

    def character_frames(self) -> list[int]:
        """Frame shown by each character at the current time."""
        return [c.frame_at(self.time) for c in self.characters]

    def label_text(self) -> str:
        """The line under the slider: the clip's length and rate, and the characters' own frames where they differ.

        The slider itself shows the time (its description) and the clock's
        frame (its readout), sent together; this line changes during play
        only when a character's frame differs from the clock's (other rates).
        """
        end = (self.n_frames - 1) / self.fps
        text = f"clip {end:.3f} s, frames 0-{self.n_frames - 1} at {self.fps:g} fps"
        frames = self.character_frames()
        if any(f != self._frame for f in frames):
            text += f"; characters' frames {', '.join(str(f) for f in frames)}"
        return text

    @on_main_thread
    def set_frame(self, frame: int) -> None:
        """Show clock frame ``frame`` (also moves the slider; while playing, play on from there)."""
        f = int(frame)
        if not 0 <= f < self.n_frames:
            raise IndexError(f"Expected `frame` in [0, {self.n_frames}), got {frame}")
        if self._playing:
            self._play_clock.start(f, now=self._now())
        self._apply_frame(f)

    @on_main_thread
    def set_time(self, t: float) -> None:
        """Show the frame nearest to time ``t`` seconds (clamped to the clip)."""
        self.set_frame(int(np.clip(round(float(t) * self.fps), 0, self.n_frames - 1)))

    @on_main_thread
    def set_motions(
        self,
        motions: Motion | Sequence[Motion],
        *,
        labels: Sequence[str] | None = None,
        reset_camera: bool | None = None,
    ) -> None:
        """Show new motions in this viewer, keeping its plotter and widget (and a camera the user moved).

        Meant for edits: after a path drag, pass the edited characters and the
        3D view (static image or trame view) just updates.

        Parameters
        ----------
        motions : Motion or sequence of Motion
            The new characters.
        labels : sequence of str, optional
            New legend names (default: keep the current ones when the number
            of characters is unchanged, else each motion's name).
        reset_camera : bool, optional
            Fit the camera to the new scene (the whole clip of every new
            character in the picture).  Default: when the camera is still
            where the viewer put it; a camera the user moved stays.

        Notes
        -----
        When the number of characters is unchanged and every character keeps
        its counts of joints (with end sites) and bones, the existing meshes
        receive the new points **in place**: no actor or mesh is re-created.
        Otherwise the characters' actors are rebuilt inside the same plotter.
        The clock (``fps`` unless it was given to the constructor,
        ``n_frames``, the slider's range) follows the new motions; the
        current time is kept, clamped to the new last frame, and playback
        goes on from there.  The ground grid is widened if the characters
        walk off it; overlays are left as they are.
        """
        items = as_motions(motions)
        if labels is not None and len(labels) != len(items):
            raise ValueError(f"Expected {len(items)} `labels`, got {len(labels)}")
        same_count = len(items) == len(self.characters)
        if labels is None and same_count:
            labels = [c.label for c in self.characters]
        new = [self._character(k, m, None if labels is None else labels[k]) for k, m in enumerate(items)]
        in_place = same_count and all(
            a.positions.shape[1] == b.positions.shape[1] and len(a.segments) == len(b.segments)
            for a, b in zip(self.characters, new, strict=True)
        )
        if in_place:
            for old, c in zip(self.characters, new, strict=True):
                c.bones, c.joints, c.actors = old.bones, old.joints, old.actors  # same meshes, new points
        else:
            for k in range(len(self.characters)):
                for name in (f"bones{k}", f"joints{k}"):
                    self.plotter.remove_actor(name, render=False)  # type: ignore[arg-type]  # as set_background
            for k, c in enumerate(new):
                self._add_character_actors(k, c)
        self.characters = new
        self._update_legend()

        time_now = self.time
        self.fps, self.n_frames = self._clock(items)
        frame = int(np.clip(round(time_now * self.fps), 0, self.n_frames - 1))
        self._play_clock.fps, self._play_clock.n_frames = self.fps, self.n_frames
        if self._playing:
            self._play_clock.start(frame, now=self._now())
        self._bounds = self._scene_bounds()
        if self._ground_mesh is not None:
            self._update_ground(*self._bounds)
        refit = bool(reset_camera or (reset_camera is None and not self.camera_moved()))
        if refit:
            self._frame = frame
            self._frame_camera(frame)
        if self.slider is not None:
            self._sync_controls(frame)
        self._client_send(chars=True, overlays=True, ground=True, camera=refit)
        self._apply_frame(frame)

    def _sync_controls(self, frame: int) -> None:
        """Fit the slider to the clock without a render per change."""
        with self._moving_controls():
            if frame > self.slider.max:  # keep value <= max at every step
                self.slider.max = self.n_frames - 1
                self.slider.value = frame
            else:
                self.slider.value = frame
                self.slider.max = self.n_frames - 1

    @contextlib.contextmanager
    def _moving_controls(self) -> Iterator[None]:
        """Changes of the controls made in this block are the viewer's own: its observers ignore them."""
        self._quiet_thread = threading.get_ident()
        try:
            yield
        finally:
            self._quiet_thread = None

    def _apply_frame(self, frame: int, *, controls: bool = True) -> None:
        """Move everything to clock frame ``frame``: characters, overlays, camera, slider, label, picture.

        ``controls=False`` (playback between two slider updates) leaves the
        slider and label as they are.  An overlay that raises does not stop
        the others, nor the slider and label; its error is raised once all of
        them show ``frame``.
        """
        self._frame = frame
        t = frame / self.fps
        for c in self.characters:
            p = c.positions[c.frame_at(t)]
            pts, normals = tube_points(p[c.segments[:, 0]], p[c.segments[:, 1]], self.bone_radius, self._sides)
            _write_points(c.bones, pts, normals)
            _write_points(c.joints, self._spheres.points(p))
        error: Exception | None = None
        for ov in self.overlays.values():
            try:
                self._update_overlay(ov, t)
            except Exception as err:  # noqa: BLE001 - raised below, once the view is consistent
                error = error or err
        if self.follow:
            root = self.characters[0].anchor(t)
            shift = root - self._camera_root
            shift[1] = 0.0
            cam = self.plotter.camera
            cam.position = tuple(np.asarray(cam.position) + shift)
            cam.focal_point = tuple(np.asarray(cam.focal_point) + shift)
            self._camera_root = self._camera_root + shift
            self.plotter.renderer.ResetCameraClippingRange()
        if controls:
            self._show_on_controls(frame)
        self._refresh()
        if error is not None:
            raise error

    def _show_on_controls(self, frame: int) -> None:
        """Slider (value and time in one message: never one without the other) and label at ``frame``."""
        if self.slider is not None:
            with self._moving_controls(), self.slider.hold_sync():
                self.slider.value = frame
                self.slider.description = f"{frame / self.fps:.3f} s"
        if self._label is not None:
            self._label.value = html.escape(self.label_text())
        self._controls_at = self._now()

    # ------------------------------------------------------------ playback
    @on_main_thread
    def toggle_playback(self) -> None:
        """Start playback, or pause it if it runs (the play button)."""
        if self._playing:
            self.stop_playback()
        else:
            self.start_playback()

    @on_main_thread
    def start_playback(self) -> None:
        """Play in real time from the current frame (from the first one when at the end).

        Raises
        ------
        RuntimeError
            Without a running asyncio loop in the main thread (a script):
            playback runs on the loop of the Jupyter kernel.
        """
        if self._playing:
            return
        loop = self._loop
        if loop is None or loop.is_closed() or not loop.is_running():
            raise RuntimeError(
                "Playback runs on the asyncio loop of a Jupyter kernel; no loop was running when this "
                "viewer was built. Use set_frame() or set_time() to move through the clip."
            )
        start = 0 if self._frame >= self.n_frames - 1 else self._frame
        self._play_clock = PlayClock(self.fps, self.n_frames)
        self._play_clock.start(start, now=self._now())
        self._playing = True
        self._controls_at = -math.inf  # the first picture moves the slider
        self._update_play_button()
        self._set_picture_quality(self.play_quality)
        if start != self._frame:
            self._apply_frame(start)
        self._client_control()  # the page plays on its own clock from here
        self._play_task = loop.create_task(self._play_loop())

    @on_main_thread
    def stop_playback(self) -> None:
        """Pause playback on the frame shown."""
        was_playing, self._playing = self._playing, False
        task, self._play_task = self._play_task, None
        if task is not None and not task.done() and task is not current_task():
            task.cancel()
        self._update_play_button()
        if was_playing and self._client is not None:
            self._apply_frame(self._frame)  # the kernel's meshes and the page pause on the slider's frame
        elif was_playing:
            self._show_on_controls(self._frame)
        if was_playing and self._set_picture_quality(100):
            self._render_view()  # the paused picture at full quality

    def _set_picture_quality(self, quality: int) -> bool:
        """JPEG quality of the trame view's pictures; False when there is no such view."""
        views = getattr(getattr(self._view, "viewer", None), "views", ())
        done = False
        for view in views:
            helper = getattr(view, "_helper", None)
            if helper is None or not getattr(view.server, "protocol", None):
                continue
            try:
                helper.set_image_quality(self.plotter.render_window, int(quality), 1)
                done = True
            except Exception:  # noqa: BLE001 - no client connected yet: it sets its own
                _log.debug("MotionViewer: could not set the picture quality", exc_info=True)
        return done

    def _update_play_button(self) -> None:
        if self.play is not None:
            with self._moving_controls():
                self.play.description = "pause" if self._playing else "play"
                self.play.icon = "pause" if self._playing else "play"

    async def _play_loop(self) -> None:
        """Draw the wall clock's frame, rest, repeat; stop on the last frame or on an error."""
        try:
            while self._playing and self._client is not None:  # the page draws: follow its clock on the controls
                frame = self._play_clock.frame_at(self._now())
                if frame != self._frame:
                    self._frame = frame
                    self._show_on_controls(frame)
                if frame >= self.n_frames - 1:
                    break
                await self._sleep(1.0 / self.slider_rate)
            while self._playing and self._client is None:
                began = self._now()
                frame = self._play_clock.frame_at(began)
                if frame != self._frame:
                    last = frame >= self.n_frames - 1
                    due = last or began - self._controls_at >= 1.0 / self.slider_rate - 1e-9
                    self._apply_frame(frame, controls=due)
                    self.pictures += 1
                    self.frame_cost = self._now() - began
                    self.play_log.append((began, frame, self.frame_cost))
                    self._push_latest_soon()
                if frame >= self.n_frames - 1:
                    break
                spent = self._now() - began
                await self._sleep(max(1.0 / self.play_rate - spent, self.play_rest * spent, 0.001))
        except asyncio.CancelledError:
            return
        except Exception as err:  # noqa: BLE001 - shown in the widget; nobody awaits this task
            _log.exception("MotionViewer: playback failed")
            if self._status is not None:
                self._status.value = error_html(err)
        if self._play_task is current_task():
            self._play_task = None
            self.stop_playback()

    def _step(self, delta: int) -> None:
        """One frame back or forward (the step buttons); pauses playback."""
        if self._playing:
            self.stop_playback()
        self.set_frame(int(np.clip(self._frame + delta, 0, self.n_frames - 1)))

    # ------------------------------------------------------------- threads
    def _queue(self, call: Callable[[], Any]) -> bool:
        """Hand ``call`` to the main thread's loop if this is another thread; False: run it here.

        Without a loop running in the main thread (a script, the tests) the
        call runs in the calling thread, as it always did.
        """
        if threading.current_thread() is threading.main_thread():
            return False
        loop = self._loop
        if loop is None or loop.is_closed() or not loop.is_running():
            return False
        try:
            loop.call_soon_threadsafe(self._run_queued, call)
        except RuntimeError:  # the loop closed meanwhile
            return False
        self.queued_calls += 1
        return True

    def _run_queued(self, call: Callable[[], Any]) -> None:
        """Run a call queued from another thread; show its error (there is no caller to raise to)."""
        try:
            call()
        except Exception as err:  # noqa: BLE001 - shown in the widget and logged
            _log.exception("MotionViewer: a queued update failed")
            if self._status is not None:
                self._status.value = error_html(err)

    def _draw_pending_frame(self) -> None:
        """Show the newest slider frame set from another thread (one draw for a burst of moves)."""
        with self._lock:
            frame, self._pending_frame = self._pending_frame, None
        if frame is not None:
            self._show_slider_frame(frame)

    def _refresh(self) -> None:
        """Push the new geometry to whatever shows it (from the main thread; see the module notes)."""
        if self._view is None:
            return
        if threading.current_thread() is not threading.main_thread():
            with self._lock:
                queued, self._render_queued = self._render_queued, True
            if queued or self._queue(self._refresh_queued):
                return
            with self._lock:
                self._render_queued = False
        self._render_view()

    def _refresh_queued(self) -> None:
        with self._lock:
            self._render_queued = False
        self._render_view()

    def _render_view(self) -> None:
        if self._view is None:
            return
        if self.backend == "static":
            self._view.value = self._png()
        elif self._client is not None:
            self._client_control()
        elif hasattr(self._view, "viewer"):
            # the view renders the window itself while making the picture: no render here
            self._view.viewer.update()

    def _push_latest_soon(self) -> None:
        """Send the newest picture a moment after a push (trame's encoder works in the background).

        trame's image delivery renders, hands the pixels to an encoder thread
        and sends the newest *finished* JPEG, so each push sends the picture
        of the push before; it would send the last one only 0.5 s later.  A
        second delivery 5 ms on sends the picture just encoded (none when it
        was already sent).
        """
        if self._loop is None or not hasattr(self._view, "viewer"):
            return
        self._loop.call_later(0.005, self._push_latest)

    def _push_latest(self) -> None:
        try:
            server = self._view.viewer.server
            protocol = getattr(server, "protocol", None)
            if protocol is None:
                return
            from trame_vtk.modules.vtk import get_helper
            from trame_vtk.modules.vtk.protocols import vtkWebPublishImageDelivery

            view_id = get_helper(server).id(self.plotter.render_window)
            for link in protocol.getLinkProtocols():
                if isinstance(link, vtkWebPublishImageDelivery):
                    link.push_render(view_id)
        except Exception:  # noqa: BLE001 - an optimisation only; the 0.5 s re-send still comes
            _log.debug("MotionViewer: could not re-send the newest picture", exc_info=True)

    # ------------------------------------------------------------ overlays
    def add_points(
        self,
        name: str,
        points: OverlayData,
        *,
        color: str = "#d62728",
        radius: float = 0.035,
        fps: float | None = None,
    ) -> None:
        """Spheres at points that move with the time (e.g. the centre of mass).

        Parameters
        ----------
        name : str
            Key of the overlay (adding the same name again replaces it).
        points : (F, k, 3) array, (k, 3) array, list of (k_i, 3) arrays or callable ``f(t) -> (k, 3)``
            See the module notes; NaN rows are hidden.
        color : str
        radius : float
            Sphere radius, metres.
        fps : float, optional
            Frame rate of per-frame data (default the first character's).
        """
        self._add_overlay(name, "points", points, color, fps, {"radius": float(radius)})

    def add_lines(
        self,
        name: str,
        points: OverlayData,
        *,
        color: str = "#222222",
        width: float = 3.0,
        closed: bool = False,
        fps: float | None = None,
    ) -> None:
        """A polyline through the points of each frame (e.g. a path or a trail).

        ``width`` is in pixels; ``closed`` joins the last point to the first.
        Data forms as in :meth:`add_points`.
        """
        self._add_overlay(name, "lines", points, color, fps, {"width": float(width), "closed": bool(closed)})

    def add_polygon(
        self,
        name: str,
        points: OverlayData,
        *,
        color: str = "#2ca02c",
        opacity: float = 0.35,
        width: float = 3.0,
        fill: bool = True,
        fps: float | None = None,
    ) -> None:
        """A closed polygon (e.g. the support polygon), its points in order.

        The outline is drawn in ``color``; with ``fill`` the inside too, at
        ``opacity`` (the polygon is filled as a fan from its first point, so
        give a convex polygon such as a convex hull).  The vertex count may
        change from frame to frame.
        """
        style = {"width": float(width), "closed": True, "fill": bool(fill), "opacity": float(opacity)}
        self._add_overlay(name, "polygon", points, color, fps, style)

    @on_main_thread
    def remove_overlay(self, name: str) -> None:
        """Remove the overlay called ``name``."""
        ov = self.overlays.pop(name, None)
        if ov is None:
            raise KeyError(f"No overlay named {name!r}; overlays are {list(self.overlays)}")
        self.plotter.remove_actor(ov.actor, render=False)
        self._client_send(overlays=True)
        self._refresh()

    def overlay_points(self, name: str) -> NDArray[np.float64]:
        """Vertices the overlay ``name`` shows on the current frame, shape (k, 3)."""
        try:
            ov = self.overlays[name]
        except KeyError:
            raise KeyError(f"No overlay named {name!r}; overlays are {list(self.overlays)}") from None
        return ov.at(self.time)

    @on_main_thread
    def _add_overlay(
        self, name: str, kind: OverlayKind, data: Any, color: str, fps: float | None, style: dict[str, Any]
    ) -> None:
        if name in self.overlays:
            self.remove_overlay(name)
        ov = Overlay(
            name=str(name),
            kind=kind,
            data=check_overlay_data(name, data),
            fps=float(fps) if fps is not None else self.characters[0].motion.fps,
            color=color,
            style=style,
        )
        import pyvista as pv

        ov.mesh = pv.PolyData()
        self._fill_overlay(ov, ov.at(self.time))
        opts: dict[str, Any] = {"color": color, "name": f"overlay:{name}", "reset_camera": False}
        if kind == "points":
            opts["smooth_shading"] = False
        else:
            opts.update(line_width=style["width"], opacity=style.get("opacity", 1.0) if style.get("fill") else 1.0)
        ov.actor = self.plotter.add_mesh(ov.mesh, **opts)
        if kind == "points":
            ov.actor.prop.interpolation = "gouraud"
        self.overlays[ov.name] = ov
        self._client_send(overlays=True)
        self._refresh()

    def _fill_overlay(self, ov: Overlay, pts: NDArray[np.float64]) -> None:
        """Rebuild the overlay mesh for ``pts`` (same object; topology may change)."""
        import pyvista as pv

        k = len(pts)
        if ov.kind == "points":
            spheres = ov.style.setdefault("spheres", sphere_set(ov.style["radius"], resolution=10))
            if k == ov.count and k > 0:
                _write_points(ov.mesh, spheres.points(pts))
                return
            new = _mesh(spheres.points(pts), spheres.faces(k), spheres.normals(k)) if k else pv.PolyData()
        else:
            if k == ov.count and k > 0:
                _write_points(ov.mesh, pts)
                return
            if k < 2:
                new = pv.PolyData()
            else:
                lines, faces = overlay_cells(k, closed=bool(ov.style.get("closed", False)), fill=bool(ov.style.get("fill")))
                # explicit cells: no vertex cell per point
                new = pv.PolyData(np.array(pts, dtype=float), lines=lines, faces=faces)
        ov.mesh.copy_from(new)
        ov.count = k

    def _update_overlay(self, ov: Overlay, t: float) -> None:
        self._fill_overlay(ov, ov.at(t))

    # ------------------------------------------------------------- output
    def screenshot(self) -> NDArray[np.uint8]:
        """Render off-screen and return the image, shape (H, W, 3), uint8."""
        self.plotter.render()
        img = self.plotter.screenshot(return_img=True)
        return np.asarray(img, dtype=np.uint8)

    def _png(self) -> bytes:
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(self.screenshot()).save(buf, format="png")
        return buf.getvalue()

    @property
    def widget(self) -> Any:
        """The ipywidgets box: 3D view, legend, play and step buttons, frame slider, time label, keys, status."""
        if self._widget is None:
            self._widget = self._build_widget()
        return self._widget

    def _build_widget(self) -> Any:
        import ipywidgets as w

        self.slider = w.IntSlider(
            value=self._frame,
            min=0,
            max=self.n_frames - 1,
            step=1,
            description=f"{self.time:.3f} s",
            continuous_update=True,
            style={"description_width": "72px"},
            tooltip="the frame shown (drag or type a frame number); the label is its time on the clock",
            # a usable track (width less the time and the frame readout): at least 300 px wherever the viewer sits
            layout=w.Layout(flex="1 1 480px", min_width="480px", max_width="760px"),
        )
        self.slider.add_class("mocaplab-viewer-slider")
        self.play = w.Button(
            description="play",
            icon="play",
            tooltip="play in real time (frames the view cannot draw in time are skipped)",
            layout=w.Layout(width="88px", flex="0 0 auto"),
        )
        self.play.add_class("mocaplab-viewer-play")
        self.back = w.Button(
            icon="step-backward", tooltip="one frame back", layout=w.Layout(width="40px", flex="0 0 auto")
        )
        self.forward = w.Button(
            icon="step-forward", tooltip="one frame forward", layout=w.Layout(width="40px", flex="0 0 auto")
        )
        self._label = w.HTML(layout=w.Layout(width="auto"))
        self._label.add_class("mocaplab-viewer-label")
        self._status = w.HTML(layout=w.Layout(width="auto"))
        self._status.add_class("mocaplab-viewer-status")
        self._legend = w.HTML(layout=w.Layout(width="auto"))
        self._legend.add_class("mocaplab-viewer-legend")
        self._update_legend()
        self.slider.observe(self._on_slider, names="value")
        self.play.on_click(self._on_play)
        self.back.on_click(self._on_back)
        self.forward.on_click(self._on_forward)
        if self.backend == "static":
            self._view = w.Image(value=self._png(), format="png")
        elif self.backend == "none":
            self._view = None
        elif self.backend == "client":
            self._view = self._client_view()
        else:
            self._view = self._trame_view()
        controls = w.HBox(
            [self.play, self.back, self.forward, self.slider],
            layout=w.Layout(flex_flow="row wrap", align_items="center", width="100%"),
        )
        # space plays, the arrows step: the buttons' own actions (_controls.viewer_shortcuts), listed on this line
        where = "click the picture, a button or this line first" if self.backend == "client" else KeyCapture.WHERE
        self.keys = KeyCapture(viewer_shortcuts(lambda: self), scope="mocaplab-viewer", where=where)
        children = ([self._view] if self._view is not None else []) + [
            self._legend,
            controls,
            self._label,
            self.keys,
            self._status,
        ]
        width = int(self.plotter.window_size[0])
        # as wide as the view, and at least as wide as the controls' row (buttons and a 300 px track)
        box = w.VBox(children, layout=w.Layout(width=f"{max(width, 680)}px", max_width="100%"))
        box.add_class("mocaplab-viewer")
        self._apply_frame(self._frame)
        return box

    def _trame_view(self) -> Any:
        """pyvista's trame iframe in server-rendering mode."""
        width = int(self.plotter.window_size[0])
        options = {
            "mode": _TRAME_MODES[self.backend],
            "collapse_menu": width < TOOLBAR_WIDTH,
            "handler": iframe_widget,
        }
        enabled, prefix = proxy_setting()
        if enabled is not None:  # else pyvista's theme decides (off unless set with pv.global_theme.trame)
            options["server_proxy_enabled"] = enabled
        if prefix is not None:
            options["server_proxy_prefix"] = prefix
        secure_trame_server()
        with without_vtklocal():
            return self.plotter.show(
                jupyter_backend=_TRAME_MODES[self.backend],
                return_viewer=True,
                auto_close=False,
                jupyter_kwargs=options,
            )

    # ------------------------------------------------------- client backend
    def _client_view(self) -> Any:
        """The "client" backend's view: a trame page drawing the scene with vtk.js in the browser.

        The page (:mod:`mocaplab.widgets.vtkjs_page`) gets the whole clip
        once; it then draws each frame itself and plays on its own clock,
        told only where to start and whether to play.
        """
        server = vtkjs_page.start_server()
        names = self._client_attach(server)
        src = vtkjs_page.build_page(server, names, joint_radius=self.joint_radius)
        width, height = self.plotter.window_size
        return iframe_widget(None, src, width=f"{int(width)}px", height=f"{int(height)}px")

    def _client_attach(self, server: Any) -> dict[str, Any]:
        """Give this viewer its state variables on the trame ``server`` and fill them: the whole scene once.

        Returns the names: ``key`` (the viewer's prefix) and one per part
        (``chars``, ``overlays``, ``ground``, ``camera``, ``ctl``, ``start``).
        """
        names = vtkjs_page.state_names(vtkjs_page.new_key())
        self._client = {"server": server, **names}
        state = server.state
        state.client_only("mocaplab_ready")
        state.setdefault("mocaplab_ready", False)
        state[names["start"]] = self._frame  # the frame drawn before the page's first control
        self._client_send(chars=True, overlays=True, ground=True, camera=True, flush=False)
        state[names["ctl"]] = self._client_ctl()
        return self._client

    def _client_ctl(self) -> dict[str, Any]:
        """What the page plays: from which frame, whether it runs, at which rate (``seq`` makes each one new)."""
        self._client_seq += 1
        return vtkjs_page.control_payload(
            playing=self._playing, frame=self._frame, fps=self.fps, n_frames=self.n_frames, seq=self._client_seq
        )

    def _client_control(self) -> None:
        """Tell the page the frame to show (and, while playing, to play on from)."""
        if self._client is None:
            return
        state = self._client["server"].state
        with state:
            state[self._client["ctl"]] = self._client_ctl()

    def _client_send(
        self,
        *,
        chars: bool = False,
        overlays: bool = False,
        ground: bool = False,
        camera: bool = False,
        flush: bool = True,
    ) -> None:
        """Send the parts of the scene that changed to the page (each part a new state value)."""
        client = self._client
        if client is None:
            return
        self._client_seq += 1
        key, seq, state = client["key"], self._client_seq, client["server"].state
        values: dict[str, Any] = {}
        if chars:
            values[client["chars"]] = vtkjs_page.characters_payload(
                self.characters,
                key=key,
                seq=seq,
                bone_radius=self.bone_radius,
                joint_radius=self.joint_radius,
                sides=self._sides,
                n_frames=self.n_frames,
                fps=self.fps,
            )
        if overlays:
            values[client["overlays"]] = vtkjs_page.overlays_payload(
                self.overlays.values(), key=key, seq=seq, n_frames=self.n_frames, fps=self.fps
            )
        if ground:
            values[client["ground"]] = vtkjs_page.ground_payload(self._ground_mesh)
        if camera:
            values[client["camera"]] = vtkjs_page.camera_payload(self.plotter.camera, seq)
        if flush:
            with state:
                state.update(values)
        else:
            state.update(values)

    # plain-value callbacks: each forwards one event to the viewer, its error shown in the status line
    def _on_play(self, _button: Any) -> None:
        self._shown(self.toggle_playback)

    def _on_back(self, _button: Any) -> None:
        self._shown(self._step_on_main_thread, -1)

    def _on_forward(self, _button: Any) -> None:
        self._shown(self._step_on_main_thread, +1)

    def _shown(self, call: Callable[..., Any], *args: Any) -> None:
        """Run a button's action; an error goes to the status line (a click has no caller to raise to)."""
        try:
            call(*args)
        except Exception as err:  # noqa: BLE001 - shown in the widget
            if self._status is not None:
                self._status.value = error_html(err)
            return
        if self._status is not None and self._status.value and threading.current_thread() is threading.main_thread():
            self._status.value = ""

    @on_main_thread
    def _step_on_main_thread(self, delta: int) -> None:
        self._step(delta)

    def _on_slider(self, change: dict[str, Any]) -> None:
        if self._quiet_thread == threading.get_ident():  # the viewer moved it itself
            return
        frame = int(change["new"])
        if threading.current_thread() is not threading.main_thread():
            with self._lock:  # coalesce: one queued draw shows the newest frame
                queued, self._pending_frame = self._pending_frame is not None, frame
            if queued or self._queue(self._draw_pending_frame):
                return
            with self._lock:  # no loop to hand it to: draw here, as without subshells
                self._pending_frame = None
        self._show_slider_frame(frame)

    def _show_slider_frame(self, frame: int) -> None:
        frame = int(np.clip(frame, 0, self.n_frames - 1))
        if self._playing:  # a move while playing: play on from there
            self._play_clock.start(frame, now=self._now())
        try:
            self._apply_frame(frame)
            if self._status.value:
                self._status.value = ""
        except Exception as err:  # show it in the widget instead of losing it in the log
            self._status.value = error_html(err)
            raise

    def show(self) -> Any:
        """Display the widget in the notebook (and return it)."""
        from IPython.display import display

        display(self.widget)
        return self.widget

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    @on_main_thread
    def close(self) -> None:
        """Stop playback and release the render window."""
        self.stop_playback()
        self.plotter.close()

    def __repr__(self) -> str:
        names = ", ".join(c.label for c in self.characters)
        return f"<MotionViewer [{names}] {self.n_frames} frames at {self.fps:g} fps, backend {self.backend!r}>"
