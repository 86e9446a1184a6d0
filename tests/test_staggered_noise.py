"""Filtering rotations before timing edits (Coleman 2008, section 6): the filter, the noise layer, jitter."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.staggered import StaggeredTimingWarning, delete_pose, edit_pose, extract, insert_pose, retime, succession
from mocaplab.staggered.noise import filter_mask, jitter, orientation_filter


def angle(a, b):
    return quat.angle(quat.mul(quat.inv(a), b))


def test_filter_is_lee_shin_on_angular_displacements(rng: np.random.Generator) -> None:
    """H(q)_i = q_i exp(sum_k a_k log(q_i^-1 q_{i+k})), to first order in the displacements."""
    F = 80
    q = quat.exp(np.cumsum(rng.normal(scale=0.01, size=(F, 2, 3)), axis=0))
    out = orientation_filter(q, 0.03, 120.0)
    a = filter_mask(0.03, 120.0)
    n = (a.size - 1) // 2
    assert np.isclose(a.sum(), 1.0) and a.argmax() == n
    direct = np.empty_like(q)
    for i in range(F):
        rel = quat.log(quat.mul(quat.inv(q[i]), q[np.clip(i + np.arange(-n, n + 1), 0, F - 1)]))
        direct[i] = quat.mul(q[i], quat.exp(np.einsum("k,kjc->jc", a, rel)))
    moved = angle(q, out).max()
    assert angle(direct, out).max() < 0.05 * moved
    assert np.allclose(np.linalg.norm(out, axis=-1), 1.0)
    assert np.all(np.sum(out * q, axis=-1) > 0)  # the inputs' hemispheres


def test_filter_keeps_constants_and_slow_turns_and_removes_buzz() -> None:
    still = np.tile(quat.from_axis_angle([0, 1, 0], 0.4), (30, 3, 1))
    assert np.array_equal(orientation_filter(still, 0.03, 120.0), still)
    t = np.arange(240) / 120.0
    turn = quat.from_axis_angle([0, 0, 1], 0.8 * t)
    buzz = quat.from_axis_angle([0, 0, 1], 0.8 * t + 0.02 * np.sin(2 * np.pi * 30 * t))
    inner = slice(20, -20)
    assert angle(orientation_filter(turn, 0.03, 120.0), turn)[inner].max() < 1e-9  # linear in angle: kept
    assert angle(orientation_filter(buzz, 0.03, 120.0), turn)[inner].max() < 0.002  # 30 Hz: gone
    assert np.array_equal(orientation_filter(buzz, 0.0, 120.0), buzz)
    with pytest.raises(ValueError, match="sigma"):
        orientation_filter(buzz, -1.0, 120.0)
    with pytest.raises(ValueError, match="rotations"):
        orientation_filter(np.zeros((4, 3)), 0.03, 120.0)


def test_noise_layer_reproduces_the_clip(cmu) -> None:
    walk = cmu("16_15")
    sm = extract(walk)
    assert sm.rotation_noise is not None and sm.noise_u is not None
    assert sm.rotation_noise.shape == (walk.n_frames, walk.n_joints, 3)
    assert angle(sm.evaluate().rotations, walk.rotations).max() < 1e-9
    # the other layers carry the filtered clip
    smooth = orientation_filter(walk.rotations, 0.03, walk.fps)
    assert angle(sm.evaluate(noise=False).rotations, smooth).max() < 1e-9
    # still joints have no noise, so they stay skipped by evaluation
    st = sm.static_joints()
    assert st.any() and np.all(sm.rotation_noise[:, st] == 0.0)
    # off: no layer, and the extreme values are the capture's own
    raw = extract(walk, filter_sigma=None)
    assert raw.rotation_noise is None and raw.noise_u is None
    assert angle(raw.evaluate().rotations, walk.rotations).max() < 1e-9


def test_noise_follows_the_poses_not_the_refinements(cmu) -> None:
    walk = cmu("16_15")
    sm = extract(walk)
    t = walk.times
    n0 = sm.noise_values(t)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        late = succession(sm, 0.03, 2.0)
        moved = retime(sm, 5, float(sm.times[5] + 0.05))
    assert np.array_equal(late.noise_values(t), n0)  # refinements leave it alone
    # a retimed pose carries its noise: the sample of the pose's frame plays at the new pose time
    f = int(round(sm.times[5] * walk.fps))
    assert np.allclose(moved.noise_values([moved.times[5]])[0], n0[f], atol=1e-12)
    # inserting or deleting poses keeps it in place (and the motion, see test_staggered_edit)
    T = sm.knot_times
    ins = insert_pose(sm, float(0.5 * (T[4].max() + T[5].min())))
    assert np.allclose(ins.noise_values(t), n0, atol=1e-12)
    assert np.allclose(delete_pose(sm, 4).noise_values(t), n0, atol=1e-12)


def test_editing_the_true_pose_includes_the_noise(cmu) -> None:
    walk = cmu("16_15")
    sm = extract(walk, max_poses=10)
    k = 4
    _, rot = sm.true_pose(k)
    f = int(round(sm.times[k] * walk.fps))
    assert angle(rot, walk.rotations[f]).max() < 1e-9  # the true pose is the capture at t_k
    target = np.array(rot)
    j = walk.skeleton.index(walk.skeleton.roles["left_shoulder"])
    target[j] = quat.mul(rot[j], quat.from_axis_angle([0, 0, 1], 0.3))
    out = edit_pose(sm, k, rotations=target, which="true")
    assert angle(out.true_pose(k)[1], target).max() < 1e-9


def test_timing_edits_do_not_amplify_capture_noise(cmu) -> None:
    """Section 6: whole-body succession (s = 0.03, l = 2) on the walk keeps the head within 1.5x its jitter."""
    walk = cmu("16_15")
    head = walk.skeleton.roles["head"]
    before = jitter(walk, head)
    assert 0.3e-3 < before < 0.8e-3  # about half a millimetre of capture noise
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        filtered = jitter(succession(extract(walk), 0.03, 2.0).evaluate(), head)
        unfiltered = jitter(succession(extract(walk, filter_sigma=None), 0.03, 2.0).evaluate(), head)
    assert filtered < 1.5 * before
    assert unfiltered > 3.0 * before  # without the filter the decorrelated noise shows
