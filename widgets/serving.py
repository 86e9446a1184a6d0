"""How the 3D viewer reaches the browser: the kernel's trame server, its secret and address, and its thread.

:class:`~mocaplab.widgets.viewer.MotionViewer` shows its ``trame``,
``server`` and ``client`` views in an iframe served by the kernel's trame
server (one per kernel, shared by all views; pyvista starts it).  This module
holds what that needs and nothing of the scene (:mod:`mocaplab.widgets.scene`)
or of the page that the ``client`` backend loads
(:mod:`mocaplab.widgets.vtkjs_page`): who may connect, through which address,
and on which thread the viewer's calls run.

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

The iframe is told the address of the trame server's websocket
(``sessionURL``, :func:`session_url`): without it the trame page first asks a
ParaView launcher at ``.../paraview/`` (a ``POST`` that the trame server
answers with 405, logged as an error in the browser console), then falls back
to that websocket.

Who may connect
---------------
The trame server's websocket (wslink) lets a client in only if its first
message carries the server's secret, and wslink's default secret is the
public string ``"wslink-secret"``: with it, any process of the machine (any
user's, on a shared course server) could connect to the 3D view and call its
remote methods.  The viewer gives the kernel's trame server a random secret
instead (:data:`TRAME_SECRET`, :func:`secrets.token_urlsafe`, 256 bits, one
per kernel), set before the server starts through trame's own ``--authKey``
option (:func:`secure_trame_server`), and hands it only to the page that
shows the view, in its iframe's address (``secret=``, which the trame page
reads with its other address parameters and sends in its first message;
:func:`iframe_widget`).  The server still listens on 127.0.0.1 only, and the
address still goes through ``jupyter-server-proxy`` where one is used.  A
plain pyvista plot that started the server earlier with the default secret
has its secret replaced: its page must be shown again.

The trame server is started without ``trame-vtklocal``
(:func:`without_vtklocal`): pyvista loads it when it is installed, and it then
downloads VTK's WebAssembly build from gitlab.kitware.com, which prints a
traceback into some later cell when the machine is offline or behind a
firewall.  The views used here (remote and vtk.js local rendering) do not
need it.

Threads
-------
VTK renders only in the thread that owns its (EGL off-screen) render window:
the kernel's main thread, where the viewer is built and where trame's server
runs on the kernel's asyncio loop.  JupyterLab 4.6 sends widget messages to a
kernel *subshell* by default, so with ipykernel 7 a slider move or a button
click runs its Python callback in another thread; rendering there gives a
black view with white dashes in the browser.  The viewer therefore remembers
the asyncio loop running in the main thread when it is built
(:func:`main_thread_loop`) and, when one of its methods that touch the scene
is called from another thread, queues the whole call onto that loop
(:func:`on_main_thread`, ``loop.call_soon_threadsafe``), in call order, and
returns at once.  Calls made in the main thread, or when no loop was running
there (a script, the tests), run immediately.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import os
import secrets
import sys
import threading
import urllib.parse
from collections.abc import Callable, Iterator, Mapping
from typing import Any, Concatenate, ParamSpec, Protocol, TypeVar

__all__ = [
    "PROXY_ENV_VAR",
    "PROXY_OFF",
    "TRAME_SECRET",
    "current_task",
    "iframe_widget",
    "main_thread_loop",
    "on_main_thread",
    "proxy_setting",
    "quiet_vtk",
    "secure_trame_server",
    "server_base_url",
    "session_url",
    "trame_proxy_prefix",
    "without_vtklocal",
]

# The explicit proxy setting (see trame_proxy_prefix) and the values that turn the proxy off.
PROXY_ENV_VAR = "MOCAPLAB_TRAME_PROXY"
PROXY_OFF = ("off", "direct", "none", "0", "false", "no")

# The kernel's trame secret (module notes, "Who may connect"): made once per process and never changed.
# The prefix keeps the trame page from reading it as a number (it converts numeric address parameters).
TRAME_SECRET = "mocaplab-" + secrets.token_urlsafe(32)

_MAIN_LOOP: asyncio.AbstractEventLoop | None = None  # the loop last seen running in the main thread


# --------------------------------------------------------------------------
# starting the server
# --------------------------------------------------------------------------
@contextlib.contextmanager
def quiet_vtk() -> Iterator[None]:
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
def without_vtklocal() -> Iterator[None]:
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


def secure_trame_server() -> Any:
    """The kernel's pyvista trame server, set to admit only clients that know :data:`TRAME_SECRET`.

    Before it starts, the secret becomes the default of trame's ``--authKey``
    option (what the server reads when it starts); a server that already runs
    (a plain pyvista plot started it) gets the secret on its running protocol.
    """
    import pyvista as pv
    from trame_pyvista.widgets import get_server
    from trame_server.protocol import CoreServer

    server = get_server(name=pv.global_theme.trame.jupyter_server_name)
    server.cli.set_defaults(authKey=TRAME_SECRET, authKeyFile=None)
    if CoreServer.authentication_token != TRAME_SECRET:
        CoreServer.authentication_token = TRAME_SECRET  # what a protocol created from now on takes
        protocol = server.protocol
        if protocol is not None:
            protocol.updateSecret(TRAME_SECRET)
    return server


# --------------------------------------------------------------------------
# the address the browser uses
# --------------------------------------------------------------------------
def server_base_url(environ: Mapping[str, str]) -> str | None:
    """The base URL of the Jupyter server that started this kernel, from its runtime file.

    A Jupyter server writes ``jpserver-<pid>.json`` (with ``base_url``) into
    the Jupyter runtime folder, and the kernels it starts get its process id
    in ``JPY_PARENT_PID``.  None when there is no such file (a script, a
    kernel started by something else) or it cannot be read.
    """
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
       runtime file, see :func:`server_base_url`): ``<base_url>proxy/``.
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

    Examples
    --------
    >>> trame_proxy_prefix({"JUPYTERHUB_SERVICE_PREFIX": "/user/ann/"})
    '/user/ann/proxy/'
    """
    env = os.environ if environ is None else environ
    value = env.get(PROXY_ENV_VAR, "").strip()
    if value.lower() in PROXY_OFF:
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
        base = server_base_url(env) or "/"
        if base.strip("/") == "" and not pyvista_prefix:
            return None
    tail = (pyvista_prefix or "proxy/").strip("/")
    return "/" + "/".join(p for p in (base.strip("/"), tail) if p) + "/"


