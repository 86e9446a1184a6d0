"""The Laplacian space solver (eqs. 3-7, s4.2) and the time warp (eqs. 8-9, s4.4) on real CMU walks."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab.editing import (
    AbsoluteTime,
    Duration,
    PinDirection,
    PinPosition,
    Relative,
    SceneEditor,
    Sync,
    deformation_energy,
    edit,
)
from mocaplab.editing.flips import FLIP_RATE, detect_tangent_flips
from mocaplab.editing.paths import central_tangents, ground_angle, laplacian_coordinates, wrap_angle


@pytest.fixture(scope="module")
def walk(mocap_dir):
    from mocaplab import data

    return data.cmu("16_15").resample(30)


@pytest.fixture(scope="module")
def pair(mocap_dir):
    from mocaplab import data

    return [data.cmu("16_15").resample(30), data.cmu("16_11").resample(30).transformed(translation=[2.0, 0, 0])]


def ground(m):
    return m.root_positions[:, [0, 2]]


def test_pins_at_original_positions_are_the_identity(pair):
    a, b = pair
    cons = [
        PinPosition(0, 0, ground(a)[0], hard=True),
        PinPosition(0, 80, ground(a)[80]),
        PinPosition(1, 30, ground(b)[30]),
        AbsoluteTime(1, None, b.times[40], frames=(40, 75)),
        PinDirection(1, 50, central_tangents(ground(b))[50]),
        AbsoluteTime(0, 10, a.times[10], hard=True),
        Duration(1, 5, 60, b.times[60] - b.times[5]),
    ]
    res = edit(pair, cons)
    for k, m in enumerate(pair):
        np.testing.assert_allclose(res.paths[k], ground(m), atol=1e-6)
        np.testing.assert_allclose(res.times[k], m.times, atol=1e-6)
    assert res.shape_distortion < 1e-6
    assert res.energies.total < 1e-12


def test_no_constraint_is_the_identity(pair):
    res = edit(pair, [])
    for k, m in enumerate(pair):
        np.testing.assert_allclose(res.paths[k], ground(m), atol=1e-6)
        np.testing.assert_allclose(res.times[k], m.times, atol=1e-9)


def test_hard_constraints_hold_exactly_after_large_edits(pair):
    a, b = pair
    pa = ground(a)
    cons = [
        PinPosition(0, 0, pa[0] + [0.5, -0.2], hard=True),
        PinPosition(0, 100, pa[100] + [1.5, -1.0], hard=True),
        PinDirection(0, 60, 1.2, hard=True),
        Relative(1, 40, 0, 60, (0.3, 1.0), direction=(0.0, -1.0), hard=True),
        AbsoluteTime(0, 0, 0.5, hard=True),
        Duration(0, 10, 90, 4.0, hard=True),
        Sync(1, 40, 0, 60, offset=0.2, hard=True),
    ]
    res = edit(pair, cons)
    assert res.hard_residual_space < 1e-6
    assert res.hard_residual_time < 1e-6
    p0, p1 = res.paths
    np.testing.assert_allclose(p0[0], pa[0] + [0.5, -0.2], atol=1e-6)
    np.testing.assert_allclose(p0[100], pa[100] + [1.5, -1.0], atol=1e-6)
    t = central_tangents(p0)[60]
    assert ground_angle(t) == pytest.approx(1.2, abs=1e-6)
    assert res.times[0][0] == pytest.approx(0.5, abs=1e-6)
    assert res.times[0][90] - res.times[0][10] == pytest.approx(4.0, abs=1e-6)
    assert res.times[1][40] - res.times[0][60] == pytest.approx(0.2, abs=1e-6)
    assert max(res.residuals()[i] for i in range(len(cons))) < 1e-6


def test_soft_pin_translation_keeps_shape_exactly(walk):
    # one soft pin: a pure translation costs no Laplacian energy, so it is met exactly
    p = ground(walk)
    res = edit([walk], [PinPosition(0, 50, p[50] + [2.0, 1.0])])
    np.testing.assert_allclose(res.paths[0], p + [2.0, 1.0], atol=1e-6)


def test_shape_phase_scales_and_rotates_as_a_similarity(walk):
    # two pins: phase 1 alone moves the path by a similarity (eq. 3 is similarity invariant)
    p = ground(walk)
    F = len(p)
    target = p[0] + 0.6 * (p[-1] - p[0]) @ np.array([[0.0, 1.0], [-1.0, 0.0]])
    res = edit(
        [walk], [PinPosition(0, 0, p[0], hard=True), PinPosition(0, F - 1, target, hard=True)], scale_compensation=False
    )
    np.testing.assert_allclose(laplacian_coordinates(res.paths[0])[1:-1], laplacian_coordinates(p)[1:-1], atol=1e-6)
    assert res.length_change[0] == pytest.approx(-0.4, abs=1e-6)


def test_scale_compensation_evens_out_scaling(walk):
    # bend the path: keep its start and start direction, swing its end by 90 degrees.
    # Phase 1 alone stretches some segments and squeezes others; phase 2 (eq. 7)
    # brings every segment back towards its own length.
    p = ground(walk)
    F = len(p)
    d = p[-1] - p[0]
    rot = np.array([[0.0, 1.0], [-1.0, 0.0]])
    cons = [
        PinPosition(0, 0, p[0], hard=True),
        PinDirection(0, 0, d, hard=True),
        PinPosition(0, F - 1, p[0] + rot @ d, hard=True),
    ]
    shape_only = edit([walk], cons, scale_compensation=False)
    both = edit([walk], cons)
    assert both.hard_residual_space < 1e-9
    seg0 = np.linalg.norm(np.diff(p, axis=0), axis=1)
    ratio_shape = np.linalg.norm(np.diff(shape_only.paths[0], axis=0), axis=1) / seg0
    ratio_both = np.linalg.norm(np.diff(both.paths[0], axis=0), axis=1) / seg0
    assert np.abs(ratio_both - 1).mean() < 0.7 * np.abs(ratio_shape - 1).mean()
    assert np.ptp(ratio_both) < 0.5 * np.ptp(ratio_shape)
    np.testing.assert_allclose(both.shape_paths[0], shape_only.paths[0], atol=1e-9)


def test_unconstrained_character_keeps_its_path(pair):
    a, b = pair
    res = edit(pair, [PinPosition(0, 0, ground(a)[0] + [3.0, 1.0], hard=True), PinPosition(0, 90, ground(a)[90])])
    np.testing.assert_allclose(res.paths[1], ground(b), atol=1e-6)
    np.testing.assert_allclose(res.times[1], b.times, atol=1e-9)


def test_time_warp_follows_constraints_and_stays_uniform(walk):
    h = walk.dt
    res = edit([walk], [AbsoluteTime(0, 0, 1.0, hard=True), Duration(0, 0, 60, 3.0, hard=True)])
    t = res.times[0]
    assert t[0] == pytest.approx(1.0, abs=1e-9) and t[60] - t[0] == pytest.approx(3.0, abs=1e-9)
    dt = np.diff(t)
    np.testing.assert_allclose(dt[:60], 3.0 / 60, atol=1e-9)  # stretched uniformly
    np.testing.assert_allclose(dt[60:], h, atol=1e-9)  # the rest keeps its pace


@pytest.mark.parametrize("squeeze", [0.2, 0.05, 0.01])
def test_time_warp_is_strictly_increasing_and_bounded(walk, squeeze):
    # soft constraints asking for steps below h_min (and time flowing backwards)
    h = walk.dt
    cons = [AbsoluteTime(0, 20, 2.0), AbsoluteTime(0, 80, 2.0 + squeeze * 60 * h - 0.5)]
    ed = SceneEditor([walk], cons, min_step=0.25, max_step=4.0)
    res = ed.result
    dt = np.diff(res.times[0])
    assert np.all(dt > 0)
    assert dt.min() >= 0.25 * h * (1 - 1e-9)
    assert dt.max() <= 4.0 * h * (1 + 1e-9)
    assert res.min_time_step_ratio >= 0.25 - 1e-9
    assert res.active_steps  # the inserted equalities of section 4.4


def test_time_warp_slowdown_bounded(walk):
    h = walk.dt
    # 30 s: far beyond what 4x slower steps reach by frame 10, within TIME_REACH (10 scene durations)
    res = edit([walk], [AbsoluteTime(0, 0, 0.0, hard=True), AbsoluteTime(0, 10, 30.0)])
    dt = np.diff(res.times[0])
    assert dt.max() <= 4.0 * h * (1 + 1e-9) and np.all(dt > 0)


def test_relative_and_sync_between_two_walks(pair):
    a, b = pair
    cons = [
        PinPosition(0, 0, ground(a)[0], hard=True),
        PinPosition(0, 100, ground(a)[100] + [0.8, 0.4]),
        Relative(1, 60, 0, 80, (0.0, 1.0), direction=(-1.0, 0.0)),
        Sync(1, 60, 0, 80, weight=10.0),
        AbsoluteTime(0, 0, 0.0, hard=True),
    ]
    res = edit(pair, cons)
    p0, p1 = res.paths
    t0 = central_tangents(p0)[80]
    from mocaplab.editing.paths import rot90

    # equation 1 in metres on the edited path: 1 m to the left of the edited tangent (soft: about)
    u = t0 / np.linalg.norm(t0)
    d = p1[60] - p0[80]
    assert d @ rot90(u) == pytest.approx(1.0, abs=0.02)
    assert abs(d @ u) < 0.02
    # residuals() is that metric error (here: soft, so not zero), measured independently
    miss = np.linalg.norm(d - rot90(u))
    t1_ = central_tangents(p1)[60]
    chord = np.linalg.norm(t1_ / np.linalg.norm(t1_) + u)  # direction (-1, 0): facing the other way
    assert res.residuals()[2] == pytest.approx(max(miss, chord), rel=1e-6)
    t1 = central_tangents(p1)[60]
    assert t1 @ t0 / (np.linalg.norm(t1) * np.linalg.norm(t0)) < -0.99
    assert abs(res.times[1][60] - res.times[0][80]) < 1e-3


def test_stationary_segment_stays_rigid(mocap_dir):
    from mocaplab import data

    stop = data.cmu("16_34").resample(30)
    p = ground(stop)
    ed = SceneEditor([stop], [PinPosition(0, 0, p[0], hard=True), PinPosition(0, 40, p[40])])
    (seg,) = ed.segments[0]
    assert seg[1] == stop.n_frames
    res = ed.drag(1, p[40] + [1.0, 0.5])
    a, b = seg
    X, Y = p[a:b], res.paths[0][a:b]
    assert np.abs(Y - X).max() > 0.5  # it moved ...
    dx = np.linalg.norm(X[:, None] - X[None], axis=-1)
    dy = np.linalg.norm(Y[:, None] - Y[None], axis=-1)
    np.testing.assert_allclose(dy, dx, atol=1e-6)  # ... as a rigid body
    turn = res.heading_change[0][a:b]
    np.testing.assert_allclose(turn, turn[0], atol=1e-9)  # the standing character turns as one
    # without rigid segments the same drag deforms it
    free = edit([stop], ed.constraints, stationary=None)
    Z = free.paths[0][a:b]
    assert np.abs(np.linalg.norm(Z[:, None] - Z[None], axis=-1) - dx).max() > 1e-4


def _fold(n, F=120, noise=0.0, seed=0):
    """A swaying walk's tangents and a copy with ``n`` reversed frames in the middle."""
    rng = np.random.default_rng(seed)
    ang = 0.1 * np.sin(np.arange(F) / 6.0)
    t0 = 0.09 * np.c_[np.sin(ang), np.cos(ang)]
    t1 = t0 * (1.0 + 0.3 * np.sin(np.arange(F) / 4.0))[:, None]  # a deformation changes lengths
    s = F // 2 - n // 2
    t1[s : s + n] *= -1
    t1 += noise * 0.09 * rng.standard_normal(t1.shape)
    run = np.zeros(F, bool)
    run[s : s + n] = True
    return t0, t1, run


