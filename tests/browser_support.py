"""Drive the lessons in JupyterLab with a real headless Chromium (used by ``test_browser.py``).

Three pieces, each usable alone:

* :class:`JupyterLabServer` starts ``jupyter lab`` on 127.0.0.1 with a random
  free port and a random token in a folder, waits until it answers, and stops
  it by process id (its whole process group, then any kernel it left behind).
* :func:`launch_chromium` starts Debian's ``/usr/bin/chromium`` through
  Playwright's Python package (no browser download: there is no internet).
* :class:`LessonPage` opens one notebook in JupyterLab, runs all its cells with
  the ``notebook:run-all-cells`` command, waits for the kernel, collects
  console errors from the widget manager, and takes screenshots.

Pixel helpers (:func:`image_std`, :func:`image_change`) compare screenshots:
a canvas "is not blank" when its pixels vary, and a view "changed" when the
mean absolute difference of two screenshots of it is above a small threshold.
Both thresholds are in 8-bit grey levels.
"""

from __future__ import annotations

import io
import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

CHROMIUM = os.environ.get("MOCAPLAB_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
]

# Console errors that mean the front end lost a widget or its comm channel.
WIDGET_ERROR = re.compile(r"widget|manager|\bcomm\b|comm_|comm ", re.IGNORECASE)


def free_port() -> int:
    """Return a TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _children_of(pid: int) -> list[int]:
    """All descendants of ``pid`` (read from /proc; empty where /proc is missing)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").glob("[0-9]*"):
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # the command name may contain spaces and parentheses: split after the last ')'
        fields = stat[stat.rfind(")") + 2 :].split()
        parents[int(entry.name)] = int(fields[1])
    found: list[int] = []
    frontier = [pid]
    while frontier:
        p = frontier.pop()
        kids = [c for c, pp in parents.items() if pp == p]
        found.extend(kids)
        frontier.extend(kids)
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie child still answers kill(0); reap it if it is ours
    try:
        done, _ = os.waitpid(pid, os.WNOHANG)
        return done == 0
    except ChildProcessError:
        state = Path(f"/proc/{pid}/stat")
        try:
            return state.read_text().split(")")[-1].split()[0] != "Z"
        except OSError:
            return False


