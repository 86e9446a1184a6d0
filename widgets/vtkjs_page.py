"""The page of the viewer's ``client`` backend: the browser draws the scene with vtk.js.

:class:`~mocaplab.widgets.viewer.MotionViewer` with ``backend="client"``
sends its scene (:mod:`mocaplab.widgets.scene`) once into the trame state of a
page of its own on the kernel's trame server (:mod:`mocaplab.widgets.serving`:
same secret, same proxy route).  This module holds that page and the state it
reads; the viewer decides when to send what.

What the page gets
------------------
Each character's drawn points on every one of its frames (float32, base64),
its bone pairs and its frame on each clock frame
(:func:`characters_payload`); the overlays sampled once, a callable on every
clock frame (:func:`overlays_payload`); the ground grid as lines
(:func:`ground_payload`) and the fitted camera (:func:`camera_payload`).
Each part is one state value (:func:`state_names`); a new value replaces it.

What the page does
------------------
:data:`CLIENT_JS` (registered as ``trame.utils.mocaplab``) draws the whole
crowd as two glyph sets (bones as 6-sided cylinders placed by one 3x3 matrix
each, joints as low-poly spheres, a colour per glyph; a crowd of more than
:data:`MAX_JOINT_SPHERES` points is drawn as stick figures), overlays as their own
meshes, and plays on its own clock (``requestAnimationFrame``), writing each
frame's few arrays straight into vtk.js.  A browser that cannot draw
:data:`PLAY_TARGET_RATE` pictures a second while playing (software WebGL on a
busy machine) draws the play with fewer pixels, down to
:data:`PLAY_MIN_RATIO` of the view's size, and sharp again when it stops.
The kernel only sends where to start and whether to play
(:func:`control_payload`).  The mouse rotates and
zooms (vtk.js's interactor); a camera reset goes back to the fitted camera.
The page's WebGL contexts are made without multisampling (in a browser
without a GPU it costs several times the picture).  vtk.js comes bundled with
trame-vtk: nothing is fetched from the internet.
"""

from __future__ import annotations

import base64
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .scene import Character, Overlay
from .serving import proxy_setting, secure_trame_server, without_vtklocal

__all__ = [
    "CLIENT_JS",
    "b64",
    "build_page",
    "camera_payload",
    "characters_payload",
    "control_payload",
    "ground_payload",
    "new_key",
    "overlays_payload",
    "rgb",
    "start_server",
    "state_names",
]

#: Bones drawn as cylinders and joints as spheres while the scene has at most this many drawn points (about
#: eight characters); a larger crowd is drawn as stick figures, a line of :data:`STICK_WIDTH` pixels per bone
#: in one draw.  In software WebGL (a browser without a GPU) each glyph costs about 20 microseconds a picture
#: (16 walkers: 20 ms of WebGL work a picture as glyphs, 14 ms as lines), and at a crowd's size a cylinder
#: is a few pixels wide anyway.
MAX_JOINT_SPHERES = 320
STICK_WIDTH = 3
#: Pictures per second a playing view aims at: a browser that draws fewer (software WebGL on a busy
#: laptop) draws the play with fewer pixels, down to :data:`PLAY_MIN_RATIO` of the view's width and height
#: (a quarter of the pixels), and at full resolution again when it stops.  Chromium without a GPU beside two
#: CPU-bound processes on two cores draws 49-59 pictures/s at full resolution (benchmarks/bench_viewer.py, by
#: its trace); a browser also encoding a screencast of itself draws fewer, and this brings it back up.
PLAY_TARGET_RATE = 30.0
PLAY_MIN_RATIO = 0.5

