"""Deploying the lab for a course: trame behind a proxy, Binder's files, an nbgrader round trip.

* :func:`mocaplab.widgets.serving.trame_proxy_prefix` decides where the trame
  iframe points (JupyterHub, a server's base URL, an explicit setting);
  ``tests/test_deploy_browser.py`` checks the same in a real hub and browser.
* ``.binder/`` (what repo2docker reads) agrees with ``pyproject.toml`` and
  ``.ci/run``: building the image needs Docker, which CI does not have.
* nbgrader: two lessons with exercises (Kim et al.'s lesson 03, Shin et al.'s
  lesson 09) go through ``generate_assignment`` and ``autograde`` in a
  temporary course folder: the student versions lose their solutions and
  score nothing, the instructor's versions score full marks.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from mocaplab.widgets import serving, viewer
from mocaplab.widgets.serving import PROXY_ENV_VAR, trame_proxy_prefix

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    tomllib = pytest.importorskip("tomli")

ROOT = Path(__file__).resolve().parents[1]
BINDER = ROOT / ".binder"


# ------------------------------------------------------------ trame behind a proxy
def runtime_file(folder: Path, pid: int, base_url: str) -> dict[str, str]:
    """A Jupyter server's runtime file (``jpserver-<pid>.json``) and the environment of a kernel it started."""
    folder.mkdir(parents=True, exist_ok=True)
    info = {"base_url": base_url, "port": 8888, "pid": pid, "url": f"http://127.0.0.1:8888{base_url}"}
    (folder / f"jpserver-{pid}.json").write_text(json.dumps(info))
    return {"JUPYTER_RUNTIME_DIR": str(folder), "JPY_PARENT_PID": str(pid)}


def test_direct_on_a_plain_server(tmp_path):
    assert trame_proxy_prefix({}) is None
    assert trame_proxy_prefix(runtime_file(tmp_path, 4242, "/")) is None


def test_jupyterhub_routes_through_the_users_proxy():
    assert trame_proxy_prefix({"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/"}) == "/user/ann/proxy/"
    assert trame_proxy_prefix({"JUPYTERHUB_SERVICE_PREFIX": "/hub/user/ann"}) == "/hub/user/ann/proxy/"
    # a named server
    assert trame_proxy_prefix({"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/lab2/"}) == "/user/ann/lab2/proxy/"


def test_a_server_base_url_routes_through_its_proxy(tmp_path):
    env = runtime_file(tmp_path, 4242, "/course/lab/")
    assert trame_proxy_prefix(env) == "/course/lab/proxy/"
    # only the runtime file of the server that started this kernel counts
    assert trame_proxy_prefix({**env, "JPY_PARENT_PID": "4243"}) is None
    # an unreadable runtime file is a plain server
    (tmp_path / "jpserver-4244.json").write_text("{not json")
    assert trame_proxy_prefix({**env, "JPY_PARENT_PID": "4244"}) is None


def test_without_jpy_parent_pid_the_parent_process_is_the_server(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "getppid", lambda: 777)
    env = runtime_file(tmp_path, 777, "/base/")
    del env["JPY_PARENT_PID"]
    assert trame_proxy_prefix(env) == "/base/proxy/"


def test_the_explicit_setting_wins(tmp_path):
    hub = {"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/"}
    assert trame_proxy_prefix({**hub, PROXY_ENV_VAR: "off"}) is None
    assert trame_proxy_prefix({**hub, PROXY_ENV_VAR: "Direct"}) is None
    assert trame_proxy_prefix({**hub, PROXY_ENV_VAR: "auto"}) == "/user/ann/proxy/"
    assert trame_proxy_prefix({PROXY_ENV_VAR: "/lab/proxy"}) == "/lab/proxy/"
    assert trame_proxy_prefix({PROXY_ENV_VAR: "https://lab.example.org/p/"}) == "https://lab.example.org/p/"
    assert trame_proxy_prefix({**runtime_file(tmp_path, 1, "/course/"), PROXY_ENV_VAR: "0"}) is None