@pytest.mark.parametrize("n", range(1, 31))
def test_detect_tangent_flips_repairs_whole_folds(n):
    # Figure 4: a stretch of reversed tangents, 1 to 30 frames (up to the 1 s window at 30 fps)
    t0, t1, run = _fold(n)
    flips = detect_tangent_flips(t0, t1, fps=30.0)
    assert np.array_equal(flips, run), (np.flatnonzero(flips), np.flatnonzero(run))
    # with some noise on the deformed tangents: the whole fold, and at most a frame more on each side
    t0, t1, run = _fold(n, noise=0.05, seed=n)
    flips = detect_tangent_flips(t0, t1, fps=30.0)
    assert flips[run].all() and flips.sum() <= run.sum() + 2


def test_detect_tangent_flips_window_is_in_seconds():
    t0, t1, run = _fold(15)
    assert np.array_equal(detect_tangent_flips(t0, t1, fps=30.0, window=1.0), run)
    # a 0.3 s window does not pair the two jumps of a 0.5 s fold: only the frames at the jumps are flagged
    # (and around them until the repaired heading is smooth), not the whole fold
    short = detect_tangent_flips(t0, t1, fps=30.0, window=0.3)
    assert not short[run].all() and short.any()
    # the same fold at 120 fps lasts 60 frames: the 1 s window still pairs them
    t0, t1, run = _fold(60, F=480)
    assert np.array_equal(detect_tangent_flips(t0, t1, fps=120.0), run)