# The page side (see the module notes): decodes the clip sent once, steps through it on the browser's clock and
# hands each frame's small arrays to vtk.js.  Registered as ``trame.utils.mocaplab`` (``utils.mocaplab`` in the
# page's template expressions).
CLIENT_JS = r"""
(function () {
  const trame = window.trame;
  if (trame.utils.mocaplab) { return; }
  const M = { decoded: {}, players: {}, maxJointSpheres: @MAX_JOINT_SPHERES@ };
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
  // All characters in two glyph sets (bones as cylinders, joints as spheres) with a colour per glyph: two
  // actors for any crowd.  A crowd of more than M.maxJointSpheres points is drawn as stick figures instead
  // (one line per bone, one draw: in software WebGL each glyph costs about 20 microseconds a picture).
  // The sets not drawn stay mounted, empty and hidden (unmounting a vtk-polydata with data arrays logs
  // "instance deleted" in trame-vtk).
  M.crowd = function (s, f) {
    const d = decoded(s);
    if (!d) { return null; }
    if (d.frame === f && d.crowd) { return d.crowd; }
    let nb = 0, nj = 0;
    for (const c of d.chars) { nb += c.segs.length / 2; nj += c.n; }
    const detailed = nj <= M.maxJointSpheres;
    if (!d.colors) {
      d.colors = { bones: new Uint8Array(3 * nb), joints: new Uint8Array(3 * nj) };
      d.sticks = new Uint32Array(3 * nb);  // line cells (2, a, b) over all characters' points
      let b = 0, j = 0;
      for (const c of d.chars) {
        const rgb = c.color.map(function (x) { return Math.round(255 * x); });
        for (let i = 0; i < c.segs.length / 2; i++, b++) {
          d.colors.bones.set(rgb, 3 * b);
          d.sticks.set([2, j + c.segs[2 * i], j + c.segs[2 * i + 1]], 3 * b);
        }
        for (let i = 0; i < c.n; i++) { d.colors.joints.set(rgb, 3 * (j + i)); }
        j += c.n;
      }
    }
    const out = { centres: new Float32Array(detailed ? 3 * nb : 0), frames: new Float32Array(detailed ? 9 * nb : 0),
                  joints: new Float32Array(3 * nj), detailed: detailed };
    let b = 0, j = 0;
    d.chars.forEach(function (c, k) {
      if (detailed) {
        const bones = M.bones(s, k, f);
        out.centres.set(bones.centres, 3 * b);
        out.frames.set(bones.frames, 9 * b);
      }
      out.joints.set(M.joints(s, k, f), 3 * j);
      b += c.segs.length / 2;
      j += c.n;
    });
    out.boneColors = detailed ? d.colors.bones : new Uint8Array(0);
    out.jointColors = d.colors.joints;
    out.sticks = detailed ? new Uint32Array(0) : d.sticks;
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
  M.view = function (key) {
    const comp = trame.refs[key + "_view"];
    return comp && comp.$ && comp.$.provides && comp.$.provides.view;
  };
  M.draw = function (key, f) {
    M.frames[key] = f;
    const view = M.view(key);
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
      } else if (id === "mocaplab-joints" || id === "mocaplab-sticks") {
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
  // Dynamic resolution: a browser that draws in software (no GPU) and cannot keep up with the play
  // (fewer than M.targetRate pictures a second, or the clip's own rate if lower) draws it with fewer
  // pixels, down to M.minRatio of the view's width and height, stretched to the view.  Every 0.3 s the
  // ratio follows the rate drawn (the cost of a picture goes with its pixels, the square of the ratio):
  // below the rate wanted it aims M.aimAbove x above it (a rate that hovers at the target shows fewer
  // pictures than the target half of the time); with headroom (M.raiseAbove x the rate wanted) it goes
  // back up.  The next play starts at the ratio
  // the last one ended with; a stopped view is drawn at full resolution.
  M.targetRate = @TARGET_RATE@;
  M.minRatio = @MIN_RATIO@;
  M.aimAbove = 1.15;
  M.raiseAbove = 1.5;
  M.resolution = function (key, ratio) {
    const view = M.view(key), gl = view && view.openglRenderWindow, box = view && view.container;
    if (!gl || !box) { return false; }
    const r = box.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    const w = Math.max(10, Math.floor(r.width * dpr * ratio)), h = Math.max(10, Math.floor(r.height * dpr * ratio));
    const size = gl.getSize();
    if (size[0] !== w || size[1] !== h) { gl.setSize(w, h); }
    return true;
  };
  // Playback on the page's clock: ctl = {playing, frame, fps, n_frames} from the kernel.
  M.control = function (key, ctl) {
    if (!ctl) { return; }
    const player = M.players[key] || (M.players[key] = { token: 0, ratio: 1, playRatio: 1 });
    player.token += 1;
    const token = player.token;
    const last = ctl.n_frames - 1;
    const ratio = ctl.playing && ctl.frame < last ? player.playRatio : 1;
    if (ratio !== player.ratio) { player.ratio = ratio; M.resolution(key, ratio); }
    M.draw(key, ctl.frame);
    if (!ctl.playing) { return; }
    const start = performance.now(), wanted = Math.min(M.targetRate, ctl.fps);
    let since = start, drawn = 0;
    function tick(now) {
      if (player.token !== token) { return; }
      const f = Math.min(ctl.frame + Math.floor(((now - start) / 1000) * ctl.fps + 1e-9), last);
      if (f >= last && player.ratio !== 1) { player.ratio = 1; M.resolution(key, 1); }
      if (M.frames[key] !== f) { M.draw(key, f); drawn += 1; }
      if (now - since >= 300 && f < last) {
        const rate = (1000 * drawn) / (now - since);
        player.rate = rate;
        let next = player.ratio;
        if (rate < wanted) { next = Math.max(M.minRatio, next * Math.sqrt(rate / (M.aimAbove * wanted))); }
        else if (rate > M.raiseAbove * wanted) { next = Math.min(1, next * 1.15); }
        if (next !== player.ratio) { player.ratio = player.playRatio = next; M.resolution(key, next); }
        since = now;
        drawn = 0;
      }
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
  // Keys pressed over the view go to the notebook page, whose viewer takes the ones it knows (space, the
  // arrows: _controls.KeyCapture); this page is an iframe of another origin, its key events stay here.
  window.addEventListener("keydown", function (e) {
    if (window.parent === window) { return; }
    window.parent.postMessage({ mocaplabKey: { key: e.key, ctrlKey: e.ctrlKey, metaKey: e.metaKey,
                                               altKey: e.altKey, shiftKey: e.shiftKey } }, "*");
    if (e.key === " " || e.key === "ArrowLeft" || e.key === "ArrowRight") { e.preventDefault(); }
  });
  trame.utils.mocaplab = M;
  // set once the template that loaded this script has rendered (a change during its own render is lost)
  setTimeout(function () { trame.state.set("mocaplab_ready", true); }, 0);
})();
""".replace("@MAX_JOINT_SPHERES@", str(MAX_JOINT_SPHERES)).replace("@TARGET_RATE@", repr(PLAY_TARGET_RATE)).replace(
    "@MIN_RATIO@", repr(PLAY_MIN_RATIO)
)
_COUNTER = iter(range(1, 1 << 62))
# The state values of one viewer's page (each ``<key>_<part>``).
PARTS = ("chars", "overlays", "ground", "camera", "ctl", "start")


