"""Refinement without knee pops (issue 23 item 8): the goal layer's last step smooths the legs' kinks.

The exact IK pass of :func:`mocaplab.goals.enforce_goals` meets every foot
plant on every frame, and where a plant starts or ends its correction
changes velocity in one frame; ``goals._smooth_kinks`` moves that change out
of the held frames.  These tests compare ``enforce_goals`` with and without
that step on a real walk: fewer kinks, the same plants, hands untouched.
"""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import goals, quality
from mocaplab.contacts import foot_contacts
from mocaplab.displacement import rotation_displacement
from mocaplab.goals import EndEffector, effector_goals, enforce_goals, foot_goals, world_targets


@pytest.fixture(scope="module")
def clip(cmu):
    return cmu("16_15")[:480]  # a walk: heel strikes, toe-offs, near-straight stance knees


@pytest.fixture(scope="module")
def dance(cmu):
    return cmu("05_02")[:480]  # fast steps: the exact pass bends the stance knees 4x the input's acceleration


def _enforce(motion, gs, monkeypatch, *, smooth: bool):
    with monkeypatch.context() as mp:
        if not smooth:
            mp.setattr(goals, "_smooth_kinks", lambda motion, out, goals: out)
        return enforce_goals(motion, gs)


def _kink(motion, out, joint):
    """Peak second difference of a joint's correction, rad per frame^2."""
    d = rotation_displacement(motion.rotations, out.rotations)[:, motion.skeleton.index(joint)]
    return float(np.linalg.norm(np.diff(d, 2, axis=0), axis=-1).max())


def test_knee_corrections_lose_their_kinks(dance, monkeypatch):
    gs = foot_goals(dance, foot_contacts(dance))
    raw = _enforce(dance, gs, monkeypatch, smooth=False)
    out = _enforce(dance, gs, monkeypatch, smooth=True)
    knees = [dance.skeleton.roles[f"{side}_knee"] for side in ("left", "right")]
    for knee in knees:
        assert _kink(dance, out, knee) < 0.5 * _kink(dance, raw, knee), knee
    # the knees' peak angular acceleration is within the quality limit of refinement (2x the input's + 20)
    acc_in, acc_out = quality.angular_acceleration(dance), quality.angular_acceleration(out)
    for knee in knees:
        j = dance.skeleton.index(knee)
        assert acc_out[j] <= 2.0 * acc_in[j] + 20.0, (knee, acc_in[j], acc_out[j])


def test_held_plants_stay_where_the_exact_pass_put_them(clip, monkeypatch):
    gs = foot_goals(clip, foot_contacts(clip))
    raw = _enforce(clip, gs, monkeypatch, smooth=False)
    out = _enforce(clip, gs, monkeypatch, smooth=True)
    knee = clip.skeleton.roles["left_knee"]
    assert _kink(clip, out, knee) < 0.8 * _kink(clip, raw, knee)
    # frames a plant holds fully keep the exact pass's foot positions (within a millimetre)
    sk = clip.skeleton
    p_raw, p_out = raw.global_positions(), out.global_positions()
    for g in gs:
        held = g.weights >= 1.0
        j = sk.index(g.joint)
        assert held.any()
        moved = np.linalg.norm(p_out[held, j] - p_raw[held, j], axis=-1)
        assert moved.max() < 1e-3 and moved.mean() < 3e-4, (g.joint, moved.max(), moved.mean())


