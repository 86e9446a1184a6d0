"""MotionViewer headless: static backend, off-screen rendering, widgets driven from Python."""

from __future__ import annotations

import asyncio
import dataclasses
import html
import sys
import threading

import numpy as np
import pytest

pv = pytest.importorskip("pyvista")
pytest.importorskip("ipywidgets")

from mocaplab.widgets.scene import fit_view  # noqa: E402
from mocaplab.widgets.serving import session_url  # noqa: E402
from mocaplab.widgets.viewer import MotionViewer, PlayClock, sphere_set  # noqa: E402


@pytest.fixture(scope="module")
def walk(cmu):
    return cmu("16_15")


@pytest.fixture(scope="module")
def viewer(walk):
    v = MotionViewer(walk, backend="static", window_size=(320, 240))
    v.widget  # noqa: B018 - builds the slider, play button and image
    yield v
    v.close()


def _sphere_centres(v: MotionViewer, k: int = 0) -> np.ndarray:
    c = v.characters[k]
    n = c.positions.shape[1]
    pts = np.asarray(c.joints.points).reshape(n, -1, 3)
    return (pts - v._spheres.template[None]).mean(axis=1)


def test_slider_moves_spheres_and_tubes_to_the_fk_of_that_frame(viewer, walk):
    sk = walk.skeleton
    actors_before = dict(viewer.plotter.actors)
    meshes_before = [(c.bones, c.joints) for c in viewer.characters]
    viewer.slider.value = 200
    assert viewer.frame == 200 and viewer.character_frames() == [200]
    fk = walk.global_positions()[200]
    centres = _sphere_centres(viewer)
    assert np.allclose(centres[: sk.n_joints], fk, atol=1e-9)
    assert np.allclose(centres[sk.n_joints :], walk.end_site_positions()[200], atol=1e-9)
    # each tube runs from its parent joint (bottom ring) to its joint (top ring)
    c = viewer.characters[0]
    rings = np.asarray(c.bones.points).reshape(len(c.segments), 2, viewer._sides, 3).mean(axis=2)
    assert np.allclose(rings[: sk.n_joints - 1, 0], fk[sk.parents[1:]], atol=1e-9)
    assert np.allclose(rings[: sk.n_joints - 1, 1], fk[1:], atol=1e-9)
    radii = np.linalg.norm(
        np.asarray(c.bones.points).reshape(len(c.segments), 2, viewer._sides, 3) - rings[:, :, None], axis=-1
    )
    assert np.allclose(radii, viewer.bone_radius)
    # geometry changed in place: same actors, same meshes
    assert dict(viewer.plotter.actors).keys() == actors_before.keys()
    assert all(viewer.plotter.actors[k] is a for k, a in actors_before.items())
    assert [(c.bones, c.joints) for c in viewer.characters] == meshes_before
    assert viewer.characters[0].actors[1].mapper.dataset is viewer.characters[0].joints


def test_screenshot_is_not_blank_and_follows_the_frame(viewer):
    viewer.set_frame(0)
    raw = viewer.screenshot()
    assert raw.shape == (240, 320, 3) and raw.dtype == np.uint8
    a = raw.astype(float)
    assert a.std() > 10  # not a blank canvas
    png_before = viewer._view.value
    viewer.set_frame(300)
    assert viewer.slider.value == 300  # set_frame drives the slider
    b = viewer.screenshot().astype(float)
    assert np.abs(a - b).mean() > 0.5
    assert viewer._view.value != png_before  # the static image widget was re-rendered
    assert viewer.slider.description == "2.500 s", "the slider shows the time with the frame"


def test_controls_play_step_and_a_usable_slider(viewer):
    """Play and step buttons beside a slider whose track keeps at least 300 px."""
    box = viewer.widget
    assert box.children[0] is viewer._view
    legend, controls, label, keys, status = box.children[1:]
    assert legend is viewer._legend and label is viewer._label and status is viewer._status and keys is viewer.keys
    assert list(controls.children) == [viewer.play, viewer.back, viewer.forward, viewer.slider]
    assert viewer.slider.max == viewer.n_frames - 1
    assert int(viewer.slider.layout.min_width.removesuffix("px")) >= 480  # track = width - time (72 px) - readout
    assert viewer.play.description == "play" and viewer.play.icon == "play"
    assert legend.layout.display == "none", "no legend for one character"
    viewer.set_frame(10)
    viewer.forward.click()
    assert viewer.frame == viewer.slider.value == 11
    viewer.back.click()
    viewer.back.click()
    assert viewer.frame == viewer.slider.value == 9 and viewer.slider.description == f"{9 / 120:.3f} s"
    viewer.set_frame(0)
    viewer.back.click()  # clamped, no error
    assert viewer.frame == 0 and viewer._status.value == ""


