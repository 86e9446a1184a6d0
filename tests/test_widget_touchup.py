"""TouchUpStepper driven headless: buttons, schedule edits, plots, 3D overlays."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.physics import TouchUpSession, touch_up

pytest.importorskip("ipywidgets")
from mocaplab.widgets import TouchUpStepper  # noqa: E402


@pytest.fixture(scope="module")
def bent(mocap_dir):
    from mocaplab import data

    walk = data.cmu("16_15").resample(30)[:60]
    yaw = np.linspace(0.0, 0.6, walk.n_frames)
    q = quat.from_yaw(yaw)
    root = walk.root_positions.copy()
    root[1:, [0, 2]] = root[0, [0, 2]] + np.cumsum(
        quat.rotate(q[:-1], np.diff(root, axis=0) * [1, 0, 1])[:, [0, 2]], axis=0
    )
    return walk.with_root(root_positions=root, root_rotations=quat.mul(q, walk.rotations[:, 0]))


def _mean_mm(widget: TouchUpStepper) -> float:
    return float(widget.mean_label.value.split("<b>")[1].split("</b>")[0])


def test_step_and_back_buttons_move_through_the_session(bent):
    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    assert "mocaplab-touchup-step" in w.step_button._dom_classes
    assert "mocaplab-touchup-mean" in w.mean_label._dom_classes
    before = _mean_mm(w)
    assert w.back_button.disabled
    w.step_button.click()
    assert w.status.value == ""
    assert w.session.index == 1
    after = _mean_mm(w)
    assert after < before
    assert after == pytest.approx(1000 * w.session.current.mean_zmp_distance, abs=0.01)
    w.back_button.click()
    assert w.session.index == 0 and _mean_mm(w) == pytest.approx(before)
    w.iteration_button.click()
    assert w.session.index == 3
    # the figure lines follow the session
    assert np.allclose(w._line_now.get_ydata(), 1000 * w.session.current.zmp_distance, equal_nan=True)
    assert len(w._line_mean.get_xdata()) == 4
    # the label names the best complete pass so far (the touch-up's result)
    best = w.session.history.best
    assert best in (0, 3) and f"best so far: step {best}" in w.mean_label.value
    assert "without a ZMP" not in w.mean_label.value  # no ground frame lost its ZMP


def test_figure9_marks_the_best_pass(bent):
    from mocaplab.widgets.touchup import plot_mean_distance

    h = touch_up(bent, iterations=2, tol=None, footplants="ik")
    ax = plot_mean_distance(h)
    ring = [line for line in ax.get_lines() if line.get_label() == "best pass (the result)"]
    assert len(ring) == 1 and ring[0].get_xdata()[0] == h.best
    assert ring[0].get_ydata()[0] == pytest.approx(1000 * h.mean_zmp_distance[h.best])


def test_schedule_edits_reach_the_session(bent):
    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    w.step_button.click()
    w.rows[2].rho.value = 0.6
    assert w.session.schedule[2].rho == pytest.approx(0.6)
    w.rows[1].sigma.value = 0.5
    assert w.session.schedule[1].sigma == pytest.approx(0.5)
    w.rows[2].s2.value = "LeftArm"
    assert w.session.schedule[2].s2 == ("LeftArm",)
    assert w.status.value == ""
    # a bad joint name is reported in the widget, the schedule is kept
    w.rows[2].s2.value = "LeftWing"
    assert "LeftWing" in w.status.value
    assert w.session.schedule[2].s2 == ("LeftArm",)
    w.step_button.click()
    assert w.session.index == 2 and w.status.value == ""
    # the message is HTML-escaped, so a name like "<Wing>" is shown, not eaten as a tag
    w.rows[2].s2.value = "<Wing>"
    assert "&lt;Wing&gt;" in w.status.value and "<Wing>" not in w.status.value


def test_stepper_accepts_a_session_and_rejects_bad_input(bent):
    s = TouchUpSession(bent, footplants="ik")
    w = TouchUpStepper(s, viewer=False)
    assert w.session is s
    with pytest.raises(ValueError, match="no session options"):
        TouchUpStepper(s, viewer=False, footplants="ik")
    with pytest.raises(TypeError, match="Motion"):
        TouchUpStepper("walk", viewer=False)  # type: ignore[arg-type]


def test_viewer_draws_com_zmp_and_support_polygon(bent):
    w = TouchUpStepper(bent, footplants="ik", viewer_options={"backend": "static", "window_size": (200, 150)})
    v = w.viewer
    assert set(v.overlays) >= {"com", "zmp", "support"}
    bal = w.session.current.balance
    v.set_frame(10)
    assert np.allclose(v.overlay_points("com"), bal.com[10][None])
    poly = v.overlay_points("support")
    assert len(poly) >= 3 and np.allclose(poly[:, 1], 0.003)
    w.step_button.click()
    assert w.viewer_updates == 1
    now = w.session.current.balance.com[10]
    assert np.allclose(w.viewer.overlay_points("com"), now[None])
    # the drawn sphere moved with the step (not just the data behind it)
    assert np.allclose(np.asarray(w.viewer.overlays["com"].mesh.points).mean(axis=0), now, atol=1e-6)
    w.viewer.close()


# ------------------------------------------------------------ measures, reset, export, sync
@pytest.fixture(scope="module")
def jump(mocap_dir):
    from mocaplab import data
    from mocaplab.contacts import foot_contacts

    j = data.cmu("16_05").resample(30)
    return j, foot_contacts(j)


def _bold(text: str) -> list[float]:
    """The numbers shown in bold (a unit after the number is dropped)."""
    return [float(part.split("</b>")[0].split()[0]) for part in text.split("<b>")[1:]]


def test_header_shows_ground_and_flight_measures(jump, bent):
    j, contacts = jump
    w = TouchUpStepper(j, viewer=False, contacts=contacts, footplants="ik")
    assert "mocaplab-touchup-flight" in w.flight_label._dom_classes and w.flight_label.layout.display is None
    assert w.mean_label.value.startswith("mean ZMP distance over ground frames")
    # beside the whole, the mean without the end frames no step corrects
    cur = w.session.current
    assert f"{1000 * cur.mean_zmp_distance_interior:.2f} mm without the {cur.edge_frames} frames" in w.mean_label.value
    assert cur.mean_zmp_distance_interior != cur.mean_zmp_distance

    def shown() -> tuple[float, float, float]:
        (f,) = w.session.current.flights
        mean, g, spread = _bold(w.mean_label.value)[0], *_bold(w.flight_label.value)
        assert mean == pytest.approx(1000 * w.session.current.mean_zmp_distance, abs=0.006)
        assert g == pytest.approx(f.gravity, abs=0.006) and spread == pytest.approx(f.momentum_spread, abs=6e-4)
        return mean, g, spread

    before = shown()
    assert "input" in w.flight_label.value and "9.81" in w.flight_label.value
    assert w.session.current.next_adjustment.stage == "flight"
    w.step_button.click()  # a flight step: the flight measures change
    after = shown()
    assert after[1:] != before[1:] and w.status.value == ""
    w.back_button.click()
    assert shown() == before
    # a clip without flights: no flight line
    walk = TouchUpStepper(bent, viewer=False, footplants="ik")
    assert walk.session.current.flights == () and walk.flight_label.layout.display == "none"


def test_a_two_frame_flight_says_it_is_too_short_to_fit(jump):
    from mocaplab.contacts import Contacts
    from mocaplab.physics import flight_stages

    j, contacts = jump
    ((a, b),) = flight_stages(contacts)
    mask = np.array(contacts.mask, copy=True)
    mask[a + 2 : b] = mask[b]  # the flight ends after two frames
    short = Contacts(contacts.joints, mask, contacts.fps)
    with pytest.warns(UserWarning):  # the feet planted in the air slide
        w = TouchUpStepper(j, viewer=False, contacts=short, footplants="ik")
    (f,) = w.session.current.flights
    assert (f.stop - f.start, f.fitted) == (2, False)
    assert "fitted gravity <b>too short to fit (2 frames)</b> (input too short to fit (2 frames)" in w.flight_label.value
    assert "nan" not in w.flight_label.value


def test_adjustment_labels_are_escaped(bent):
    import dataclasses

    sk = bent.skeleton
    evil = "<b>LThumb</b>"
    m = bent.replace(skeleton=dataclasses.replace(sk, names=tuple(evil if n == "LThumb" else n for n in sk.names)))
    w = TouchUpStepper(m, viewer=False, footplants="ik")
    w.rows[1].s2.value = evil
    assert w.status.value == "" and w.session.schedule[1].s2 == (evil,)
    w.step_button.click()
    assert "&lt;b&gt;LThumb&lt;/b&gt;" in w.step_label.value and "<b>LThumb" not in w.step_label.value  # next: ...
    w.step_button.click()
    assert "&lt;b&gt;LThumb&lt;/b&gt;" in w.step_label.value and "<b>LThumb" not in w.step_label.value  # step 1: ...


def test_reset_goes_back_to_step_0_and_the_first_schedule(bent):
    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    first = w.session.schedule
    assert "mocaplab-reset" in w.reset_button._dom_classes and w.reset_button.disabled
    before = _mean_mm(w)
    w.step_button.click()
    w.step_button.click()
    w.rows[0].rho.value = 0.9  # an edit at step 2 applies from there on
    assert not w.reset_button.disabled
    w.reset_button.click()
    s = w.session
    assert s.index == 0 and s.schedule == first and w.rows[0].rho.value == first[0].rho
    assert w.back_button.disabled and w.reset_button.disabled and _mean_mm(w) == pytest.approx(before)
    assert np.allclose(w._line_now.get_ydata(), 1000 * s.input.zmp_distance, equal_nan=True)
    # an edit at step 0 is undone by reset too
    w.rows[1].sigma.value = 0.5
    w.reset_button.click()
    assert s.schedule == first and w.rows[1].sigma.value == round(first[1].sigma, 4)
    # with the schedule unchanged, the steps computed are kept
    w.step_button.click()
    computed = s.current
    w.reset_button.click()
    w.step_button.click()
    assert s.current is computed


def test_controls_follow_the_session_after_errors(bent, monkeypatch):
    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    w.rows[2].s2.value = "LeftWing"
    assert "LeftWing" in w.status.value and w.session.schedule[2].s2 == ("arms",)
    assert w.rows[2].s2.value == "arms"  # the box shows the schedule kept, not the name refused
    w.rows[0].stage.value = "flight"  # S3 must be empty in flight: refused, the row shows the session's stage
    assert "empty `s3`" in w.status.value
    assert w.rows[0].stage.value == w.session.schedule[0].stage == "ground"
    monkeypatch.setattr(w.session, "forward", lambda: (_ for _ in ()).throw(RuntimeError("<boom>")))
    w.step_button.click()
    assert "&lt;boom&gt;" in w.status.value and w.session.index == 0 and w.back_button.disabled


def test_export_writes_the_step_shown(bent, tmp_path):
    from mocaplab.io import load_bvh

    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    w.step_button.click()
    w.export.path.value = str(tmp_path / "touched.bvh")
    w.export.button.click()
    assert "mocaplab-export" in w.export.button._dom_classes and w.status.value == ""
    back = load_bvh(tmp_path / "touched.bvh", scale=0.01)  # save_bvh writes centimetres
    now, first = w.session.current.motion, w.session.input.motion
    assert np.abs(back.global_positions() - now.global_positions()).max() < 1e-3
    assert np.abs(back.global_positions() - first.global_positions()).max() > 2e-3


def test_plots_leave_room_for_the_toolbar(bent):
    pytest.importorskip("ipympl")
    from mocaplab.widgets._drag import TOOLBAR_PX

    w = TouchUpStepper(bent, viewer=False, footplants="ik")
    for plot in (w._plot8, w._plot9):
        assert plot.widget is plot.canvas  # the ipympl canvas, its toolbar over the left edge
        renderer = plot.figure.canvas.get_renderer()
        plot.figure.draw(renderer)
        ax = plot.figure.axes[0]
        assert ax.get_tightbbox(renderer).x0 >= TOOLBAR_PX  # one figure pixel per CSS pixel


@pytest.mark.filterwarnings("ignore:The motion path follows joint")
@pytest.mark.parametrize("convention", ["mixamo", "game_studio"])
def test_any_skeleton_and_roles(converted, convention):
    m, names = converted("16_15", convention, slice(0, 240))
    m = m.resample(30)
    w = TouchUpStepper(m, viewer=False, footplants="ik")
    assert w.session.current.roles["left_ankle"] == names["LeftFoot"]
    w.step_button.click()
    assert w.status.value == "" and w.session.index == 1 and np.isfinite(_mean_mm(w))
    head = names["Neck1"]
    v = TouchUpStepper(m, viewer=False, footplants="ik", roles={"head": head})
    assert v.session.current.roles["head"] == head
