"""JupyterHub for a small mocaplab course on one machine (a few dozen students).

Run it from this folder: ``jupyterhub -f deploy/jupyterhub_config.py`` (as
root, so that the hub can start each student's server as that student).
Students log in with their system accounts (PAM); each gets a working copy
of the course's lessons in ``~/mocaplab-lessons`` when their server starts
(``python -m mocaplab.lessons copy``: new lessons are added, the ones a
student changed are kept), and JupyterLab opens in it.  The 3D views go
through jupyter-server-proxy by themselves (``JUPYTERHUB_SERVICE_PREFIX``).

Settings, read from the hub's environment (the defaults suit one machine):

``MOCAPLAB_COURSE_LESSONS``
    The course's copy of ``lessons/`` (a git clone the instructor updates
    with ``git pull``); default the ``lessons/`` folder beside this file.
``MOCAPLAB_DATA_DIR``
    The shared data mirror (``python -m mocaplab.data fetch``), passed to
    every student's server; unset, each student downloads the clips.
``MOCAPLAB_HUB_STATE``
    Where the hub keeps its database, cookie secret and process ids
    (default ``/srv/mocaplab-hub``).
``MOCAPLAB_HUB_IP``, ``MOCAPLAB_HUB_PORT``
    Where the hub listens (default every interface, port 8000); put it
    behind an HTTPS reverse proxy or set ``c.JupyterHub.ssl_cert`` /
    ``ssl_key`` for a network other than a classroom's.
``MOCAPLAB_HUB_USERS``, ``MOCAPLAB_HUB_ADMINS``
    Comma-separated accounts allowed to log in, and the instructors among
    them (admins may log in too).  With neither, every system account may.
``MOCAPLAB_HUB_THREADS``
    BLAS/OpenMP threads per student's kernel (default 1, so that a class
    running lessons at once shares the cores instead of fighting for them).
``MOCAPLAB_HUB_IDLE_MINUTES``
    Stop servers idle this long (default 60) when ``jupyterhub-idle-culler``
    is installed; 0 keeps them.

A site-specific file may load this one and override anything:
``c = get_config(); load_subconfig("/path/to/deploy/jupyterhub_config.py")``.
"""

from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

c = get_config()  # noqa: F821 - JupyterHub's config loader defines it

HERE = Path(__file__).resolve().parent
env = os.environ.get
COURSE_LESSONS = Path(env("MOCAPLAB_COURSE_LESSONS") or HERE.parent / "lessons").expanduser()
STATE = Path(env("MOCAPLAB_HUB_STATE") or "/srv/mocaplab-hub").expanduser()
#: The working copy's folder in each student's home.
LESSONS_FOLDER = "mocaplab-lessons"
THREADS = str(int(env("MOCAPLAB_HUB_THREADS") or 1))
IDLE_MINUTES = int(env("MOCAPLAB_HUB_IDLE_MINUTES") or 60)

# ---------------------------------------------------------------- the hub
STATE.mkdir(parents=True, exist_ok=True)
c.JupyterHub.ip = env("MOCAPLAB_HUB_IP") or ""
c.JupyterHub.port = int(env("MOCAPLAB_HUB_PORT") or 8000)
c.JupyterHub.db_url = f"sqlite:///{STATE / 'jupyterhub.sqlite'}"
c.JupyterHub.cookie_secret_file = str(STATE / "jupyterhub_cookie_secret")
c.JupyterHub.pid_file = str(STATE / "jupyterhub.pid")
c.ConfigurableHTTPProxy.pid_file = str(STATE / "proxy.pid")
c.JupyterHub.cleanup_servers = True

# ---------------------------------------------------------------- who logs in
users = {u.strip() for u in (env("MOCAPLAB_HUB_USERS") or "").split(",") if u.strip()}
admins = {u.strip() for u in (env("MOCAPLAB_HUB_ADMINS") or "").split(",") if u.strip()}
c.JupyterHub.authenticator_class = "pam"
if users or admins:
    c.Authenticator.allowed_users = users | admins
else:
    c.Authenticator.allow_all = True
c.Authenticator.admin_users = admins

# ---------------------------------------------------------------- each student's server
c.JupyterHub.spawner_class = "localprocess"
c.Spawner.cmd = [str(Path(sys.executable).parent / "jupyterhub-singleuser")]
c.Spawner.default_url = "/lab"
c.Spawner.start_timeout = 120  # the first start imports pyvista and VTK
c.Spawner.http_timeout = 120
c.Spawner.environment = {
    "OMP_NUM_THREADS": THREADS,
    "OPENBLAS_NUM_THREADS": THREADS,
    "MKL_NUM_THREADS": THREADS,
}
if env("MOCAPLAB_DATA_DIR"):
    c.Spawner.environment["MOCAPLAB_DATA_DIR"] = env("MOCAPLAB_DATA_DIR")


def _home(spawner) -> Path:  # noqa: ANN001
    """The student's home folder: the spawner's own idea of it, else the system account's."""
    home = getattr(spawner, "home_dir", None)  # SimpleLocalProcessSpawner
    if home:
        return Path(home)
    import pwd

    return Path(pwd.getpwnam(spawner.user.name).pw_dir)


def _chown_to(folder: Path, name: str) -> None:
    """Give the copied lessons to the student when the hub runs as root."""
    if not (hasattr(os, "geteuid") and os.geteuid() == 0):
        return
    import pwd

    try:
        account = pwd.getpwnam(name)
    except KeyError:
        return
    for path in [folder, *folder.rglob("*")]:
        shutil.chown(path, account.pw_uid, account.pw_gid)


def copy_lessons_for(spawner) -> None:  # noqa: ANN001
    """Before a student's server starts: bring the working copy up to date and open JupyterLab in it."""
    from mocaplab.lessons import copy_lessons

    home = _home(spawner)
    home.mkdir(parents=True, exist_ok=True)
    dest = home / LESSONS_FOLDER
    done = copy_lessons(dest, source=COURSE_LESSONS)
    _chown_to(dest, spawner.user.name)
    spawner.notebook_dir = str(dest)
    spawner.log.info(
        "mocaplab lessons for %s: %d added, %d updated, %d kept (changed by the student)",
        spawner.user.name,
        len(done.added),
        len(done.updated),
        len(done.kept),
    )


c.Spawner.pre_spawn_hook = copy_lessons_for

# ---------------------------------------------------------------- idle servers
if IDLE_MINUTES > 0 and shutil.which("jupyterhub-idle-culler") is not None:
    c.JupyterHub.load_roles = [
        {
            "name": "jupyterhub-idle-culler",
            "scopes": ["list:users", "read:users:activity", "read:servers", "delete:servers"],
            "services": ["jupyterhub-idle-culler"],
        }
    ]
    c.JupyterHub.services = [
        {"name": "jupyterhub-idle-culler", "command": ["jupyterhub-idle-culler", f"--timeout={60 * IDLE_MINUTES}"]}
    ]