def new_key() -> str:
    """A new viewer's prefix of its state values and page template (``mocaplab_v<n>``, unique in the kernel)."""
    return f"mocaplab_v{next(_COUNTER)}"


def state_names(key: str) -> dict[str, str]:
    """The state value of each of :data:`PARTS` for the viewer ``key``, and ``key`` itself."""
    return {"key": key, **{part: f"{key}_{part}" for part in PARTS}}


def start_server() -> Any:
    """The kernel's trame server (with its secret, :func:`~mocaplab.widgets.serving.secure_trame_server`), running."""
    from trame_pyvista.jupyter import elegantly_launch

    server = secure_trame_server()
    if not server.running:
        with without_vtklocal():
            elegantly_launch(server, wslink_backend="aiohttp")
    return server


def _rgb_scalars(vtkw: Any, values: str) -> Any:
    """A ``vtk-data-array`` of uint8 RGB colours, one per point, set as the point scalars, from the page
    expression ``values`` (the colour of each glyph or line point)."""
    return vtkw.VtkDataArray(
        name="colors", registration="setScalars", type="Uint8Array", values=(values,), number_of_components=("3",)
    )


def build_page(server: Any, names: Mapping[str, Any], *, joint_radius: float) -> str:
    """Register the page of the viewer ``names["key"]`` on the trame ``server``; return its address.

    Parameters
    ----------
    server : trame_server.Server
        The kernel's trame server (:func:`start_server`).
    names : mapping
        The viewer's state names (:func:`state_names`).
    joint_radius : float
        Radius of the joints' spheres, metres.

    Returns
    -------
    str
        The address of the page for an iframe (through the proxy where one is used), without the secret.
    """
    from trame.ui.html import DivLayout
    from trame.widgets import client, html
    from trame.widgets import vtk as vtkw
    from trame_pyvista.jupyter import build_url

    key = names["key"]
    chars, ovl, ref = names["chars"], names["overlays"], f"{key}_view"
    ml = "utils.mocaplab"
    frame = f"{ml}.at('{key}', {names['start']})"  # not watched: playing never re-renders the template
    with DivLayout(server, template_name=key, style="position:absolute;inset:0;margin:0;overflow:hidden"):
        client.Script(CLIENT_JS)
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
                    actor=(f"{{visibility: {crowd}.detailed}}",),
                    property=("{interpolation: 1}",),
                    # a 3x3 matrix per bone; its colour from the uint8 RGB scalars
                    mapper=(
                        "{orientationArray: 'frame', orientationMode: 2, "
                        "colorMode: 0, scalarVisibility: true, scaling: false}",
                    ),
                ):
                    with vtkw.VtkPolyData("bones", points=(f"{crowd}.centres",)):
                        with vtkw.VtkPointData():
                            vtkw.VtkDataArray(name="frame", values=(f"{crowd}.frames",), number_of_components=("9",))
                            _rgb_scalars(vtkw, f"{crowd}.boneColors")
                    vtkw.VtkAlgorithm(
                        vtk_class="vtkCylinderSource",
                        state=("{height: 1, radius: 1, resolution: 6, capping: false, direction: [1, 0, 0]}",),
                        port=1,
                    )
                with vtkw.VtkGlyphRepresentation(
                    id="mocaplab-joints",
                    actor=(f"{{visibility: {crowd}.detailed}}",),
                    mapper=("{colorMode: 0, scalarVisibility: true, scaling: false}",),
                ):
                    with vtkw.VtkPolyData("joints", points=(f"{crowd}.joints",)):
                        with vtkw.VtkPointData():
                            _rgb_scalars(vtkw, f"{crowd}.jointColors")
                    vtkw.VtkAlgorithm(
                        vtk_class="vtkSphereSource",
                        state=(f"{{radius: {joint_radius}, thetaResolution: 6, phiResolution: 4}}",),
                        port=1,
                    )
                # a crowd's stick figures: a line per bone between the joints' points, in one draw
                with vtkw.VtkGeometryRepresentation(
                    id="mocaplab-sticks",
                    actor=(f"{{visibility: !{crowd}.detailed}}",),
                    property=(f"{{lineWidth: {STICK_WIDTH}, ambient: 1, diffuse: 0}}",),
                    mapper=("{colorMode: 0, scalarVisibility: true}",),
                ):
                    with vtkw.VtkPolyData("sticks", points=(f"{crowd}.joints",), lines=(f"{crowd}.sticks",)):
                        with vtkw.VtkPointData():
                            _rgb_scalars(vtkw, f"{crowd}.jointColors")
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
    enabled, prefix = proxy_setting()  # None: pyvista's theme decides, as for the server view
    return str(build_url(server, ui=key, server_proxy_enabled=enabled, server_proxy_prefix=prefix))


