"""Benchmark: real-time 3D playback of the MotionViewer, drawn by the browser or by the kernel.

Kernel side (headless, always): the cost of one frame of server rendering,
split into the geometry update (new points in the fixed meshes, overlays,
label) and the render (Mesa's llvmpipe, EGL off-screen), without
anti-aliasing (what the viewer does) and with pyvista's default 8x MSAA.
Medians of repeats, on lesson 01's viewer (one character) and lesson 05's
relay (eight characters).

Browser side (when Chromium and Playwright are there; ``--no-browser`` skips
it), issue 29: for each backend, ``client`` (the browser draws with vtk.js,
the kernel sends the clip once) and ``server`` (the kernel renders and sends
JPEG pictures, the fallback and the baseline), a JupyterLab serves a copy of
``lessons/`` and headless Chromium (software WebGL, no GPU) runs

* lesson 01 and plays its viewer (one character, CMU 16_15 at 120 fps, with
  its contact and root-path overlays);
* lesson 05 (its kernel's memory is the figure; a cell that fails is
  reported), then a viewer of 16 walkers in that kernel (CMU 16_15 and 02_01,
  eight each, on a 4 x 4 grid 1.2 m apart, 640 x 420), and plays it.

Each scene is played through two routes (``--routes``): ``lab``, a plain
JupyterLab, and ``hub``, a JupyterHub with its configurable-http-proxy set up
from ``deploy/`` (the deployment test's :class:`Hub`), where the student logs
in and the browser reaches the kernel's trame server only through the proxy.
``--load N`` keeps N CPU-bound processes running beside the browser runs (a
busy course server; the browser here shares the machine, where a student's
would not; ``--browser-nice -10`` runs Chromium ahead of them, as on a
student's own machine, while the kernel still competes with the load).

Each play lasts ``--seconds`` s with Chromium's screencast counting the
distinct pictures the 3D view shows (``tests/browser_support.py``,
:func:`play_viewer`) and psutil reading the kernel process's CPU time from the
click to the end of the count (percent of one core).  The screencast encodes
and ships every picture it counts, and beside a busy machine's load it is the
bottleneck itself: a plain canvas repainted on every frame over the view
(``screencast_ceiling``, printed per route) counts 20-22 pictures/s beside two
CPU-bound processes.  So each browser-drawn play is played once more under
Chromium's tracing, which counts the new pictures of the view that reached the
display (``traced_pictures``), and the targets are judged on that count, with
the screencast's figure and ceiling beside it.  Printed per backend:
pictures per second, kernel CPU, the pictures the kernel drew and their cost,
the largest lag of the time label behind the wall clock, whether the slider
and the label ever disagreed, and the kernel's resident memory after lessons
01 and 05; then the browser-drawn figures against the targets (1 character:
30 pictures/s with the kernel under 5 % of a core; 16 characters: 24/s under
10 %) and against server rendering, as ratios.  The load average before and
after is printed too: the machine may be shared.  ``--options`` also plays
server-rendering variants on lesson 05's relay (JPEG quality 100, half-size
pictures, pyvista's hybrid ``trame`` mode).

Run: ``python benchmarks/bench_viewer.py [--seconds 3] [--repeats 20] [--options] [--no-browser]
[--routes lab,hub] [--load 2]``.
Needs the CMU mirror (``MOCAPLAB_DATA_DIR``, default ``../shared/mocap``
beside the checkout) and psutil (``/proc`` is read without it).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def _mirror() -> str:
    value = os.environ.get("MOCAPLAB_DATA_DIR") or str(ROOT.parent / "shared" / "mocap")
    if not (Path(value) / "manifest.json").is_file():
        sys.exit(f"CMU mirror not found at {value}: set MOCAPLAB_DATA_DIR")
    return value


def _lesson_namespace(stem: str, until: str) -> dict[str, Any]:
    """Run the code cells of ``lessons/<stem>.ipynb`` (fast mode, no 3D views) until ``until`` is defined."""
    import matplotlib

    matplotlib.use("Agg")
    os.environ["MOCAPLAB_FAST"] = "1"
    os.environ["MOCAPLAB_JUPYTER_BACKEND"] = "none"
    cells = json.loads((ROOT / "lessons" / f"{stem}.ipynb").read_text())["cells"]
    ns: dict[str, Any] = {"__name__": "__lesson__"}
    for cell in cells:
        if cell["cell_type"] != "code":
            continue
        with contextlib.redirect_stdout(io.StringIO()):  # the lesson's own prints
            exec(compile("".join(cell["source"]), f"{stem}.ipynb", "exec"), ns)  # noqa: S102 - our own lessons
        if until in ns:
            return ns
    raise RuntimeError(f"lessons/{stem}.ipynb never defines {until!r}")


def _median_ms(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def kernel_costs(repeats: int) -> dict[str, dict[str, float]]:
    """Per-frame kernel cost of the two scenes, headless: geometry, render without and with MSAA."""
    from mocaplab.widgets import MotionViewer

    ns01 = _lesson_namespace("01_motion_data", "planted")
    ns05 = _lesson_namespace("05_synchronized_characters", "curled")

    def viewer01(backend: str) -> Any:
        v = MotionViewer(ns01["walk"], backend=backend)
        v.add_points("contacts", ns01["planted"], color="red", radius=0.04)
        v.add_lines("root path", ns01["walk"].root_positions * [1, 0, 1], color="gray")
        return v

    def viewer05(backend: str) -> Any:
        return MotionViewer(list(ns05["curled"].motions), window_size=(640, 420), backend=backend)

    out = {}
    for name, make in (("lesson 01 (1 character)", viewer01), ("lesson 05 (8 characters)", viewer05)):
        v = make("none")
        frames = iter(np.resize(np.arange(0, v.n_frames, max(1, v.n_frames // 97)), 100_000))
        geometry = _median_ms(lambda: v._apply_frame(int(next(frames))), repeats)  # noqa: B023
        rw = v.plotter.render_window
        rw.Render()

        def frame_and_render() -> None:
            v._apply_frame(int(next(frames)))  # noqa: B023
            rw.Render()  # noqa: B023

        plain = _median_ms(frame_and_render, repeats)
        rw.SetMultiSamples(8)
        rw.Render()
        msaa = _median_ms(frame_and_render, repeats)
        v.close()
        out[name] = {"geometry_ms": geometry, "render_ms": plain - geometry, "render_msaa8_ms": msaa - geometry}
    return out


# ------------------------------------------------------------------ browser
# Targets of issue 29, in headless Chromium: (distinct pictures per second, most kernel CPU in % of one core).
TARGETS = {"1 character": (30.0, 5.0), "16 characters": (24.0, 10.0)}
# Sixteen walkers (CMU 16_15 and 02_01, eight each) on a 4 x 4 grid 1.2 m apart, made in lesson 05's kernel.
_CROWD = (
    "import dataclasses as _dc\n"
    "from mocaplab.data import cmu as _cmu\n"
    "from mocaplab.widgets import MotionViewer as _MV\n"
    "_clips = [_cmu('16_15'), _cmu('02_01')]\n"
    "crowd16 = _MV([_dc.replace(_clips[k % 2], root_positions=_clips[k % 2].root_positions "
    "+ [1.2 * (k % 4), 0.0, 1.2 * (k // 4)]) for k in range(16)], window_size=(640, 420))\n"
    "crowd16"
)
_OPTIONS = {
    "server q100": "{new} = MotionViewer(list(curled.motions), window_size=(640, 420)); {new}.play_quality = 100",
    "server q80 ratio 0.5": (
        "{new} = MotionViewer(list(curled.motions), window_size=(640, 420))\n"
        "def _half(q, _v={new}):\n"
        "    for _w in _v._view.viewer.views:\n"
        "        _w._helper.set_image_quality(_v.plotter.render_window, int(q), 0.5)\n"
        "    return True\n"
        "{new}._set_picture_quality = _half"
    ),
    "pyvista 'trame'": (
        "import mocaplab.widgets.viewer as _mv\n"
        "_mv._TRAME_MODES['trame'] = 'trame'  # pyvista's hybrid mode: picture + scene on every update\n"
        "{new} = MotionViewer(list(curled.motions), window_size=(640, 420), backend='trame')\n"
        "_mv._TRAME_MODES['trame'] = 'server'"
    ),
}


def _busy_loops(n: int) -> list[Any]:
    """``n`` CPU-bound processes (``while True: pass``): the load of a busy course server."""
    import subprocess

    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def _play_lessons(
    server: Any, context: Any, shots: Path, *, seconds: float, options: bool, backend: str
) -> dict[str, dict[str, Any]]:
    """Lesson 01's viewer and a 16-walker crowd in lesson 05's kernel, played on ``server`` in ``context``."""
    from browser_support import LessonPage, kernel_pid, play_viewer, process_rss_mb, screencast_ceiling, traced_pictures

    def played(lesson: LessonPage, var: str, pid: int) -> dict[str, Any]:
        r = play_viewer(lesson, var, seconds=seconds, pid=pid)
        if backend == "client":  # and again, counted by a trace instead of the screencast
            r["traced"] = traced_pictures(lesson, var, seconds=seconds)
        return r

    out: dict[str, dict[str, Any]] = {}
    lesson = LessonPage(context, server, "01_motion_data.ipynb", shots)
    lesson.open()
    lesson.run_all()
    pid = kernel_pid(lesson)
    out["memory"] = {"01": process_rss_mb(pid)}
    out["1 character"] = played(lesson, "viewer", pid)
    view = out["1 character"]["box"].locator("iframe.pyvista").first.bounding_box()
    out["ceiling"] = {"screencast_per_s": screencast_ceiling(lesson.page, view, seconds=seconds)}
    lesson.close()
    lesson = LessonPage(context, server, "05_synchronized_characters.ipynb", shots)
    lesson.open()
    try:
        lesson.run_all()
    except AssertionError as err:  # the crowd below does not need the lesson's results
        out["lesson 05 error"] = {"error": str(err)}
    pid = kernel_pid(lesson)
    out["memory"]["05"] = process_rss_mb(pid)
    lesson.run_cell(_CROWD)
    out["16 characters"] = played(lesson, "crowd16", pid)
    lesson.kernel_eval("crowd16.close()")
    if options and backend == "server" and "lesson 05 error" not in out:
        for k, (label, code) in enumerate(_OPTIONS.items()):
            new = f"_option{k}"
            lesson.run_cell(code.format(new=new) + f"\n{new}")
            out[f"8 characters, {label}"] = play_viewer(lesson, new, seconds=seconds, pid=pid)
            lesson.kernel_eval(f"{new}.close()")
    for r in out.values():
        r.pop("box", None)
    out["console"] = {"errors": list(lesson.console)}
    lesson.close()
    return out


def browser_figures(
    seconds: float, options: bool, routes: list[str], browser_nice: int = 0
) -> dict[str, dict[str, dict[str, Any]]]:
    """For each route (``lab``: JupyterLab; ``hub``: a JupyterHub with its proxy, from ``deploy/``) and backend
    (``server``, ``client``): the two scenes played in headless Chromium, and the kernel's memory after lessons
    01 and 05.  Keys of the result: ``"<route> <backend>"``.  ``browser_nice`` is the niceness Chromium runs at
    (negative: ahead of the kernel and the load, as a student's own machine would be; needs root)."""
    from browser_support import CHROMIUM, CHROMIUM_ARGS, JupyterLabServer, copy_lessons, server_env

    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("browser figures skipped: the playwright package is not installed")
        return {}
    if not Path(CHROMIUM).exists():
        print(f"browser figures skipped: no Chromium at {CHROMIUM}")
        return {}
    results: dict[str, dict[str, dict[str, Any]]] = {}
    for route in routes:
        for backend in ("server", "client"):
            with tempfile.TemporaryDirectory() as tmp:
                base = Path(tmp)
                root = copy_lessons(ROOT / "lessons", base / "lessons")
                env = server_env(_mirror())
                env["MOCAPLAB_JUPYTER_BACKEND"] = backend
                args = list(CHROMIUM_ARGS)
                if route == "hub":
                    from test_deploy_browser import CHP, Hub  # the deployment test's hub: one home

                    if CHP is None:
                        print("hub figures skipped: configurable-http-proxy not found")
                        break
                    server: Any = Hub(root, env=env, state_dir=base / "state")
                    # a browser on another machine: the kernel's trame server only through the hub's proxy
                    args.append("--host-resolver-rules=MAP localhost ~NOTFOUND")
                else:
                    server = JupyterLabServer(root, env=env, state_dir=base / "state")
                server.start()
                try:
                    if browser_nice:  # inherited by Playwright's driver and its Chromium, not by the kernel
                        os.setpriority(os.PRIO_PROCESS, 0, browser_nice)
                    with sync_playwright() as p:
                        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=args)
                        try:
                            context = browser.new_context(viewport={"width": 1800, "height": 1100})
                            if route == "hub":
                                server.login(context)
                            results[f"{route} {backend}"] = _play_lessons(
                                server,
                                context,
                                base / "shots",
                                seconds=seconds,
                                options=options and route == "lab",
                                backend=backend,
                            )
                        finally:
                            browser.close()
                finally:
                    if browser_nice:
                        os.setpriority(os.PRIO_PROCESS, 0, 0)
                    server.stop()
    return results