def test_several_characters_of_different_lengths_and_rates(walk, cmu):
    salsa = cmu("60_10")[:240]  # 60 fps, 4 s
    short = walk[:120]  # 120 fps, 1 s
    v = MotionViewer([short, salsa], backend="static", window_size=(320, 240), labels=["walk", "salsa"])
    assert v.fps == pytest.approx(120.0, rel=1e-6) and v.fps == max(short.fps, salsa.fps)
    assert v.n_frames == int(round(salsa.duration * v.fps)) + 1
    v.set_time(2.0)
    assert v.frame == 240
    assert v.character_frames() == [119, 120]  # the walk holds its last pose
    assert v.label_text() == "clip 3.983 s, frames 0-478 at 120 fps; characters' frames 119, 120"
    assert np.allclose(_sphere_centres(v, 1)[: salsa.n_joints], salsa.global_positions()[120], atol=1e-9)
    assert np.allclose(_sphere_centres(v, 0)[: short.n_joints], short.global_positions()[119], atol=1e-9)
    img = v.screenshot()
    assert img.std() > 10
    v.close()


def test_overlays_follow_the_time(walk):
    v = MotionViewer(walk, backend="static", window_size=(200, 150), ground=False)
    com = walk.root_positions[:, None] * [1.0, 0.0, 1.0]  # (F, 1, 3)
    v.add_points("com", com, color="red", radius=0.05)
    v.add_lines("path", walk.root_positions * [1.0, 0.0, 1.0])  # (k, 3): static
    counts = [3 + (i % 3) for i in range(walk.n_frames)]
    ragged = [np.c_[np.cos(np.arange(k)), np.zeros(k), np.sin(np.arange(k))] for k in counts]
    v.add_polygon("support", ragged, fill=True)
    v.add_points("target", lambda t: np.array([[t, 1.0, 0.0], [np.nan, 0.0, 0.0]]))
    v.set_frame(50)
    assert np.allclose(v.overlay_points("com"), com[50])
    spheres = sphere_set(0.05)
    assert np.allclose(np.asarray(v.overlays["com"].mesh.points), spheres.points(com[50]))
    assert v.overlay_points("target").shape == (1, 3) and np.isclose(v.overlay_points("target")[0, 0], 50 / 120)
    mesh = v.overlays["support"].mesh
    assert mesh.n_points == counts[50] and mesh.n_cells == counts[50] - 1  # the outline + a fan of triangles
    v.set_frame(51)
    assert mesh is v.overlays["support"].mesh and mesh.n_points == counts[51]
    actor = v.overlays["support"].actor
    v.set_frame(52)
    assert v.overlays["support"].actor is actor
    assert v.overlays["path"].mesh.n_points == walk.n_frames
    v.remove_overlay("path")
    assert "path" not in v.overlays and "overlay:path" not in v.plotter.actors
    with pytest.raises(KeyError, match="support"):
        v.remove_overlay("nothing")
    with pytest.raises(ValueError, match=r"\(F, k, 3\)"):
        v.add_points("bad", np.zeros((10, 2)))
    v.close()


def test_callback_errors_are_shown_in_the_widget_and_leave_it_consistent(walk):
    v = MotionViewer(walk[:60], backend="none")
    box = v.widget
    assert v._view is None and len(box.children) == 5  # legend, controls, label, keys' help line, status

    def broken(t):
        if t > 0.1:
            raise RuntimeError("overlay exploded")
        return np.zeros((1, 3))

    v.add_points("broken", broken)
    with pytest.raises(RuntimeError):
        v.slider.value = 30
    assert "overlay exploded" in v._status.value
    # the engine, the slider, the label and the characters all show frame 30
    assert v.frame == v.slider.value == 30 and v.slider.description == "0.250 s"
    assert v._label.value == html.escape(v.label_text())
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], walk.global_positions()[30], atol=1e-9)
    v.remove_overlay("broken")
    v.slider.value = 10
    assert v._status.value == ""
    v.close()


