"""The staggered constraint layer judged by :func:`mocaplab.quality.compare` (issue 25).

Cases, limits and why:

=====================  ======================  ===============================================
clip, edit             rows checked            reason
=====================  ======================  ===============================================
05_02, succession 0.01 displacement, angular    the input's knees are numerically straight at
                       acceleration, flips      the end: the bend axis there is rounding noise
49_03, succession 0.01 the same                 long dance, many contact spans: the root
                                                lowering must fade out past each span's end
16_05, 49_03 (0.02)    the same                 pass (a take-off, a landing)
salsa 60_10 (exag 0.3) the same                 passes
realworld/*/*.bvh      the same                 seven pass; one is a strict xfail with its
(succession 0.02)                               numbers and cause in ``_CASES`` (the
                                                edit's own, not the layer's)
=====================  ======================  ===============================================

Limits are quality's defaults: one-frame moves within 1.5x the input's + 2 mm,
angular accelerations within 2x + 20 rad/s^2, no new flipped hinge frame.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocaplab import Motion, Skeleton, ik, quality
from mocaplab.goals import Goal, solve_goals
from mocaplab.staggered import exaggerate, extract, succession


@pytest.mark.parametrize(("clip", "s"), [("05_02", 0.01), ("49_03", 0.01)])
def test_layer_adds_no_pops(cmu, clip, s):
    m = cmu(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = succession(extract(m, constraints=True), s).evaluate()
    report = quality.compare(m, out)
    for row in ("displacement", "angular_acceleration", "hinge_flips"):
        assert not report[row].regressed, report


_OPEN = "the layer still adds a pop here (issue 25 step 3, open): "
_EDIT = "not the layer (the edit without it does the same; issue 25, open): "
#: (clip or realworld file, edit, amount, None if within quality's default limits, else the measured reason)
_CASES = [
    # held since the layer smooths its per-frame solution where no goal holds fully (goals._smooth_kinks, the
    # held frames pinned): the take-off knee LeftLeg 656 -> 218 rad/s^2 (input 198), released over 0.1 s from
    # 110 mm behind the delayed leg; the landing toe's pull-in RightToeBase 47.9 -> 33.5 mm/frame (input 27.6)
    ("16_05", "succession", 0.02, None),
    ("49_03", "succession", 0.02, None),
    ("60_10", "exaggerate", 0.3, None),  # held since b836ba8 (goals: the toe's carry smoothed): lShin 247 vs 147
    ("test_freebvh.bvh", "succession", 0.02, None),  # held since b836ba8
    ("test_mocapbank.bvh", "succession", 0.02, None),
    # held since a succession tapers toward the clip's end (edit.SUCCESSION_TAPER): the 24 fps walk's left hand
    # ended on a one-frame segment, LeftHand 34.9 -> 9.6 rad/s^2 (input 6.1; not the layer: the edit alone)
    ("walk01.bvh", "succession", 0.02, None),
    # held since a correction grows and falls no faster than its joint's largest input speed (constraints.
    # _PULL_IN_SPEED): a 0.3 s toe touch at 30 fps whose toe the succession delays by 3-4 frames sweeps 33 cm past
    # its plant; holding it throughout pulled the leg: RightLeg 124.8 -> 97.4 mm/frame (input 67.8), worst LeftFoot 1.48x
    ("animation.bvh", "succession", 0.02, None),
    # held since quality.hinge_flips counts the bend's component about the hinge: across the input's own elbow jump
    # (18 -> 35 degrees in one frame, its axis 66-70 degrees off the hinge) the edit passes 20.6 degrees at 96 degrees
    # off, -2.2 degrees about the hinge: bent sideways by the capture's near-straight noise, not backwards
    ("test_optitrack.bvh", "succession", 0.02, None),
    # held since the flexion a goal adds leans onto the hinge (ik.two_bone_deltas): LeftKnee 718 -> 476 rad/s^2,
    # input 261 (the captured knee straightens through 11 degrees in two frames while the lowered root bends it)
    ("A_test.bvh", "succession", 0.02, None),
    ("bvh_test1.bvh", "succession", 0.02, _EDIT + "LeftHand 208.1 mm/frame against 105.2 (limit 159.8), a smooth "
     "6-frame bump with no rotation pop: delayed 0.02 s per level at 30 fps, the arm's rotations that kept the hand "
     "at 3 m/s in the capture no longer coincide and it whips at 6 m/s"),
    # held since the same smoothing: LeftLeg 1,207 -> 686 rad/s^2 (input 344, limit 708), RightLeg 955 -> 493 (304);
    # 453 and 288 since a target past a straight leg's reach takes its excess off the root lowering's allowance
    ("AV_8Walk_Meredith_HVHA_Rep1.bvh", "succession", 0.02, None),
]


def _case(clip, kind, amount, reason):
    marks = () if reason is None else (pytest.mark.xfail(strict=True, reason=reason),)
    return pytest.param(clip, kind, amount, marks=marks, id=f"{clip}-{kind}-{amount}")


@pytest.mark.parametrize(("clip", "kind", "amount"), [_case(*c) for c in _CASES])
def test_layer_adds_no_pops_on_more_clips(cmu, mocap_dir, clip, kind, amount):
    import mocaplab as ml

    if clip.endswith(".bvh"):
        found = sorted(mocap_dir.glob(f"realworld/*/{clip}"))
        assert found, clip
        m = ml.load(found[0])
    else:
        m = cmu(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sm = extract(m, constraints=True)
        out = (succession(sm, amount) if kind == "succession" else exaggerate(sm, amount)).evaluate()
    report = quality.compare(m, out)
    for row in ("displacement", "angular_acceleration", "hinge_flips"):
        assert not report[row].regressed, report


def test_layer_holds_its_plants_exactly_and_smooths_around_them(cmu):
    # the per-frame solution is smoothed where no goal holds fully (the broad jump's take-off knee: 656 rad/s^2,
    # input 198) and kept exactly where one does: the soft hold of the goal solver's exact pass left the planted
    # feet 1.7 mm off here
    m = cmu("16_05")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        edited = succession(extract(m, constraints=True), 0.02)
    out, free = edited.evaluate(), edited.evaluate(constraints=False)
    layer = edited.constraints
    w, targets = layer.weights_and_targets(edited, out.times)
    idx = [m.skeleton.index(n) for n in layer.joints]
    on = w == 1.0
    assert np.linalg.norm(free.global_positions()[:, idx] - targets, axis=-1)[on].max() > 0.1
    assert np.linalg.norm(out.global_positions()[:, idx] - targets, axis=-1)[on].max() < 1e-4
    knee = m.skeleton.index(m.skeleton.roles["left_knee"])
    assert quality.angular_acceleration(out)[knee] < 1.25 * quality.angular_acceleration(m)[knee]


def test_a_plant_the_edit_sweeps_past_is_pulled_in_no_faster_than_the_joint_moves(cmu):
    # the body carried 0.4 m sideways in 2 frames and back in 2 (6 m/s, the feet's largest input speed 3.5-3.8)
    # in mid-stance, as a delayed toe sweeps past its plant: the layer's correction of each foot grows and falls
    # at most at the foot's largest input speed (0.5 m/s at least); the weights are left alone away from the sweep
    m = cmu("16_15").resample(30)[:90]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sm = extract(m, constraints=True)
    free, layer = sm.evaluate(constraints=False), sm.constraints
    w0, targets = layer.weights_and_targets(sm, free.times)
    held = np.flatnonzero(np.all(w0[:, :2] == 1.0, axis=1))  # frames the left foot is held fully
    a = int(held[held >= 15][0])
    bump = np.zeros((m.n_frames, 3))
    bump[a : a + 6, 0] = [0.2, 0.4, 0.4, 0.4, 0.4, 0.2]
    swept = free.replace(root_positions=free.root_positions + bump)
    w, _ = layer.weights_and_targets(sm, free.times, motion=swept)
    idx = [m.skeleton.index(n) for n in layer.joints]
    size = w * np.linalg.norm(swept.global_positions()[:, idx] - targets, axis=-1)
    speed = np.maximum(layer.speeds.max(axis=0), 0.5)
    assert np.all(np.abs(np.diff(size, axis=0)) <= speed / m.fps + 1e-9)
    assert np.all(w <= w0) and w[a : a + 6, :2].min() < 0.75
    away = np.ones(m.n_frames, dtype=bool)
    away[a - 12 : a + 18] = False
    assert np.array_equal(w[away], w0[away])
    # the unedited motion is left alone (the layer is the identity there)
    assert np.array_equal(layer.weights_and_targets(sm, free.times, motion=free)[0], w0)


def _leg() -> Skeleton:
    return Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 0, 0], [0, -0.5, 0], [0, -0.5, 0]])


def test_hyperextended_knee_left_alone_at_zero_weight_and_carried_with_weight():
    # a knee bent 5 degrees against its hinge (+x), the target where the ankle is
    a, b = np.zeros(3), np.array([0.0, -0.5, 0.0])
    bend = np.radians(5.0)
    c = b + 0.5 * np.array([0.0, -np.cos(bend), -np.sin(bend)])  # bent about -x
    hinge = np.array([1.0, 0.0, 0.0])
    q_up0, q_mid0 = ik.two_bone_deltas(a, b, c, c, hinge=hinge, weight=0.0)
    np.testing.assert_allclose(q_mid0, [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(np.abs(q_up0[3]), 1.0, atol=1e-12)
    # weight 1: mirrored to the hinge's side (a 10 degree turn of the lower leg), distance kept
    _, q_mid1 = ik.two_bone_deltas(a, b, c, c, hinge=hinge, weight=1.0)
    assert np.degrees(2 * np.arccos(min(abs(q_mid1[3]), 1.0))) == pytest.approx(10.0, abs=1e-6)
    # in between, the turn grows with the weight (continuous, no jump at small weights)
    turns = [np.degrees(2 * np.arccos(min(abs(ik.two_bone_deltas(a, b, c, c, hinge=hinge, weight=w)[1][3]), 1.0)))
             for w in (0.01, 0.5, 0.99)]
    assert turns[0] < 0.5 and 4.0 < turns[1] < 6.0 and turns[2] > 9.5


def test_near_straight_solution_is_continuous():
    # bends of 1e-8 .. 1e-2 radians against the hinge: a target 2 cm closer gives nearly the same knee
    a, b = np.zeros(3), np.array([0.0, -0.5, 0.0])
    hinge = np.array([1.0, 0.0, 0.0])
    target = np.array([0.0, -0.98, 0.0])
    knees = []
    for eps in (1e-8, 1e-5, 1e-3, 1e-2):
        c = b + 0.5 * np.array([0.0, -np.cos(eps), -np.sin(eps)])
        q_up, q_mid = ik.two_bone_deltas(a, b, c, target, hinge=hinge)
        from mocaplab import quat

        knees.append(a + quat.rotate(q_up, b - a))
        end = a + quat.rotate(q_up, (b - a) + quat.rotate(q_mid, c - b))
        np.testing.assert_allclose(end, target, atol=5e-4)  # the blend near straight misses by < 0.5 mm
    knees = np.array(knees)
    assert np.ptp(knees, axis=0).max() < 0.01  # the same knee whichever side the start is bent to
    assert np.all(np.abs(knees[:, 2]) > 0.05)  # bent (on the hinge side, the same for every start)


def _solved_leg(hip, knee, ankle, target, hinge):
    """Knee and ankle positions after :func:`mocaplab.ik.two_bone_deltas` carries the ankle to ``target``."""
    from mocaplab import quat

    q_up, q_mid = ik.two_bone_deltas(hip, knee, ankle, target, hinge=hinge)
    new_knee = hip + quat.rotate(q_up, knee - hip)
    return new_knee, new_knee + quat.rotate(quat.mul(q_up, q_mid), ankle - knee)


def test_added_flexion_leans_onto_the_hinge_continuously():
    # a captured knee straightening from 30 to 1.5 degrees about its own axis, 40 degrees from the hinge about
    # the thigh, asked each frame for a 40-degree bend (perfume/A_test under a lowered root): the bend the goal
    # adds is about the hinge, so the bending direction reaches the hinge's plane gradually, where switching to
    # the hinge only inside the 3-11.5 degree band swung it by 36 degrees over two frames
    from mocaplab import quat

    bends = np.radians([30.0, 20.0, 12.0, 8.0, 5.0, 3.0, 1.5])
    n = bends.size
    hip, knee = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.55, 0.0])
    off = np.radians(40.0)
    own = np.array([np.cos(off), 0.0, np.sin(off)])
    ankle = knee + quat.rotate(ik._axis_angle(np.tile(own, (n, 1)), bends), np.array([0.0, -0.45, 0.0]))
    hinge = np.array([-1.0, 0.0, 0.0])  # a positive bend about `own` turns the lower leg about -own
    reach = 0.45 * np.sqrt(2.0 + 2.0 * np.cos(np.radians(40.0)))
    target = hip + reach * (ankle - hip) / np.linalg.norm(ankle - hip, axis=1, keepdims=True)
    new_knee, new_ankle = _solved_leg(hip, knee, ankle, target, hinge)
    np.testing.assert_allclose(new_ankle, target, atol=1e-9)
    axis = np.cross(hip - new_knee, new_ankle - new_knee)
    from_hinge = np.degrees(np.arccos(np.clip(axis @ hinge / np.linalg.norm(axis, axis=1), -1.0, 1.0)))
    assert 25.0 < from_hinge[0] < 35.0  # 10 of the 40 degrees added about the hinge: a quarter of the way over
    assert from_hinge[-1] < 1.0
    assert np.abs(np.diff(from_hinge)).max() < 12.0, from_hinge.round(1)  # the previous rule: 23 degrees in a frame


def test_zero_weight_legs_are_left_exactly_as_they_were():
    sk = _leg()
    n = 5
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (n, 3, 1))
    bend = np.radians(4.0)
    rot[:, 1] = [np.sin(bend / 2), 0.0, 0.0, np.cos(bend / 2)]  # a knee bent 4 degrees against the hinge +x
    m = Motion(sk, rot, np.zeros((n, 3)), 30)
    target = m.global_positions()[:, 2]
    w = np.array([0.0, 0.0, 0.5, 1.0, 0.0])
    out = solve_goals(m, [Goal("ankle", target, w, kind="foot")], adjust_root=False, hinges={"ankle": [1.0, 0, 0]})
    free = w == 0
    np.testing.assert_array_equal(out.rotations[free], m.rotations[free])
    assert not np.allclose(out.rotations[3], m.rotations[3])  # held with weight 1: carried to the hinge side


def test_a_target_past_a_straight_legs_reach_is_not_met_at_its_current_straightness():
    # a leg bent 2 degrees whose held ankle goes 1 cm past its full length: the root comes down by the excess
    # twice over, so the leg ends 1 cm shorter than it was instead of exactly as straight (where a knee near
    # straight turns the peak of a held leg's reach into a kink)
    sk = _leg()
    n = 10
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (n, 3, 1))
    bend = np.radians(2.0)
    rot[:, 1] = [np.sin(bend / 2), 0.0, 0.0, np.cos(bend / 2)]
    m = Motion(sk, rot, np.tile([0.0, 1.0, 0.0], (n, 1)), 30)
    pos = m.global_positions()
    ankle = pos[:, 2] + [0.0, -0.01, 0.0]
    out = solve_goals(m, [Goal("ankle", ankle, np.ones(n), kind="foot")], reach=0.96)
    now = out.global_positions()
    np.testing.assert_allclose(now[:, 2], ankle, atol=1e-6)
    before = np.linalg.norm(pos[:, 2] - pos[:, 0], axis=-1)
    after = np.linalg.norm(now[:, 2] - now[:, 0], axis=-1)
    assert np.all(after < before - 0.009)


def test_max_reach_lowers_the_root_under_a_leg_held_nearly_straight():
    # a leg bent 2 degrees, held where its ankle is: left alone by default, lowered to max_reach when capped
    sk = _leg()
    n = 40
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (n, 3, 1))
    bend = np.radians(2.0)
    rot[:, 1] = [np.sin(bend / 2), 0.0, 0.0, np.cos(bend / 2)]
    m = Motion(sk, rot, np.tile([0.0, 1.0, 0.0], (n, 1)), 30)
    ankle = m.global_positions()[:, 2]
    goal = Goal("ankle", ankle, np.ones(n), kind="foot")
    free = solve_goals(m, [goal], reach=0.96)
    np.testing.assert_allclose(free.root_positions, m.root_positions, atol=1e-12)
    capped = solve_goals(m, [goal], reach=0.96, max_reach=0.99)
    pos = capped.global_positions()
    assert np.linalg.norm(pos[:, 2] - pos[:, 0], axis=-1).max() <= 0.99 * 1.0 + 1e-9
    np.testing.assert_allclose(pos[:, 2], ankle, atol=1e-6)  # the ankle still held
    assert np.all(capped.root_positions[:, 1] < 1.0 - 0.009)  # lowered, not pushed sideways


@pytest.mark.parametrize("w_r", [0.5, 1.0])
def test_an_exaggeration_keeps_knees_and_elbows_bending_their_own_way(cmu, monkeypatch, w_r):
    # 05_02's right elbow folds 131-135 degrees on frames 373-391, its average pose 35: exaggerated by 0.5 it
    # went past 180 degrees and bent the other way on 19 frames; a hinge's change is shortened there instead
    import mocaplab.staggered.edit as edit

    m = cmu("05_02")
    roles = m.skeleton.roles
    arms = [roles[f"{side}_{part}"] for side in ("left", "right") for part in ("shoulder", "elbow")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sm = extract(m)
        kept = exaggerate(sm, w_r, joints=arms, reference="average")
        monkeypatch.setattr(edit, "_keep_hinges", lambda sm, pos, rot, new_rot: new_rot)
        asked = exaggerate(sm, w_r, joints=arms, reference="average")
    axes = quality.hinge_axes(m)
    assert quality.hinge_flips(asked.evaluate(), axes)["right_elbow"] > 10  # what the guard prevents
    assert not any(quality.hinge_flips(kept.evaluate(), axes).values())
    elbows = [m.skeleton.index(roles[f"{side}_elbow"]) for side in ("left", "right")]
    others = np.setdiff1d(np.arange(m.skeleton.n_joints), elbows)
    np.testing.assert_array_equal(kept.rotation_values[:, others], asked.rotation_values[:, others])
    changed = np.any(kept.rotation_values[:, elbows] != asked.rotation_values[:, elbows], axis=(1, 2))
    assert 0 < changed.sum() < sm.n_poses  # only where a fold passes the limit
    poses = [kept.pose_motion(k, which="non-staggered").global_positions()[0] for k in range(sm.n_poses)]
    g = np.array(poses)
    for side in ("left", "right"):  # the kept poses fold at most to the limit (the input's most is 135)
        u, mid, lo = (m.skeleton.index(roles[f"{side}_{p}"]) for p in ("shoulder", "elbow", "wrist"))
        a, b = g[:, u] - g[:, mid], g[:, lo] - g[:, mid]
        cos = np.einsum("fi,fi->f", a, b) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
        assert 180.0 - np.degrees(np.arccos(np.clip(cos, -1, 1))).min() <= edit.HINGE_FOLD_LIMIT + 1e-3
