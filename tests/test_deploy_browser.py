"""The lab deployed as a course deploys it: behind a base URL and behind JupyterHub, in a real browser.

Two deployments, each started for real on 127.0.0.1 with the components a
course uses, serving a temporary copy of ``lessons/``:

* ``base_url``: plain JupyterLab with ``ServerApp.base_url=/course/lab/``;
* ``hub``: a JupyterHub (its ``configurable-http-proxy`` from npm, the dummy
  authenticator, the simple local-process spawner running the student's
  ``jupyterhub-singleuser`` as the current user, root included), the student
  server given the lessons and ``MOCAPLAB_DATA_DIR`` through the spawner's
  ``environment``; Playwright logs in as ``student`` with the hub's login form.

In each, Debian's Chromium (told that ``localhost``, where the kernel's trame
server listens, does not resolve: a browser on another machine) opens lesson 01 from the student's server, runs
it, and checks that the trame iframe's address goes through
jupyter-server-proxy under the deployment's prefix, that the 3D view shows a
rendered picture, follows the frame slider and plays (distinct pictures over
time, counted with Chromium's screencast); then lesson 03's path editor is
dragged and its 3D view shows the edit.  Every process started is stopped by
its process id (process groups, then any descendant left), even on failure.

Run: ``pytest -m browser tests/test_deploy_browser.py`` (needs Chromium and,
for the hub, ``configurable-http-proxy``: ``npm install -g
configurable-http-proxy``; outside CI the module or test is skipped when one
is missing).
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import test_browser as tb  # the lesson checks of the plain-server suite: one home for them
from browser_support import (
    CHROMIUM,
    CHROMIUM_ARGS,
    JupyterLabServer,
    LessonPage,
    _children_of,
    copy_lessons,
    free_port,
    server_env,
    stop_process_tree,
)

pytestmark = [pytest.mark.browser, pytest.mark.timeout(420)]

ROOT = Path(__file__).resolve().parents[1]
BASE_URL = "/course/lab/"
STUDENT = "student"
# Distinct pictures per second the 3D view must show while playing behind a proxy
# (the direct target of test_browser is 15; every picture crosses one or two more hops here).
PLAY_TARGET = 6.0
CHP = shutil.which("configurable-http-proxy")
sync_api = tb.sync_api


class BaseUrlLab(JupyterLabServer):
    """:class:`browser_support.JupyterLabServer` with ``ServerApp.base_url`` set (in its own config folder)."""

    def __init__(self, root_dir: Path, *, env: dict[str, str], state_dir: Path, base_url: str) -> None:
        super().__init__(root_dir, env=env, state_dir=state_dir)
        self.base_url = base_url
        self.proxy_prefix = f"{base_url}proxy/"

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}{self.base_url.rstrip('/')}"

    def start(self, *, timeout: float = 90.0) -> None:
        config = Path(self.state_dir) / "jupyter_config_dir"
        config.mkdir(parents=True, exist_ok=True)
        (config / "jupyter_server_config.json").write_text(json.dumps({"ServerApp": {"base_url": self.base_url}}))
        super().start(timeout=timeout)

    def login(self, context: Any) -> None:
        """Nothing to do: the lesson's address carries the server's token."""


DEPLOY_CONFIG = ROOT / "deploy" / "jupyterhub_config.py"
# The course's configuration (deploy/jupyterhub_config.py), with only what a test on 127.0.0.1 changes:
# the dummy authenticator (the student has no system account), the simple spawner (the student's server
# runs as the current user, home in the test's folder), the proxy from npm, and a service token for the test.
_HUB_CONFIG = """\
c = get_config()  # noqa: F821 - JupyterHub's config loader defines it
load_subconfig({deploy!r})  # noqa: F821
c.JupyterHub.hub_ip = "127.0.0.1"
c.JupyterHub.hub_port = {hub_port}
c.ConfigurableHTTPProxy.command = [{chp!r}]
c.ConfigurableHTTPProxy.api_url = "http://127.0.0.1:{api_port}"
c.JupyterHub.authenticator_class = "dummy"
c.JupyterHub.spawner_class = "simple"
c.SimpleLocalProcessSpawner.home_dir_template = {home!r}
c.Spawner.cmd = [{singleuser!r}]
c.Spawner.args = {args!r}
c.Spawner.environment.update({environment!r})
c.JupyterHub.services.append({{"name": "mocaplab-test", "api_token": {token!r}}})
c.JupyterHub.load_roles.append(
    {{"name": "mocaplab-test", "scopes": ["admin:users", "admin:servers", "access:servers"], "services": ["mocaplab-test"]}}
)
"""

# What the student's server needs from the test's environment (the spawner passes only what it is given).
_PASSED = ("MOCAPLAB_", "OPENBLAS_", "OMP_", "PYVISTA_", "VTK_")


class Hub:
    """A JupyterHub on 127.0.0.1 and one student's server, started for real and stopped by process id.

    It has what :class:`browser_support.LessonPage` needs of a server: ``url``
    (the student's server behind the hub), ``token`` (a hub service token
    allowed to reach that server), ``root_dir`` and :meth:`log_tail`.
    """

    def __init__(self, root_dir: Path, *, env: dict[str, str], state_dir: Path, user: str = STUDENT) -> None:
        self.course_lessons = Path(root_dir)  # the course's copy; the student works in a copy of it
        self.state_dir = Path(state_dir)
        self.root_dir = self.state_dir / "home" / user / "mocaplab-lessons"  # deploy/: ~/mocaplab-lessons
        self.env = dict(env)
        self.user = user
        self.token = secrets.token_hex(16)
        self.port = 0
        self.proc: subprocess.Popen[bytes] | None = None
        self.log_path = self.state_dir / "jupyterhub.log"
        self._log: Any = None
        self._descendants: set[int] = set()
        self.proxy_prefix = f"/user/{user}/proxy/"

    @property
    def hub_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def url(self) -> str:
        return f"{self.hub_url}/user/{self.user}"

    def _config(self) -> Path:
        state = self.state_dir
        dirs = {}
        for name in ("JUPYTER_CONFIG_DIR", "JUPYTER_DATA_DIR", "JUPYTER_RUNTIME_DIR", "IPYTHONDIR"):
            dirs[name] = str(state / "student" / name.lower())
            Path(dirs[name]).mkdir(parents=True, exist_ok=True)
        settings = state / "student" / "user-settings"
        for rel, value in (
            ("apputils-extension/notification.jupyterlab-settings", {"fetchNews": "false", "checkForUpdates": False}),
            ("notebook-extension/tracker.jupyterlab-settings", {"windowingMode": "none"}),
        ):
            path = settings / "@jupyterlab" / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(value))
        environment = {k: v for k, v in self.env.items() if k.startswith(_PASSED)} | dirs
        args = [
            "--LabApp.expose_app_in_browser=True",
            f"--LabApp.user_settings_dir={settings}",
            f"--LabApp.workspaces_dir={state / 'student' / 'workspaces'}",
            "--LabApp.news_url=",
        ]
        if hasattr(os, "geteuid") and os.geteuid() == 0:  # CI runs as root
            args.append("--ServerApp.allow_root=True")
        # deploy/jupyterhub_config.py's settings
        self.env.update(
            MOCAPLAB_HUB_IP="127.0.0.1",
            MOCAPLAB_HUB_PORT=str(self.port),
            MOCAPLAB_HUB_STATE=str(state),
            MOCAPLAB_COURSE_LESSONS=str(self.course_lessons),
            MOCAPLAB_HUB_IDLE_MINUTES="0",
        )
        text = _HUB_CONFIG.format(
            deploy=str(DEPLOY_CONFIG),
            hub_port=free_port(),
            api_port=free_port(),
            chp=CHP,
            home=str(state / "home" / "{username}"),
            singleuser=str(Path(sys.executable).parent / "jupyterhub-singleuser"),
            args=args,
            environment=environment,
            token=self.token,
        )
        path = state / "jupyterhub_config.py"
        path.write_text(text)
        return path

    def hub_api(self, method: str, path: str, body: Any = None, *, timeout: float = 10.0) -> Any:
        return self._request(self.hub_url + "/hub/api" + path, method, body, timeout=timeout)

    def api(self, method: str, path: str, body: Any = None, *, timeout: float = 10.0) -> Any:
        """The student server's REST API (through the hub's proxy, with the service token)."""
        return self._request(self.url + path, method, body, timeout=timeout)

    def _request(self, url: str, method: str, body: Any, *, timeout: float) -> Any:
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(url, data=data, method=method)
        req.add_header("Authorization", f"token {self.token}")
        if data is not None:
            req.add_header("Content-Type", "application/json")
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            raw = resp.read()
        return json.loads(raw) if raw else None

    def _remember_descendants(self) -> None:
        if self.proc is not None:
            self._descendants.update(_children_of(self.proc.pid))

    def start(self, *, timeout: float = 150.0) -> None:
        """Start the hub, wait for its API, then spawn the student's server and wait until it is ready."""
        self.state_dir.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        config = self._config()
        self._log = open(self.log_path, "ab")  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "jupyterhub", "-f", str(config)],
            cwd=self.state_dir,
            env=self.env,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        deadline = time.monotonic() + timeout
        while True:
            self._remember_descendants()
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"JupyterHub did not answer on {self.hub_url}; log tail:\n{self.log_tail()}")
            try:
                self.hub_api("GET", "/")
                break
            except (urllib.error.URLError, ConnectionError, OSError):
                time.sleep(0.25)
        self.hub_api("POST", f"/users/{self.user}")
        try:
            self.hub_api("POST", f"/users/{self.user}/server", timeout=timeout)
        except urllib.error.HTTPError as err:
            if err.code != 202:  # 202: spawn pending
                raise
        while True:
            self._remember_descendants()
            model = self.hub_api("GET", f"/users/{self.user}")
            server = (model.get("servers") or {}).get("", {})
            if server.get("ready"):
                self._remember_descendants()
                return
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the student's server did not start; hub log tail:\n{self.log_tail()}")
            time.sleep(0.5)

    def login(self, context: Any) -> None:
        """Log in as the student with the hub's login form (the dummy authenticator takes any password)."""
        page = context.new_page()
        try:
            page.goto(f"{self.hub_url}/hub/login", wait_until="domcontentloaded", timeout=60000)
            page.fill("#username_input", self.user)
            page.fill("#password_input", "any-password")
            page.click("#login_submit")
            page.wait_for_url(f"{self.url}/**", timeout=90000)  # the hub sends the student to their server
        finally:
            page.close()

    def _stop_student_server(self) -> None:
        try:
            self.hub_api("DELETE", f"/users/{self.user}/server", timeout=30)
        except (urllib.error.URLError, ConnectionError, OSError, ValueError):
            pass

    def log_tail(self, n: int = 60) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""

    def stop(self) -> None:
        """Stop the student's server, the hub and its proxy, by process id. Safe to call twice."""
        proc, self.proc = self.proc, None
        if proc is not None:
            self._descendants.update(_children_of(proc.pid))
        for pid_file in ("proxy.pid", "jupyterhub.pid"):  # started in sessions of their own
            try:
                self._descendants.add(int((self.state_dir / pid_file).read_text().strip()))
            except (OSError, ValueError):
                pass
        stop_process_tree(proc, self._descendants, before=self._stop_student_server, wait=20)
        if self._log is not None:
            self._log.close()
            self._log = None