def test_detect_tangent_flips_leaves_real_turns_alone():
    t0 = np.tile([0.0, 1.0], (40, 1))
    assert not detect_tangent_flips(t0, t0, fps=30.0).any()
    # a smooth U-turn (legitimate) is not a flip
    ang = np.linspace(0, np.pi, 40)
    turn = np.c_[np.sin(ang), np.cos(ang)]
    assert not detect_tangent_flips(t0, turn, fps=30.0).any()
    with pytest.raises(ValueError, match="fps"):
        detect_tangent_flips(t0, t0, fps=0.0)
    with pytest.raises(ValueError, match=r"Expected `rate` > 0 degrees per second .* got -30"):
        detect_tangent_flips(t0, t0, fps=30.0, rate=-30.0)


@pytest.mark.parametrize("fps", [30.0, 60.0, 120.0])
@pytest.mark.parametrize("end", ["start", "end"])
def test_reversed_runs_reaching_an_end_are_flagged(fps, end):
    # the first or last 0.3 s turned round (a fold whose return lies beyond the clip): the whole run, at any rate
    F, n = int(4 * fps), int(0.3 * fps)
    t0, t1, _ = _fold(0, F=F)
    run = np.zeros(F, bool)
    run[:n] = end == "start"
    run[F - n :] = end == "end"
    t1[run] *= -1
    assert np.array_equal(detect_tangent_flips(t0, t1, fps=fps), run)
    # with a shorter window the run is not one reversed stretch: only frames around the jump, not the run
    far = detect_tangent_flips(t0, t1, fps=fps, window=0.2)
    assert far.any() and not far[run].all()