def test_text_from_data_and_errors_is_escaped(walk):
    """A joint name or a label that is HTML (from a downloaded file) is shown as text, never run."""
    evil = "<img src=x onerror=alert(1)>"
    names = (evil,) + walk.skeleton.names[1:]
    m = walk[:60].replace(skeleton=dataclasses.replace(walk.skeleton, names=names))
    v = MotionViewer([m, walk[:60]], backend="none", labels=[evil, "<b>walk</b>"])
    v.widget  # noqa: B018

    def missing_joint(t):
        if t > 0.1:
            raise KeyError(f"no target for joint {m.skeleton.names[0]}")
        return np.zeros((1, 3))

    v.add_points("targets", missing_joint)
    with pytest.raises(KeyError):
        v.slider.value = 20
    for text in (v._status.value, v._legend.value):
        assert "<img" not in text and "<b>" not in text
    assert html.escape(evil) in v._status.value
    assert html.escape(evil) in v._legend.value and "&lt;b&gt;walk&lt;/b&gt;" in v._legend.value
    v.close()


def test_bad_arguments(walk):
    with pytest.raises(ValueError, match="at least one"):
        MotionViewer([])
    with pytest.raises(TypeError, match=r"motions\[1\]"):
        MotionViewer([walk, "walk"])
    with pytest.raises(ValueError, match="backend"):
        MotionViewer(walk, backend="vr")
    with pytest.raises(ValueError, match="labels"):
        MotionViewer(walk, backend="none", labels=["a", "b"])
    v = MotionViewer(walk[:10], backend="none")
    with pytest.raises(IndexError, match="frame"):
        v.set_frame(10)
    v.close()


def test_backend_from_environment(walk, monkeypatch):
    monkeypatch.setenv("MOCAPLAB_JUPYTER_BACKEND", "none")
    v = MotionViewer(walk[:10])
    assert v.backend == "none"
    assert "backend 'none'" in repr(v)
    v.close()


def test_trame_backend_builds_an_updatable_view(walk):
    pytest.importorskip("trame_pyvista")
    v = MotionViewer(walk[:60], backend="trame", window_size=(320, 240))
    box = v.widget
    view = box.children[0]
    assert hasattr(view, "viewer") and "index.html" in view.src  # pyvista's trame iframe widget
    v.slider.value = 30
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], walk.global_positions()[30], atol=1e-9)
    # the trame server runs without trame-vtklocal (it downloads VTK.wasm from the internet)
    loaded = getattr(view.viewer.server.root_server, "_loaded_modules", set())
    assert not [m for m in loaded if getattr(m, "__name__", "").startswith("trame_vtklocal")]
    assert sys.modules.get("trame.widgets.vtklocal", 0) is not None, "the import block is lifted afterwards"
    v.close()


def test_set_motions_updates_the_meshes_in_place(walk, monkeypatch):
    v = MotionViewer(walk[:240], backend="static", window_size=(200, 150))
    box = v.widget
    v.set_frame(100)
    plotter, view, actors = v.plotter, v._view, dict(v.plotter.actors)
    meshes = (v.characters[0].bones, v.characters[0].joints)
    png = view.value

    def no_plotter(*args, **kwargs):
        raise AssertionError("set_motions must not create a plotter")

    monkeypatch.setattr(pv, "Plotter", no_plotter)
    edited = walk[:300].transformed(yaw=0.3, translation=(1.0, 0.0, 0.5))
    v.set_motions(edited)
    assert v.plotter is plotter and v.widget is box and v._view is view
    assert dict(v.plotter.actors).keys() == actors.keys()
    assert all(v.plotter.actors[k] is a for k, a in actors.items()), "no actor re-created"
    assert (v.characters[0].bones, v.characters[0].joints) == meshes, "same meshes, new points"
    assert v.characters[0].motion is edited
    assert v.frame == 100 and v.slider.value == 100
    centres = _sphere_centres(v)
    assert np.allclose(centres[: walk.n_joints], edited.global_positions()[100], atol=1e-9)
    assert np.allclose(centres[walk.n_joints :], edited.end_site_positions()[100], atol=1e-9)
    assert v.n_frames == 300 and v.slider.max == 299
    assert view.value != png, "the static image was re-rendered"
    x0, x1, z0, z1 = v._ground_extent
    root = edited.root_positions
    assert x0 <= root[:, 0].min() and root[:, 0].max() <= x1 and z0 <= root[:, 2].min() and root[:, 2].max() <= z1

    # shorter motions: the current frame is clamped to the new last frame
    v.set_motions(walk[:50])
    assert v.n_frames == 50 and v.slider.max == 49
    assert v.frame == 49 and v.slider.value == 49
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], walk.global_positions()[49], atol=1e-9)
    v.slider.value = 10  # the slider still drives the new motions
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], walk.global_positions()[10], atol=1e-9)
    v.close()