# ---------------------------------------------------------------- fixtures
@pytest.fixture(scope="module", params=["base_url", "hub"])
def deployed(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """The lessons served by one deployment, stopped by process id afterwards."""
    if not tb.LESSONS.is_dir():
        pytest.skip("no lessons/ folder")
    base = tmp_path_factory.mktemp(f"deploy-{request.param}")
    root = copy_lessons(tb.LESSONS, base / "lessons")
    env = server_env(os.environ.get("MOCAPLAB_DATA_DIR"))
    if request.param == "base_url":
        server: Any = BaseUrlLab(root, env=env, state_dir=base / "state", base_url=BASE_URL)
    else:
        if CHP is None:
            if os.environ.get("CI"):
                raise RuntimeError(
                    "the hub test needs configurable-http-proxy (npm install -g configurable-http-proxy)"
                )
            pytest.skip("configurable-http-proxy not found (npm install -g configurable-http-proxy)")
        server = Hub(root, env=env, state_dir=base / "state")
    t0 = time.monotonic()
    try:
        server.start()
        print(f"{request.param}: started in {time.monotonic() - t0:.1f} s")
        yield server
    finally:
        server.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_api.sync_playwright() as playwright:
        # a browser on another machine than the kernel: "localhost" (where trame listens) is not reachable
        chromium = playwright.chromium.launch(
            executable_path=CHROMIUM,
            headless=True,
            args=[*CHROMIUM_ARGS, "--host-resolver-rules=MAP localhost ~NOTFOUND"],
        )
        try:
            yield chromium
        finally:
            chromium.close()


@pytest.fixture
def open_lesson(deployed: Any, browser: Any, shots_dir: Path) -> Iterator[Any]:
    """``open_lesson("01", "MotionViewer")``: that lesson opened from the deployment, logged in as the student."""
    pages: list[LessonPage] = []
    contexts: list[Any] = []
    name = "hub" if isinstance(deployed, Hub) else "base-url"

    def opener(number: str, *needs: str) -> LessonPage:
        notebook = tb.lesson_or_skip(number, *needs)
        shutil.copy2(notebook, deployed.root_dir / notebook.name)
        context = browser.new_context(viewport={"width": 1800, "height": 1100})
        contexts.append(context)
        deployed.login(context)
        for old in (shots_dir / name).glob(f"{notebook.stem}-*.png"):  # this lesson's shots of an earlier run
            old.unlink()
        page = LessonPage(context, deployed, notebook.name, shots_dir / name)
        pages.append(page)
        page.open()
        return page

    yield opener
    for page in pages:
        try:
            page.screenshot("final")
        except Exception:  # noqa: BLE001 - evidence only
            pass
        page.close()
    for context in contexts:
        context.close()


shots_dir = tb.shots_dir


def assert_through_proxy(iframe: Any, deployed: Any) -> None:
    """The trame iframe's address goes through jupyter-server-proxy under the deployment's prefix."""
    src = iframe.get_attribute("src") or ""
    assert src.startswith(deployed.proxy_prefix), (
        f"the trame iframe's address {src!r} does not go through jupyter-server-proxy at {deployed.proxy_prefix}"
    )


# ---------------------------------------------------------------- tests
def test_lesson_01_renders_follows_the_slider_and_plays(open_lesson: Any, deployed: Any) -> None:
    t0 = time.monotonic()
    lesson = open_lesson("01", "MotionViewer")
    seconds = lesson.run_all()
    page = lesson.page
    iframe = tb.trame_frame(page)
    iframe.wait_for(state="attached", timeout=60000)
    assert_through_proxy(iframe, deployed)
    _, first = tb.rendered_view(lesson, iframe)
    lesson.screenshot("viewer", iframe)
    assert tb.image_std(first) > tb.MIN_VIEW_STD

    viewer_box = page.locator(".mocaplab-viewer").last
    slider = viewer_box.locator(".mocaplab-viewer-slider").first
    time_shown = slider.locator(".widget-label").first
    before = tb.text_of(time_shown)
    tb.set_slider(slider, 40)
    page.wait_for_function(
        "([el, before]) => el.textContent.trim() !== before",
        arg=[time_shown.element_handle(), before],
        timeout=30000,
    )
    _, change = tb.wait_view_change(lesson, lambda: tb._largest_surface(iframe.content_frame), first)
    lesson.screenshot("viewer-frame-40", viewer_box)
    assert change > tb.MIN_CHANGE, f"moving the frame slider did not change the 3D view (mean change {change:.3f})"
    assert tb.text_of(time_shown) == f"{40 / 120:.3f} s"

    played = tb.play_measured(lesson, "viewer", PLAY_TARGET)
    lesson.screenshot("viewer-played", viewer_box)
    rate = played["pictures_per_s"]
    assert rate >= PLAY_TARGET, f"the 3D view showed {rate:.1f} distinct pictures per second of play behind the proxy"
    assert played["state"]["time"] > 1.0, f"the viewer did not play on: {played['state']}"
    tb.assert_no_console_errors(lesson)  # e.g. no 405 from a launcher request: the page knows its websocket
    print(f"lesson 01 ran in {seconds:.1f} s; the test took {time.monotonic() - t0:.1f} s; played {rate:.1f}/s")


def test_lesson_03_path_editor_drags(open_lesson: Any, deployed: Any) -> None:
    t0 = time.monotonic()
    lesson = open_lesson("03", "PathEditor")
    lesson.run_all()
    page = lesson.page
    editor = page.locator(".mocaplab-path-editor").first
    editor.wait_for(timeout=60000)
    iframe = tb.trame_frame(editor)
    iframe.wait_for(state="attached", timeout=60000)
    assert_through_proxy(iframe, deployed)
    _, view_before = tb.rendered_view(lesson, iframe)

    result = tb._drag_handle(lesson, "path", "PathEditor", (70.0, -45.0))
    lesson.screenshot("path-editor-dragged", editor)
    moved = tb._assert_handle_under_mouse(lesson, result, axes=(0, 1))
    assert moved["data"] != result["handle"]["data"]

    def surface() -> Any:
        return tb._largest_surface(tb.trame_frame(page.locator(".mocaplab-path-editor").first).content_frame)

    tb.rendered_view(lesson, tb.trame_frame(editor))
    _, change = tb.wait_view_change(lesson, surface, view_before, timeout=45)
    lesson.screenshot("path-editor-3d-after", editor)
    assert change > tb.MIN_CHANGE, f"the 3D view did not change after the path edit (mean change {change:.3f})"
    tb.assert_no_widget_errors(lesson)
    print(f"lesson 03 drag test took {time.monotonic() - t0:.1f} s")


def test_the_hub_gives_the_student_a_working_copy(deployed: Any) -> None:
    """deploy/jupyterhub_config.py copies the course's lessons to ~/mocaplab-lessons and opens the server there."""
    if not isinstance(deployed, Hub):
        pytest.skip("the hub's pre-spawn hook")
    names = {p.name for p in deployed.course_lessons.glob("*.ipynb")} | {"00_glossary.md"}
    assert names <= {p.name for p in deployed.root_dir.iterdir()}
    listing = deployed.api("GET", "/api/contents")  # the student's server serves the working copy
    assert names <= {item["name"] for item in listing["content"]}
