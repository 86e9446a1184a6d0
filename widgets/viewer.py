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
continues from there (a step pauses).  Playing needs the kernel's asyncio loop
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
* ``"client"``: the browser draws the 3D view (vtk.js, bundled with
  trame-vtk: nothing is fetched from the internet).  The kernel sends the
  scene once, into the trame state of a page of its own on the same trame
  server (same secret, same proxy route): each character's drawn points on
  every one of its frames (float32), its bone pairs and its frame on each
  clock frame, the overlays sampled once (a callable on every clock frame),
  the ground grid and the fitted camera.  The page draws the whole crowd as
  two glyph sets (bones as 6-sided cylinders placed by one 3x3 matrix each,
  joints as low-poly spheres, a colour per glyph), overlays as their own
  meshes, and plays on its own clock (``requestAnimationFrame``), writing
  each frame's few arrays straight into vtk.js.  The kernel only sends
  where to start and whether to play (on play, pause, a slider move or a
  step) and moves the slider :attr:`~MotionViewer.slider_rate` times per
  second from its own clock while the page plays: it draws no picture.  The
  mouse rotates and zooms (vtk.js's interactor); a camera reset goes back
  to the fitted camera.  :meth:`~MotionViewer.set_motions` and the overlay
  methods send the changed part again.  The page's WebGL contexts are made
  without multisampling (in a browser without a GPU it costs several times
  the picture).  ``follow=True`` does not move this view's camera.
* ``"static"`` renders off-screen and shows a PNG image that is re-rendered
  when the slider moves (used by the tests and by nbval);
* ``"none"`` builds the controls without any 3D view.

The trame toolbar starts collapsed (one button that opens it) in views
narrower than :data:`TOOLBAR_WIDTH` pixels, where its icons would overlap.
The iframe is told the address of the trame server's websocket
(``sessionURL``): without it the trame page first asks a ParaView launcher at
``.../paraview/`` (a ``POST`` that the trame server answers with 405, logged
as an error in the browser console), then falls back to that websocket.

Behind a proxy
--------------
The trame server listens on a port of the kernel's machine.  Under JupyterHub
(``JUPYTERHUB_SERVICE_PREFIX`` set), or when the Jupyter server has a base URL
other than ``/`` (``--ServerApp.base_url=/course/lab/``), the iframe's address
goes through ``jupyter-server-proxy`` (``<prefix>proxy/<port>/index.html``),
which the browser reaches wherever it runs, and the page's websocket is given
as ``ws://USE_HOST<prefix>proxy/<port>/ws``, which the trame page completes
with its own host; otherwise the address is ``http://localhost:<port>/``.
``MOCAPLAB_TRAME_PROXY`` sets the prefix for other proxies, or ``off`` (see
:func:`trame_proxy_prefix`).

Who may connect
---------------
The trame server's websocket (wslink) lets a client in only if its first
message carries the server's secret, and wslink's default secret is the
public string ``"wslink-secret"``: with it, any process of the machine (any
user's, on a shared course server) could connect to the 3D view and call its
remote methods.  The viewer gives the kernel's trame server a random secret
instead (:func:`secrets.token_urlsafe`, 256 bits, one per kernel: pyvista
runs one trame server per kernel for all its views), set before the server
starts through trame's own ``--authKey`` option, and hands it only to the
page that shows the view, in its iframe's address (``secret=``, which the
trame page reads with its other address parameters and sends in its first
message).  The server still listens on 127.0.0.1 only, and the address still
goes through ``jupyter-server-proxy`` where one is used.  A plain pyvista
plot that started the server earlier with the default secret has its secret
replaced: its page must be shown again.

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
overlay methods, playback, :meth:`~MotionViewer.close`, the slider's callback)
is called from another thread, queues the whole call onto that loop
(``loop.call_soon_threadsafe``), in call order, and returns at once.  Slider
moves are coalesced: a burst of them draws the newest frame once.  Calls made
in the main thread, or when no loop was running there (a script, the tests),
run immediately as before, so the static backend's image is re-rendered
before the call returns.  An error in a queued call is shown in the widget's
status line.  Every text from data or from an exception (labels, messages)
is HTML-escaped before it goes into the widget.

The trame server is started without ``trame-vtklocal``: pyvista loads it when
it is installed, and it then downloads VTK's WebAssembly build from
gitlab.kitware.com, which prints a traceback into some later cell when the
machine is offline or behind a firewall.  The views used here (remote and
vtk.js local rendering) do not need it.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import functools
import html
import io
import logging
import math
import os
import secrets
import sys
import threading
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mocaplab.editing.paths import with_roles
from mocaplab.motion import Motion

__all__ = [
    "MotionViewer",
    "PlayClock",
    "BACKENDS",
    "DEFAULT_BACKEND",
    "TOOLBAR_WIDTH",
    "PROXY_ENV_VAR",
    "default_backend",
    "fit_view",
    "trame_proxy_prefix",
]

BACKENDS = ("trame", "server", "client", "static", "none")
ENV_VAR = "MOCAPLAB_JUPYTER_BACKEND"
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f")
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
# The explicit proxy setting (see trame_proxy_prefix) and the values that turn the proxy off.
PROXY_ENV_VAR = "MOCAPLAB_TRAME_PROXY"
_PROXY_OFF = ("off", "direct", "none", "0", "false", "no")
# Share of the picture's area the characters' box may fill (the rest is margin).
_FILL = 0.9

OverlayData = ArrayLike | Sequence[ArrayLike] | Callable[[float], ArrayLike]

_log = logging.getLogger(__name__)
_MAIN_LOOP: asyncio.AbstractEventLoop | None = None  # the loop last seen running in the main thread


DEFAULT_BACKEND = "client"


def default_backend() -> str:
    """The backend named by ``MOCAPLAB_JUPYTER_BACKEND`` (default :data:`DEFAULT_BACKEND`, the browser draws)."""
    return os.environ.get(ENV_VAR, DEFAULT_BACKEND).strip().lower() or DEFAULT_BACKEND


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


def _server_base_url(environ: Mapping[str, str]) -> str | None:
    """The base URL of the Jupyter server that started this kernel, from its runtime file.

    A Jupyter server writes ``jpserver-<pid>.json`` (with ``base_url``) into
    the Jupyter runtime folder, and the kernels it starts get its process id
    in ``JPY_PARENT_PID``.  None when there is no such file (a script, a
    kernel started by something else) or it cannot be read.
    """
    import json

    pid = environ.get("JPY_PARENT_PID", "").strip() or str(os.getppid())
    if not pid.isdigit():
        return None
    runtime = environ.get("JUPYTER_RUNTIME_DIR")
    if not runtime:
        try:
            from jupyter_core.paths import jupyter_runtime_dir
        except ImportError:  # pragma: no cover - jupyter_core comes with ipykernel
            return None
        runtime = jupyter_runtime_dir()
    try:
        with open(os.path.join(runtime, f"jpserver-{pid}.json"), encoding="utf-8") as f:
            info = json.load(f)
    except (OSError, ValueError):
        return None
    base = info.get("base_url") if isinstance(info, dict) else None
    return base if isinstance(base, str) and base else None


def trame_proxy_prefix(environ: Mapping[str, str] | None = None) -> str | None:
    """The address prefix through which the browser reaches the trame server, or None for direct.

    The 3D view is a trame server on a port of the kernel's machine.  A
    browser on another machine (JupyterHub, Binder, a server behind a
    reverse proxy) cannot reach that port, so the iframe's address goes
    through ``jupyter-server-proxy`` instead: ``<prefix><port>/index.html``.
    In order:

    1. ``MOCAPLAB_TRAME_PROXY`` (see :data:`PROXY_ENV_VAR`): ``"off"``
       (also ``"direct"``, ``"none"``, ``"0"``) reaches the port directly;
       ``"auto"`` or empty uses the rules below; anything else is the prefix
       itself, a path (``"/user/ann/proxy/"``) or a full address
       (``"https://lab.example.org/proxy/"``), for other proxies.
    2. pyvista's ``PYVISTA_TRAME_SERVER_PROXY_PREFIX``, when set: a full
       address as it is, a path joined to the hub's or server's prefix (as
       pyvista does under JupyterHub).
    3. Under JupyterHub (``JUPYTERHUB_SERVICE_PREFIX``, e.g. ``/user/ann/``):
       ``/user/ann/proxy/``.
    4. A Jupyter server with a base URL other than ``/`` (read from its
       runtime file, see :func:`_server_base_url`): ``<base_url>proxy/``.
    5. Otherwise None: ``http://localhost:<port>/``, browser and kernel on
       one machine.

    Parameters
    ----------
    environ : Mapping[str, str], optional
        The environment to read (default ``os.environ``).

    Returns
    -------
    str or None
        The prefix, ending in ``/``.
    """
    env = os.environ if environ is None else environ
    value = env.get(PROXY_ENV_VAR, "").strip()
    if value.lower() in _PROXY_OFF:
        return None
    if value and value.lower() != "auto":
        return value.rstrip("/") + "/"
    pyvista_prefix = env.get("PYVISTA_TRAME_SERVER_PROXY_PREFIX", "").strip()
    service = env.get("JUPYTERHUB_SERVICE_PREFIX", "").strip()
    if pyvista_prefix.startswith("http"):
        return pyvista_prefix.rstrip("/") + "/"
    if service:
        base = service
    else:
        base = _server_base_url(env) or "/"
        if base.strip("/") == "" and not pyvista_prefix:
            return None
    tail = (pyvista_prefix or "proxy/").strip("/")
    return "/" + "/".join(p for p in (base.strip("/"), tail) if p) + "/"


def _session_url(src: str) -> str | None:
    """The websocket address of the trame server behind the iframe address ``src``.

    ``http://localhost:PORT/index.html?ui=...`` serves its websocket at
    ``ws://localhost:PORT/ws``.  A path (behind jupyter-server-proxy:
    ``/user/ann/proxy/PORT/index.html``) gives ``ws://USE_HOST/user/ann/proxy/PORT/ws``:
    the trame page puts the browser's own host and ``ws``/``wss`` (as the page
    is ``http``/``https``) in place of ``USE_HOST``.  The page lower-cases
    such an address first, so a path with capitals gets None: the page then
    finds its websocket by itself, after a request to a launcher that the
    trame server answers with 405.
    """
    parts = urllib.parse.urlsplit(src)
    path = parts.path.rsplit("/", 1)[0]
    if not parts.scheme and not parts.netloc and path.startswith("/"):
        return f"ws://USE_HOST{path}/ws" if path == path.lower() else None
    if parts.scheme not in ("http", "https") or not parts.netloc:
        return None
    scheme = "wss" if parts.scheme == "https" else "ws"
    return f"{scheme}://{parts.netloc}{path}/ws"


def _iframe_widget(viewer: Any, src: str, **kwargs: Any) -> Any:
    """pyvista's trame iframe widget, its address naming the websocket (no launcher request, no 405) and
    carrying the server's secret (see "Who may connect" in the module notes)."""
    from trame_pyvista.jupyter import Widget

    ws = _session_url(src)
    if ws is not None:
        src = f"{src}{'&' if '?' in src else '?'}sessionURL={urllib.parse.quote(ws, safe='')}"
    src = f"{src}{'&' if '?' in src else '?'}secret={urllib.parse.quote(_TRAME_SECRET, safe='')}"
    return Widget(viewer, src, **kwargs)


# The kernel's trame secret (module notes, "Who may connect"): made once per process and never changed.
# The prefix keeps the trame page from reading it as a number (it converts numeric address parameters).
_TRAME_SECRET = "mocaplab-" + secrets.token_urlsafe(32)


def _secure_trame_server() -> Any:
    """The kernel's pyvista trame server, set to admit only clients that know :data:`_TRAME_SECRET`.

    Before it starts, the secret becomes the default of trame's ``--authKey``
    option (what the server reads when it starts); a server that already runs
    (a plain pyvista plot started it) gets the secret on its running protocol.
    """
    import pyvista as pv
    from trame_pyvista.widgets import get_server
    from trame_server.protocol import CoreServer

    server = get_server(name=pv.global_theme.trame.jupyter_server_name)
    server.cli.set_defaults(authKey=_TRAME_SECRET, authKeyFile=None)
    if CoreServer.authentication_token != _TRAME_SECRET:
        CoreServer.authentication_token = _TRAME_SECRET  # what a protocol created from now on takes
        protocol = server.protocol
        if protocol is not None:
            protocol.updateSecret(_TRAME_SECRET)
    return server


# The page side of the "client" backend (see "Backends" in the module notes): decodes the clip sent once,
# steps through it on the browser's clock and hands each frame's small arrays to vtk.js.  Registered as
# ``trame.utils.mocaplab`` (``utils.mocaplab`` in the page's template expressions).
_CLIENT_JS = r"""
(function () {
  const trame = window.trame;
  if (trame.utils.mocaplab) { return; }
  const M = { decoded: {}, players: {} };
  // WebGL contexts of this page without multisampling: in a browser without a GPU (software WebGL) it
  // costs several times the picture, as in the kernel's renders (see the module notes).
  const getContext = HTMLCanvasElement.prototype.getContext;
  HTMLCanvasElement.prototype.getContext = function (kind, options) {
    if (typeof kind === "string" && kind.indexOf("webgl") === 0) {
      options = Object.assign({}, options || {}, { antialias: false });
    }
    return getContext.call(this, kind, options);
  };
  function bytes(b64) {
    const bin = atob(b64), out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) { out[i] = bin.charCodeAt(i); }
    return out.buffer;
  }
  function decoded(s) {
    if (!s) { return null; }
    let d = M.decoded[s.id];
    if (d) { return d; }
    d = { chars: [], overlays: [] };
    for (const c of s.chars || []) {
      d.chars.push({ pos: new Float32Array(bytes(c.pos)), index: new Int32Array(bytes(c.index)),
                     segs: c.segs, n: c.n_points, radius: c.radius, frame: -1, bones: null,
                     color: c.color, jointRadius: c.joint_radius });
    }
    for (const o of s.overlays || []) {
      d.overlays.push({ pts: new Float32Array(bytes(o.pts)), offsets: new Int32Array(bytes(o.offsets)),
                        index: new Int32Array(bytes(o.index)), kind: o.kind, closed: o.closed, fill: o.fill });
    }
    for (const key of Object.keys(M.decoded)) {
      if (key.split("/")[0] === s.id.split("/")[0]) { delete M.decoded[key]; }
    }
    M.decoded[s.id] = d;
    return d;
  }
  M.joints = function (s, k, f) {
    const d = decoded(s), c = d && d.chars[k];
    if (!c) { return new Float32Array(0); }
    const i = c.index[Math.min(Math.max(f, 0), c.index.length - 1)];
    return c.pos.subarray(i * c.n * 3, (i + 1) * c.n * 3);
  };
  M.bones = function (s, k, f) {
    const d = decoded(s), c = d && d.chars[k];
    if (!c) { return { centres: new Float32Array(0), frames: new Float32Array(0) }; }
    if (c.frame === f && c.bones) { return c.bones; }
    // each bone: its centre, and the columns of the matrix taking the unit cylinder (axis x) onto it:
    // the bone itself, then two perpendicular radii
    const p = M.joints(s, k, f), segs = c.segs, nb = segs.length / 2, r = c.radius;
    const centres = new Float32Array(nb * 3), frames = new Float32Array(nb * 9);
    for (let b = 0; b < nb; b++) {
      const a = 3 * segs[2 * b], e = 3 * segs[2 * b + 1];
      let dx = p[e] - p[a], dy = p[e + 1] - p[a + 1], dz = p[e + 2] - p[a + 2];
      const len = Math.hypot(dx, dy, dz);
      centres[3 * b] = 0.5 * (p[a] + p[e]);
      centres[3 * b + 1] = 0.5 * (p[a + 1] + p[e + 1]);
      centres[3 * b + 2] = 0.5 * (p[a + 2] + p[e + 2]);
      let ax = 0, ay = 1, az = 0;
      if (len > 1e-9) { ax = dx / len; ay = dy / len; az = dz / len; } else { dx = 0; dy = 1e-6; dz = 0; }
      const hx = Math.abs(ax) < 0.9 ? 1 : 0, hz = 1 - hx;  // a helper axis not along the bone
      let ux = ay * hz, uy = az * hx - ax * hz, uz = -ay * hx;  // axis x helper
      const ul = Math.hypot(ux, uy, uz);
      ux /= ul; uy /= ul; uz /= ul;
      const vx = ay * uz - az * uy, vy = az * ux - ax * uz, vz = ax * uy - ay * ux;
      frames.set([dx, dy, dz, r * ux, r * uy, r * uz, r * vx, r * vy, r * vz], 9 * b);
    }
    c.frame = f;
    c.bones = { centres: centres, frames: frames };
    return c.bones;
  };
  // All characters in two glyph sets (bones, joints) with a colour per glyph: two actors for any crowd.
  M.crowd = function (s, f) {
    const d = decoded(s);
    if (!d) { return null; }
    if (d.frame === f && d.crowd) { return d.crowd; }
    let nb = 0, nj = 0;
    for (const c of d.chars) { nb += c.segs.length / 2; nj += c.n; }
    const out = { centres: new Float32Array(3 * nb), frames: new Float32Array(9 * nb), joints: new Float32Array(3 * nj) };
    if (!d.colors) {
      d.colors = { bones: new Uint8Array(3 * nb), joints: new Uint8Array(3 * nj) };
      let b = 0, j = 0;
      for (const c of d.chars) {
        const rgb = c.color.map(function (x) { return Math.round(255 * x); });
        for (let i = 0; i < c.segs.length / 2; i++, b++) { d.colors.bones.set(rgb, 3 * b); }
        for (let i = 0; i < c.n; i++, j++) { d.colors.joints.set(rgb, 3 * j); }
      }
    }
    let b = 0, j = 0;
    d.chars.forEach(function (c, k) {
      const bones = M.bones(s, k, f);
      out.centres.set(bones.centres, 3 * b);
      out.frames.set(bones.frames, 9 * b);
      out.joints.set(M.joints(s, k, f), 3 * j);
      b += c.segs.length / 2;
      j += c.n;
    });
    out.boneColors = d.colors.bones;
    out.jointColors = d.colors.joints;
    out.jointRadius = d.chars.length ? d.chars[0].jointRadius : 0;
    d.frame = f;
    d.crowd = out;
    return out;
  };
  M.overlay = function (s, k, f) {
    const d = decoded(s), o = d && d.overlays[k];
    if (!o) { return { points: new Float32Array(0), lines: null, polys: null }; }
    const i = o.index[Math.min(Math.max(f, 0), o.index.length - 1)];
    const a = o.offsets[i], b = o.offsets[i + 1], n = b - a;
    const points = o.pts.subarray(3 * a, 3 * b);
    let lines = null, polys = null;
    if (o.kind !== "points" && n >= 2) {
      const closed = o.closed && n > 2;
      lines = new Uint32Array(n + 1 + (closed ? 1 : 0));
      lines[0] = n + (closed ? 1 : 0);
      for (let j = 0; j < n; j++) { lines[j + 1] = j; }
      if (closed) { lines[n + 1] = 0; }
      if (o.fill && n >= 3) {
        polys = new Uint32Array(4 * (n - 2));
        for (let j = 0; j < n - 2; j++) { polys.set([3, 0, j + 1, j + 2], 4 * j); }
      }
    }
    return { points: points, lines: lines || new Uint32Array(0), polys: polys || new Uint32Array(0) };
  };
  // The frame each view shows (set by control and by the clock; the template reads it, unwatched).
  M.frames = {};
  M.at = function (key, initial) { return key in M.frames ? M.frames[key] : initial; };
  // Draw frame f of the viewer `key` straight into its vtk.js data (no template update): the glyph
  // sets and overlays are found by their representation ids.
  M.draw = function (key, f) {
    M.frames[key] = f;
    const comp = trame.refs[key + "_view"];
    const view = comp && comp.$ && comp.$.provides && comp.$.provides.view;
    const chars = trame.state.get(key + "_chars"), ovl = trame.state.get(key + "_overlays");
    if (!view || !chars) { return false; }
    const crowd = M.crowd(chars, f);
    for (const actor of view.renderer.getActors()) {
      const id = String(actor.get("representationId").representationId || "");
      if (id.indexOf("mocaplab-") !== 0 || !actor.getMapper()) { continue; }
      const data = actor.getMapper().getInputData(0);
      if (!data) { continue; }
      if (id === "mocaplab-bones") {
        data.getPoints().setData(crowd.centres, 3);
        const frames = data.getPointData().getArrayByName("frame");
        if (frames) { frames.setData(crowd.frames, 9); }
      } else if (id === "mocaplab-joints") {
        data.getPoints().setData(crowd.joints, 3);
      } else if (id.indexOf("mocaplab-overlay-") === 0) {
        const shape = M.overlay(ovl, Number(id.slice(17)), f);
        data.getPoints().setData(shape.points, 3);
        data.getLines().setData(shape.lines);
        data.getPolys().setData(shape.polys);
      }
      data.modified();
    }
    view.renderer.resetCameraClippingRange();
    view.renderWindow.render();
    return true;
  };
  // Playback on the page's clock: ctl = {playing, frame, fps, n_frames} from the kernel.
  M.control = function (key, ctl) {
    if (!ctl) { return; }
    const player = M.players[key] || (M.players[key] = { token: 0 });
    player.token += 1;
    const token = player.token;
    M.draw(key, ctl.frame);
    if (!ctl.playing) { return; }
    const start = performance.now(), last = ctl.n_frames - 1;
    function tick(now) {
      if (player.token !== token) { return; }
      const f = Math.min(ctl.frame + Math.floor(((now - start) / 1000) * ctl.fps + 1e-9), last);
      if (M.frames[key] !== f) { M.draw(key, f); }
      if (f < last) { requestAnimationFrame(tick); }
    }
    requestAnimationFrame(tick);
  };
  // The fitted camera, set again whenever the view resets its camera (after it mounts, and on request).
  M.views = {};
  M.camera = function (ref, view, cam) {
    view = view || M.views[ref];
    if (!view || !cam) { return; }
    M.views[ref] = view;
    view.getCamera();  // makes the camera the active one, which setCamera changes
    view.setCamera(cam);
  };
  trame.utils.mocaplab = M;
  // set once the template that loaded this script has rendered (a change during its own render is lost)
  setTimeout(function () { trame.state.set("mocaplab_ready", true); }, 0);
})();
"""
_CLIENT_COUNTER = iter(range(1, 1 << 62))


def _rgb(color: str) -> list[float]:
    """A colour name or ``#rrggbb`` as three floats in [0, 1]."""
    import pyvista as pv

    return [float(x) for x in pv.Color(color).float_rgb]


def _b64(array: ArrayLike, dtype: str) -> str:
    """An array's bytes (C order, the given dtype) as base64 text, for the page to decode."""
    import base64

    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


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


def _error_html(err: BaseException) -> str:
    """An exception as status HTML: its text escaped, wrapped (never cut)."""
    text = html.escape(f"{type(err).__name__}: {err}")
    return f"<pre style='color:#b00;white-space:pre-wrap;overflow-wrap:anywhere;margin:0'>{text}</pre>"


def fit_view(
    corners: ArrayLike,
    direction: ArrayLike,
    up: ArrayLike,
    *,
    view_angle: float,
    aspect: float,
    fill: float = _FILL,
    top_band: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Focal point and position of the nearest perspective camera that sees every corner.

    The camera looks along ``-direction`` with ``up`` up.  A point at depth
    ``z`` in front of it, ``x`` to the right and ``y`` up (camera axes) is
    inside the picture when ``|x| <= fill * aspect * tan(view_angle / 2) * z``
    and ``-1 <= y / (fill * tan(view_angle / 2) * z) <= 1 - 2 * top_band``:
    the top ``top_band`` of the picture's height is kept free (a toolbar lies
    there).  The camera distance is the smallest for which both ranges hold
    for every corner (found by bisection: each range only widens with the
    distance); the focal point then centres the corners between the limits.

    Parameters
    ----------
    corners : array_like, shape (n, 3)
        Points that must be inside the picture (a box's corners).
    direction : array_like, shape (3,)
        From the scene towards the camera (any length).
    up : array_like, shape (3,)
        The view-up vector.
    view_angle : float
        Vertical view angle in degrees (VTK's default is 30).
    aspect : float
        Picture width over height.
    fill : float
        Largest share of the half-width and half-height a corner may reach.
    top_band : float
        Share of the picture's height kept free at its top, in [0, 0.5).

    Returns
    -------
    focal_point, position : ndarray, shape (3,)
    """
    pts = np.asarray(corners, dtype=float).reshape(-1, 3)
    w = np.asarray(direction, dtype=float)
    w = w / np.linalg.norm(w)
    right = np.cross(-w, np.asarray(up, dtype=float))
    right /= np.linalg.norm(right)
    upv = np.cross(right, -w)
    centre = pts.mean(axis=0)
    d = pts - centre
    a, x, y = d @ w, d @ right, d @ upv
    ty = fill * math.tan(math.radians(view_angle) / 2.0)
    tx, top = ty * aspect, 1.0 - 2.0 * float(top_band)

    def ranges(dist: float) -> tuple[float, float, float, float]:
        z = dist - a
        return (
            float(np.max(x - tx * z)),
            float(np.min(x + tx * z)),
            float(np.max(y - top * ty * z)),
            float(np.min(y + ty * z)),
        )

    def fits(dist: float) -> bool:
        x0, x1, y0, y1 = ranges(dist)
        return x0 <= x1 and y0 <= y1

    size = float(np.ptp(pts, axis=0).max()) + 1e-3
    near = float(a.max()) + 1e-6
    far = near + size
    while not fits(far):
        far = near + 2.0 * (far - near)
    for _ in range(60):
        mid = 0.5 * (near + far)
        near, far = (near, mid) if fits(mid) else (mid, far)
    x0, x1, y0, y1 = ranges(far)
    focal = centre + 0.5 * (x0 + x1) * right + 0.5 * (y0 + y1) * upv
    return focal, focal + far * w


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
        self.back: Any = None
        self.forward: Any = None
        self._label: Any = None
        self._legend: Any = None
        self._status: Any = None
        self._quiet_thread: int | None = None  # the thread moving the controls itself (its echoes are ignored)
        self._loop = _main_thread_loop()  # where calls from other threads are queued
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
        with _quiet_vtk():
            self.plotter = pv.Plotter(off_screen=True, notebook=interactive, window_size=list(window_size))
        # no anti-aliasing: on Mesa's llvmpipe 8x MSAA makes a picture ~5x dearer (FXAA is as dear)
        self.plotter.disable_anti_aliasing()
        if self.plotter.render_window is not None:
            self.plotter.render_window.SetMultiSamples(0)
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
        return _Character(m, color, str(name), pos, segs, int(new[pj]))

    def _scene_bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Box of every drawn point of every character over its whole clip, grown by the joint radius."""
        all_pts = np.concatenate([c.positions.reshape(-1, 3) for c in self.characters])
        pad = max(self.joint_radius, self.bone_radius)
        return all_pts.min(axis=0) - pad, all_pts.max(axis=0) + pad

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

    def legend_html(self) -> str:
        """The legend (one coloured dot and escaped name per character); empty for one character."""
        if len(self.characters) < 2:
            return ""
        items = "".join(
            f"<span style='white-space:nowrap;margin-right:14px'>"
            f"<span style='color:{html.escape(c.color, quote=True)};font-size:1.3em'>&#9679;</span> "
            f"{html.escape(c.label)}</span> "
            for c in self.characters
        )
        return f"<div style='display:flex;flex-wrap:wrap;align-items:center;line-height:1.6'>{items}</div>"

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
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (floor, top) for z in (lo[2], hi[2])])
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

    @_on_main_thread
    def set_frame(self, frame: int) -> None:
        """Show clock frame ``frame`` (also moves the slider; while playing, play on from there)."""
        f = int(frame)
        if not 0 <= f < self.n_frames:
            raise IndexError(f"Expected `frame` in [0, {self.n_frames}), got {frame}")
        if self._playing:
            self._play_clock.start(f, now=self._now())
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
            pts, normals = _tube_points(p[c.segments[:, 0]], p[c.segments[:, 1]], self.bone_radius, self._sides)
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
    @_on_main_thread
    def toggle_playback(self) -> None:
        """Start playback, or pause it if it runs (the play button)."""
        if self._playing:
            self.stop_playback()
        else:
            self.start_playback()

    @_on_main_thread
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

    @_on_main_thread
    def stop_playback(self) -> None:
        """Pause playback on the frame shown."""
        was_playing, self._playing = self._playing, False
        task, self._play_task = self._play_task, None
        if task is not None and not task.done() and task is not _current_task():
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
                self._status.value = _error_html(err)
        if self._play_task is _current_task():
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
                self._status.value = _error_html(err)

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

    @_on_main_thread
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
        self._client_send(overlays=True)
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
        """The ipywidgets box: 3D view, legend, play and step buttons, frame slider, time label, status."""
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
        children = ([self._view] if self._view is not None else []) + [
            self._legend,
            controls,
            self._label,
            self._status,
        ]
        width = int(self.plotter.window_size[0])
        # as wide as the view, and at least as wide as the controls' row (buttons and a 300 px track)
        box = w.VBox(children, layout=w.Layout(width=f"{max(width, 680)}px", max_width="100%"))
        box.add_class("mocaplab-viewer")
        self._apply_frame(self._frame)
        return box

    def _trame_view(self) -> Any:
        """pyvista's trame iframe in server-rendering mode (or vtk.js for ``"client"``)."""
        width = int(self.plotter.window_size[0])
        options = {
            "mode": _TRAME_MODES[self.backend],
            "collapse_menu": width < TOOLBAR_WIDTH,
            "handler": _iframe_widget,
        }
        prefix = trame_proxy_prefix()
        if prefix is not None:
            options["server_proxy_enabled"] = True
            options["server_proxy_prefix"] = prefix
        elif os.environ.get(PROXY_ENV_VAR, "").strip().lower() in _PROXY_OFF:
            options["server_proxy_enabled"] = False
        # else pyvista's theme decides (off unless set with pv.global_theme.trame.server_proxy_enabled)
        _secure_trame_server()
        with _without_vtklocal():
            return self.plotter.show(
                jupyter_backend=_TRAME_MODES[self.backend],
                return_viewer=True,
                auto_close=False,
                jupyter_kwargs=options,
            )

    # ------------------------------------------------------- client backend
    def _client_view(self) -> Any:
        """The "client" backend's view: a trame page drawing the scene with vtk.js in the browser.

        The page gets the whole clip once (each character's drawn points on
        every frame, float32) with the bone pairs, overlays sampled on the
        clock, the ground and the fitted camera; it then draws each frame
        itself (bones as cylinder glyphs, joints as sphere glyphs) and plays
        on its own clock, told only where to start and whether to play.
        """
        from trame.ui.html import DivLayout
        from trame.widgets import client, html
        from trame.widgets import vtk as vtkw
        from trame_pyvista.jupyter import build_url, elegantly_launch

        server = _secure_trame_server()
        if not server.running:
            with _without_vtklocal():
                elegantly_launch(server, wslink_backend="aiohttp")
        names = self._client_attach(server)
        key = names["key"]
        chars, ovl, ref = names["chars"], names["overlays"], f"{key}_view"
        ml = "utils.mocaplab"
        frame = f"{ml}.at('{key}', {names['start']})"  # not watched: playing never re-renders the template
        with DivLayout(server, template_name=key, style="position:absolute;inset:0;margin:0;overflow:hidden"):
            client.Script(_CLIENT_JS)
            client.ClientStateChange(
                value=names["ctl"], change=f"{ml} && {ml}.control('{key}', {names['ctl']})", trigger_on_create=True
            )
            client.ClientStateChange(
                value="mocaplab_ready", change=f"mocaplab_ready && {ml}.control('{key}', {names['ctl']})"
            )
            client.ClientStateChange(
                value=names["camera"], change=f"{ml} && {ml}.camera('{ref}', trame.refs['{ref}'], {names['camera']})"
            )
            with vtkw.VtkView(
                ref=ref,
                v_if="mocaplab_ready",
                background=("[1, 1, 1]",),
                __events=[("reset", "resetCamera")],
                reset=f"{ml}.camera('{ref}', trame.refs['{ref}'], {names['camera']})",
                style="position:absolute;inset:0",
            ):
                ground = names["ground"]
                with vtkw.VtkGeometryRepresentation(
                    v_if=ground,
                    property=("{color: [0.733, 0.733, 0.733], ambient: 1, diffuse: 0}",),
                ):
                    vtkw.VtkPolyData("ground", points=(f"{ground}.points",), lines=(f"{ground}.lines",))
                crowd = f"{ml}.crowd({chars}, {frame})"
                # kept mounted when new motions come (new arrays, same components): a vtk-polydata with
                # vtk-data-array children that unmounts logs "instance deleted" (trame-vtk deletes the
                # dataset before its arrays let go of it)
                with html.Div(v_if=f"{chars} && {chars}.chars.length"):
                    with vtkw.VtkGlyphRepresentation(
                        id="mocaplab-bones",
                        property=("{interpolation: 1}",),
                        # a 3x3 matrix per bone; its colour from the uint8 RGB scalars
                        mapper=(
                            "{orientationArray: 'frame', orientationMode: 2, "
                            "colorMode: 0, scalarVisibility: true, scaling: false}",
                        ),
                    ):
                        with vtkw.VtkPolyData("bones", points=(f"{crowd}.centres",)):
                            with vtkw.VtkPointData():
                                vtkw.VtkDataArray(
                                    name="frame", values=(f"{crowd}.frames",), number_of_components=("9",)
                                )
                                vtkw.VtkDataArray(
                                    name="colors",
                                    registration="setScalars",
                                    type="Uint8Array",
                                    values=(f"{crowd}.boneColors",),
                                    number_of_components=("3",),
                                )
                        vtkw.VtkAlgorithm(
                            vtk_class="vtkCylinderSource",
                            state=("{height: 1, radius: 1, resolution: 6, capping: false, direction: [1, 0, 0]}",),
                            port=1,
                        )
                    with vtkw.VtkGlyphRepresentation(
                        id="mocaplab-joints", mapper=("{colorMode: 0, scalarVisibility: true, scaling: false}",)
                    ):
                        with vtkw.VtkPolyData("joints", points=(f"{crowd}.joints",)):
                            with vtkw.VtkPointData():
                                vtkw.VtkDataArray(
                                    name="colors",
                                    registration="setScalars",
                                    type="Uint8Array",
                                    values=(f"{crowd}.jointColors",),
                                    number_of_components=("3",),
                                )
                        vtkw.VtkAlgorithm(
                            vtk_class="vtkSphereSource",
                            state=(f"{{radius: {self.joint_radius}, thetaResolution: 6, phiResolution: 4}}",),
                            port=1,
                        )
                with html.Div(v_for=f"(o, k) in {ovl}.overlays", key=("k + '/' + o.kind",)):
                    shape = f"{ml}.overlay({ovl}, k, {frame})"
                    with vtkw.VtkGlyphRepresentation(
                        v_if="o.kind === 'points'", id=("'mocaplab-overlay-' + k",), property=("{color: o.color}",)
                    ):
                        vtkw.VtkPolyData("points", points=(f"{shape}.points",))
                        vtkw.VtkAlgorithm(
                            vtk_class="vtkSphereSource",
                            state=("{radius: o.radius, thetaResolution: 6, phiResolution: 4}",),
                            port=1,
                        )
                    with vtkw.VtkGeometryRepresentation(
                        v_else=True,
                        id=("'mocaplab-overlay-' + k",),
                        property=("{color: o.color, lineWidth: o.width, opacity: o.opacity, ambient: 0.3}",),
                    ):
                        vtkw.VtkPolyData(
                            "lines",
                            points=(f"{shape}.points",),
                            lines=(f"{shape}.lines",),
                            polys=(f"{shape}.polys",),
                        )
        prefix = trame_proxy_prefix()
        if prefix is not None:
            enabled: bool | None = True
        elif os.environ.get(PROXY_ENV_VAR, "").strip().lower() in _PROXY_OFF:
            enabled = False
        else:
            enabled = None  # pyvista's theme decides, as for the server view
        src = build_url(server, ui=key, server_proxy_enabled=enabled, server_proxy_prefix=prefix)
        width, height = self.plotter.window_size
        return _iframe_widget(None, src, width=f"{int(width)}px", height=f"{int(height)}px")

    def _client_attach(self, server: Any) -> dict[str, Any]:
        """Give this viewer its state variables on the trame ``server`` and fill them: the whole scene once.

        Returns the names: ``key`` (the viewer's prefix) and one per part
        (``chars``, ``overlays``, ``ground``, ``camera``, ``ctl``, ``start``).
        """
        key = f"mocaplab_v{next(_CLIENT_COUNTER)}"
        names = {part: f"{key}_{part}" for part in ("chars", "overlays", "ground", "camera", "ctl", "start")}
        self._client = {"server": server, "key": key, **names}
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
        return {
            "playing": bool(self._playing),
            "frame": int(self._frame),
            "fps": float(self.fps),
            "n_frames": int(self.n_frames),
            "seq": self._client_seq,
        }

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
        if self._client is None:
            return
        self._client_seq += 1
        state = self._client["server"].state
        values: dict[str, Any] = {}
        if chars:
            values[self._client["chars"]] = self._client_characters()
        if overlays:
            values[self._client["overlays"]] = self._client_overlays()
        if ground:
            values[self._client["ground"]] = self._client_ground()
        if camera:
            cam = self.plotter.camera
            values[self._client["camera"]] = {
                "position": [float(x) for x in cam.position],
                "focalPoint": [float(x) for x in cam.focal_point],
                "viewUp": [float(x) for x in cam.up],
                "centerOfRotation": [float(x) for x in cam.focal_point],
                "seq": self._client_seq,
            }
        if flush:
            with state:
                state.update(values)
        else:
            state.update(values)

    def _client_characters(self) -> dict[str, Any]:
        """Every character's drawn points on each of its frames, its bones and its frame on each clock frame."""
        clock = np.arange(self.n_frames) / self.fps
        out = []
        for c in self.characters:
            index = [c.frame_at(t) for t in clock]
            out.append(
                {
                    "pos": _b64(c.positions, "<f4"),
                    "n_points": int(c.positions.shape[1]),
                    "segs": [int(x) for x in c.segments.reshape(-1)],
                    "index": _b64(index, "<i4"),
                    "color": _rgb(c.color),
                    "radius": self.bone_radius,
                    "joint_radius": self.joint_radius,
                    "sides": self._sides,
                }
            )
        return {"id": f"{self._client['key']}_chars/{self._client_seq}", "chars": out}

    def _client_overlays(self) -> dict[str, Any]:
        """Each overlay's points sampled once (its own frames, or the clock's for a callable), NaN rows left out."""
        clock = np.arange(self.n_frames) / self.fps
        out = []
        for ov in self.overlays.values():
            if callable(ov.data):
                samples, index = [ov.at(t) for t in clock], np.arange(self.n_frames)
            elif isinstance(ov.data, np.ndarray) and ov.data.ndim == 2:
                samples, index = [ov.at(0.0)], np.zeros(self.n_frames, dtype=np.int64)
            else:
                n = len(ov.data)
                samples = [ov.at(i / ov.fps) for i in range(n)]
                index = np.clip(np.round(clock * ov.fps), 0, n - 1).astype(np.int64)
            offsets = np.concatenate([[0], np.cumsum([len(p) for p in samples])])
            pts = np.concatenate(samples) if samples else np.zeros((0, 3))
            out.append(
                {
                    "kind": ov.kind,
                    "pts": _b64(pts, "<f4"),
                    "offsets": _b64(offsets, "<i4"),
                    "index": _b64(index, "<i4"),
                    "color": _rgb(ov.color),
                    "radius": ov.style.get("radius", 0.0),
                    "width": ov.style.get("width", 1.0),
                    "opacity": ov.style.get("opacity", 1.0) if ov.style.get("fill") else 1.0,
                    "closed": bool(ov.style.get("closed", False)),
                    "fill": bool(ov.style.get("fill", False)),
                }
            )
        return {"id": f"{self._client['key']}_overlays/{self._client_seq}", "overlays": out}

    def _client_ground(self) -> dict[str, Any] | None:
        """The ground grid (the plotter's mesh) as its grid lines, one polyline per row and column; None without.

        Lines only, on the white background: a filled floor with its edges
        drawn over it made each picture of software WebGL about twice as dear
        (headless Chromium, lesson 01: 22 against 12 ms).
        """
        if self._ground_mesh is None:
            return None
        grid = self._ground_mesh
        nx, nz = int(grid.dimensions[0]), int(grid.dimensions[1])
        ids = np.arange(nx * nz).reshape(nz, nx)  # VTK's point order: x fastest
        rows = [np.r_[nx, ids[k]] for k in range(nz)] + [np.r_[nz, ids[:, k]] for k in range(nx)]
        return {
            "points": [round(float(x), 6) for x in np.asarray(grid.points).reshape(-1)],
            "lines": [int(x) for x in np.concatenate(rows)],
        }

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
                self._status.value = _error_html(err)
            return
        if self._status is not None and self._status.value and threading.current_thread() is threading.main_thread():
            self._status.value = ""

    @_on_main_thread
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
            self._status.value = _error_html(err)
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
        """Stop playback and release the render window."""
        self.stop_playback()
        self.plotter.close()

    def __repr__(self) -> str:
        names = ", ".join(c.label for c in self.characters)
        return f"<MotionViewer [{names}] {self.n_frames} frames at {self.fps:g} fps, backend {self.backend!r}>"


def _current_task() -> asyncio.Task[Any] | None:
    try:
        return asyncio.current_task()
    except RuntimeError:  # no running loop in this thread
        return None