def test_pyvistas_own_prefix_is_respected():
    assert trame_proxy_prefix({"PYVISTA_TRAME_SERVER_PROXY_PREFIX": "/proxy/"}) == "/proxy/"
    hub = {"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/", "PYVISTA_TRAME_SERVER_PROXY_PREFIX": "/relay/"}
    assert trame_proxy_prefix(hub) == "/user/ann/relay/"
    full = {"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/", "PYVISTA_TRAME_SERVER_PROXY_PREFIX": "https://h/x/"}
    assert trame_proxy_prefix(full) == "https://h/x/"


def test_reads_os_environ_by_default(monkeypatch):
    monkeypatch.setenv("JUPYTERHUB_SERVICE_PREFIX", "/user/bo/")
    monkeypatch.delenv(PROXY_ENV_VAR, raising=False)
    assert trame_proxy_prefix() == "/user/bo/proxy/"


def test_the_iframe_address_through_the_proxy(monkeypatch):
    """pyvista builds ``<prefix><port>/index.html``; the viewer adds the websocket's address."""
    from trame_pyvista.jupyter import build_url

    server = type("Server", (), {"port": 40123})()
    src = build_url(server, ui="P_1", server_proxy_enabled=True, server_proxy_prefix="/user/ann/proxy/")
    assert src == "/user/ann/proxy/40123/index.html?ui=P_1&reconnect=auto"
    # the trame page puts its own host (and ws or wss) in place of USE_HOST
    assert serving.session_url(src) == "ws://USE_HOST/user/ann/proxy/40123/ws"
    assert serving.session_url("/user/Ann/proxy/40123/index.html?ui=P") is None  # the page lower-cases it
    assert serving.session_url("proxy/40123/index.html") is None
    direct = build_url(server, ui="P_1", server_proxy_enabled=False)
    assert serving.session_url(direct) == "ws://localhost:40123/ws"
    assert serving.session_url("https://lab.example.org/p/40123/index.html?ui=P") == "wss://lab.example.org/p/40123/ws"


def test_the_viewer_passes_the_prefix_to_pyvista(monkeypatch):
    """The trame view's options carry the prefix (the browser test checks the iframe it gives)."""
    seen = {}

    class FakePlotter:
        window_size = (640, 400)

        def show(self, **kwargs):
            seen.update(kwargs["jupyter_kwargs"])
            return "view"

    fake = type("V", (), {"backend": "trame", "plotter": FakePlotter()})()
    monkeypatch.setenv("JUPYTERHUB_SERVICE_PREFIX", "/user/ann/")
    monkeypatch.delenv(PROXY_ENV_VAR, raising=False)
    assert viewer.MotionViewer._trame_view(fake) == "view"
    assert seen["server_proxy_enabled"] is True and seen["server_proxy_prefix"] == "/user/ann/proxy/"
    seen.clear()
    monkeypatch.setenv(PROXY_ENV_VAR, "off")
    viewer.MotionViewer._trame_view(fake)
    assert seen["server_proxy_enabled"] is False and "server_proxy_prefix" not in seen
    # a plain server: pyvista's own theme decides (a setting made with pv.global_theme is kept)
    seen.clear()
    monkeypatch.delenv(PROXY_ENV_VAR)
    monkeypatch.delenv("JUPYTERHUB_SERVICE_PREFIX")
    viewer.MotionViewer._trame_view(fake)
    assert "server_proxy_enabled" not in seen and "server_proxy_prefix" not in seen


# ------------------------------------------------------------ Binder / repo2docker
def _requirement_name(line: str) -> str:
    return re.split(r"[<>=!~\[; ]", line.strip(), maxsplit=1)[0].lower().replace("_", "-")


def _ci_apt_packages() -> set[str]:
    text = (ROOT / ".ci" / "run").read_text()
    found: set[str] = set()
    for line in text.splitlines():
        if "apt-get install" in line:
            words = line.split("apt-get install", 1)[1].split(">")[0].split()
            found.update(w for w in words if not w.startswith("-") and not w.startswith("$"))
    return found