def test_flip_rate_is_per_second():
    # a fold that turns the tangent round over 0.1 s: 3 frames of 60 degrees at 30 fps, 12 of 15 at 120 fps;
    # a per-frame threshold of 30 degrees finds it at 30 fps only, the default rate at both
    for fps in (30.0, 120.0):
        F = int(2 * fps)
        t0 = np.tile([0.0, 0.05], (F, 1))
        turn = np.clip((np.arange(F) - fps) / (0.1 * fps), 0.0, 1.0) * np.pi  # 0 -> 180 degrees in 0.1 s
        t1 = 0.05 * np.c_[np.sin(turn), np.cos(turn)]
        t1[int(1.5 * fps) :] = t0[int(1.5 * fps) :]  # turned back 0.4 s later, at once
        found = detect_tangent_flips(t0, t1, fps=fps)
        assert found[int(1.1 * fps) : int(1.5 * fps)].all() and not found[: int(0.9 * fps)].any()
        per_frame = detect_tangent_flips(t0, t1, fps=fps, rate=30.0 * fps)  # 30 degrees per frame
        assert per_frame[int(1.05 * fps) : int(1.5 * fps)].all() == (fps == 30.0)
    assert FLIP_RATE == 900.0


@pytest.fixture(scope="module")
def blender_walk(mocap_dir):
    import warnings

    from mocaplab import load_bvh

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no unit in the file
        return load_bvh(mocap_dir / "realworld/bvhtoolbox/walk01.bvh")  # Blender export, 24 fps, 5.5 m straight


def _squeezed_headings(motion, fps, **options):
    w = motion.resample(fps)
    p = ground(w)
    F = len(p)
    cons = [PinPosition(0, 0, p[0], hard=True), PinPosition(0, F - 1, p[0] + 0.5 * (p[-1] - p[0]), hard=True)]
    res = edit([w], cons, **options)
    return np.arange(F) / fps, np.degrees(res.heading_change[0]), res.flips[0]


def test_a_squeezed_walk_does_not_turn_round_at_its_start_at_any_frame_rate(blender_walk):
    # squeezed to half its chord, the walk's first 0.3 s fold back: unrepaired, its heading starts 157 degrees
    # round and turns 80-86 degrees in the first 0.25 s; repaired, the heading change is held there
    grid = np.arange(0.0, 4.0, 1 / 30)
    headings = {}
    for fps in (30.0, 60.0, 120.0):
        t, hc, flips = _squeezed_headings(blender_walk, fps)
        assert flips[: int(0.25 * fps)].all()  # the reversed run that reaches the start
        k = int(0.25 * fps)
        assert abs(hc[k] - hc[0]) < 5 and abs(hc[-1] - hc[-1 - k]) < 10  # no turn over the ends
        assert np.abs(hc).max() < 20
        headings[fps] = np.interp(grid, t, hc)
        t_off, off, _ = _squeezed_headings(blender_walk, fps, flip_rate=None)
        assert abs(off[0] - off[-1]) > 150  # the unrepaired heading starts turned round
    # the same repaired headings at 30, 60 and 120 fps, within a few degrees
    assert np.abs(headings[60.0] - headings[30.0]).max() < 5
    assert np.abs(headings[120.0] - headings[30.0]).max() < 5


def test_flip_rate_option_is_checked_when_the_editor_is_made(walk):
    p = ground(walk)
    cons = [PinPosition(0, 0, p[0], hard=True)]
    with pytest.raises(ValueError, match=r"Expected `flip_rate` > 0 degrees per second"):
        edit([walk], cons, flip_rate=0.0)
    with pytest.raises(TypeError, match="flip_threshold"):
        edit([walk], cons, flip_threshold=0.5)  # radians per frame is gone: the option was renamed


def test_squeezing_16_15_to_a_tenth_leaves_no_heading_jump(walk):
    # squeezing a walk to 10% of its length folds its path many times over; after the repair
    # the heading turns by at most 30 degrees between frames (the default flip_rate, 900 degrees/s, at 30 fps)
    p = ground(walk)
    F = len(p)
    cons = [PinPosition(0, 0, p[0], hard=True), PinPosition(0, F - 1, p[0] + 0.1 * (p[-1] - p[0]), hard=True)]
    res = edit([walk], cons)
    t_new = central_tangents(res.paths[0])
    phi = wrap_angle(ground_angle(t_new) - ground_angle(res.original_paths[0].tangents))
    assert np.degrees(np.abs(wrap_angle(np.diff(phi)))).max() > 90  # the raw tangents flip
    assert np.degrees(np.abs(np.diff(res.heading_change[0]))).max() <= 30 + 1e-9
    from mocaplab import quat

    yaw = np.unwrap(quat.yaw(res.edited_motions[0].rotations[:, 0]))
    yaw0 = np.unwrap(quat.yaw(walk.rotations[:, 0]))
    assert np.degrees(np.abs(np.diff(yaw))).max() <= 30 + np.degrees(np.abs(np.diff(yaw0))).max()
    # the old detector (31-frame circular mean, 90 degrees) let the heading jump by 86 degrees here;
    # with the repair switched off the heading spins
    off = edit([walk], cons, flip_rate=None)
    assert np.degrees(np.abs(np.diff(off.heading_change[0]))).max() > 60