def test_end_effector_arms_and_unheld_joints_are_left_exact(clip, monkeypatch):
    n = clip.n_frames
    hand = clip.skeleton.roles["right_wrist"] if "right_wrist" in clip.skeleton.roles else "RightHand"
    target = clip.global_positions()[n // 2, clip.skeleton.index(hand)] + [0.1, 0.05, 0.0]
    ee = EndEffector(hand, (n // 2 - 5, n // 2 + 5), target)
    gs = foot_goals(clip, foot_contacts(clip)) + effector_goals(clip, [ee], [world_targets(ee, [clip])])
    raw = _enforce(clip, gs, monkeypatch, smooth=False)
    out = _enforce(clip, gs, monkeypatch, smooth=True)
    sk = clip.skeleton
    j = sk.index(hand)
    arm = []
    while j >= 0:
        arm.append(j)
        j = int(sk.parents[j])
    np.testing.assert_array_equal(out.rotations[:, arm], raw.rotations[:, arm])
    np.testing.assert_array_equal(out.root_positions, raw.root_positions)
    # the head is above no goal: untouched
    head = sk.index(sk.roles["head"]) if "head" in sk.roles else sk.index("Head")
    np.testing.assert_array_equal(out.rotations[:, head], raw.rotations[:, head])


def test_a_jittery_toe_does_not_shake_the_leg(cmu):
    # CMU 05_02's left toe jumps by up to 40 mm a frame about a still ankle (frames 150-180, toe planted, heel
    # up, ankle free); the foot solve used to carry the ankle rigidly with it, 52 mm in one frame, knee and hip
    # following
    dance = cmu("05_02")[:960]
    gs = foot_goals(dance, foot_contacts(dance))
    sk = dance.skeleton
    ankle, toe = sk.index("LeftFoot"), sk.index("LeftToeBase")
    solved = goals.solve_goals(dance, gs).global_positions()
    held = next(g for g in gs if g.joint == "LeftToeBase").weights >= 1.0
    assert held[150:181].all()
    assert (next(g for g in gs if g.joint == "LeftFoot").weights[150:181] == 0.0).all()
    step = np.linalg.norm(np.diff(solved[150:181, ankle], axis=0), axis=-1)
    jump = np.linalg.norm(np.diff(dance.global_positions()[150:181, toe], axis=0), axis=-1)
    assert jump.max() > 0.03  # the input's toe does jump
    assert step.max() < 0.025, step.max()  # 49 mm before; what is left follows the toe goal's jittery height
    # and the toe is still on its plant's spot on the ground (its height goal follows the jittery toe's own)
    target = next(g for g in gs if g.joint == "LeftToeBase").targets
    np.testing.assert_allclose(solved[150:181, toe][:, [0, 2]], target[150:181][:, [0, 2]], atol=6e-3)


def test_held_toes_drift_little_after_the_kink_smoothing(dance, monkeypatch):
    gs = foot_goals(dance, foot_contacts(dance))
    raw = _enforce(dance, gs, monkeypatch, smooth=False)
    out = _enforce(dance, gs, monkeypatch, smooth=True)
    sk = dance.skeleton
    for g in gs:
        if g.kind != "toe":
            continue
        j, held = sk.index(g.joint), g.weights >= 1.0
        off = np.linalg.norm(out.global_positions()[held, j] - raw.global_positions()[held, j], axis=-1)
        assert off.max() < 0.01, (g.joint, off.max())


def test_a_nearly_straight_knee_bends_about_its_hinge():
    # a knee 2 degrees from straight whose bend axis swings by 100 degrees over 11 frames (capture noise), asked
    # to bend to about 8 degrees: it bends in its hinge's plane, so the knee does not swing across with the axis
    from mocaplab import ik, quat

    n = 11
    hip, knee = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.55, 0.0])
    swing = np.radians(np.linspace(0.0, 100.0, n))
    axes = np.stack([np.sin(swing), np.zeros(n), -np.cos(swing)], axis=1)  # from -z toward +x
    tilt = ik._axis_angle(axes, np.full(n, -np.radians(2.0)))
    ankle = knee + quat.rotate(tilt, np.array([0.0, -0.45, 0.0]))
    hinge = np.array([0.0, 0.0, 1.0])
    target = hip + (ankle - hip) * 0.998
    q_up, q_mid = ik.two_bone_deltas(hip, knee, ankle, target, hinge=hinge)
    new_knee = hip + quat.rotate(q_up, knee - hip)
    new_ankle = new_knee + quat.rotate(quat.mul(q_up, q_mid), ankle - knee)
    np.testing.assert_allclose(new_ankle, target, atol=1e-9)
    bend = np.cross(hip - new_knee, new_ankle - new_knee)
    bend /= np.linalg.norm(bend, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(bend @ hinge, -1, 1))).max() < 10.0
    assert np.linalg.norm(np.diff(new_knee, axis=0), axis=1).max() < 2e-3