def _agree(pairs: list[tuple[int, int]]) -> str:
    bad = [p for p in pairs if p[0] != p[1]]
    return f"slider = label in {len(pairs) - len(bad)}/{len(pairs)} reads" + (f" (differ: {bad[:3]})" if bad else "")


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds of play measured in the browser")
    parser.add_argument("--repeats", type=int, default=20, help="frames timed per kernel figure")
    parser.add_argument("--options", action="store_true", help="also measure server-rendering options (8 characters)")
    parser.add_argument("--no-browser", action="store_true", help="kernel figures only")
    parser.add_argument(
        "--routes", default="lab,hub", help="comma-separated: lab (JupyterLab), hub (JupyterHub and its proxy)"
    )
    parser.add_argument(
        "--load", type=int, default=0, help="CPU-bound processes kept running during the browser runs (a busy server)"
    )
    parser.add_argument(
        "--browser-nice",
        type=int,
        default=0,
        help="niceness of Chromium (e.g. -10: the browser stands for a student's own machine; needs root)",
    )
    args = parser.parse_args()
    os.environ["MOCAPLAB_DATA_DIR"] = _mirror()

    print("kernel, per frame of server rendering (headless, median):")
    for name, r in kernel_costs(args.repeats).items():
        print(
            f"  {name:26s} geometry {r['geometry_ms']:6.2f} ms   render {r['render_ms']:6.2f} ms"
            f"   (with 8x MSAA {r['render_msaa8_ms']:6.2f} ms)"
        )
    if args.no_browser:
        return
    loops = _busy_loops(args.load)
    try:
        time.sleep(2.0 if loops else 0.0)
        print(f"\nbefore the browser runs ({args.load} busy processes beside them): {_load()}")
        routes = [r.strip() for r in args.routes.split(",") if r.strip()]
        results = browser_figures(args.seconds, args.options, routes, args.browser_nice)
        print(f"after them: {_load()}")
    finally:
        for proc in loops:
            proc.kill()
            proc.wait()
    if not results:
        return
    print(
        f"\nbrowser, headless Chromium with software WebGL (no GPU), {args.seconds:g} s of play"
        f" (kernel CPU over the play), {args.load} busy processes beside it on {os.cpu_count()} cores,"
        f" Chromium at niceness {args.browser_nice} (the kernel and the load at 0):"
    )
    for name, out in results.items():
        print(f"  {name}:")
        for key, r in out.items():
            if key in ("memory", "console", "ceiling"):
                continue
            if "error" in r:
                print(f"    {key}: {r['error']}")
                continue
            cost = r["kernel_cost_ms"]
            print(
                f"    {key:34s} {r['pictures_per_s']:5.1f} pictures/s   kernel {r['kernel_cpu_percent']:5.1f} % of a core\n"
                f"        kernel drew {r['kernel_pictures_per_s']:5.1f} pictures/s"
                f"{'' if cost is None else f' at {cost:.1f} ms each'}; "
                f"label lag at most {r['max_lag_s'] if r['max_lag_s'] is None else round(r['max_lag_s'], 3)} s; "
                f"{_agree(r['label_slider'])}"
                + ("" if r.get("drawn_width_share") is None else f"; drawn at {r['drawn_width_share']:.2f} of the width")
            )
            traced = r.get("traced")
            if traced is not None:
                shown = traced["pictures_per_s"]
                print(
                    f"        traced play: {'n/a' if shown is None else f'{shown:5.1f}'} new pictures/s on the display"
                    f" ({traced['display_frames_per_s']:.1f} display frames/s)"
                    + ("" if traced.get("drawn_width_share") is None
                       else f"; drawn at {traced['drawn_width_share']:.2f} of the width")
                )
        ceiling = out.get("ceiling", {}).get("screencast_per_s")
        if ceiling is not None:
            print(f"    screencast ceiling (a plain canvas repainted every frame over the view): {ceiling:5.1f} pictures/s")
        memory = out.get("memory", {})
        print(
            f"    kernel memory (RSS) after lesson 01: {memory.get('01', float('nan')):.0f} MB, "
            f"after lesson 05: {memory.get('05', float('nan')):.0f} MB"
        )
        if out.get("console", {}).get("errors"):
            print(f"    console errors: {out['console']['errors']}")
    for route in dict.fromkeys(name.split()[0] for name in results):
        client, server = results.get(f"{route} client"), results.get(f"{route} server")
        if client is None or server is None:
            continue
        print(f"\n{route}: browser drawing ('client') against the targets and against server rendering ('server'):")
        for key, (rate_target, cpu_target) in TARGETS.items():
            c, sv = client.get(key), server.get(key)
            if c is None or sv is None or "error" in c or "error" in sv:
                continue
            traced = (c.get("traced") or {}).get("pictures_per_s")
            if traced is not None:
                print(f"  {key:14s} traced pictures/s {traced:5.1f} (target {rate_target:g}: x{traced / rate_target:.2f})")
            print(
                f"  {key:14s} pictures/s {c['pictures_per_s']:5.1f} (target {rate_target:g}: "
                f"x{c['pictures_per_s'] / rate_target:.2f}; server {sv['pictures_per_s']:.1f}: "
                f"x{c['pictures_per_s'] / max(sv['pictures_per_s'], 1e-9):.2f}; screencast ceiling "
                f"{client.get('ceiling', {}).get('screencast_per_s', float('nan')):.1f})   "
                f"kernel CPU {c['kernel_cpu_percent']:.1f} % (target < {cpu_target:g} %: "
                f"x{c['kernel_cpu_percent'] / cpu_target:.2f}; server {sv['kernel_cpu_percent']:.1f} %: "
                f"x{c['kernel_cpu_percent'] / max(sv['kernel_cpu_percent'], 1e-9):.2f})"
            )
        for lesson in ("01", "05"):
            c_mb, s_mb = client["memory"].get(lesson), server["memory"].get(lesson)
            if c_mb is not None and s_mb is not None:
                print(
                    f"  kernel memory after lesson {lesson}: {c_mb:.0f} MB (server {s_mb:.0f} MB: x{c_mb / s_mb:.2f})"
                )


if __name__ == "__main__":
    main()