def test_binder_installs_the_package_with_its_dependencies():
    """repo2docker runs ``pip install -r .binder/requirements.txt``: the project itself, so pyproject is the one list."""
    lines = [ln.strip() for ln in (BINDER / "requirements.txt").read_text().splitlines() if ln.strip() and ln[0] != "#"]
    assert any(re.fullmatch(r"(-e\s+)?\.\.?(/)?(\[[a-z,]+\])?", ln) for ln in lines), (
        f".binder/requirements.txt must install the repository (a line '.' or '-e .'): {lines}"
    )
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    declared = {_requirement_name(d) for d in project["dependencies"]}
    assert "jupyter-server-proxy" in declared, "the trame views behind a hub need jupyter-server-proxy"
    others = [ln for ln in lines if not ln.startswith(("-e", "."))]
    assert all(_requirement_name(ln) in declared for ln in others), (
        f"requirements not declared in pyproject.toml: {others}"
    )


def test_binder_apt_has_the_debian_packages_ci_installs_for_vtk():
    apt = {ln.strip() for ln in (BINDER / "apt.txt").read_text().splitlines() if ln.strip() and ln[0] != "#"}
    ci = _ci_apt_packages()
    gl = {p for p in ci if p.startswith(("libgl", "libegl", "libx", "libosmesa"))}
    assert gl, f"no GL/X packages found in .ci/run's apt-get install lines: {sorted(ci)}"
    assert gl <= apt, f".binder/apt.txt lacks {sorted(gl - apt)} that .ci/run installs for VTK"
    assert "chromium" not in apt, "the browser is for the tests, not for the image"


def test_binder_post_build_and_runtime():
    post = BINDER / "postBuild"
    assert os.access(post, os.X_OK), ".binder/postBuild must be executable (repo2docker runs it)"
    text = post.read_text()
    assert text.startswith("#!"), "postBuild needs a shebang line"
    assert "jupyter server extension enable" in text and "jupyter_server_proxy" in text
    runtime = (BINDER / "runtime.txt").read_text().strip()
    requires = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["requires-python"]
    minimum = tuple(int(x) for x in re.search(r">=\s*([0-9.]+)", requires).group(1).split("."))
    version = tuple(int(x) for x in re.fullmatch(r"python-([0-9.]+)", runtime).group(1).split("."))
    assert version >= minimum, f".binder/runtime.txt asks for {runtime}, pyproject requires {requires}"


# ------------------------------------------------------------ extras: what students and instructors install
def _extras() -> dict[str, set[str]]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    found = {name: {_requirement_name(r) for r in reqs} for name, reqs in project["optional-dependencies"].items()}
    return {"": {_requirement_name(r) for r in project["dependencies"]}, **found}


def test_the_course_tools_are_an_extra_students_do_not_install():
    extras = _extras()
    assert {"jupyterhub", "nbgrader"} <= extras["course"]
    assert not {"jupyterhub", "nbgrader"} & extras[""], "a student's `pip install -e .` must not pull the hub"
    assert "jupyter-server-proxy" in extras[""], "students' servers behind the hub need jupyter-server-proxy"
    assert "mocaplab" in extras["dev"], "dev includes the course extra (the suite runs the hub and nbgrader)"
    assert not {"jupyterhub", "nbgrader"} & extras["dev"], "one home for the course tools: the course extra"


# ------------------------------------------------------------ deploy/jupyterhub_config.py
DEPLOY_CONFIG = ROOT / "deploy" / "jupyterhub_config.py"


def load_hub_config(monkeypatch, **settings: str):
    """deploy/jupyterhub_config.py as JupyterHub loads it, with ``settings`` in the hub's environment."""
    from traitlets.config.loader import PyFileConfigLoader

    for name in [n for n in os.environ if n.startswith("MOCAPLAB_HUB_")] + ["MOCAPLAB_DATA_DIR"]:
        monkeypatch.delenv(name, raising=False)
    for name, value in settings.items():
        monkeypatch.setenv(name, value)
    return PyFileConfigLoader(DEPLOY_CONFIG.name, path=str(DEPLOY_CONFIG.parent)).load_config()