def test_tangent_flip_repaired_when_squeezing(walk):
    # Figure 4: squeezing a path makes its tangent flip; the heading must not spin round
    p = ground(walk)
    F = len(p)
    cons = [PinPosition(0, 0, p[0], hard=True), PinPosition(0, F - 1, p[-1] - 0.9 * (p[-1] - p[0]), hard=True)]
    res = edit([walk], cons)
    t_new = central_tangents(res.paths[0])
    phi = wrap_angle(ground_angle(t_new) - ground_angle(res.original_paths[0].tangents))
    assert np.abs(wrap_angle(np.diff(phi))).max() > np.pi / 2  # raw tangents flip
    assert res.flips[0].any()
    psi = np.diff(res.heading_change[0])
    assert np.abs(psi).max() < np.pi / 2  # repaired heading turns less than the threshold per frame
    # repaired tangents agree with the raw ones away from flips, where the walk moves steadily before and after
    # the squeeze (slower, the heading is blended at TURN_RATE: a slow tangent's direction is mostly sway)
    from mocaplab.editing.flips import STEADY_SPEED

    steady = np.minimum(np.linalg.norm(res.original_paths[0].tangents, axis=1), np.linalg.norm(t_new, axis=1))
    good = ~res.flips[0] & ~res.original_paths[0].degenerate & (steady >= 2 * STEADY_SPEED / walk.fps)
    cosang = np.einsum("ij,ij->i", res.tangents[0][good], t_new[good]) / np.linalg.norm(t_new[good], axis=1)
    np.testing.assert_allclose(cosang, 1.0, atol=1e-9)


def test_energy_terms(pair):
    a, _ = pair
    res0 = edit(pair, [PinPosition(0, 0, ground(a)[0])])
    assert deformation_energy(res0) == pytest.approx(0.0, abs=1e-9)
    res = edit(pair, [PinPosition(0, 0, ground(a)[0], hard=True), PinPosition(0, 100, ground(a)[100] + [1.0, 0.0])])
    e = res.energies
    assert e.shape > 0 and e.scale > 0 and e.time == pytest.approx(0.0, abs=1e-12)
    E = deformation_energy(res, cs=2.0, ct=1.0)
    length = res.original_paths[0].length
    assert E == pytest.approx(e.total + 2.0 * abs(res.length_change[0]) * length, rel=1e-9)