class JupyterLabServer:
    """A ``jupyter lab`` process serving ``root_dir`` on 127.0.0.1 with a token.

    Parameters
    ----------
    root_dir : Path
        Folder served (the notebooks are opened relative to it).
    env : dict of str to str
        Environment of the server and so of its kernels.
    state_dir : Path
        Where the server's config, runtime files, user settings, workspaces
        and log go, so the run never touches the user's own Jupyter state.

    Notes
    -----
    The server runs in its own session (process group). :meth:`stop` asks it
    to shut its kernels down over the REST API, sends SIGTERM to the group,
    waits, sends SIGKILL to the group, and finally kills by pid any
    descendant (kernels run in their own process groups) still alive.
    """

    def __init__(self, root_dir: Path, *, env: dict[str, str], state_dir: Path) -> None:
        self.root_dir = Path(root_dir)
        self.env = dict(env)
        self.state_dir = Path(state_dir)
        self.token = secrets.token_hex(16)
        self.port = 0
        self.proc: subprocess.Popen[bytes] | None = None
        self.log_path = self.state_dir / "jupyterlab.log"
        self._log: Any = None
        self._descendants: set[int] = set()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    # -- start ---------------------------------------------------------------
    def _write_settings(self) -> Path:
        """User settings that keep pop-ups (news, update checks) off the page."""
        settings = self.state_dir / "user-settings"
        note = settings / "@jupyterlab" / "apputils-extension" / "notification.jupyterlab-settings"
        note.parent.mkdir(parents=True, exist_ok=True)
        note.write_text(json.dumps({"fetchNews": "false", "checkForUpdates": False}))
        # render every cell: with JupyterLab's windowed notebooks, cells far from
        # the viewport are laid out lazily, so an output below a long lesson keeps
        # moving while it is scrolled to and never counts as stable for a screenshot
        tracker = settings / "@jupyterlab" / "notebook-extension" / "tracker.jupyterlab-settings"
        tracker.parent.mkdir(parents=True, exist_ok=True)
        tracker.write_text(json.dumps({"windowingMode": "none"}))
        return settings

    def start(self, *, timeout: float = 90.0) -> None:
        """Start the server and wait until ``/api/status`` answers (retry on a port clash)."""
        self.state_dir.mkdir(parents=True, exist_ok=True)
        settings = self._write_settings()
        env = dict(self.env)
        for name in ("JUPYTER_CONFIG_DIR", "JUPYTER_DATA_DIR", "JUPYTER_RUNTIME_DIR", "IPYTHONDIR"):
            key = name.lower()
            (self.state_dir / key).mkdir(exist_ok=True)
            env[name] = str(self.state_dir / key)
        last_error = ""
        for _attempt in range(3):
            self.port = free_port()
            cmd = [
                sys.executable,
                "-m",
                "jupyterlab",
                "--no-browser",
                "--ServerApp.ip=127.0.0.1",
                f"--ServerApp.port={self.port}",
                "--ServerApp.port_retries=0",
                f"--IdentityProvider.token={self.token}",
                f"--ServerApp.root_dir={self.root_dir}",
                "--LabApp.expose_app_in_browser=True",
                f"--LabApp.user_settings_dir={settings}",
                f"--LabApp.workspaces_dir={self.state_dir / 'workspaces'}",
                "--LabApp.news_url=",
            ]
            if hasattr(os, "geteuid") and os.geteuid() == 0:  # CI containers run as root
                cmd.append("--ServerApp.allow_root=True")
            self._log = open(self.log_path, "ab")  # noqa: SIM115 - closed in stop()
            self.proc = subprocess.Popen(
                cmd,
                cwd=self.root_dir,
                env=env,
                stdout=self._log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
            )
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if self.proc.poll() is not None:
                    break
                try:
                    self.api("GET", "/api/status")
                    return
                except (urllib.error.URLError, ConnectionError, OSError):
                    time.sleep(0.25)
            last_error = self.log_tail()
            self.stop()
        raise RuntimeError(f"jupyter lab did not answer on 127.0.0.1; log tail:\n{last_error}")

    # -- REST --------------------------------------------------------------
    def api(self, method: str, path: str, body: Any = None, *, timeout: float = 10.0) -> Any:
        """Call the server's REST API with the token; return the decoded JSON (or None)."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.url + path, data=data, method=method)
        req.add_header("Authorization", f"token {self.token}")
        if data is not None:
            req.add_header("Content-Type", "application/json")
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            raw = resp.read()
        return json.loads(raw) if raw else None

    def shutdown_kernels(self) -> None:
        """Shut down every kernel of the server (ignores a server already gone)."""
        try:
            for kernel in self.api("GET", "/api/kernels") or []:
                self.api("DELETE", f"/api/kernels/{kernel['id']}", timeout=20.0)
        except (urllib.error.URLError, ConnectionError, OSError, ValueError):
            pass

    def log_tail(self, n: int = 40) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""

    # -- stop --------------------------------------------------------------
    def stop(self) -> None:
        """Stop the server and everything it started, by process id. Safe to call twice."""
        proc, self.proc = self.proc, None
        stop_process_tree(proc, self._descendants, before=self.shutdown_kernels, wait=15)
        if self._log is not None:
            self._log.close()
            self._log = None


def stop_process_tree(
    proc: subprocess.Popen[Any] | None,
    descendants: set[int],
    *,
    before: Callable[[], None] | None = None,
    wait: float = 15,
) -> None:
    """Stop ``proc`` (the leader of its own session), its process group and ``descendants``, by id.

    ``before`` runs first while the leader still answers (a polite shutdown);
    the children seen before and after it join ``descendants``.  SIGTERM to
    the group, SIGKILL after ``wait`` seconds, SIGKILL again to members left
    behind by a leader already gone, then every recorded descendant still
    alive.  ``descendants`` is emptied.
    """
    if proc is not None:
        if proc.poll() is None:
            descendants.update(_children_of(proc.pid))
            if before is not None:
                before()
                descendants.update(_children_of(proc.pid))
            try:
                os.killpg(proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait(timeout=10)
        # the leader may be gone while group members linger
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    for pid in sorted(descendants):
        if _alive(pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    descendants.clear()


def server_env(data_dir: str | None) -> dict[str, str]:
    """The environment of a student's JupyterLab: interactive backends, fast lessons.

    ``MOCAPLAB_JUPYTER_BACKEND=client`` (the default a student gets: the
    browser draws the 3D view) replaces the static images of the test runs;
    the Agg matplotlib backend and pyvista's forced off-screen mode set for
    headless runs are removed, as a student would not have them.
    """
    env = dict(os.environ)
    for name in ("MPLBACKEND", "PYVISTA_OFF_SCREEN", "JUPYTER_PLATFORM_DIRS", "PYTEST_CURRENT_TEST"):
        env.pop(name, None)
    env["MOCAPLAB_JUPYTER_BACKEND"] = "client"
    env["MOCAPLAB_FAST"] = "1"
    if data_dir:
        env["MOCAPLAB_DATA_DIR"] = data_dir
    # the kernel runs the interpreter of this venv; put its scripts first
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    return env


def copy_lessons(src: Path, dst: Path) -> Path:
    """Copy the lesson notebooks (and any data next to them) into ``dst``."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "__pycache__"))
    return dst