def test_the_hub_config_sets_up_a_small_course(tmp_path, monkeypatch):
    state = tmp_path / "state"
    c = load_hub_config(
        monkeypatch,
        MOCAPLAB_HUB_STATE=str(state),
        MOCAPLAB_DATA_DIR="/srv/mocap",
        MOCAPLAB_HUB_USERS="ann, bob",
        MOCAPLAB_HUB_ADMINS="teacher",
        MOCAPLAB_HUB_PORT="8123",
        MOCAPLAB_HUB_THREADS="2",
    )
    assert state.is_dir() and c.JupyterHub.db_url == f"sqlite:///{state / 'jupyterhub.sqlite'}"
    assert c.JupyterHub.cookie_secret_file == str(state / "jupyterhub_cookie_secret")
    assert c.JupyterHub.port == 8123
    assert c.JupyterHub.authenticator_class == "pam" and c.JupyterHub.spawner_class == "localprocess"
    assert c.Authenticator.allowed_users == {"ann", "bob", "teacher"} and c.Authenticator.admin_users == {"teacher"}
    environment = c.Spawner.environment
    assert environment["MOCAPLAB_DATA_DIR"] == "/srv/mocap", "the students' kernels find the shared mirror"
    assert environment["OPENBLAS_NUM_THREADS"] == environment["OMP_NUM_THREADS"] == "2"
    assert c.Spawner.default_url == "/lab" and c.Spawner.start_timeout >= 60
    singleuser = Path(c.Spawner.cmd[0])
    assert singleuser.name == "jupyterhub-singleuser" and singleuser.is_file()
    # no account list: anyone with an account on the machine; no mirror: nothing passed
    open_course = load_hub_config(monkeypatch, MOCAPLAB_HUB_STATE=str(state))
    assert open_course.Authenticator.allow_all is True and "MOCAPLAB_DATA_DIR" not in open_course.Spawner.environment


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, message: str, *args: object) -> None:
        self.lines.append(message % args)


def test_each_student_gets_a_working_copy_of_the_course_lessons(tmp_path, monkeypatch):
    """The pre-spawn hook copies the course's lessons to ~/mocaplab-lessons and opens the server there."""
    from types import SimpleNamespace

    course = tmp_path / "course-lessons"
    shutil.copytree(ROOT / "lessons", course, ignore=shutil.ignore_patterns("*.py", ".*", "__pycache__"))
    c = load_hub_config(monkeypatch, MOCAPLAB_HUB_STATE=str(tmp_path / "state"), MOCAPLAB_COURSE_LESSONS=str(course))
    hook = c.Spawner.pre_spawn_hook
    home = tmp_path / "home" / "ann"
    spawner = SimpleNamespace(home_dir=str(home), user=SimpleNamespace(name="ann"), log=_Log(), notebook_dir="")
    hook(spawner)
    mine = home / "mocaplab-lessons"
    assert spawner.notebook_dir == str(mine)
    names = sorted(p.name for p in course.glob("*.ipynb")) + ["00_glossary.md"]
    for name in names:
        assert (mine / name).read_bytes() == (course / name).read_bytes()
    assert f"{len(names)} added" in spawner.log.lines[-1]
    # the student works; the course updates lesson 02 and adds a lesson; the next start keeps the work
    (mine / "01_motion_data.ipynb").write_text("{}")
    (course / "02_motion_paths.ipynb").write_bytes((course / "02_motion_paths.ipynb").read_bytes() + b"\n")
    (course / "99_extra.ipynb").write_bytes((course / "01_motion_data.ipynb").read_bytes())
    hook(spawner)
    assert (mine / "01_motion_data.ipynb").read_text() == "{}"
    assert (mine / "02_motion_paths.ipynb").read_bytes() == (course / "02_motion_paths.ipynb").read_bytes()
    assert (mine / "99_extra.ipynb").is_file()
    assert "1 added, 1 updated, 1 kept" in spawner.log.lines[-1]
    # the default course copy is the lessons/ folder beside deploy/
    default = load_hub_config(monkeypatch, MOCAPLAB_HUB_STATE=str(tmp_path / "state"))
    bob = SimpleNamespace(home_dir=str(tmp_path / "bob"), user=SimpleNamespace(name="bob"), log=_Log(), notebook_dir="")
    default.Spawner.pre_spawn_hook(bob)
    assert (tmp_path / "bob" / "mocaplab-lessons" / "00_glossary.md").read_bytes() == (
        ROOT / "lessons" / "00_glossary.md"
    ).read_bytes()


