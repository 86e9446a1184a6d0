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
    root[1:, [0, 2]] = root[0, [0, 2]] + np.cumsum(quat.rotate(q[:-1], np.diff(root, axis=0) * [1, 0, 1])[:, [0, 2]], axis=0)
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
