"""The "client" backend of the MotionViewer, kernel side: what it sends the page, and what it does not.

The page (vtk.js in the browser) gets the whole clip once and plays it on its
own clock; these tests read the trame state the viewer fills, through a
stand-in for the trame server, and decode it as the page does (base64 of
little-endian float32/int32).  The page itself is tested in headless
Chromium (tests/test_browser.py).
"""

from __future__ import annotations

import asyncio
import base64
import dataclasses

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pytest.importorskip("ipywidgets")

from mocaplab.widgets.viewer import MotionViewer  # noqa: E402


class _State(dict):
    """trame's server state as the viewer uses it: items, update, client_only, a flushing context."""

    def __init__(self) -> None:
        super().__init__()
        self.client_side: set[str] = set()
        self.flushes = 0
        self.history: list[tuple[str, object]] = []

    def __setitem__(self, key: str, value: object) -> None:
        self.history.append((key, value))
        super().__setitem__(key, value)

    def update(self, values: dict) -> None:  # type: ignore[override]
        for key, value in values.items():
            self[key] = value

    def client_only(self, *names: str) -> None:
        self.client_side.update(names)

    def __enter__(self) -> _State:
        return self

    def __exit__(self, *exc: object) -> None:
        self.flushes += 1


class _Server:
    def __init__(self) -> None:
        self.state = _State()


def _f32(text: str, shape: tuple[int, ...]) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype="<f4").reshape(shape)


def _i32(text: str) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype="<i4")


def _attached(motions, **options) -> tuple[MotionViewer, _State, dict]:
    v = MotionViewer(motions, backend="client", **options)
    server = _Server()
    names = v._client_attach(server)
    return v, server.state, names


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")


def test_the_whole_clip_goes_once_as_each_characters_points_and_clock_mapping(walk, cmu):
    """Decoded as the page does, every character's points on every frame, its bones and its frame per clock frame."""
    run = cmu("02_01")
    slow = dataclasses.replace(walk[::2], fps=walk.fps / 2)  # the same walk at 60 fps
    v, state, names = _attached([walk, slow, run])
    chars = state[names["chars"]]["chars"]
    assert len(chars) == 3
    for c, sent in zip(v.characters, chars, strict=True):
        n = sent["n_points"]
        pos = _f32(sent["pos"], (-1, n, 3))
        np.testing.assert_allclose(pos, c.positions, atol=1e-5)
        assert np.array_equal(np.reshape(sent["segs"], (-1, 2)), c.segments)
        index = _i32(sent["index"])
        assert len(index) == v.n_frames
        for i in (0, 1, 7, v.n_frames // 2, v.n_frames - 1):
            assert index[i] == c.frame_at(i / v.fps)
    # the 60 fps copy shows the same time as the 120 fps walk on every clock frame (within one of its frames)
    full, half = (_f32(chars[k]["pos"], (-1, chars[k]["n_points"], 3)) for k in (0, 1))
    i_full, i_half = _i32(chars[0]["index"]), _i32(chars[1]["index"])
    shown = np.abs(full[i_full] - half[i_half]).max(axis=(1, 2))
    assert shown.max() < np.abs(np.diff(full, axis=0)).max(axis=(1, 2)).max() * 1.01
    # colours and sizes the page draws with
    assert chars[0]["color"] == pytest.approx([0x1F / 255, 0x77 / 255, 0xB4 / 255])
    assert chars[0]["radius"] == v.bone_radius and chars[0]["joint_radius"] == v.joint_radius
    # the page starts on the viewer's frame, paused, and keeps its "ready" flag to itself
    ctl = state[names["ctl"]]
    assert ctl["playing"] is False and ctl["frame"] == v.frame and ctl["n_frames"] == v.n_frames
    assert ctl["fps"] == v.fps and state[names["start"]] == v.frame
    assert "mocaplab_ready" in state.client_side
    v.close()


def test_overlays_are_sampled_once_without_nan_rows(walk):
    v, state, names = _attached(walk[:120])
    per_frame = np.tile(np.arange(6.0).reshape(1, 2, 3), (120, 1, 1)) + np.arange(120.0)[:, None, None]
    per_frame[5, 1] = np.nan  # hidden on frame 5
    v.add_points("com", per_frame)
    v.add_polygon("square", np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], float))
    v.add_lines("trail", lambda t: np.array([[t, 0.0, 0.0], [t, 1.0, 0.0]]))
    sent = state[names["overlays"]]["overlays"]
    assert [o["kind"] for o in sent] == ["points", "polygon", "lines"]

    def shown(o: dict, i: int) -> np.ndarray:
        pts, offsets, index = _f32(o["pts"], (-1, 3)), _i32(o["offsets"]), _i32(o["index"])
        k = index[i]
        return pts[offsets[k] : offsets[k + 1]]

    for i in (0, 4, 5, 6, 119):
        v.set_frame(i)
        for o, name in zip(sent, ("com", "square", "trail"), strict=True):
            np.testing.assert_allclose(shown(o, i), v.overlay_points(name), atol=1e-5)
    assert len(shown(sent[0], 5)) == 1, "the NaN row is left out"
    assert len(_i32(sent[1]["offsets"])) == 2, "a static polygon is sent once"
    assert sent[1]["closed"] and sent[1]["fill"] and sent[1]["opacity"] == pytest.approx(0.35)
    v.remove_overlay("square")
    assert [o["kind"] for o in state[names["overlays"]]["overlays"]] == ["points", "lines"]
    v.close()