def test_pinned_frames_keep_their_values_and_the_rest_is_smoothed_around_them():
    # the staggered constraint layer pins the frames a goal holds fully: the smoother solves the others with those
    # fixed (the same normal equations, the pinned unknowns moved to the right-hand side)
    rng = np.random.default_rng(3)
    n, frames = 40, 6.0
    values = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    weights = 1.0 + 50.0 * rng.random(n)
    pinned = np.zeros(n, dtype=bool)
    pinned[10:18] = pinned[30] = True
    got = goals._whittaker(values, weights, frames, pinned)
    np.testing.assert_array_equal(got[pinned], values[pinned])
    # by hand: minimise sum W |x - v|^2 + lam |D2 x|^2 over the free frames, the pinned ones fixed
    d2 = np.diff(np.eye(n), 2, axis=0)
    a = np.diag(weights) + frames**4 / 16.0 * d2.T @ d2
    free = ~pinned
    want = np.linalg.solve(a[np.ix_(free, free)], weights[free, None] * values[free] - a[np.ix_(free, pinned)] @ values[pinned])
    np.testing.assert_allclose(got[free], want, rtol=1e-9, atol=1e-9)
    # without pins, the banded smoother moves every frame
    assert np.abs(goals._whittaker(values, weights, frames)[pinned] - values[pinned]).max() > 0.01


def _heel_strike_corrections(clip, contacts):
    gs = {g.joint: g for g in foot_goals(clip, contacts, reference=clip)}
    pos = clip.global_positions()
    out = []
    for joint in ("LeftFoot", "RightFoot"):
        j = clip.skeleton.index(joint)
        out += [np.linalg.norm(gs[joint].targets[a] - pos[a, j]) for a, b in contacts.intervals(joint) if a > 0]
    return np.array(out), gs


def test_a_planted_foot_rolls_onto_its_heel_and_off_its_toe_before_its_plant_holds(clip, monkeypatch):
    # CMU 16_15's ankle travels 58-77 mm over a contact interval, most of it rolling onto the heel after the
    # strike and off the toe before lifting.  Held at one spot over the whole interval, the ankle needed up to
    # 54 mm of correction faded in before heel strike; the plant now holds only while the joint is slower than
    # STILL_SPEED, and the goal rolls with the captured joint before and after
    contacts = foot_contacts(clip)
    rolled, gs = _heel_strike_corrections(clip, contacts)
    with monkeypatch.context() as mp:
        mp.setattr(goals, "STILL_SPEED", np.inf)  # the plant held over the whole interval
        held, _ = _heel_strike_corrections(clip, contacts)
    assert held.max() > 0.045 and rolled.max() < 0.04, (held, rolled)
    assert rolled.mean() < 0.6 * held.mean(), (held, rolled)
    # where the ankle rests the goal is one spot on the ground
    pos = clip.global_positions()
    speed = np.linalg.norm(np.gradient(pos, axis=0), axis=-1) * clip.fps
    for joint in ("LeftFoot", "RightFoot"):
        j = clip.skeleton.index(joint)
        for a, b in contacts.intervals(joint):
            still = np.flatnonzero(speed[a:b, j] < goals.STILL_SPEED) + a
            spot = gs[joint].targets[still[0] : still[-1] + 1][:, [0, 2]]
            assert np.ptp(spot, axis=0).max() < 1e-9, (joint, a)
    # refinement of the unedited clip keeps the knees' accelerations (was 110 -> 358 rad/s^2 at the left knee)
    out = enforce_goals(clip, list(gs.values()))
    acc_in, acc_out = quality.angular_acceleration(clip), quality.angular_acceleration(out)
    for knee in ("LeftLeg", "RightLeg"):
        j = clip.skeleton.index(knee)
        assert acc_out[j] <= 2.0 * acc_in[j] + 20.0, (knee, acc_in[j], acc_out[j])


def test_the_rolling_travel_turns_with_the_edit(clip, monkeypatch):
    # an edit that turns the whole clip by 90 degrees about +Y: the goals are the unedited clip's goals, turned
    # (on a level floor: on the capture's, inclined 0.3 degrees, the turned feet stand higher or lower)
    from mocaplab import Motion, quat

    monkeypatch.setattr(goals, "estimate_floor", lambda motion, contacts: None)

    turn = quat.from_yaw(np.pi / 2)
    turned = Motion(
        clip.skeleton,
        np.concatenate([quat.mul(turn, clip.rotations[:, :1]), clip.rotations[:, 1:]], axis=1),
        quat.rotate(turn, clip.root_positions),
        clip.fps,
    )
    contacts = foot_contacts(clip)
    plain = foot_goals(clip, contacts, reference=clip)
    edited = foot_goals(turned, contacts, reference=clip)
    for g0, g1 in zip(plain, edited, strict=True):
        np.testing.assert_allclose(g1.weights, g0.weights)
        np.testing.assert_allclose(g1.targets, quat.rotate(turn, g0.targets), atol=1e-9)