def test_set_motions_follows_the_clock_and_keeps_the_time(walk):
    v = MotionViewer(walk[:240], backend="static", window_size=(120, 90))
    v.widget  # noqa: B018
    v.set_frame(120)  # t = 1 s
    slow = walk[:240].resample(30)
    v.set_motions(slow)
    assert v.fps == pytest.approx(30.0) and v.n_frames == slow.n_frames
    assert v.frame == 30 and v.time == pytest.approx(1.0)
    assert v._play_clock.fps == pytest.approx(30.0) and v._play_clock.n_frames == slow.n_frames
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], slow.global_positions()[30], atol=1e-9)
    fixed = MotionViewer(walk[:60], backend="none", fps=60.0)
    fixed.set_motions(slow)
    assert fixed.fps == 60.0, "an fps given to the constructor is kept"
    with pytest.raises(ValueError, match="labels"):
        fixed.set_motions(slow, labels=["a", "b"])
    with pytest.raises(TypeError, match=r"motions\[0\]"):
        fixed.set_motions(["walk"])
    v.close()
    fixed.close()


def test_set_motions_rebuilds_actors_when_the_skeletons_change(walk, cmu):
    salsa = cmu("60_10")[:60]
    v = MotionViewer(walk[:120], backend="static", window_size=(160, 120))
    v.widget  # noqa: B018
    plotter = v.plotter
    v.set_frame(40)
    v.set_motions([walk[:120], salsa], labels=["walk", "salsa"])
    assert v.plotter is plotter
    assert {"bones0", "joints0", "bones1", "joints1"} <= set(v.plotter.actors)
    assert v.characters[1].actors[1].mapper.dataset is v.characters[1].joints
    assert v.character_frames() == [40, 20]
    assert np.allclose(_sphere_centres(v, 1)[: salsa.n_joints], salsa.global_positions()[20], atol=1e-9)
    assert "walk" in v._legend.value and "salsa" in v._legend.value and v._legend.layout.display == ""
    assert plotter.legend is None, "the legend is HTML beside the view, not under the trame toolbar"
    v.set_motions(salsa)  # one character of another skeleton
    assert "bones1" not in v.plotter.actors and v._legend.layout.display == "none"
    assert np.allclose(_sphere_centres(v)[: salsa.n_joints], salsa.global_positions()[20], atol=1e-9)
    assert v.screenshot().std() > 10
    v.close()


def test_set_motions_updates_the_trame_view(walk, monkeypatch):
    pytest.importorskip("trame_pyvista")
    v = MotionViewer(walk[:60], backend="trame", window_size=(160, 120))
    view = v.widget.children[0]
    updates = []
    monkeypatch.setattr(view.viewer, "update", lambda *a, **k: updates.append(1))
    edited = walk[:90].transformed(translation=(0.5, 0.0, 0.0))
    v.set_motions(edited)
    assert v.widget.children[0] is view and updates, "the embedded view was told to update"
    assert v.slider.max == 89
    assert np.allclose(_sphere_centres(v)[: walk.n_joints], edited.global_positions()[0], atol=1e-9)
    v.close()


def test_display_hooks(walk, capsys):
    v = MotionViewer(walk[:10], backend="none")
    v._ipython_display_()  # outside a kernel IPython prints the widget's text form
    assert v.show() is v.widget
    assert "VBox" in capsys.readouterr().out
    v.close()