def proxy_setting() -> tuple[bool | None, str | None]:
    """Whether pyvista's iframe address goes through a proxy, and the prefix (from ``os.environ``).

    ``(True, prefix)`` with a prefix (:func:`trame_proxy_prefix`), ``(False,
    None)`` when :data:`PROXY_ENV_VAR` turns the proxy off, else ``(None,
    None)``: pyvista's theme decides (off unless set with
    ``pv.global_theme.trame.server_proxy_enabled``).
    """
    prefix = trame_proxy_prefix()
    if prefix is not None:
        return True, prefix
    if os.environ.get(PROXY_ENV_VAR, "").strip().lower() in PROXY_OFF:
        return False, None
    return None, None


def session_url(src: str) -> str | None:
    """The websocket address of the trame server behind the iframe address ``src``.

    ``http://localhost:PORT/index.html?ui=...`` serves its websocket at
    ``ws://localhost:PORT/ws``.  A path (behind jupyter-server-proxy:
    ``/user/ann/proxy/PORT/index.html``) gives ``ws://USE_HOST/user/ann/proxy/PORT/ws``:
    the trame page puts the browser's own host and ``ws``/``wss`` (as the page
    is ``http``/``https``) in place of ``USE_HOST``.  The page lower-cases
    such an address first, so a path with capitals gets None: the page then
    finds its websocket by itself, after a request to a launcher that the
    trame server answers with 405.

    Examples
    --------
    >>> session_url("http://localhost:8123/index.html?ui=P_1")
    'ws://localhost:8123/ws'
    """
    parts = urllib.parse.urlsplit(src)
    path = parts.path.rsplit("/", 1)[0]
    if not parts.scheme and not parts.netloc and path.startswith("/"):
        return f"ws://USE_HOST{path}/ws" if path == path.lower() else None
    if parts.scheme not in ("http", "https") or not parts.netloc:
        return None
    scheme = "wss" if parts.scheme == "https" else "ws"
    return f"{scheme}://{parts.netloc}{path}/ws"


def iframe_widget(viewer: Any, src: str, **kwargs: Any) -> Any:
    """pyvista's trame iframe widget, its address naming the websocket (no launcher request, no 405) and
    carrying the server's secret (see "Who may connect" in the module notes)."""
    from trame_pyvista.jupyter import Widget

    ws = session_url(src)
    if ws is not None:
        src = f"{src}{'&' if '?' in src else '?'}sessionURL={urllib.parse.quote(ws, safe='')}"
    src = f"{src}{'&' if '?' in src else '?'}secret={urllib.parse.quote(TRAME_SECRET, safe='')}"
    return Widget(viewer, src, **kwargs)


# --------------------------------------------------------------------------
# the main thread
# --------------------------------------------------------------------------
def main_thread_loop() -> asyncio.AbstractEventLoop | None:
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


class _Queues(Protocol):
    def _queue(self, call: Callable[[], Any]) -> bool: ...


_S = TypeVar("_S", bound=_Queues)
_P = ParamSpec("_P")
_R = TypeVar("_R")


def on_main_thread(method: Callable[Concatenate[_S, _P], _R]) -> Callable[Concatenate[_S, _P], _R | None]:
    """Run a scene-changing method in the main thread (queued there when called from another).

    The object's ``_queue(call)`` decides: True when it handed ``call`` to
    the main thread's loop (the method then returns None at once), False to
    run it here.
    """

    @functools.wraps(method)
    def wrapper(self: _S, /, *args: _P.args, **kwargs: _P.kwargs) -> _R | None:
        if self._queue(functools.partial(method, self, *args, **kwargs)):
            return None
        return method(self, *args, **kwargs)

    return wrapper


def current_task() -> asyncio.Task[Any] | None:
    """The asyncio task running this code, None outside one (or without a running loop in this thread)."""
    try:
        return asyncio.current_task()
    except RuntimeError:  # no running loop in this thread
        return None