# --------------------------------------------------------------------------
# the state the page reads
# --------------------------------------------------------------------------
def rgb(color: str) -> list[float]:
    """A colour name or ``#rrggbb`` as three floats in [0, 1]."""
    import pyvista as pv

    return [float(x) for x in pv.Color(color).float_rgb]


def b64(array: ArrayLike, dtype: str) -> str:
    """An array's bytes (C order, the given dtype) as base64 text, for the page to decode."""
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def characters_payload(
    characters: Sequence[Character],
    *,
    key: str,
    seq: int,
    n_frames: int,
    fps: float,
    bone_radius: float,
    joint_radius: float,
    sides: int,
) -> dict[str, Any]:
    """Every character's drawn points on each of its frames, its bones and its frame on each clock frame.

    ``n_frames`` and ``fps`` are the viewer's clock; ``key`` and ``seq`` make the payload's ``id`` (the page
    decodes each id once).
    """
    clock = np.arange(n_frames) / fps
    out = []
    for c in characters:
        index = [c.frame_at(t) for t in clock]
        out.append(
            {
                "pos": b64(c.positions, "<f4"),
                "n_points": int(c.positions.shape[1]),
                "segs": [int(x) for x in c.segments.reshape(-1)],
                "index": b64(index, "<i4"),
                "color": rgb(c.color),
                "radius": bone_radius,
                "joint_radius": joint_radius,
                "sides": sides,
            }
        )
    return {"id": f"{key}_chars/{seq}", "chars": out}