def launch_chromium(playwright: Any) -> Any:
    """Launch Debian's Chromium headless through Playwright (never downloads a browser)."""
    return playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)


# -- pixels ------------------------------------------------------------------
def png_to_grey(png: bytes) -> np.ndarray:
    """Decode a PNG screenshot to a float grey image in [0, 255], shape (H, W)."""
    from PIL import Image

    img = Image.open(io.BytesIO(png)).convert("L")
    return np.asarray(img, dtype=float)


def image_std(png: bytes) -> float:
    """Standard deviation of the grey levels of a screenshot (0 for a blank one)."""
    return float(png_to_grey(png).std())


def image_change(before: bytes, after: bytes) -> float:
    """Mean absolute grey-level difference of two screenshots (crops to the common size)."""
    a, b = png_to_grey(before), png_to_grey(after)
    h, w = min(a.shape[0], b.shape[0]), min(a.shape[1], b.shape[1])
    return float(np.abs(a[:h, :w] - b[:h, :w]).mean())


# -- one notebook in the browser ---------------------------------------------
_CELL_STATE_JS = """
() => {
  const app = window.jupyterapp;
  if (!app) return {phase: 'no-app'};
  const panel = app.shell.currentWidget;
  if (!panel || !panel.content || !panel.sessionContext) return {phase: 'no-notebook'};
  const kernel = panel.sessionContext.session && panel.sessionContext.session.kernel;
  const status = kernel ? kernel.status : 'none';
  const cells = [];
  const model = panel.content.model;
  if (!model) return {phase: 'no-model', status};
  for (let i = 0; i < model.cells.length; i++) {
    const cell = model.cells.get(i);
    if (cell.type !== 'code') continue;
    const src = cell.sharedModel.getSource();
    const errors = [];
    for (let k = 0; k < cell.outputs.length; k++) {
      const out = cell.outputs.get(k).toJSON();
      if (out.output_type === 'error') errors.push(out.ename + ': ' + out.evalue);
    }
    cells.push({index: i, empty: src.trim() === '', count: cell.executionCount, errors});
  }
  const running = Array.from(panel.content.node.querySelectorAll('.jp-InputPrompt'))
      .some(n => n.textContent.includes('*'));
  return {phase: 'ok', status, running, cells};
}
"""