# ------------------------------------------------------------------ threads
# JupyterLab 4.6 sends widget messages to a kernel subshell: with ipykernel 7 the
# callbacks run in another thread, where VTK cannot render (black view in the browser).


async def _until(predicate, what: str) -> None:
    """Let the running loop work until ``predicate()`` holds."""
    for _ in range(200):
        if predicate():
            return
        await asyncio.sleep(0.005)
    raise AssertionError(f"the loop never got to: {what}")


def _in_thread(target, *args) -> None:
    worker = threading.Thread(target=target, args=args, name="subshell-test")
    worker.start()
    worker.join(timeout=30)
    assert not worker.is_alive()


def test_updates_from_another_thread_render_in_the_main_thread(walk):
    main = threading.main_thread()
    rendered_in: list[threading.Thread] = []

    async def scenario() -> None:
        v = MotionViewer(walk[:240], backend="static", window_size=(160, 120))
        v.widget  # noqa: B018 - built in the main thread, as in a notebook cell
        png = v._view.value
        real = v.screenshot

        def spy():
            rendered_in.append(threading.current_thread())
            return real()

        v.screenshot = spy  # every render of the static view goes through it

        # a kernel-subshell callback: queued onto the main loop, nothing done in the worker
        _in_thread(v.set_frame, 60)
        assert v.queued_calls == 1
        assert v.frame == 0 and rendered_in == [] and v._view.value == png
        await _until(lambda: v.frame == 60, "set_frame(60)")
        assert rendered_in == [main] and v._view.value != png
        assert v.slider.value == 60

        # slider moves from the front end (a burst, as the play button sends): one draw of the newest
        def burst() -> None:
            for f in (70, 80, 90):
                v.slider.value = f

        _in_thread(burst)
        assert v.frame == 60 and len(rendered_in) == 1
        await _until(lambda: v.frame == 90, "the slider burst")
        await asyncio.sleep(0.02)
        assert rendered_in == [main, main], "one render for the whole burst, in the main thread"
        assert np.allclose(_sphere_centres(v)[: walk.n_joints], walk.global_positions()[90], atol=1e-9)

        # calls keep their order: new motions first, then the time on their clock
        slow = walk[:240].resample(30)

        def edit() -> None:
            v.set_motions(slow)
            v.set_time(1.0)

        _in_thread(edit)
        await _until(lambda: v.fps == pytest.approx(30.0) and v.frame == 30, "set_motions then set_time")
        assert all(t is main for t in rendered_in)

        # an error in a queued call has no caller to reach: it is shown in the widget
        _in_thread(v.set_frame, 10_000)
        await _until(lambda: "IndexError" in v._status.value, "the error shown")
        v.close()

    asyncio.run(scenario())


def test_updates_from_another_thread_without_a_loop_run_there(walk):
    v = MotionViewer(walk[:60], backend="none")  # built with no loop running: nothing to hand calls to
    v.widget  # noqa: B018
    _in_thread(v.set_frame, 30)
    assert v.frame == 30 and v.queued_calls == 0
    _in_thread(setattr, v.slider, "value", 40)
    assert v.frame == 40 and v.queued_calls == 0
    v.close()


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
def test_follow_tracks_the_pelvis_whatever_the_layout(walk):
    """A static joint 0 above the travelling pelvis: the camera follows the pelvis (Motion.path_joint)."""
    from test_editing_conventions import renamed, static_root

    clip = walk[:240]
    shifts = []
    for m in (clip, static_root(clip)):
        v = MotionViewer(m, backend="none", follow=True)
        assert np.allclose(v.characters[0].anchor(0.0), clip.root_positions[0]), "the camera follows the pelvis"
        assert v.characters[0].positions.shape == (
            clip.n_frames,
            clip.n_joints + len(clip.skeleton.end_site_parents),
            3,
        ), "joint_Root not drawn"
        before = np.asarray(v.plotter.camera.focal_point)
        v.set_frame(v.n_frames - 1)
        shifts.append(np.asarray(v.plotter.camera.focal_point) - before)
        v.close()
    travel = clip.root_positions[-1] - clip.root_positions[0]
    assert np.allclose(shifts[0][[0, 2]], travel[[0, 2]], atol=1e-6) and np.linalg.norm(travel[[0, 2]]) > 1.0
    assert np.allclose(shifts[1], shifts[0], atol=1e-9), "the same camera as for the CMU layout"
    # roles fixed by hand choose the followed joint
    m = renamed(clip)
    v = MotionViewer([m, m], backend="none", roles={"pelvis": "Spine_02"})
    spine = m.global_positions()[0, m.skeleton.index("Spine_02")]
    assert all(np.allclose(c.anchor(0.0), spine) for c in v.characters)
    v.set_motions([m, m, m])
    assert np.allclose(v.characters[2].anchor(0.0), spine)
    v.close()
    v = MotionViewer([m, m], backend="none", roles=[None, {"pelvis": "Spine_02"}])
    assert np.allclose(v.characters[0].anchor(0.0), clip.root_positions[0])
    assert np.allclose(v.characters[1].anchor(0.0), spine)
    v.close()
    with pytest.raises(ValueError, match="one per character"):
        MotionViewer([m, m], backend="none", roles=[None])


