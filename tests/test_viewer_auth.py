"""Nobody in: the 3D view's trame server admits only the page that shows it (issue 27, item 3).

A real wslink client talks to the viewer's trame server on 127.0.0.1: its
first message (``wslink.hello``) without a secret, with wslink's public
default ``"wslink-secret"`` or with a wrong one is refused; with the secret
from the page's own iframe address it is admitted.
"""

from __future__ import annotations

import asyncio
import urllib.parse

import pytest

pv = pytest.importorskip("pyvista")
pytest.importorskip("ipywidgets")
pytest.importorskip("trame_pyvista")
aiohttp = pytest.importorskip("aiohttp")
msgpack = pytest.importorskip("msgpack")

from mocaplab.widgets.viewer import MotionViewer  # noqa: E402
from wslink.chunking import UnChunker, generate_chunks  # noqa: E402


@pytest.fixture(scope="module")
def view(cmu):
    pv.OFF_SCREEN = True
    viewer = MotionViewer(cmu("16_15")[:60], backend="trame", window_size=(320, 240))
    shown = viewer.show()
    widget = viewer._view
    assert shown is not None and widget is not None
    yield widget
    viewer.close()


async def _hello(port: int, secret: str | None) -> dict:
    """Open the view's websocket, send wslink's first message, return the server's answer."""
    args = [{"secret": secret}] if secret is not None else [{}]
    message = {"wslink": "1.0", "id": "system:c0:0", "method": "wslink.hello", "args": args, "kwargs": {}}
    unchunker = UnChunker()
    async with aiohttp.ClientSession() as session, session.ws_connect(f"ws://127.0.0.1:{port}/ws") as ws:
        for chunk in generate_chunks(msgpack.packb(message), 0):
            await ws.send_bytes(chunk)
        while True:
            frame = await asyncio.wait_for(ws.receive(), timeout=20)
            assert frame.type == aiohttp.WSMsgType.BINARY, frame
            whole = unchunker.process_chunk(frame.data)
            if whole is not None:
                return msgpack.unpackb(whole) if isinstance(whole, (bytes, bytearray)) else whole


def hello(port: int, secret: str | None) -> dict:
    return asyncio.run(_hello(port, secret))


def page_secret(src: str) -> str:
    (value,) = urllib.parse.parse_qs(urllib.parse.urlsplit(src).query)["secret"]
    return value


def test_the_default_secret_and_no_secret_are_refused(view):
    port = view.viewer.server.port
    for secret in (None, "wslink-secret", "", page_secret(view.src)[:-1]):
        answer = hello(port, secret)
        assert "result" not in answer and answer["error"]["message"] == "Authentication failed", (secret, answer)


def test_the_page_own_secret_is_admitted(view):
    secret = page_secret(view.src)
    assert secret.startswith("mocaplab-") and len(secret) >= 40  # 256 random bits, not a public default
    answer = hello(view.viewer.server.port, secret)
    assert "error" not in answer and answer["result"]["clientID"].startswith("c")


def test_the_server_listens_on_the_loopback_only(view):
    assert view.viewer.server._server_options.host == "127.0.0.1"