class LessonPage:
    """One notebook opened in JupyterLab in a fresh browser page.

    Parameters
    ----------
    context : playwright BrowserContext
    server : JupyterLabServer
    notebook : str
        Path of the notebook relative to the server's root.
    shots : Path
        Folder for the screenshots; files are named ``<stem>-<NN>-<label>.png``.
    """

    def __init__(self, context: Any, server: JupyterLabServer, notebook: str, shots: Path) -> None:
        self.server = server
        self.notebook = notebook
        self.shots = Path(shots)
        self.shots.mkdir(parents=True, exist_ok=True)
        self.page = context.new_page()
        self.console: list[str] = []
        self.page_errors: list[str] = []
        self._n_shots = 0
        self.page.on("console", self._on_console)
        self.page.on("pageerror", lambda err: self.page_errors.append(str(err)))

    def _on_console(self, msg: Any) -> None:
        if msg.type == "error":
            self.console.append(msg.text)

    # -- opening and running -----------------------------------------------
    def open(self, *, timeout: float = 90.0) -> None:
        """Open the notebook and wait for its kernel to be idle."""
        # a workspace of its own, reset: tabs of earlier pages are not restored (nor their kernels started)
        workspace = re.sub(r"[^A-Za-z0-9_-]", "-", Path(self.notebook).stem) + "-" + secrets.token_hex(3)
        url = f"{self.server.url}/lab/workspaces/{workspace}/tree/{self.notebook}?reset&token={self.server.token}"
        self.page.goto(url, wait_until="domcontentloaded", timeout=timeout * 1000)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            ready = self.page.evaluate(
                """() => {
                     const app = window.jupyterapp;
                     const p = app && app.shell.currentWidget;
                     const k = p && p.sessionContext && p.sessionContext.session && p.sessionContext.session.kernel;
                     return !!(k && k.status === 'idle' && p.content && p.content.model && p.content.model.cells.length > 0);
                   }"""
            )
            if ready:
                # more room for the lesson: close the file browser, as a student would on a laptop
                self.page.evaluate(
                    "() => { const app = window.jupyterapp;"
                    " if (!app.shell.leftCollapsed) return app.commands.execute('application:toggle-left-area'); }"
                )
                return
            # a notebook without kernel metadata asks for a kernel: accept the default (Python 3)
            accept = self.page.locator(".jp-Dialog .jp-Dialog-button.jp-mod-accept")
            if accept.count():
                accept.first.click()
            self.page.wait_for_timeout(250)
        self.screenshot("open-timeout")
        raise AssertionError(f"{self.notebook}: kernel not idle after {timeout:.0f} s\n{self.server.log_tail()}")

    def cell_state(self) -> dict[str, Any]:
        return self.page.evaluate(_CELL_STATE_JS)

    def run_all(self, *, timeout: float = 150.0) -> float:
        """Run all cells (command ``notebook:run-all-cells``) and wait until all have run.

        Returns the seconds it took. Fails with the cell's error (name and
        value) if a cell raised, and with the kernel status on a timeout.
        """
        t0 = time.monotonic()
        self.page.evaluate("() => window.jupyterapp.commands.execute('notebook:run-all-cells')")
        deadline = t0 + timeout
        state: dict[str, Any] = {}
        while time.monotonic() < deadline:
            self.page.wait_for_timeout(500)
            state = self.cell_state()
            if state.get("phase") != "ok":
                continue
            for cell in state["cells"]:
                if cell["errors"]:
                    raise AssertionError(f"{self.notebook}: cell {cell['index']} raised {cell['errors'][0]}")
            if state["status"] in ("dead", "unknown"):
                raise AssertionError(f"{self.notebook}: kernel {state['status']}\n{self.server.log_tail()}")
            todo = [c for c in state["cells"] if not c["empty"] and c["count"] is None]
            if not todo and not state["running"] and state["status"] == "idle":
                return time.monotonic() - t0
        raise AssertionError(f"{self.notebook}: cells not done after {timeout:.0f} s; last state {state}")

    def wait_idle(self, *, timeout: float = 120.0, settle: float = 1.0) -> None:
        """Wait until the kernel has been idle for ``settle`` seconds (work started by a click is done)."""
        deadline = time.monotonic() + timeout
        idle_since: float | None = None
        while time.monotonic() < deadline:
            status = self.page.evaluate(
                "() => { const p = window.jupyterapp.shell.currentWidget;"
                " const k = p && p.sessionContext.session && p.sessionContext.session.kernel;"
                " return k ? k.status : 'none'; }"
            )
            now = time.monotonic()
            if status == "idle":
                idle_since = idle_since if idle_since is not None else now
                if now - idle_since >= settle:
                    return
            else:
                idle_since = None
            self.page.wait_for_timeout(200)
        raise AssertionError(f"{self.notebook}: kernel still busy after {timeout:.0f} s")

    def stderr_tracebacks(self) -> list[str]:
        """Tracebacks printed to a cell's output stream (a student sees them even if the cell "worked")."""
        return self.page.evaluate(
            """() => {
                 const model = window.jupyterapp.shell.currentWidget.content.model;
                 const found = [];
                 for (let i = 0; i < model.cells.length; i++) {
                   const cell = model.cells.get(i);
                   if (cell.type !== 'code') continue;
                   for (let k = 0; k < cell.outputs.length; k++) {
                     const out = cell.outputs.get(k).toJSON();
                     if (out.output_type !== 'stream') continue;
                     const text = Array.isArray(out.text) ? out.text.join('') : String(out.text);
                     if (!text.includes('Traceback (most recent call last)')) continue;
                     const lines = text.replace(/\\x1b\\[[0-9;]*m/g, '').trim().split('\\n');
                     found.push('cell ' + i + ': ' + lines[lines.length - 1].slice(0, 240));
                   }
                 }
                 return found;
               }"""
        )

    def kernel_eval(self, code: str, *, timeout: float = 30.0) -> str:
        """Run ``code`` in the notebook's kernel (not in a cell); return its stdout."""
        return self.page.evaluate(
            """async ([code, timeout]) => {
                 const p = window.jupyterapp.shell.currentWidget;
                 const k = p.sessionContext.session.kernel;
                 let text = '';
                 const future = k.requestExecute({code, silent: false, store_history: false});
                 future.onIOPub = (msg) => {
                   if (msg.header.msg_type === 'stream') text += msg.content.text;
                   if (msg.header.msg_type === 'error') text += 'ERROR ' + msg.content.ename + ': ' + msg.content.evalue;
                 };
                 await Promise.race([future.done, new Promise((_, rej) => setTimeout(() => rej(new Error('timeout')), timeout))]);
                 return text;
               }""",
            [code, timeout * 1000],
        )

    def run_cell(self, source: str, *, timeout: float = 120.0) -> None:
        """Append a code cell with ``source`` to the notebook, run it and wait until the kernel is idle."""
        self.page.evaluate(
            """async (src) => {
                 const app = window.jupyterapp;
                 const nb = app.shell.currentWidget.content;
                 const n = nb.model.cells.length;
                 nb.model.sharedModel.insertCell(n, {cell_type: 'code', source: src});
                 nb.activeCellIndex = n;
                 await app.commands.execute('notebook:run-cell');
               }""",
            source,
        )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.page.wait_for_timeout(300)
            state = self.cell_state()
            if state.get("phase") != "ok":
                continue
            last = state["cells"][-1]
            if last["errors"]:
                raise AssertionError(f"{self.notebook}: the added cell raised {last['errors'][0]}")
            if last["count"] is not None and not state["running"] and state["status"] == "idle":
                return
        raise AssertionError(f"{self.notebook}: the added cell did not finish within {timeout:.0f} s")

    # -- evidence ----------------------------------------------------------
    def screenshot(self, label: str, locator: Any = None) -> Path:
        """Save a screenshot (of the page, or of ``locator``) and return its path."""
        self._n_shots += 1
        stem = Path(self.notebook).stem
        path = self.shots / f"{stem}-{self._n_shots:02d}-{label}.png"
        if locator is None:
            self.page.screenshot(path=str(path), full_page=False)
        else:
            locator.screenshot(path=str(path))
        return path

    def widget_errors(self) -> list[str]:
        """Console errors that mention a widget, the widget manager or a comm, plus page errors."""
        return [m for m in self.console if WIDGET_ERROR.search(m)] + self.page_errors

    def close(self) -> None:
        """Shut the notebook's kernel down (frees memory for the next lesson) and close the page."""
        try:
            self.page.evaluate(
                "() => { const p = window.jupyterapp.shell.currentWidget;"
                " return p && p.sessionContext && p.sessionContext.shutdown(); }"
            )
        except Exception:  # noqa: BLE001 - page may already be gone; the server stop cleans up
            pass
        self.page.close()