# ----------------------------------------------------------------- playback
class _FakeClock:
    """A wall clock the test moves: drawing a picture costs ``cost`` s, sleeping advances by the wait."""

    def __init__(self, cost: float) -> None:
        self.now = 1000.0
        self.cost = cost
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds
        await asyncio.sleep(0)


def _play_with(v: MotionViewer, clock: _FakeClock) -> list[tuple[float, int, int, str]]:
    """Wire ``clock`` into ``v``; record (time, frame, slider value, slider time) of every drawn picture."""
    seen: list[tuple[float, int, int, str]] = []
    draw = v._apply_frame

    def costly(frame: int, **options) -> None:
        began = clock.now
        draw(frame, **options)
        seen.append((began, v.frame, v.slider.value, v.slider.description))
        clock.now += clock.cost

    v._apply_frame = costly
    v._now, v._sleep = clock, clock.sleep
    return seen


@pytest.mark.parametrize("cost", [0.0, 0.1])
def test_playback_follows_the_wall_clock_and_skips_what_it_cannot_draw(walk, cost):
    """Frame = start + floor(elapsed * fps) at every picture: never behind, slider and label on the same frame."""

    async def scenario() -> None:
        v = MotionViewer(walk[:240], backend="none")  # 2 s at 120 fps
        v.widget  # noqa: B018
        v.set_frame(12)
        clock = _FakeClock(cost)
        seen = _play_with(v, clock)
        t0 = clock.now
        v.play.click()
        assert v.playing and v.play.description == "pause"
        await _until(lambda: not v.playing, "the end of the clip")
        assert v.play.description == "play" and v.frame == v.n_frames - 1
        frames = [f for _, f, _, _ in seen]
        updates = []
        for k, (began, frame, slider, label) in enumerate(seen):
            assert frame == min(12 + int(np.floor((began - t0) * v.fps + 1e-9)), v.n_frames - 1)
            assert label == f"{slider / v.fps:.3f} s", "the slider's time and frame always agree"
            if k == 0 or slider != seen[k - 1][2]:
                assert slider == frame, "the slider moves to the frame drawn"
                updates.append(began)
        assert seen[-1][2] == v.slider.value == v.n_frames - 1, "on the last frame at the end"
        gaps = np.diff(updates[:-1])
        assert np.all(gaps >= 1 / v.slider_rate - 1e-9), "at most slider_rate slider updates per second"
        assert np.all(gaps <= 1 / v.slider_rate + max(1 / 30, 1.5 * cost) + 1e-9), "and not fewer"
        steps = np.diff(frames)
        if cost == 0.0:  # at most play_rate pictures per second: 120 fps / 30 = every 4th frame
            assert set(steps[:-1]) == {4}
        else:  # 0.1 s per picture, then a rest of half of it: 0.15 s = 18 frames skipped each time
            assert set(steps[:-1]) == {18}
            assert all(s == pytest.approx(0.05) for s in clock.sleeps[1:]), "rest: half the cost"
        # the last frame is drawn when the clip's time is up (within one picture), not later
        duration = (v.n_frames - 1 - 12) / v.fps
        assert seen[-2][0] - t0 < duration <= seen[-1][0] - t0 < duration + max(1 / 30, 1.5 * cost) + 1e-9
        v.close()

    asyncio.run(scenario())