def test_u_shaped_drag_turns_smoothly(walk):
    # keep the middle ahead and bring the end back beside the start: a U, the heading turns ~180 degrees, no flips
    p = ground(walk)
    F = len(p)
    cons = [
        PinPosition(0, 0, p[0], hard=True),
        PinPosition(0, F // 2, p[0] + 0.5 * (p[-1] - p[0]) + [0.5, 0.0]),
        PinPosition(0, F - 1, p[0] + [1.0, 0.0], hard=True),
    ]
    res = edit([walk], cons)
    assert not res.flips[0].any()
    turn = res.heading_change[0]
    assert abs(abs(turn[-1] - turn[0]) - np.pi) < 0.6
    assert np.abs(np.diff(turn)).max() < np.pi / 4
    # where the walk moves steadily the heading follows the deformed tangent exactly (section 4.1)
    from mocaplab.editing.flips import STEADY_SPEED

    t_new = central_tangents(res.paths[0])
    steady = np.minimum(np.linalg.norm(res.original_paths[0].tangents, axis=1), np.linalg.norm(t_new, axis=1))
    good = steady >= 2 * STEADY_SPEED / walk.fps
    assert good.sum() > 0.5 * F
    cosang = np.einsum("ij,ij->i", res.tangents[0][good], t_new[good]) / np.linalg.norm(t_new[good], axis=1)
    np.testing.assert_allclose(cosang, 1.0, atol=1e-9)


def test_variational_constraints_are_sampled_every_tenth_frame(pair):
    a, b = pair
    cons = [
        PinPosition(0, 0, ground(a)[0], hard=True),
        PinPosition(0, 100, ground(a)[100] + [0.5, 0.5]),
        Relative(1, None, 0, None, (0.0, 1.0), frames=(20, 60), other_frames=(30, 70), weight=100.0),
        Sync(1, None, 0, None, frames=(20, 60), other_frames=(30, 70), hard=True),
    ]
    res = edit(pair, cons)
    assert res.hard_residual_time < 1e-6
    np.testing.assert_allclose(res.times[1][20:61:10], res.times[0][30:71:10], atol=1e-6)
    from mocaplab.editing.paths import rot90

    t0 = central_tangents(res.paths[0])
    for i in range(20, 61, 10):
        j = i + 10
        want = res.paths[0][j] + rot90(t0[j]) / np.linalg.norm(t0[j])  # 1 m to the left, in metres
        assert np.linalg.norm(res.paths[1][i] - want) < 0.02


# ------------------------------------------------------------ relative constraints in metres
@pytest.fixture(scope="module")
def tied(walk):
    """16_15 and a copy walking 0.8 m to its left."""
    from mocaplab.editing import MotionPath

    path = MotionPath.from_motion(walk)
    mid = walk.n_frames // 2
    n = path.normals[mid] / np.linalg.norm(path.normals[mid])
    return [walk, walk.transformed(translation=(0.8 * n[0], 0.0, 0.8 * n[1]))]


def squeezed(tied, factor, **rel):
    a = tied[0]
    p, F = ground(a), a.n_frames
    return [
        PinPosition(0, 0, p[0], hard=True),
        PinPosition(0, F - 1, p[0] + factor * (p[-1] - p[0]), hard=True),
        Relative(1, other=0, offset=(0.0, 0.8), frames=(30, F - 30), **rel),
    ]


@pytest.mark.parametrize("factor", [0.6, 0.8, 1.0, 1.5])
def test_relative_offsets_stay_metres_when_the_path_is_squeezed_or_stretched(tied, factor):
    cons = squeezed(tied, factor, hard=True)
    res = edit(tied, cons)
    frames = [s[0] for s in cons[2].samples(10)]
    gaps = np.linalg.norm(res.paths[1][frames] - res.paths[0][frames], axis=1)
    assert np.abs(gaps - 0.8).max() < 0.05 * 0.8  # the bound; in fact:
    assert np.abs(gaps - 0.8).max() < 1e-3
    assert res.residuals()[2] < 1e-3 and res.hard_residual_space < 1e-9
    # one solve: a hard relative's rows are those of eqs. 1-2, whose gap follows the tangent's stretch
    plain = edit(tied, cons, relative_iterations=1)
    off = np.abs(np.linalg.norm(plain.paths[1][frames] - plain.paths[0][frames], axis=1) - 0.8).max()
    if factor != 1.0:
        assert off > 0.1, "the linear form alone is off by more than 10 cm"
        assert plain.residuals()[2] == pytest.approx(off, rel=0.2), "and residuals() reports it in metres"
        assert any("still changing" in n for n in plain.notes)


def test_relative_angle_forms_face_the_right_way(tied):
    a = tied[0]
    p, F = ground(a), a.n_frames
    mid = F // 2
    for angle, want in ((0.0, 0.0), (np.pi / 2, 90.0), (np.pi, 180.0), (-np.pi / 2, -90.0)):
        cons = [
            PinPosition(0, 0, p[0], hard=True),
            PinPosition(0, F - 1, p[-1], hard=True),
            Relative(1, mid, 0, mid, (0.0, 0.8), direction=angle, hard=True),
        ]
        res = edit(tied, cons)
        ta, tb = central_tangents(res.paths[0])[mid], central_tangents(res.paths[1])[mid]
        got = np.degrees(wrap_angle(ground_angle(tb) - ground_angle(ta)))
        assert abs(wrap_angle(np.radians(got - want))) < 1e-6, (angle, got)


def test_relative_iteration_is_deterministic_and_the_editor_agrees(tied):
    # edit() starts the metric iteration from the linear rows: the same constraints give the same result;
    # the editor starts a drag from the previous update's corrections: both converge to relative_tolerance
    cons = squeezed(tied, 0.7, weight=5.0)
    ref = edit(tied, cons)
    again = edit(tied, cons)
    assert ref.relative_iterations > 1
    for k in (0, 1):
        np.testing.assert_array_equal(ref.paths[k], again.paths[k])
    ed = SceneEditor(tied, squeezed(tied, 1.0, weight=5.0))
    for f in np.linspace(1.0, 0.7, 7)[1:]:
        res = ed.drag(1, squeezed(tied, f, weight=5.0)[1].position)
    # both meet the metric targets to the tolerance (1 mm); a soft relative's lever (equation 1 scales
    # with the tangent) makes their positions differ a few times that
    tol = 1e-3
    assert ref.notes == () and res.notes == ()
    for k in (0, 1):
        np.testing.assert_allclose(res.paths[k], ref.paths[k], atol=10 * tol)
    assert res.relative_iterations <= ref.relative_iterations <= 4, "warm starts need no more solves"


def test_relative_iteration_stops_when_it_stops_improving(tied):
    # a soft relative offset far from anything reachable: the corrections no longer settle, the
    # iteration keeps its best iterate (a few solves, not relative_iterations) and says so
    a = tied[0]
    p, F = ground(a), a.n_frames
    cons = [
        PinPosition(0, 0, p[0], hard=True),
        PinPosition(0, F - 1, p[-1], hard=True),
        Relative(1, 40, 0, 40, (0.0, 25.0), weight=0.1),
    ]
    res = edit(tied, cons, relative_iterations=50)
    assert res.relative_iterations < 50
    assert np.all(np.isfinite(res.paths[1])) and np.abs(res.paths[1]).max() < 100.0


def test_hard_pins_are_met_or_raise_at_any_magnitude(walk):
    """A hard pin double precision cannot place near the scene raises instead of being silently missed (#17)."""
    import warnings

    from mocaplab.editing import ConstraintError

    F = walk.n_frames
    ed = SceneEditor([walk], [PinPosition(0, 0, (0.0, 0.0), hard=True), PinPosition(0, F - 1, (3.0, 1.0), hard=True)])
    before = np.array(ed.result.paths[0])
    raised = 0
    for far in 10.0 ** np.arange(3, 301, 3):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                path = np.asarray(ed.drag(1, (far, 1.0)).paths[0])
        except ConstraintError as err:
            raised += 1
            assert "out of numeric range" in str(err) and "scene 4" in str(err), str(err)
            assert err.indices and set(err.indices) <= {0, 1}
            continue
        # met: both pins hold to the scene's tolerance (never a silently violated hard pin)
        assert abs(path[-1, 0] - far) <= 1e-5 and abs(path[-1, 1] - 1.0) <= 1e-5 and np.abs(path[0]).max() <= 1e-5
    assert raised >= 10  # most magnitudes past ~1e12 m cannot be met
    ed.drag(1, (3.0, 1.0))
    np.testing.assert_allclose(np.array(ed.result.paths[0]), before, atol=1e-9)
    with pytest.raises(ConstraintError, match="out of numeric range"):
        ed.drag(1, (1e150, 1.0))
    np.testing.assert_allclose(np.array(ed.result.paths[0]), before, atol=1e-9)  # the editor kept its last good edit


def test_hard_times_far_away_raise(walk):
    from mocaplab.editing import ConstraintError

    ed = SceneEditor([walk], [AbsoluteTime(0, walk.n_frames - 1, 1.0, hard=True)])
    assert abs(ed.drag(0, 10.0).times[0][-1] - 10.0) < 1e-9
    for far in (1e15, 1e20, 1e100):
        with pytest.raises(ConstraintError, match="within .*TIME_REACH"):  # refused before any solve
            ed.drag(0, far)
    assert abs(ed.result.times[0][-1] - 10.0) < 1e-9, "a refused drag leaves the editor as it was"


def test_range_errors_name_the_dragged_target(walk):
    """A drag that keeps the structure reuses the factorisation; the error still names the constraint as dragged."""
    import warnings

    from mocaplab.editing import ConstraintError

    F = walk.n_frames
    ed = SceneEditor([walk], [PinPosition(0, 0, (0.0, 0.0), hard=True), PinPosition(0, F - 1, (3.0, 1.0), hard=True)])
    ed.drag(1, (3.5, 1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.raises(ConstraintError, match="out of numeric range") as err:
            ed.drag(1, (1e150, 1.0))
    text = str(err.value)
    assert 1 in err.value.indices
    assert "position=(1e+150, 1.0)" in text and "position=(3.0, 1.0)" not in text, text
    k = [c for c in err.value.constraints if not isinstance(c, str)][list(err.value.indices).index(1)]
    assert k.position == (1e150, 1.0)
    assert ed.constraints[1].position == (3.5, 1.0)  # the editor kept its last good edit


def _pinned_apart(tied, gap, *, hard):
    """Hard pins on both characters at frame 40, ``gap`` metres apart, and a Relative asking for 0.8 m."""
    a = ground(tied[0])
    n = ground(tied[1])[40] - a[40]
    n = n / np.linalg.norm(n)
    return [
        PinPosition(0, 40, a[40], hard=True),
        PinPosition(1, 40, a[40] + gap * n, hard=True),
        Relative(1, 40, 0, 40, (0.0, 0.8), hard=hard),
    ]


@pytest.mark.parametrize("gap", [1.5, 3.0])
def test_a_soft_relative_between_hard_pins_is_a_compromise_with_a_warning(tied, gap):
    from mocaplab.editing import RelativeConflictWarning

    cons = _pinned_apart(tied, gap, hard=False)
    with pytest.warns(RelativeConflictWarning, match=r"#2 is missed by .* hard constraints #0, #1"):
        res = edit(tied, cons)
    assert res.hard_residual_space < 1e-9
    # the pins hold, so the gap stays; the offset is missed by its difference from 0.8 m (a compromise)
    assert np.linalg.norm(res.paths[1][40] - res.paths[0][40]) == pytest.approx(gap, abs=1e-9)
    assert res.residuals()[2] == pytest.approx(gap - 0.8, abs=0.1)
    ((i, err, pins),) = res.conflicts
    assert (i, pins) == (2, (0, 1)) and err == pytest.approx(res.residuals()[2], rel=1e-6)
    # the relative met where the pins allow it: no conflict, no note
    fine = edit(tied, _pinned_apart(tied, 0.8, hard=False))
    assert fine.conflicts == () and fine.residuals()[2] < 1e-3


@pytest.mark.parametrize("gap", [1.5, 3.0])
def test_a_hard_relative_between_hard_pins_names_itself_and_the_pins(tied, gap):
    from mocaplab.editing import ConstraintError

    with pytest.raises(ConstraintError, match=r"hard relative constraint #2 Relative.* it fights #0 PinPosition") as err:
        edit(tied, _pinned_apart(tied, gap, hard=True))
    assert set(err.value.indices) == {0, 1, 2}
    assert "out of numeric range" not in str(err.value)


def _formation(walk, n, columns):
    """``n`` copies of ``walk`` in rows of ``columns`` (0.8 m apart, rows 1.2 m behind) following a leader.

    The leader: a hard pin on its first frame and a soft one on its last (index 1, the one dragged);
    every other character a hard first frame and soft Relatives (metres, where it is) to its left
    neighbour, or to the character ahead for a row's first, at three frames (issue 23, item 4).
    """
    from mocaplab.editing import MotionPath

    path = MotionPath.from_motion(walk)
    F = walk.n_frames
    t = path.tangents[0] / np.linalg.norm(path.tangents[0])
    left = np.array([-t[1], t[0]])
    chars = []
    for k in range(n):
        r, c = divmod(k, columns)
        d = 0.8 * c * left - 1.2 * r * t
        chars.append(walk.transformed(translation=[d[0], 0.0, d[1]]))
    paths = [MotionPath.from_motion(m) for m in chars]
    cons = [PinPosition(0, 0, paths[0].positions[0], hard=True), PinPosition(0, F - 1, paths[0].positions[-1])]
    for k in range(1, n):
        b = k - 1 if k % columns else k - columns
        cons.append(PinPosition(k, 0, paths[k].positions[0], hard=True))
        for f in (10, F // 2, F - 10):
            cons.append(Relative(k, f, b, f, paths[b].local_offset(f, paths[k].positions[f])))
    return chars, cons


def _swing(cons, a):
    """The leader's end pin moved ``a`` radians round a circle of 0.8 m (``a = 0``: where it is)."""
    return np.asarray(cons[1].position) + 0.8 * np.array([np.cos(a) - 1.0, np.sin(a)])


def test_a_formation_drag_settles_in_few_solves_whatever_the_drag_history(walk):
    """Twelve characters tied in rows by soft Relatives follow a dragged leader (issue 23, item 4)."""
    chars, cons = _formation(walk, 12, 4)
    ed = SceneEditor(chars, cons)
    solves = []
    for a in np.linspace(0.05, 0.6, 12):
        res = ed.drag(1, _swing(cons, a))
        solves.append(res.relative_iterations)
    rel = [i for i, c in enumerate(cons) if isinstance(c, Relative)]
    residuals = res.residuals()
    assert max(residuals[i] for i in rel) < 2e-3 and res.notes == ()
    assert np.median(solves) <= 2, solves
    scratch = edit(chars, list(ed.constraints))
    assert max(float(np.abs(p - q).max()) for p, q in zip(scratch.paths, res.paths, strict=True)) < 3e-3


@pytest.mark.filterwarnings("ignore::mocaplab.editing.PathJumpWarning")  # the swung leader kinks near its end
def test_a_deep_formation_settles_on_release_to_one_edit_whatever_the_drag_history(mocap_dir):
    """A column of 80 tied walkers swung far: the release settles every Relative, the same for any drags.

    The leader walks 16_17 then 16_11 (200 frames at 30 fps, the second clip turned and moved to continue
    the first, as bench_laplacian chains its walks).  Iterating both phases together on this chain (79
    links) stalled 6 to 8 cm from the metric targets, and two drag histories to the same end ended 9 cm
    apart (issue 23, items 4 and 8).
    """
    from mocaplab import data, quat
    from mocaplab.motion import concatenate

    first, second = (data.cmu(c).resample(30) for c in ("16_17", "16_11"))
    second = second.transformed(yaw=float(quat.yaw(first.rotations[-1, 0]) - quat.yaw(second.rotations[0, 0])))
    shift = 2 * first.root_positions[-1] - first.root_positions[-2] - second.root_positions[0]
    leader = concatenate([first, second.transformed(translation=[shift[0], 0.0, shift[2]])])[:200]
    chars, cons = _formation(leader, 80, 1)
    rel = [i for i, c in enumerate(cons) if isinstance(c, Relative)]
    histories = (np.linspace(0.05, 0.75, 15), [0.4, 0.9, 0.75])
    settled = []
    for angles in histories:
        ed = SceneEditor(chars, cons)
        for a in angles:
            dragged = ed.drag(1, _swing(cons, a))
        assert dragged.relative_iterations <= 2, "a drag makes at most relative_drag_iterations solves"
        ed.checkpoint()  # the mouse is released
        res = ed.result
        assert res.settled and res.notes == ()
        assert max(res.residuals()[i] for i in rel) < 1e-3, "settled: every Relative within 1 mm"
        settled.append(res)
        assert len(ed.undo_stack) == 2, "settling completes the gesture's undo step, it adds none"
    assert max(float(np.abs(p - q).max()) for p, q in zip(*(r.paths for r in settled), strict=True)) < 1e-3
    once = edit(chars, list(settled[0].constraints))
    for res in settled:
        for p, q in zip(res.paths, once.paths, strict=True):
            np.testing.assert_array_equal(p, q)  # the settled edit is edit()'s, whatever the drags
