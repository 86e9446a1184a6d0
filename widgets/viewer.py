"""A 3D viewer of one or several motions: pyvista skeletons, a time slider, play.

>>> from mocaplab.data import cmu                      # doctest: +SKIP
>>> from mocaplab.widgets import MotionViewer          # doctest: +SKIP
>>> viewer = MotionViewer([cmu("16_15"), cmu("02_01")])  # doctest: +SKIP
>>> viewer                                             # doctest: +SKIP

What is drawn
-------------
Each character is two meshes whose topology never changes: its bones as
tubes and its joints (and end sites) as spheres.  Moving the slider writes new
point coordinates into those meshes **in place** (no actor is re-created),
then re-renders.  A ground grid lies at y = 0 under the whole scene.
:meth:`MotionViewer.set_motions` swaps in new motions (an edited scene) the
same way: same plotter, same widget, same meshes when the skeletons match.

Time
----
Characters may have different lengths and frame rates.  The slider counts
frames of the viewer's clock, at ``fps`` frames per second (default: the
highest fps of the characters); slider frame ``i`` is time ``t = i / fps`` and
character ``k`` shows its frame ``round(t * fps_k)``, held at its last frame
once it has ended.  With one character the slider frame is its frame.

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

Rows containing NaN are left out on that frame.

Backends
--------
``MOCAPLAB_JUPYTER_BACKEND`` (default ``"trame"``) selects how the 3D view
reaches the notebook: ``"trame"``, ``"server"`` or ``"client"`` embed pyvista's
interactive trame view (rotate and zoom with the mouse; it re-renders when
the slider moves); ``"static"`` renders off-screen and shows a PNG image that
is re-rendered when the slider moves (used by the tests and by nbval);
``"none"`` builds the controls without any 3D view.

Threads
-------
VTK renders only in the thread that owns its (EGL off-screen) render window:
the kernel's main thread, where the viewer is built and where trame's server
runs on the kernel's asyncio loop.  JupyterLab 4.6 sends widget messages to a
kernel *subshell* by default, so with ipykernel 7 a slider move or a button
click runs its Python callback in another thread; rendering there gives a
black view with white dashes in the browser.  The viewer therefore remembers
the asyncio loop running in the main thread when it is built and, when one of
its methods that touch the scene (:meth:`~MotionViewer.set_frame`,
:meth:`~MotionViewer.set_time`, :meth:`~MotionViewer.set_motions`, the
overlay methods, :meth:`~MotionViewer.close`, the slider's callback) is called
from another thread, queues the whole call onto that loop
(``loop.call_soon_threadsafe``), in call order, and returns at once.  Slider
moves are coalesced: a burst of them (the play button) draws the newest frame
once.  Calls made in the main thread, or when no loop was running there (a
script, the tests), run immediately as before, so the static backend's image
is re-rendered before the call returns.  An error in a queued call is shown
in the widget's status line.

The trame server is started without ``trame-vtklocal``: pyvista loads it when
it is installed, and it then downloads VTK's WebAssembly build from
gitlab.kitware.com, which prints a traceback into some later cell when the
machine is offline or behind a firewall.  The views used here (remote and
vtk.js local rendering) do not need it.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import io
import logging
import os
import sys
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocaplab.editing.paths import with_roles
from mocaplab.motion import Motion

__all__ = ["MotionViewer", "BACKENDS", "default_backend"]

BACKENDS = ("trame", "server", "client", "static", "none")
ENV_VAR = "MOCAPLAB_JUPYTER_BACKEND"
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")

OverlayData = ArrayLike | Sequence[ArrayLike] | Callable[[float], ArrayLike]

_log = logging.getLogger(__name__)
_MAIN_LOOP: asyncio.AbstractEventLoop | None = None  # the loop last seen running in the main thread


def default_backend() -> str:
    """The backend named by ``MOCAPLAB_JUPYTER_BACKEND`` (default ``"trame"``)."""
    return os.environ.get(ENV_VAR, "trame").strip().lower() or "trame"


@contextlib.contextmanager
def _quiet_vtk() -> Iterator[None]:
    """Hide VTK's warnings while a render window is chosen.

    Without a display, VTK first tries X ("bad X server connection"), then
    falls back to EGL off-screen rendering, which works; the warning is noise.
    """
    try:
        from vtkmodules.vtkCommonCore import vtkLogger
    except ImportError:  # pragma: no cover
        yield
        return
    old = vtkLogger.GetCurrentVerbosityCutoff()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    try:
        yield
    finally:
        vtkLogger.SetStderrVerbosity(old)


@contextlib.contextmanager
def _without_vtklocal() -> Iterator[None]:
    """Hide ``trame.widgets.vtklocal`` while pyvista starts its trame server.

    pyvista's ``launch_server`` enables trame-vtklocal when the import
    succeeds, and its set-up downloads VTK's WebAssembly files in a background
    task (a traceback in a later cell when offline).  A ``None`` entry in
    ``sys.modules`` makes that import fail with ImportError, which pyvista
    skips.  The entry is removed afterwards; a module already imported on
    purpose is left alone.
    """
    name = "trame.widgets.vtklocal"
    if name in sys.modules:
        yield
        return
    sys.modules[name] = None  # type: ignore[assignment]
    try:
        yield
    finally:
        if name in sys.modules and sys.modules[name] is None:
            del sys.modules[name]


def _main_thread_loop() -> asyncio.AbstractEventLoop | None:
    """The asyncio loop of the main thread (the kernel's), if one is running.

    Read in the main thread (and remembered for viewers built elsewhere);
    None in a script or a test without a running loop.
    """
    global _MAIN_LOOP
    if threading.current_thread() is threading.main_thread():
        try:
            _MAIN_LOOP = asyncio.get_running_loop()
        except RuntimeError:
            return None
        return _MAIN_LOOP
    loop = _MAIN_LOOP
    return loop if loop is not None and not loop.is_closed() else None


def _on_main_thread(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run a scene-changing method in the main thread (queued there when called from another)."""

    @functools.wraps(method)
    def wrapper(self: MotionViewer, *args: Any, **kwargs: Any) -> Any:
        if self._queue(functools.partial(method, self, *args, **kwargs)):
            return None
        return method(self, *args, **kwargs)

    return wrapper


# --------------------------------------------------------------------------
# fixed-topology geometry: tubes and spheres whose points move
# --------------------------------------------------------------------------
def _tube_faces(n_bones: int, sides: int) -> NDArray[np.int64]:
    """VTK face array of ``n_bones`` open tubes with ``sides`` quads each."""
    s = np.arange(sides)
    base = (np.arange(n_bones) * 2 * sides)[:, None]
    quads = np.stack([base + s, base + (s + 1) % sides, base + sides + (s + 1) % sides, base + sides + s], axis=-1)
    return np.concatenate([np.full((n_bones, sides, 1), 4), quads], axis=-1).reshape(-1)


def _tube_points(a: NDArray[np.float64], b: NDArray[np.float64], radius: float, sides: int) -> tuple[Any, Any]:
    """Points (B*2*S, 3) and normals of open tubes from ``a`` (B, 3) to ``b`` (B, 3)."""
    d = b - a
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    axis = np.where(length > 1e-9, d / np.maximum(length, 1e-12), [0.0, 1.0, 0.0])
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(axis, u)
    theta = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(theta)[None, :, None] * u[:, None] + np.sin(theta)[None, :, None] * v[:, None]  # (B, S, 3)
    pts = np.stack([a[:, None] + radius * ring, b[:, None] + radius * ring], axis=1)  # (B, 2, S, 3)
    normals = np.broadcast_to(ring[:, None], pts.shape)
    return pts.reshape(-1, 3), normals.reshape(-1, 3)


@dataclass
class _SphereSet:
    """``n`` copies of one sphere mesh, moved by translating each copy."""

    radius: float
    resolution: int = 10
    template: NDArray[np.float64] = field(init=False)
    template_faces: NDArray[np.int64] = field(init=False)
    template_normals: NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        import pyvista as pv

        s = pv.Sphere(radius=1.0, theta_resolution=self.resolution, phi_resolution=max(4, self.resolution - 2))
        self.template = np.asarray(s.points, dtype=float) * self.radius
        self.template_normals = np.asarray(s.points, dtype=float)
        self.template_faces = np.asarray(s.regular_faces, dtype=np.int64)  # (C, 3) triangles

    def faces(self, n: int) -> NDArray[np.int64]:
        """VTK face array of ``n`` copies of the template sphere."""
        tris = self.template_faces[None] + (np.arange(n) * len(self.template))[:, None, None]  # (n, C, 3)
        return np.concatenate([np.full(tris.shape[:2] + (1,), 3), tris], axis=-1).reshape(-1)

    def points(self, centres: NDArray[np.float64]) -> NDArray[np.float64]:
        return (centres[:, None] + self.template[None]).reshape(-1, 3)

    def normals(self, n: int) -> NDArray[np.float64]:
        return np.tile(self.template_normals, (n, 1))


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
# characters and overlays
# --------------------------------------------------------------------------
@dataclass
class _Character:
    motion: Motion
    color: str
    label: str
    positions: NDArray[np.float64]  # (F, J + E, 3): drawn joints then end sites
    segments: NDArray[np.int64]  # (B, 2) indices into the positions
    path_joint: int = 0  # index in `positions` of the joint the camera follows (the pelvis role)
    bones: Any = None  # pyvista.PolyData
    joints: Any = None  # pyvista.PolyData
    actors: tuple[Any, ...] = ()

    def frame_at(self, t: float) -> int:
        return int(min(max(round(t * self.motion.fps), 0), self.motion.n_frames - 1))

    def anchor(self, t: float) -> NDArray[np.float64]:
        """World position of the path joint at time ``t``, shape (3,)."""
        return self.positions[self.frame_at(t), self.path_joint]


@dataclass
class _Overlay:
    name: str
    kind: str  # "points", "lines", "polygon"
    data: Any
    fps: float
    color: str
    style: dict[str, Any]
    mesh: Any = None
    actor: Any = None
    count: int = -1

    def at(self, t: float) -> NDArray[np.float64]:
        """The overlay's points at time ``t``: (k, 3) with NaN rows removed."""
        if callable(self.data):
            pts = np.asarray(self.data(float(t)), dtype=float)
        elif isinstance(self.data, np.ndarray) and self.data.ndim == 2:
            pts = self.data
        else:
            n = len(self.data)
            i = int(min(max(round(t * self.fps), 0), n - 1))
            pts = np.asarray(self.data[i], dtype=float)
        pts = pts.reshape(-1, 3) if pts.size else np.zeros((0, 3))
        return pts[np.all(np.isfinite(pts), axis=1)]


def _check_overlay_data(name: str, data: Any) -> Any:
    if callable(data):
        return data
    if isinstance(data, np.ndarray) or (isinstance(data, Sequence) and data and np.ndim(data[0]) == 1):
        arr = np.asarray(data, dtype=float)
        if arr.ndim in (2, 3) and arr.shape[-1] == 3:
            return arr
        raise ValueError(
            f"Expected overlay {name!r} data of shape (F, k, 3) or (k, 3), a list of (k_i, 3) arrays "
            f"or a callable of time, got an array of shape {arr.shape}"
        )
    if isinstance(data, Sequence) and len(data) > 0:
        frames = [np.asarray(d, dtype=float).reshape(-1, 3) if np.size(d) else np.zeros((0, 3)) for d in data]
        return frames
    raise ValueError(
        f"Expected overlay {name!r} data: (F, k, 3), (k, 3), a list of (k_i, 3) or a callable, got {data!r}"
    )


def _as_motions(motions: Motion | Sequence[Motion]) -> list[Motion]:
    """``motions`` as a non-empty list of Motion (a single Motion is one character)."""
    items = [motions] if isinstance(motions, Motion) else list(motions)
    if not items:
        raise ValueError("Expected at least one Motion in `motions`, got none")
    for k, m in enumerate(items):
        if not isinstance(m, Motion):
            raise TypeError(f"Expected `motions[{k}]` to be a Motion, got {type(m).__name__}")
    return items


# --------------------------------------------------------------------------
class MotionViewer:
    """Play one or several motions in 3D with a time slider and a play button.

    Parameters
    ----------
    motions : Motion or sequence of Motion
        The characters; lengths and frame rates may differ.
    colors : sequence of str, optional
        One colour per character (default a tab10-like cycle).
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
        Pixels of the 3D view.
    backend : str, optional
        One of :data:`BACKENDS`; default ``MOCAPLAB_JUPYTER_BACKEND`` or ``"trame"``.
    frame : int
        Initial slider frame.

    Attributes
    ----------
    plotter : pyvista.Plotter
    slider : ipywidgets.IntSlider
        The frame of the viewer's clock (created with :attr:`widget`).
    play : ipywidgets.Play
        Linked to ``slider`` in the browser.

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
        window_size: tuple[int, int] = (760, 460),
        backend: str | None = None,
        frame: int = 0,
        roles: Any = None,
    ) -> None:
        items = _as_motions(motions)
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
        self.backend = backend
        if fps is not None and not (np.isfinite(float(fps)) and float(fps) > 0):
            raise ValueError(f"Expected `fps` > 0, got {fps!r}")
        self._fps_option = None if fps is None else float(fps)
        self.fps, self.n_frames = self._clock(items)
        self.bone_radius = float(bone_radius)
        self.joint_radius = float(joint_radius)
        self.follow = bool(follow)
        self.end_sites = bool(end_sites)
        self._colors = tuple(colors or COLORS)
        self._sides = 8
        self._spheres = _SphereSet(self.joint_radius)
        self._small_spheres = _SphereSet(self.joint_radius * 0.6, resolution=8)
        self.characters = [self._character(k, m, None if labels is None else labels[k]) for k, m in enumerate(items)]
        self.overlays: dict[str, _Overlay] = {}
        self._frame = int(np.clip(frame, 0, self.n_frames - 1))
        self._widget: Any = None
        self._view: Any = None  # the embedded pyvista view (trame) or ipywidgets.Image (static)
        self.slider: Any = None
        self.play: Any = None
        self._label: Any = None
        self._status: Any = None
        self._quiet = False
        self._loop = _main_thread_loop()  # where calls from other threads are queued
        self._lock = threading.Lock()
        self._pending_frame: int | None = None  # newest slider frame not drawn yet (other threads)
        self._render_queued = False
        self.queued_calls = 0  # calls from other threads handed to the main thread's loop
        self._build_scene(window_size, ground)
        self._apply_frame(self._frame)

    # ------------------------------------------------------------- scene
    def _build_scene(self, window_size: tuple[int, int], ground: bool) -> None:
        import pyvista as pv

        interactive = self.backend in ("trame", "server", "client")
        with _quiet_vtk():
            self.plotter = pv.Plotter(off_screen=True, notebook=interactive, window_size=list(window_size))
        self.plotter.theme.allow_empty_mesh = True  # overlays may be empty on some frames
        self.plotter.set_background("white")
        lo, hi = self._scene_bounds()
        self._bounds = (lo, hi)
        self._ground: Any = None
        self._ground_mesh: Any = None
        self._ground_extent: tuple[float, float, float, float] | None = None
        if ground:
            self._update_ground(lo, hi)
        for k, c in enumerate(self.characters):
            self._add_character_actors(k, c)
        self._update_legend()
        floor = min(float(lo[1]), 0.0)
        if self.follow:
            root = self.characters[0].anchor(self._frame / self.fps)
            self._fit_camera(root - [1.0, 0.0, 1.0], root + [1.0, 0.0, 1.0], floor, float(hi[1]))
            self._camera_root = root.copy()
        else:
            self._fit_camera(lo, hi, floor, float(hi[1]))

    def _clock(self, items: Sequence[Motion]) -> tuple[float, int]:
        """The slider clock's rate and frame count for the characters ``items``."""
        rate = self._fps_option if self._fps_option is not None else max(m.fps for m in items)
        return rate, int(np.floor(max(m.duration for m in items) * rate + 1e-9)) + 1

    def _character(self, k: int, m: Motion, label: str | None) -> _Character:
        """Character ``k``: its joint and end-site positions and bone segments.

        Joints above the path joint (a static reference joint at the origin
        over a travelling pelvis) are not drawn, nor the "bone" from them to
        the pelvis (the travel over the ground): the body looks the same
        whatever the skeleton's layout.
        """
        sk = m.skeleton
        roles = self.roles
        if roles is not None and not isinstance(roles, Mapping):  # one per character
            roles = roles[k] if k < len(roles) else None
        pj = with_roles(m, roles).path_joint
        parents = np.asarray(sk.parents)
        drawn = np.ones(sk.n_joints, bool)
        j = int(parents[pj])
        while j >= 0:
            drawn[j] = False
            j = int(parents[j])
        idx = np.flatnonzero(drawn)
        new = np.full(sk.n_joints, -1, dtype=np.int64)
        new[idx] = np.arange(len(idx))
        pos = m.global_positions()[:, idx]
        child = np.flatnonzero(drawn & (parents >= 0) & drawn[np.maximum(parents, 0)])
        segs = np.stack([new[parents[child]], new[child]], axis=1)
        if self.end_sites and sk.end_site_parents.size:
            esp = np.asarray(sk.end_site_parents)
            ok = drawn[esp]
            pos = np.concatenate([pos, m.end_site_positions()[:, ok]], axis=1)
            ends = np.arange(len(idx), len(idx) + int(ok.sum()))
            segs = np.concatenate([segs, np.stack([new[esp[ok]], ends], axis=1)])
        color = self._colors[k % len(self._colors)]
        name = label if label is not None else (m.name or f"character {k}")
        return _Character(m, color, name, pos, segs, int(new[pj]))

    def _scene_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        all_pts = np.concatenate([c.positions.reshape(-1, 3) for c in self.characters])
        return all_pts.min(axis=0), all_pts.max(axis=0)

    def _update_ground(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> None:
        """Lay (or widen) the ground grid under the box ``[lo, hi]``; the actor is kept."""
        import pyvista as pv

        if self._ground_extent is not None:
            x0, x1, z0, z1 = self._ground_extent
            if x0 <= lo[0] and hi[0] <= x1 and z0 <= lo[2] and hi[2] <= z1:
                return
        margin = 1.0
        x0, x1 = np.floor(lo[0] - margin), np.ceil(hi[0] + margin)
        z0, z1 = np.floor(lo[2] - margin), np.ceil(hi[2] + margin)
        xs = np.linspace(x0, x1, int(round((x1 - x0) / 0.5)) + 1)  # 0.5 m squares
        zs = np.linspace(z0, z1, int(round((z1 - z0) / 0.5)) + 1)
        gx, gz = np.meshgrid(xs, zs, indexing="ij")
        plane = pv.StructuredGrid(gx, np.full_like(gx, -0.001), gz)
        self._ground_extent = (float(x0), float(x1), float(z0), float(z1))
        if self._ground_mesh is None:
            self._ground_mesh = plane
            self._ground = self.plotter.add_mesh(
                plane, color="#f2f2f2", show_edges=True, edge_color="#bbbbbb", lighting=False, name="ground"
            )
        else:
            self._ground_mesh.copy_from(plane)

    def _add_character_actors(self, k: int, c: _Character) -> None:
        """Make character ``k``'s two meshes (at its first frame) and their actors."""
        n_bones, n_pts = len(c.segments), c.positions.shape[1]
        p0 = c.positions[0]
        pts, normals = _tube_points(p0[c.segments[:, 0]], p0[c.segments[:, 1]], self.bone_radius, self._sides)
        c.bones = _mesh(pts, _tube_faces(n_bones, self._sides), normals)
        c.joints = _mesh(self._spheres.points(p0), self._spheres.faces(n_pts), self._spheres.normals(n_pts))
        a1 = self.plotter.add_mesh(c.bones, color=c.color, name=f"bones{k}", smooth_shading=False, reset_camera=False)
        a2 = self.plotter.add_mesh(c.joints, color=c.color, name=f"joints{k}", smooth_shading=False, reset_camera=False)
        c.actors = (a1, a2)
        for actor in c.actors:
            actor.prop.interpolation = "gouraud"

    def _update_legend(self) -> None:
        if len(self.characters) > 1:
            self.plotter.add_legend(  # replaces any previous legend
                [(c.label, c.color) for c in self.characters],
                bcolor="white",
                face="circle",
                size=(0.18, 0.05 * len(self.characters)),
            )
        elif self.plotter.legend is not None:
            self.plotter.remove_legend(render=False)

    def _fit_camera(self, lo: NDArray[np.float64], hi: NDArray[np.float64], floor: float, top: float) -> None:
        """Look from the front-right and above at the box [lo, hi] (x, z) x [floor, top] (y)."""
        centre = np.array([(lo[0] + hi[0]) / 2, (floor + top) / 2, (lo[2] + hi[2]) / 2])
        direction = np.array([1.0, 0.5, 0.9])
        direction /= np.linalg.norm(direction)
        self.plotter.camera_position = [tuple(centre + 5.0 * direction), tuple(centre), (0.0, 1.0, 0.0)]
        self.plotter.renderer.ResetCamera(lo[0], hi[0], floor, top, lo[2], hi[2])
        self.plotter.camera.zoom(1.3)
        self.plotter.renderer.ResetCameraClippingRange()  # keep the whole ground visible

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

    def character_frames(self) -> list[int]:
        """Frame shown by each character at the current time."""
        return [c.frame_at(self.time) for c in self.characters]

    @_on_main_thread
    def set_frame(self, frame: int) -> None:
        """Show clock frame ``frame`` (also moves the slider if it exists)."""
        f = int(frame)
        if not 0 <= f < self.n_frames:
            raise IndexError(f"Expected `frame` in [0, {self.n_frames}), got {frame}")
        if self.slider is not None and self.slider.value != f:
            self.slider.value = f  # the observer calls back into _apply_frame
            return
        self._apply_frame(f)

    @_on_main_thread
    def set_time(self, t: float) -> None:
        """Show the frame nearest to time ``t`` seconds (clamped to the clip)."""
        self.set_frame(int(np.clip(round(float(t) * self.fps), 0, self.n_frames - 1)))

    @_on_main_thread
    def set_motions(
        self,
        motions: Motion | Sequence[Motion],
        *,
        labels: Sequence[str] | None = None,
        reset_camera: bool = False,
    ) -> None:
        """Show new motions in this viewer, keeping its plotter, widget and camera.

        Meant for edits: after a path drag, pass the edited characters and the
        3D view (static image or trame view) just updates.

        Parameters
        ----------
        motions : Motion or sequence of Motion
            The new characters.
        labels : sequence of str, optional
            New legend names (default: keep the current ones when the number
            of characters is unchanged, else each motion's name).
        reset_camera : bool
            Fit the camera to the new scene (default: leave it where the user
            put it).

        Notes
        -----
        When the number of characters is unchanged and every character keeps
        its counts of joints (with end sites) and bones, the existing meshes
        receive the new points **in place**: no actor or mesh is re-created.
        Otherwise the characters' actors are rebuilt inside the same plotter.
        The clock (``fps`` unless it was given to the constructor,
        ``n_frames``, the slider's and play button's range) follows the new
        motions; the current time is kept, clamped to the new last frame.
        The ground grid is widened if the characters walk off it; overlays
        are left as they are.
        """
        items = _as_motions(motions)
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
                    self.plotter.remove_actor(name, render=False)
            for k, c in enumerate(new):
                self._add_character_actors(k, c)
        relabel = [c.label for c in new] != [c.label for c in self.characters]
        self.characters = new
        if relabel or not in_place:
            self._update_legend()

        time = self.time
        self.fps, self.n_frames = self._clock(items)
        frame = int(np.clip(round(time * self.fps), 0, self.n_frames - 1))
        lo, hi = self._scene_bounds()
        self._bounds = (lo, hi)
        if self._ground_mesh is not None:
            self._update_ground(lo, hi)
        if reset_camera:
            floor = min(float(lo[1]), 0.0)
            if self.follow:
                root = self.characters[0].anchor(frame / self.fps)
                self._fit_camera(root - [1.0, 0.0, 1.0], root + [1.0, 0.0, 1.0], floor, float(hi[1]))
                self._camera_root = root.copy()
            else:
                self._fit_camera(lo, hi, floor, float(hi[1]))
        if self.slider is not None:
            self._sync_controls(frame)
        self._apply_frame(frame)

    def _sync_controls(self, frame: int) -> None:
        """Fit the slider and play button to the clock without a render per change."""
        step = max(1, int(round(self.fps / 30.0)))
        self._quiet = True
        try:
            for control in (self.slider, self.play):
                if frame > control.max:  # keep value <= max at every step
                    control.max = self.n_frames - 1
                    control.value = frame
                else:
                    control.value = frame
                    control.max = self.n_frames - 1
            self.play.step = step
            self.play.interval = int(round(1000 * step / self.fps))
        finally:
            self._quiet = False

    def _apply_frame(self, frame: int) -> None:
        self._frame = frame
        t = frame / self.fps
        for c in self.characters:
            p = c.positions[c.frame_at(t)]
            pts, normals = _tube_points(p[c.segments[:, 0]], p[c.segments[:, 1]], self.bone_radius, self._sides)
            _write_points(c.bones, pts, normals)
            _write_points(c.joints, self._spheres.points(p))
        for ov in self.overlays.values():
            self._update_overlay(ov, t)
        if self.follow:
            root = self.characters[0].anchor(t)
            shift = root - self._camera_root
            shift[1] = 0.0
            cam = self.plotter.camera
            cam.position = tuple(np.asarray(cam.position) + shift)
            cam.focal_point = tuple(np.asarray(cam.focal_point) + shift)
            self._camera_root = self._camera_root + shift
            self.plotter.renderer.ResetCameraClippingRange()
        if self._label is not None:
            frames = ", ".join(str(f) for f in self.character_frames())
            self._label.value = f"<span style='white-space:nowrap'>t = {t:.3f} s &nbsp; frame {frames}</span>"
        self._refresh()

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
                self._status.value = f"<pre style='color:#b00'>{type(err).__name__}: {err}</pre>"

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
        elif hasattr(self._view, "viewer"):
            self.plotter.render()
            self._view.viewer.update()

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

    @_on_main_thread
    def remove_overlay(self, name: str) -> None:
        """Remove the overlay called ``name``."""
        ov = self.overlays.pop(name, None)
        if ov is None:
            raise KeyError(f"No overlay named {name!r}; overlays are {list(self.overlays)}")
        self.plotter.remove_actor(ov.actor, render=False)
        self._refresh()

    def overlay_points(self, name: str) -> NDArray[np.float64]:
        """Vertices the overlay ``name`` shows on the current frame, shape (k, 3)."""
        try:
            ov = self.overlays[name]
        except KeyError:
            raise KeyError(f"No overlay named {name!r}; overlays are {list(self.overlays)}") from None
        return ov.at(self.time)

    @_on_main_thread
    def _add_overlay(
        self, name: str, kind: str, data: Any, color: str, fps: float | None, style: dict[str, Any]
    ) -> None:
        if name in self.overlays:
            self.remove_overlay(name)
        ov = _Overlay(
            name=str(name),
            kind=kind,
            data=_check_overlay_data(name, data),
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
        self._refresh()

    def _fill_overlay(self, ov: _Overlay, pts: NDArray[np.float64]) -> None:
        """Rebuild the overlay mesh for ``pts`` (same object; topology may change)."""
        import pyvista as pv

        k = len(pts)
        if ov.kind == "points":
            spheres = ov.style.setdefault("spheres", _SphereSet(ov.style["radius"], resolution=10))
            if k == ov.count and k > 0:
                _write_points(ov.mesh, spheres.points(pts))
                return
            new = _mesh(spheres.points(pts), spheres.faces(k), spheres.normals(k)) if k else pv.PolyData()
        else:
            closed = ov.style.get("closed", False) and k > 2
            order = np.r_[np.arange(k), 0] if closed else np.arange(k)
            if k == ov.count and k > 0:
                _write_points(ov.mesh, pts)
                return
            if k < 2:
                new = pv.PolyData()
            else:
                faces = None
                if ov.style.get("fill") and k >= 3:
                    tris = np.stack([np.zeros(k - 2, dtype=np.int64), np.arange(1, k - 1), np.arange(2, k)], axis=1)
                    faces = np.concatenate([np.full((k - 2, 1), 3), tris], axis=1).reshape(-1)
                # explicit cells: no vertex cell per point
                new = pv.PolyData(np.array(pts, dtype=float), lines=np.r_[len(order), order], faces=faces)
        ov.mesh.copy_from(new)
        ov.count = k

    def _update_overlay(self, ov: _Overlay, t: float) -> None:
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
        """The ipywidgets box: 3D view, play button, frame slider, time label."""
        if self._widget is None:
            self._widget = self._build_widget()
        return self._widget

    def _build_widget(self) -> Any:
        import ipywidgets as w

        step = max(1, int(round(self.fps / 30.0)))
        self.slider = w.IntSlider(
            value=self._frame,
            min=0,
            max=self.n_frames - 1,
            step=1,
            description="frame",
            continuous_update=True,
            layout=w.Layout(width="60%"),
        )
        self.play = w.Play(
            value=self._frame, min=0, max=self.n_frames - 1, step=step, interval=int(round(1000 * step / self.fps))
        )
        w.jslink((self.play, "value"), (self.slider, "value"))
        self._label = w.HTML()
        self._status = w.HTML()
        self.slider.observe(self._on_slider, names="value")
        if self.backend == "static":
            self._view = w.Image(value=self._png(), format="png")
        elif self.backend == "none":
            self._view = None
        else:
            with _without_vtklocal():
                self._view = self.plotter.show(jupyter_backend=self.backend, return_viewer=True, auto_close=False)
        controls = w.HBox([self.play, self.slider, self._label])
        children = ([self._view] if self._view is not None else []) + [controls, self._status]
        box = w.VBox(children)
        self._apply_frame(self._frame)
        return box

    def _on_slider(self, change: dict[str, Any]) -> None:
        frame = int(change["new"])
        if threading.current_thread() is not threading.main_thread():
            with self._lock:  # coalesce: one queued draw shows the newest frame
                queued, self._pending_frame = self._pending_frame is not None, frame
            if queued or self._queue(self._draw_pending_frame):
                return
            with self._lock:  # no loop to hand it to: draw here, as without subshells
                self._pending_frame = None
        if self._quiet:  # set_motions moves the controls, then draws once
            return
        self._show_slider_frame(frame)

    def _show_slider_frame(self, frame: int) -> None:
        try:
            self._apply_frame(frame)
            if self._status.value:
                self._status.value = ""
        except Exception as err:  # show it in the widget instead of losing it in the log
            self._status.value = f"<pre style='color:#b00'>{type(err).__name__}: {err}</pre>"
            raise

    def show(self) -> Any:
        """Display the widget in the notebook (and return it)."""
        from IPython.display import display

        display(self.widget)
        return self.widget

    def _ipython_display_(self) -> None:
        from IPython.display import display

        display(self.widget)

    @_on_main_thread
    def close(self) -> None:
        """Release the render window."""
        self.plotter.close()

    def __repr__(self) -> str:
        names = ", ".join(c.label for c in self.characters)
        return f"<MotionViewer [{names}] {self.n_frames} frames at {self.fps:g} fps, backend {self.backend!r}>"