def test_slider_moves_and_steps_while_playing(walk):
    async def scenario() -> None:
        v = MotionViewer(walk[:240], backend="none")
        v.widget  # noqa: B018
        clock = _FakeClock(0.0)
        seen = _play_with(v, clock)
        v.play.click()
        for _ in range(3):
            await asyncio.sleep(0)
        _in_thread(setattr, v.slider, "value", 150)  # the student drags the slider (a subshell thread)
        await _until(lambda: any(f == 150 for _, f, _, _ in seen), "the slider move")
        await _until(lambda: seen[-1][1] > 170, "playing on")
        at = next(k for k, (_, f, _, _) in enumerate(seen) if f == 150)
        t150 = seen[at][0]
        for began, frame, _, _ in seen[at:]:  # the clock restarted at the slider's frame (held on the last one)
            assert frame == min(150 + int(np.floor((began - t150) * v.fps + 1e-9)), v.n_frames - 1)
        v.forward.click()  # a step pauses
        assert not v.playing and v.play.description == "play"
        frame = v.frame
        assert v.slider.value == frame and v.slider.description == f"{frame / v.fps:.3f} s"
        await asyncio.sleep(0.01)
        assert v.frame == frame, "paused"
        v.close()

    asyncio.run(scenario())


def test_play_button_from_another_thread_plays_in_the_main_thread(walk):
    main = threading.main_thread()

    async def scenario() -> None:
        v = MotionViewer(walk[:120], backend="static", window_size=(120, 90))
        v.widget  # noqa: B018
        drawn_in: list[threading.Thread] = []
        real = v.screenshot

        def spy():
            drawn_in.append(threading.current_thread())
            return real()

        v.screenshot = spy
        _in_thread(v.play.click)  # JupyterLab's subshell runs the click in another thread
        assert not v.playing and drawn_in == [], "nothing done in the worker"
        await _until(lambda: v.playing, "playback started")
        await _until(lambda: v.frame > 10, "frames drawn")
        _in_thread(v.play.click)
        await _until(lambda: not v.playing, "paused")
        assert drawn_in and all(t is main for t in drawn_in)
        v.close()

    asyncio.run(scenario())


def test_play_without_a_loop_says_why(walk):
    v = MotionViewer(walk[:60], backend="none")  # a script: no asyncio loop runs
    v.widget  # noqa: B018
    v.play.click()
    assert not v.playing and v.play.description == "play"
    assert "RuntimeError" in v._status.value and "asyncio loop" in v._status.value
    with pytest.raises(RuntimeError, match="set_frame"):
        v.start_playback()
    v.close()


def test_play_clock():
    clock = PlayClock(fps=120.0, n_frames=240)
    clock.start(10, now=5.0)
    assert clock.frame_at(4.0) == 10, "never before the start"
    assert clock.frame_at(5.5) == 70 and clock.frame_at(5.0 + 1 / 120) == 11
    assert clock.frame_at(99.0) == 239 and clock.at_end(99.0) and not clock.at_end(5.5)


# ------------------------------------------------------------------- camera
def _ndc(v: MotionViewer, points: np.ndarray) -> np.ndarray:
    """Normalised device coordinates (x, y in [-1, 1] inside the picture) of world points."""
    width, height = v.plotter.window_size
    m = v.plotter.camera.GetCompositeProjectionTransformMatrix(width / height, -1, 1)
    proj = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
    p = np.c_[points, np.ones(len(points))] @ proj.T
    return p[:, :2] / p[:, 3:]


@pytest.mark.parametrize("size", [(640, 360), (420, 340), (300, 500)])
def test_camera_frames_every_character_over_the_whole_clip(cmu, size):
    """Every drawn point of every frame (the jumper's head at the top of the jump too) is in the picture."""
    jump, walk = cmu("16_05"), cmu("16_15")
    v = MotionViewer([jump, walk.transformed(translation=(2.0, 0.0, 0.0))], backend="none", window_size=size)
    pts = np.concatenate([c.positions.reshape(-1, 3) for c in v.characters])
    ndc = _ndc(v, pts)
    assert np.abs(ndc).max() <= 0.9 + 1e-6, "inside, with a 10% margin"
    assert np.abs(ndc).max() > 0.8, "and not lost in the distance"
    v.close()