def wait_until(predicate: Callable[[], Any], *, timeout: float, interval: float = 0.25, what: str = "") -> Any:
    """Poll ``predicate`` until it returns a truthy value; raise AssertionError on timeout."""
    deadline = time.monotonic() + timeout
    value = None
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what or predicate}; last value {value!r}")


# -- counting the pictures a view shows ------------------------------------------
class PictureCounter:
    """Count the distinct pictures a region of the page shows, with Chromium's CDP screencast.

    The screencast sends a frame each time the compositor paints the page
    (never when nothing changed); each frame is cropped to ``box`` (CSS
    pixels of the viewport, as ``locator.bounding_box()`` gives them, less a
    margin of 8 frame pixels: JPEG blocks across the edge see the page around)
    and counts as a new picture when at least ``min_pixels`` of its pixels
    differ from the previous frame's crop by more than ``threshold`` grey
    levels (a skeleton moving by a few pixels changes a few hundred; the same
    picture encoded again changes none).  Changes elsewhere on the page (a
    slider, a label) are not counted.

    Parameters
    ----------
    page : playwright Page
    box : dict
        ``{"x", "y", "width", "height"}`` in CSS pixels of the viewport.
    threshold : float
        Grey-level change (8-bit) above which a pixel has changed.
    min_pixels : int
        Changed pixels that make a new picture.
    skip_top : float
        Share of the box's height left out at its top (an overlaid toolbar).

    Notes
    -----
    Frames are acknowledged as they arrive (Chromium sends no more until
    then) and decoded only in :meth:`stop`, so counting costs the page little.
    """

    def __init__(
        self,
        page: Any,
        box: dict[str, float],
        *,
        threshold: float = 24.0,
        min_pixels: int = 6,
        skip_top: float = 0.0,
        scale: float = 0.5,
    ) -> None:
        self.page = page
        self.min_pixels = int(min_pixels)
        self.scale = float(scale)
        self.box = dict(box)
        self.threshold = float(threshold)
        self.skip_top = float(skip_top)
        self.frames: list[tuple[float, str, dict[str, Any]]] = []  # (seconds, base64 jpeg, metadata)
        self._cdp: Any = None

    def _on_frame(self, params: dict[str, Any]) -> None:
        self.frames.append((time.monotonic(), params["data"], params.get("metadata", {})))
        try:
            self._cdp.send("Page.screencastFrameAck", {"sessionId": params["sessionId"]})
        except Exception:  # noqa: BLE001 - the session may be closing
            pass

    def start(self) -> None:
        self._cdp = self.page.context.new_cdp_session(self.page)
        self._cdp.on("Page.screencastFrame", self._on_frame)
        # half-size frames: encoding the full viewport for every paint would take the page's CPU
        size = self.page.viewport_size or {"width": 1800, "height": 1100}
        self._cdp.send(
            "Page.startScreencast",
            {
                "format": "jpeg",
                "quality": 70,
                "maxWidth": int(size["width"] * self.scale),
                "maxHeight": int(size["height"] * self.scale),
                "everyNthFrame": 1,
            },
        )

    def stop(self) -> None:
        if self._cdp is None:
            return
        try:
            self._cdp.send("Page.stopScreencast")
            self._cdp.detach()
        finally:
            self._cdp = None

    def crops(self) -> list[tuple[float, np.ndarray]]:
        """(arrival time, grey crop of the box) of every frame received."""
        import base64

        from PIL import Image

        out = []
        for stamp, data, meta in self.frames:
            img = Image.open(io.BytesIO(base64.b64decode(data))).convert("L")
            scale = img.width / float(meta.get("deviceWidth") or img.width)
            top = float(meta.get("offsetTop", 0.0))
            margin = 8
            x0 = int(round(self.box["x"] * scale)) + margin
            y0 = int(round((self.box["y"] + top + self.skip_top * self.box["height"]) * scale)) + margin
            x1 = int(round((self.box["x"] + self.box["width"]) * scale)) - margin
            y1 = int(round((self.box["y"] + top + self.box["height"]) * scale)) - margin
            out.append((stamp, np.asarray(img.crop((x0, y0, x1, y1)), dtype=float)))
        return out

    def distinct(self, t0: float | None = None, t1: float | None = None) -> list[float]:
        """Arrival times of the frames whose crop differs from the frame before (within [t0, t1])."""
        changes: list[float] = []
        previous: np.ndarray | None = None
        for stamp, crop in self.crops():
            new = (
                previous is None
                or crop.shape != previous.shape
                or int((np.abs(crop - previous) > self.threshold).sum()) >= self.min_pixels
            )
            if new and previous is not None and (t0 is None or stamp >= t0) and (t1 is None or stamp <= t1):
                changes.append(stamp)
            previous = crop
        return changes