# ------------------------------------------------------------ nbgrader round trip
ASSIGNMENT = "lab"
GLOSSARY = "00_glossary.md"
LESSONS = {
    "03_laplacian_path_editing.ipynb": "Kim et al. 2009",
    "09_touch_up_ground.ipynb": "Shin et al. 2003",
}


def graded_cells(nb: nbformat.NotebookNode) -> list[nbformat.NotebookNode]:
    return [c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade")]


def solution_cells(nb: nbformat.NotebookNode) -> list[nbformat.NotebookNode]:
    return [c for c in nb.cells if c.metadata.get("nbgrader", {}).get("solution")]


def _solution_lines(cell: nbformat.NotebookNode) -> list[str]:
    """The code lines between ``### BEGIN SOLUTION`` and ``### END SOLUTION`` (comments dropped)."""
    body = re.findall(r"### BEGIN SOLUTION\n(.*?)### END SOLUTION", cell.source, flags=re.S)
    return [ln.strip() for part in body for ln in part.splitlines() if ln.strip() and not ln.strip().startswith("#")]


def nbgrader(course: Path, *args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        [sys.executable, "-m", "nbgrader", *args], cwd=course, env=env, capture_output=True, text=True, timeout=900
    )
    assert done.returncode == 0, f"nbgrader {' '.join(args)} failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"
    return done


@pytest.fixture(scope="module")
def course(tmp_path_factory, request):
    """A course folder with the two lessons as one assignment, released, submitted by two students, autograded.

    ``lazy`` hands in the student version untouched; ``diligent`` hands in
    the instructor's version (the solutions).
    """
    pytest.importorskip("nbgrader", reason="nbgrader is in the course extra (pip install -e '.[course]')")
    mocap = request.getfixturevalue("mocap_dir")
    for name in LESSONS:
        path = ROOT / "lessons" / name
        if not path.is_file() or not graded_cells(nbformat.read(path, as_version=4)):
            pytest.skip(f"lessons/{name} has no nbgrader graded cell yet")
    course = tmp_path_factory.mktemp("course")
    (course / "nbgrader_config.py").write_text(
        "c = get_config()  # noqa: F821\n"
        f"c.CourseDirectory.root = {str(course)!r}\n"
        "c.CourseDirectory.course_id = 'mocaplab'\n"
        f"c.CourseDirectory.db_url = {f'sqlite:///{course}/gradebook.db'!r}\n"
        "c.ExecutePreprocessor.timeout = 600\n"
        "c.Execute.timeout = 600\n"
    )
    source = course / "source" / ASSIGNMENT
    source.mkdir(parents=True)
    for name in (*LESSONS, GLOSSARY):  # the README's recipe: the glossary the lessons link goes with them
        shutil.copy2(ROOT / "lessons" / name, source / name)
    env = dict(os.environ)
    env.update(
        MOCAPLAB_DATA_DIR=str(mocap),
        MOCAPLAB_FAST="1",
        MOCAPLAB_JUPYTER_BACKEND="static",
        PYVISTA_OFF_SCREEN="true",
        MPLBACKEND="Agg",
        JUPYTER_CONFIG_DIR=str(course / ".jupyter"),  # not the user's own nbgrader settings
    )
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    nbgrader(course, "db", "student", "add", "lazy", env=env)
    nbgrader(course, "db", "student", "add", "diligent", env=env)
    nbgrader(course, "generate_assignment", ASSIGNMENT, "--force", env=env)
    for student, folder in (("lazy", course / "release" / ASSIGNMENT), ("diligent", source)):
        handed_in = course / "submitted" / student / ASSIGNMENT
        handed_in.mkdir(parents=True)
        for name in LESSONS:
            shutil.copy2(folder / name, handed_in / name)
    nbgrader(course, "autograde", ASSIGNMENT, "--force", env=env)
    nbgrader(course, "export", env=env)
    return course


@pytest.mark.slow  # the course fixture runs each lesson twice under nbgrader (~100 s)
def test_generate_assignment_removes_the_solutions(course):
    for name, paper in LESSONS.items():
        instructor = nbformat.read(course / "source" / ASSIGNMENT / name, as_version=4)
        student = nbformat.read(course / "release" / ASSIGNMENT / name, as_version=4)
        solutions = {c.metadata["nbgrader"]["grade_id"]: c for c in solution_cells(instructor)}
        assert solutions, f"{name} ({paper}) has no solution cell"
        released = {c.metadata["nbgrader"]["grade_id"]: c for c in solution_cells(student)}
        assert released.keys() == solutions.keys()
        for grade_id, cell in solutions.items():
            lines = _solution_lines(cell)
            assert lines, f"{name}: solution cell {grade_id} has no code between its BEGIN/END SOLUTION markers"
            text = released[grade_id].source
            assert "BEGIN SOLUTION" not in text and "END SOLUTION" not in text
            leaked = [ln for ln in lines if ln in text]
            assert not leaked, f"{name}: the student version of {grade_id} still has the solution lines {leaked}"
            assert "raise NotImplementedError" in text, f"{name}: {grade_id} has no placeholder: {text!r}"
        text = json.dumps(student)
        assert "BEGIN HIDDEN TESTS" not in text, f"{name}: hidden tests left in the student version"
        assert len(graded_cells(student)) == len(graded_cells(instructor)) >= 1


@pytest.mark.slow  # the course fixture runs each lesson twice under nbgrader (~100 s)
def test_the_released_assignment_has_the_glossary_its_lessons_link(course):
    release = course / "release" / ASSIGNMENT
    assert (release / GLOSSARY).read_bytes() == (ROOT / "lessons" / GLOSSARY).read_bytes()
    for name in LESSONS:
        text = "".join(c.source for c in nbformat.read(release / name, as_version=4).cells if c.cell_type == "markdown")
        linked = set(re.findall(r"\]\(([^)#\s]+\.md)", text))
        assert GLOSSARY in linked, f"{name} no longer links the glossary"
        assert all((release / target).is_file() for target in linked), f"{name} links files not released: {linked}"


def _scores(course: Path) -> dict[str, tuple[float, float]]:
    import csv

    with open(course / "grades.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return {r["student_id"]: (float(r["raw_score"] or 0), float(r["max_score"])) for r in rows}


@pytest.mark.slow  # the course fixture runs each lesson twice under nbgrader (~100 s)
def test_student_versions_fail_their_graded_tests(course):
    scores = _scores(course)
    total = sum(
        c.metadata["nbgrader"]["points"]
        for name in LESSONS
        for c in graded_cells(nbformat.read(ROOT / "lessons" / name, as_version=4))
    )
    assert scores["lazy"] == (0.0, total), f"the untouched student versions scored {scores['lazy']}"
    for name in LESSONS:
        graded = nbformat.read(course / "autograded" / "lazy" / ASSIGNMENT / name, as_version=4)
        for cell in graded_cells(graded):
            errors = [o for o in cell.outputs if o.output_type == "error"]
            assert errors, f"{name}: graded cell {cell.metadata['nbgrader']['grade_id']} passed without an answer"


@pytest.mark.slow  # the course fixture runs each lesson twice under nbgrader (~100 s)
def test_the_instructors_versions_get_full_marks(course):
    from nbgrader.api import Gradebook

    raw, maximum = _scores(course)["diligent"]
    assert maximum >= 3 and raw == maximum, f"the solutions scored {raw} of {maximum}"
    with Gradebook(f"sqlite:///{course}/gradebook.db") as gb:
        submission = gb.find_submission(ASSIGNMENT, "diligent")
        per_notebook = {nb.name: (nb.score, nb.max_score) for nb in submission.notebooks}
    assert set(per_notebook) == {Path(n).stem for n in LESSONS}
    assert all(score == most > 0 for score, most in per_notebook.values()), per_notebook