def test_set_motions_refits_a_camera_the_user_left_alone(walk):
    v = MotionViewer(walk[:240], backend="none", window_size=(420, 340))
    moved = walk[:240].transformed(yaw=1.2, translation=(3.0, 0.0, -2.0))
    v.set_motions(moved)  # an edit moved the character: the untouched camera follows the new clip
    pts = v.characters[0].positions.reshape(-1, 3)
    assert np.abs(_ndc(v, pts)).max() <= 0.9 + 1e-6
    assert not v.camera_moved()
    v.plotter.camera.Azimuth(40.0)  # the student turns the view
    assert v.camera_moved()
    turned = np.asarray(v.plotter.camera.position)
    v.set_motions(walk[:240])
    assert np.allclose(v.plotter.camera.position, turned), "a camera the user moved stays"
    v.set_motions(walk[:240], reset_camera=True)
    assert not v.camera_moved()
    v.close()


def test_fit_view_keeps_a_band_free_and_is_tight():
    corners = np.array([[x, y, z] for x in (-1.0, 2.0) for y in (0.0, 1.8) for z in (-3.0, 4.0)])
    direction, up = np.array([1.0, 0.5, 0.9]), np.array([0.0, 1.0, 0.0])
    for band in (0.0, 0.16):
        focal, position = fit_view(corners, direction, up, view_angle=30.0, aspect=1.6, top_band=band)
        w = (position - focal) / np.linalg.norm(position - focal)
        assert np.allclose(w, direction / np.linalg.norm(direction))
        right = np.cross(-w, up)
        right /= np.linalg.norm(right)
        upv = np.cross(right, -w)
        d = corners - position
        z = d @ -w
        ty = 0.9 * np.tan(np.radians(15.0))
        x, y = (d @ right) / (1.6 * ty * z), (d @ upv) / (ty * z)
        assert np.all(np.abs(x) <= 1 + 1e-6) and np.all(y >= -1 - 1e-6) and np.all(y <= 1 - 2 * band + 1e-6)
        assert max(np.abs(x).max(), (y.max() + 1) / (2 - 2 * band) * 2 - 1) > 1 - 1e-3, "no closer camera fits"


# -------------------------------------------------------------------- trame
def test_trame_view_sends_pictures_only_and_names_its_websocket(walk, monkeypatch):
    pytest.importorskip("trame_pyvista")
    from trame_pyvista.widgets import PyVistaRemoteView

    v = MotionViewer(walk[:60], backend="trame", window_size=(420, 340))
    view = v.widget.children[0]
    assert [type(x) for x in view.viewer.views] == [PyVistaRemoteView], "server rendering: no geometry per frame"
    port = view.viewer.server.port
    assert f"sessionURL=ws%3A%2F%2Flocalhost%3A{port}%2Fws" in view.src, "no POST to a ParaView launcher (405)"
    assert view.viewer.server.state[view.viewer.SHOW_UI] is False, "a narrow view starts with its toolbar collapsed"
    # the newest encoded picture is handed to trame's image delivery (its encoder is one picture behind)
    from trame_vtk.modules.vtk.protocols import vtkWebPublishImageDelivery

    pushed = []
    monkeypatch.setattr(
        vtkWebPublishImageDelivery, "push_render", lambda self, view_id, *a, **k: pushed.append(view_id)
    )
    v._push_latest()
    from trame_vtk.modules.vtk import get_helper

    assert pushed == [get_helper(view.viewer.server).id(v.plotter.render_window)]
    v.close()
    wide = MotionViewer(walk[:60], backend="trame", window_size=(640, 400))
    view = wide.widget.children[0]
    assert view.viewer.server.state[view.viewer.SHOW_UI] is True
    assert wide._toolbar_band() == pytest.approx(64 / 400)
    wide.close()
    assert session_url("http://localhost:8123/index.html?ui=x") == "ws://localhost:8123/ws"
    assert session_url("https://host:1/a/index.html") == "wss://host:1/a/ws"
    assert session_url("proxy/8123/index.html?ui=x") is None