def count_pictures(
    page: Any,
    box: dict[str, float],
    seconds: float,
    action: Callable[[], Any],
    *,
    sample: Callable[[], Any] | None = None,
    every: float = 0.25,
    **options: Any,
) -> tuple[float, PictureCounter, list[tuple[float, Any]]]:
    """Distinct pictures per second shown in ``box`` during ``seconds`` after ``action()`` (a click on play).

    ``sample()``, if given, is called every ``every`` seconds meanwhile; its
    results come back with the seconds since the action.
    """
    counter = PictureCounter(page, box, **options)
    samples: list[tuple[float, Any]] = []
    counter.start()
    try:
        page.wait_for_timeout(300)  # a first frame of the still view
        t0 = time.monotonic()
        action()
        while time.monotonic() - t0 < seconds:
            page.wait_for_timeout(int(1000 * min(every, max(seconds - (time.monotonic() - t0), 0.01))))
            if sample is not None and time.monotonic() - t0 < seconds:
                before = time.monotonic()
                value = sample()
                samples.append(((before + time.monotonic()) / 2 - t0, value))
        t1 = time.monotonic()
    finally:
        counter.stop()
    return len(counter.distinct(t0, t1)) / (t1 - t0), counter, samples


_VIEWER_STATE = """
import json as _j, numpy as _n
_v = {var}
_l = list(_v.play_log)
print("@@json@@" + _j.dumps({{"frame": _v.frame, "time": _v.time, "playing": _v.playing, "pictures": len(_l),
    "cost_ms": float(1e3 * _n.median([c for _, _, c in _l])) if _l else None, "fps": _v.fps,
    "n_frames": _v.n_frames}}))
del _j, _n, _v, _l
"""


def kernel_pid(lesson: LessonPage) -> int:
    """Process id of the lesson's kernel."""
    out = lesson.kernel_eval("import os as _os; print('@@pid@@', _os.getpid()); del _os")
    return int([x for x in out.splitlines() if x.startswith("@@pid@@")][-1].split()[1])