def overlays_payload(overlays: Iterable[Overlay], *, key: str, seq: int, n_frames: int, fps: float) -> dict[str, Any]:
    """Each overlay's points sampled once (its own frames, or the clock's for a callable), NaN rows left out."""
    clock = np.arange(n_frames) / fps
    out = []
    for ov in overlays:
        if callable(ov.data):
            samples, index = [ov.at(t) for t in clock], np.arange(n_frames)
        elif isinstance(ov.data, np.ndarray) and ov.data.ndim == 2:
            samples, index = [ov.at(0.0)], np.zeros(n_frames, dtype=np.int64)
        else:
            n = len(ov.data)
            samples = [ov.at(i / ov.fps) for i in range(n)]
            index = np.clip(np.round(clock * ov.fps), 0, n - 1).astype(np.int64)
        offsets = np.concatenate([[0], np.cumsum([len(p) for p in samples])])
        pts = np.concatenate(samples) if samples else np.zeros((0, 3))
        out.append(
            {
                "kind": ov.kind,
                "pts": b64(pts, "<f4"),
                "offsets": b64(offsets, "<i4"),
                "index": b64(index, "<i4"),
                "color": rgb(ov.color),
                "radius": ov.style.get("radius", 0.0),
                "width": ov.style.get("width", 1.0),
                "opacity": ov.style.get("opacity", 1.0) if ov.style.get("fill") else 1.0,
                "closed": bool(ov.style.get("closed", False)),
                "fill": bool(ov.style.get("fill", False)),
            }
        )
    return {"id": f"{key}_overlays/{seq}", "overlays": out}


def ground_payload(grid: Any) -> dict[str, Any] | None:
    """The ground grid (a pyvista StructuredGrid) as its grid lines, one polyline per row and column; None without.

    Lines only, on the white background: a filled floor with its edges
    drawn over it made each picture of software WebGL about twice as dear
    (headless Chromium, lesson 01: 22 against 12 ms).
    """
    if grid is None:
        return None
    nx, nz = int(grid.dimensions[0]), int(grid.dimensions[1])
    ids = np.arange(nx * nz).reshape(nz, nx)  # VTK's point order: x fastest
    rows = [np.r_[nx, ids[k]] for k in range(nz)] + [np.r_[nz, ids[:, k]] for k in range(nx)]
    return {
        "points": [round(float(x), 6) for x in np.asarray(grid.points).reshape(-1)],
        "lines": [int(x) for x in np.concatenate(rows)],
    }


def camera_payload(camera: Any, seq: int) -> dict[str, Any]:
    """A pyvista camera as vtk.js sets it (``seq`` makes each one new)."""
    return {
        "position": [float(x) for x in camera.position],
        "focalPoint": [float(x) for x in camera.focal_point],
        "viewUp": [float(x) for x in camera.up],
        "centerOfRotation": [float(x) for x in camera.focal_point],
        "seq": seq,
    }


def control_payload(*, playing: bool, frame: int, fps: float, n_frames: int, seq: int) -> dict[str, Any]:
    """What the page plays: from which frame, whether it runs, at which rate (``seq`` makes each one new)."""
    return {"playing": bool(playing), "frame": int(frame), "fps": float(fps), "n_frames": int(n_frames), "seq": seq}