def test_the_ground_is_the_plotters_grid_as_lines(walk):
    v, state, names = _attached(walk)
    ground = state[names["ground"]]
    grid = v._ground_mesh
    points = np.reshape(ground["points"], (-1, 3))
    np.testing.assert_allclose(points, grid.points, atol=1e-6)
    nx, nz = grid.dimensions[0], grid.dimensions[1]
    cells, lines = list(ground["lines"]), []
    while cells:
        n = cells[0]
        lines.append(points[cells[1 : 1 + n]])
        cells = cells[1 + n :]
    assert sorted(len(p) for p in lines) == sorted([nx] * nz + [nz] * nx)
    lo, hi = np.asarray(grid.bounds[::2]), np.asarray(grid.bounds[1::2])
    for p in lines:  # each a straight row or column across the whole grid, at the ground's height
        span = np.ptp(p, axis=0)
        assert np.count_nonzero(span > 1e-9) == 1 and np.all(p[:, 1] == p[0, 1])
        axis = int(np.argmax(span))
        assert span[axis] == pytest.approx(hi[axis] - lo[axis])
        assert np.allclose(np.diff(p[:, axis]), 0.5), "0.5 m apart, in order"
    v.close()


def test_playing_sends_where_to_start_not_frames_and_the_slider_follows(walk):
    """The kernel draws no picture while the page plays: a few control messages, slider updates at slider_rate."""

    async def scenario() -> None:
        v = MotionViewer(walk[:240], backend="client")  # 2 s at 120 fps
        v.widget  # noqa: B018 - the controls (the view itself is attached below, without a trame server)
        state = _State()
        server = _Server()
        server.state = state
        names = v._client_attach(server)
        now = [1000.0]
        seen = []  # (clock, slider value, slider time) at each rest of the play loop

        async def sleep(seconds: float) -> None:
            seen.append((now[0], v.slider.value, v.slider.description))
            now[0] += seconds
            await asyncio.sleep(0)

        v._now, v._sleep = (lambda: now[0]), sleep
        geometry = []
        write = v._apply_frame
        v._apply_frame = lambda frame, **o: (geometry.append(frame), write(frame, **o))[1]
        v.set_frame(30)
        state.history.clear()
        geometry.clear()
        v.play.click()
        start = now[0]
        for _ in range(400):
            if not v.playing:
                break
            await asyncio.sleep(0.001)
        assert not v.playing and v.frame == v.n_frames - 1 == v.slider.value
        controls = [value for key, value in state.history if key == names["ctl"]]
        assert controls[0]["playing"] is True and controls[0]["frame"] == 30
        assert controls[-1]["playing"] is False and controls[-1]["frame"] == v.n_frames - 1
        assert len(controls) <= 3, "start, (the end), pause: never one per frame"
        assert all(key == names["ctl"] for key, _ in state.history), "only controls, the scene was sent once"
        assert geometry == [v.n_frames - 1], "the kernel's meshes move only when the play stops"
        assert v.pictures == 0
        values = [s for _, s, _ in seen]
        assert len(set(values)) >= 10, "the slider moves while the page plays"
        assert len(set(values)) <= (v.n_frames - 30) / v.fps * v.slider_rate + 3
        for t, value, label in seen:
            assert label == f"{value / v.fps:.3f} s"
            assert value == min(30 + int((t - start) * v.fps + 1e-9), v.n_frames - 1), "the wall clock's frame"
        v.close()

    asyncio.run(scenario())


def test_a_slider_move_while_playing_restarts_the_page_clock_there(walk):
    async def scenario() -> None:
        v = MotionViewer(walk[:240], backend="client")
        v.widget  # noqa: B018
        server = _Server()
        names = v._client_attach(server)
        v.play.click()
        await asyncio.sleep(0.01)
        v.slider.value = 100  # as the browser sets it
        await asyncio.sleep(0.01)
        ctl = server.state[names["ctl"]]
        assert ctl["playing"] is True and ctl["frame"] == 100
        v.stop_playback()
        ctl = server.state[names["ctl"]]
        assert ctl["playing"] is False and ctl["frame"] == v.frame == v.slider.value
        v.close()

    asyncio.run(scenario())


def test_set_motions_sends_the_new_clip_and_refits_the_camera(walk, cmu):
    v, state, names = _attached(walk)
    first_id, first_camera = state[names["chars"]]["id"], state[names["camera"]]
    run = cmu("02_01")
    v.set_motions([run, walk])
    sent = state[names["chars"]]
    assert sent["id"] != first_id and len(sent["chars"]) == 2
    np.testing.assert_allclose(
        _f32(sent["chars"][0]["pos"], (-1, sent["chars"][0]["n_points"], 3)), v.characters[0].positions, atol=1e-5
    )
    camera = state[names["camera"]]
    assert camera["seq"] != first_camera["seq"]
    np.testing.assert_allclose(camera["position"], v.plotter.camera.position)
    assert state[names["ctl"]]["n_frames"] == v.n_frames
    v.close()