def process_cpu_seconds(pid: int) -> float:
    """User plus system CPU seconds used so far by process ``pid`` (psutil, or ``/proc`` without it)."""
    try:
        import psutil
    except ImportError:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    times = psutil.Process(pid).cpu_times()
    return float(times.user + times.system)


def process_rss_mb(pid: int) -> float:
    """Resident memory of process ``pid`` in MB (psutil, or ``/proc`` without it)."""
    try:
        import psutil
    except ImportError:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
        return float("nan")
    return psutil.Process(pid).memory_info().rss / 2**20


def _viewer_parts(lesson: LessonPage, var: str, *, settle: float) -> tuple[Any, Any, Any, Any]:
    """The box, 3D view iframe, play button and slider of the lesson's ``MotionViewer`` ``var``, at frame 0, stopped
    and scrolled into view (found by a class the kernel adds to its box), after ``settle`` seconds."""
    page = lesson.page
    marker = f"mocaplab-measured-{secrets.token_hex(3)}"
    lesson.kernel_eval(f"{var}.widget.add_class({marker!r}); {var}.stop_playback(); {var}.set_frame(0)")
    box = page.locator(f".{marker}").first
    box.wait_for(timeout=30000)
    box.scroll_into_view_if_needed()
    page.wait_for_timeout(int(settle * 1000))
    iframe = box.locator("iframe.pyvista").first
    play = box.locator(".mocaplab-viewer-play button, button.mocaplab-viewer-play").first
    slider = box.locator(".mocaplab-viewer-slider").first
    return box, iframe, play, slider


def _drawn_share(iframe: Any) -> float | None:
    """The share of its view's width a browser-drawn 3D view is drawn at (the client page's dynamic resolution)."""
    handle = iframe.element_handle()
    inner = handle.content_frame() if handle is not None else None
    if inner is None:
        return None
    return inner.evaluate(
        "() => { const c = document.querySelector('canvas'); "
        "return c && c.clientWidth ? c.width / (c.clientWidth * (window.devicePixelRatio || 1)) : null; }"
    )


def play_viewer(
    lesson: LessonPage, var: str, *, seconds: float = 3.0, settle: float = 2.0, pid: int | None = None
) -> dict[str, Any]:
    """Play the lesson's ``MotionViewer`` called ``var`` for ``seconds`` and measure it as a person sees it.

    The viewer (found by a class the kernel adds to its box) is scrolled into
    view and set to frame 0; its play button is clicked with the screencast
    running over its 3D view (:class:`PictureCounter`).  Every 0.25 s the
    time label and the slider's readout are read together.  Returns the
    pictures per second, the kernel's own count and median cost per picture
    (``play_log``), the label/slider pairs, the largest lag of the label's
    time behind the wall clock since the click, and the viewer's state after.
    With the kernel's process id ``pid``, also the CPU it used from the click
    to the end of the count, in percent of one core (``kernel_cpu_percent``).
    """
    page = lesson.page
    box, iframe, play, slider = _viewer_parts(lesson, var, settle=settle)
    lesson.kernel_eval(f"{var}.play_log.clear()")
    view_box = iframe.bounding_box()

    def both() -> tuple[str, str]:  # the slider's time (its description) and frame (its readout), read together
        return slider.evaluate(
            "(el) => [el.querySelector('.widget-label').textContent, el.querySelector('.widget-readout').textContent]"
        )

    clicked: list[tuple[float, float]] = []

    def click() -> None:
        if pid is not None:
            clicked.append((time.monotonic(), process_cpu_seconds(pid)))
        play.click()

    rate, counter, samples = count_pictures(page, view_box, seconds, click, sample=both, skip_top=0.18)
    drawn = _drawn_share(iframe)  # read before the play stops (a stopped view is sharp again)
    cpu = None
    if clicked:
        (t0, c0), t1, c1 = clicked[0], time.monotonic(), process_cpu_seconds(pid)
        cpu = 100.0 * (c1 - c0) / max(t1 - t0, 1e-9)
    state = json.loads(
        [x for x in lesson.kernel_eval(_VIEWER_STATE.format(var=var)).splitlines() if x.startswith("@@json@@")][-1][8:]
    )
    lesson.kernel_eval(f"{var}.stop_playback()")
    pairs, lags = [], []
    for elapsed, (text, value) in samples:
        found = re.search(r"([\d.]+) s", text or "")
        if not found or not str(value).strip().isdigit():
            continue
        seconds_shown, frame = float(found.group(1)), int(str(value).strip())
        pairs.append((round(seconds_shown * state["fps"]), frame))  # the time shown, in frames, and the frame
        lags.append(elapsed - seconds_shown)
    return {
        "pictures_per_s": rate,
        "screencast_frames": len(counter.frames),
        "kernel_pictures_per_s": state["pictures"] / seconds,
        "kernel_cost_ms": state["cost_ms"],
        "label_slider": pairs,
        "max_lag_s": max(lags) if lags else None,
        "state": state,
        "box": box,
        "kernel_cpu_percent": cpu,
        "drawn_width_share": drawn,
    }


def traced_pictures(
    lesson: LessonPage, var: str, *, seconds: float = 3.0, settle: float = 1.0, play: bool = True
) -> dict[str, Any]:
    """New pictures per second that the browser-drawn view ``var`` puts on the display while playing, from a trace.

    The screencast (:func:`count_pictures`) encodes and ships every picture it
    counts, and on a busy machine without a GPU it becomes the bottleneck
    (:func:`screencast_ceiling`).  This plays the viewer again with Chromium's
    tracing on and counts, between two marks the view's page sets around the
    click on play, the display's frames (``Display::DrawAndSwap``) and the
    WebGL canvas's new pictures that reached them: without a GPU, Chromium
    composites in software and reads each new WebGL picture back once
    (``GLES2::ReadPixels`` in the view's renderer).  ``pictures_per_s`` is the
    smaller count per second; ``None`` when no picture was read back (a
    browser compositing on a GPU, where this count does not apply).
    ``play=False`` traces the stopped view instead (no click).
    """
    page = lesson.page
    _, iframe, button, _ = _viewer_parts(lesson, var, settle=settle)
    handle = iframe.element_handle()
    inner = handle.content_frame() if handle is not None else None
    if inner is None:
        raise RuntimeError(f"the 3D view of {var!r} has no page to trace")
    browser = page.context.browser
    browser.start_tracing(page=page, categories=["gpu", "viz", "blink.user_timing"])
    try:
        inner.evaluate("() => performance.mark('mocaplab-play')")
        if play:
            button.click()
        page.wait_for_timeout(int(seconds * 1000))
        inner.evaluate("() => performance.mark('mocaplab-played')")
        drawn = _drawn_share(iframe)
    finally:
        raw = browser.stop_tracing()
    lesson.kernel_eval(f"{var}.stop_playback()")
    data = json.loads(raw)
    events = data["traceEvents"] if isinstance(data, dict) else data
    marks = {e["name"]: e for e in events if e.get("name") in ("mocaplab-play", "mocaplab-played")}
    t0, t1, pid = marks["mocaplab-play"]["ts"], marks["mocaplab-played"]["ts"], marks["mocaplab-play"]["pid"]
    span = (t1 - t0) / 1e6

    def count(name: str, same_process: bool) -> int:
        return sum(
            1 for e in events
            if e.get("name") == name and t0 <= e.get("ts", -1) <= t1 and (not same_process or e.get("pid") == pid)
        )

    readbacks, frames = count("GLES2::ReadPixels", True), count("Display::DrawAndSwap", False)
    return {
        "pictures_per_s": min(readbacks, frames) / span if readbacks else None,
        "display_frames_per_s": frames / span,
        "new_pictures": readbacks,
        "seconds": span,
        "drawn_width_share": drawn,
    }


def screencast_ceiling(page: Any, box: dict[str, float], *, seconds: float = 3.0) -> float:
    """The most distinct pictures per second the screencast counts over ``box`` on this machine now.

    A plain 2D canvas over ``box`` is filled with a new colour on every
    animation frame (about 60 a second, far cheaper than any 3D view) and
    counted like a view (:func:`count_pictures`): what the instrument itself
    can see.  Beside two CPU-bound processes on two cores it counts 20-22.
    """
    page.evaluate(
        """(b) => { const c = document.createElement('canvas'); c.id = 'mocaplab-ceiling';
           c.width = Math.round(b.width); c.height = Math.round(b.height);
           c.style = `position:fixed;left:${b.x}px;top:${b.y}px;width:${b.width}px;height:${b.height}px;z-index:99999`;
           document.body.appendChild(c); const g = c.getContext('2d'); let n = 0;
           (function paint() { if (!c.isConnected) { return; } n += 1;
             g.fillStyle = `hsl(${(n * 37) % 360}, 80%, 50%)`; g.fillRect(0, 0, c.width, c.height);
             requestAnimationFrame(paint); })(); }""",
        box,
    )
    try:
        rate, _, _ = count_pictures(page, box, seconds, lambda: None)
    finally:
        page.evaluate("() => document.getElementById('mocaplab-ceiling')?.remove()")
    return rate
