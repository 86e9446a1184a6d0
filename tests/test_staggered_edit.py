"""Editing staggered poses (Coleman 2008, section 5): geometric and timing edits, constraints, editor."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocaplab import quality, quat
from mocaplab.staggered import (
    StaggeredEditor,
    StaggeredTimingWarning,
    delete_pose,
    edit_pose,
    exaggerate,
    extract,
    insert_pose,
    randomize,
    retime,
    succession,
    succession_depths,
)
from mocaplab.staggered.edit import average_pose, keep_knot_order


def angle(a, b):
    return quat.angle(quat.mul(quat.inv(a), b))


def max_diff(a, b) -> tuple[float, float]:
    return float(angle(a.rotations, b.rotations).max()), float(np.abs(a.root_positions - b.root_positions).max())


@pytest.fixture(scope="module")
def walk_sm(mocap_dir):
    from mocaplab import data

    walk = data.cmu("16_15")
    return walk, extract(walk, max_poses=14, optimize=False)


def test_zero_succession_and_no_value_change_return_the_original(walk_sm) -> None:
    walk, sm = walk_sm
    same = exaggerate(randomize(succession(sm, 0.0, 2.0), 0.0), 0.0)
    rot, pos = max_diff(same.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    assert np.array_equal(same.refinements, sm.refinements)
    assert succession(sm, 0.0) is sm


def test_an_edit_gives_its_motion_as_every_result_does(walk_sm) -> None:
    _, sm = walk_sm
    edited = succession(sm, 0.02)
    assert edited.motion is edited.motion  # computed once
    assert np.array_equal(edited.motion.rotations, edited.evaluate().rotations)
    assert not np.array_equal(edited.motion.rotations, sm.motion.rotations)


@pytest.mark.parametrize(
    "name", ["retime", "succession", "randomize", "edit_pose", "exaggerate", "insert_pose", "delete_pose"]
)
def test_the_edits_are_functions_and_the_old_methods_say_what_to_write(walk_sm, name) -> None:
    from mocaplab import staggered

    _, sm = walk_sm
    with pytest.raises(AttributeError, match=rf"StaggeredMotion\.{name} is gone.* write mocaplab\.staggered\.{name}\(sm, "):
        getattr(sm, name)
    assert not hasattr(sm, name)
    assert callable(getattr(staggered, name)) and getattr(staggered, name).__module__ == "mocaplab.staggered.edit"
    with pytest.raises(AttributeError, match="has no attribute 'no_such_edit'"):
        sm.no_such_edit  # noqa: B018 (other names fail as usual)


def test_succession_depths_below_a_joint(cmu) -> None:
    sk = cmu("16_15").skeleton
    d = succession_depths(sk, "LeftArm")
    names = ("root_position",) + sk.names
    assert d[names.index("LeftArm")] == 0 and d[names.index("LeftForeArm")] == 1
    assert d[names.index("LeftHand")] == 2
    assert np.isnan(d[names.index("RightArm")]) and np.isnan(d[0])
    full = succession_depths(sk)
    assert full[0] == 0 and full[1] == 0 and np.all(np.isfinite(full))
    both = succession_depths(sk, ["LeftArm", "RightArm"])
    assert both[names.index("RightHand")] == 2


def test_nonlinear_succession_offsets(walk_sm) -> None:
    _, sm = walk_sm
    s, l = 0.003, 2.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        out = succession(sm, s, l, joint="RightArm")
    d = succession_depths(sm.skeleton, "RightArm")
    dr = out.refinements - sm.refinements
    moved = np.isfinite(d)
    interior = slice(1, -1)
    assert np.allclose(dr[interior][:, moved], s * d[moved] ** l, atol=1e-12)
    assert np.all(dr[:, ~moved] == 0.0) and np.all(dr[[0, -1]] == 0.0)


def test_large_succession_warns_and_keeps_knots_ordered(walk_sm) -> None:
    _, sm = walk_sm
    with pytest.warns(StaggeredTimingWarning, match="closer to a neighbouring pose"):
        out = succession(sm, 0.05, 2.0)
    T = out.times[:, None] + out.refinements
    assert np.all(np.diff(T, axis=0) > 0)
    assert out.evaluate().n_frames == sm.n_frames


@pytest.mark.parametrize(("trial", "moved", "knee"), [("16_15", 6.64, 29.3), ("49_03", 9.20, 6.56)])
def test_strong_succession_keeps_a_third_of_every_segment(cmu, trial: str, moved: float, knee: float) -> None:
    """Issue 25: s = 0.03, l = 2 (within the explorer's sliders) no longer presses the last segments into a frame.

    Pushed knots stop a third of their poses' gap before their neighbour
    (they stopped one frame short): the worst joint's largest one-frame move
    and the knees' peak angular acceleration, as ratios to the input's, were
    ``moved`` and ``knee``.
    """
    clip = cmu(trial)
    sm = extract(clip)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        out = succession(sm, 0.03, 2.0)
    gaps = np.diff(out.knot_times, axis=0)
    assert np.all(gaps >= np.minimum(np.diff(sm.times)[:, None] / 3.0, np.diff(sm.knot_times, axis=0)) - 1e-9)
    move = quality.displacement(out.motion) / np.maximum(quality.displacement(clip), 1e-9)
    knees = [clip.skeleton.index(clip.skeleton.roles[r]) for r in ("left_knee", "right_knee")]
    acc = quality.angular_acceleration(out.motion)[knees].max() / quality.angular_acceleration(clip)[knees].max()
    assert move.max() < 2.5 < moved
    assert acc < 2.0 < knee


@pytest.mark.parametrize("s", [0.03, -0.03])
def test_succession_tapers_toward_the_end_it_moves_knots_to(walk_sm, s: float) -> None:
    """Issue 25: the last pose anchors the end a delay moves knots toward (the first, a lead): within
    SUCCESSION_TAPER offsets of it a knot moves by a third of the time left, so every segment keeps two thirds
    of its length there (pushed against the anchor and stopped by keep_knot_order, the arm's kept 0.22 and 0.26)."""
    from mocaplab.staggered.edit import SUCCESSION_TAPER

    _, sm = walk_sm
    out = succession(sm, s, 2.0, joint="LeftShoulder")
    ratio = np.diff(out.knot_times, axis=0) / np.diff(sm.knot_times, axis=0)
    assert ratio.min() > 2.0 / 3.0 - 1e-9
    d = succession_depths(sm.skeleton, "LeftShoulder")
    offset = np.where(np.isfinite(d), s * np.nan_to_num(d) ** 2, 0.0)
    anchor = sm.knot_times[-1] if s > 0 else sm.knot_times[0]
    # the arm down to the hand (offsets up to 0.27 s, less than any pose gap): full offsets away from the anchor
    far = (np.abs(anchor - sm.knot_times) >= SUCCESSION_TAPER * np.abs(offset)) & (np.nan_to_num(d) <= 3)
    far[[0, -1]] = False
    moved = out.refinements - sm.refinements
    assert np.allclose(moved[far], np.broadcast_to(offset, moved.shape)[far])
    assert (far & (offset != 0)).sum() >= 0.6 * ((d >= 1) & (d <= 3)).sum() * (sm.n_poses - 2)


def test_keep_knot_order_never_separates_knots_the_edit_left_alone(walk_sm) -> None:
    """A pair of knots already nearer than a third of their poses' gap stays as it is when the edit does not move it."""
    _, sm = walk_sm
    r = np.array(sm.refinements)
    j = 5
    r[2, j] = 0.45 * (sm.times[3] - sm.times[2])  # pose 2's knot near pose 3's
    r[3, j] = -0.45 * (sm.times[3] - sm.times[2])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        close = sm.with_refinements(r)
    assert np.array_equal(keep_knot_order(close, r), np.where(close.active, r, 0.0))
    pushed = np.array(r)
    pushed[2, j] += 0.2  # now past pose 3's knot: stopped at the pair's former gap, not pushed further
    T = sm.times + keep_knot_order(close, pushed)[:, j]
    assert T[3] - T[2] == pytest.approx(0.1 * (sm.times[3] - sm.times[2]))


def test_crossing_knots_are_rejected(walk_sm) -> None:
    _, sm = walk_sm
    r = np.array(sm.refinements)
    r[1, 5] = sm.times[3] - sm.times[1]
    with pytest.raises(ValueError, match="out of order"):
        sm.with_refinements(r)
    fixed = keep_knot_order(sm, r)
    T = sm.times[:, None] + fixed
    assert np.all(np.diff(T, axis=0) >= 1.0 / sm.fps - 1e-12)


def test_random_timing_is_seeded_bounded_and_selective(walk_sm) -> None:
    _, sm = walk_sm
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        a = randomize(sm, 0.03, joints=["LeftArm", "LeftForeArm"], seed=7)
        b = randomize(sm, 0.03, joints=["LeftArm", "LeftForeArm"], seed=7)
        c = randomize(sm, 0.03, joints=["LeftArm", "LeftForeArm"], seed=8)
    assert np.array_equal(a.refinements, b.refinements) and not np.array_equal(a.refinements, c.refinements)
    dr = a.refinements - sm.refinements
    cols = [sm.variable_index("LeftArm"), sm.variable_index("LeftForeArm")]
    assert np.abs(dr).max() <= 0.03 + 1e-12 and np.abs(dr[1:-1][:, cols]).max() > 0
    others = np.delete(dr, cols, axis=1)
    assert np.all(others == 0.0)


def test_random_timing_per_limb(walk_sm) -> None:
    """by="limb": one offset per pose and limb (the legs, the arms, the trunk), shared down the limb."""
    from mocaplab.staggered import limb_groups
    from mocaplab.staggered.edit import LIMBS

    walk, sm = walk_sm
    sk, roles = walk.skeleton, walk.skeleton.roles
    group = limb_groups(sk)
    name = {v: LIMBS[g] for v, g in zip(sm.variables, group, strict=True)}
    assert name["root_position"] == name[roles["pelvis"]] == name[roles["head"]] == "trunk"
    assert name[roles["left_ankle"]] == name[roles["left_toe"]] == name[roles["left_hip"]] == "left_leg"
    assert name[roles["right_wrist"]] == name[roles["right_clavicle"]] == "right_arm"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        tau = 0.004  # small: no knot is stopped short by a neighbour, every offset shows whole
        limb = randomize(sm, tau, seed=3, by="limb")
        per_var = randomize(sm, tau, seed=3)
    d = (limb.refinements - sm.refinements)[1:-1]
    moving = ~np.all(sm.rotation_values == sm.rotation_values[:1], axis=(0, 2))  # still joints change nothing
    for g in range(len(LIMBS)):
        cols = np.flatnonzero((group == g) & np.r_[False, moving])
        assert np.allclose(d[:, cols], d[:, cols[:1]]), LIMBS[g]  # one offset for the whole limb
    arms = [np.flatnonzero(group == LIMBS.index(a))[1] for a in ("left_arm", "right_arm")]
    assert not np.allclose(d[:, arms[0]], d[:, arms[1]])  # limbs differ: asymmetric timing
    dv = (per_var.refinements - sm.refinements)[1:-1]
    leg = np.flatnonzero(group == LIMBS.index("left_leg"))
    assert np.ptp(dv[:, leg], axis=1).max() > 0  # per variable, a limb's joints differ
    assert np.abs(d).max() <= tau + 1e-12
    with pytest.raises(ValueError, match="by"):
        randomize(sm, 0.01, by="joint")  # type: ignore[arg-type]


def test_retime_moves_the_pose_and_its_knots(walk_sm) -> None:
    walk, sm = walk_sm
    k = 5
    shift = 3 / walk.fps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        out = retime(sm, k, float(sm.times[k] + shift))
    assert out.times[k] == pytest.approx(sm.times[k] + shift)
    # the refined knot values are reached at the shifted knot times (the noise layer aside)
    m = out.evaluate(noise=False)
    j = sm.variable_index("RightLeg")
    f = int(round((sm.times[k] + sm.refinements[k, j] + shift) * walk.fps))
    assert angle(m.rotations[f, j - 1], sm.rotation_values[k, j - 1]) < 1e-9
    # far from the pose nothing changes
    far = (walk.times < sm.times[k - 1] - 0.3) | (walk.times > sm.times[k + 1] + 0.3)
    assert angle(out.evaluate().rotations[far], walk.rotations[far]).max() < 1e-9
    with pytest.raises(ValueError, match="strictly between"):
        retime(sm, k, float(sm.times[k + 1] + 0.01))
    with pytest.raises(ValueError, match="first pose"):
        retime(sm, 0, 0.1)


def test_editing_the_true_pose(walk_sm) -> None:
    walk, sm = walk_sm
    k = 6
    root, rot = sm.true_pose(k)
    target = np.array(rot)
    j = walk.skeleton.index("LeftArm")
    turn = quat.from_axis_angle([0, 0, 1], 0.3)
    target[j] = quat.mul(rot[j], turn)
    out = edit_pose(sm, k, rotations=target, root_position=root + [0.0, 0.04, 0.0], which="true")
    new_root, new_rot = out.true_pose(k)
    assert angle(new_rot, target).max() < 1e-9
    assert np.allclose(new_root, root + [0.0, 0.04, 0.0], atol=1e-12)
    # the extreme knot received an equal change (Figure 6a)
    assert np.allclose(out.root_values[k] - sm.root_values[k], [0.0, 0.04, 0.0])
    change = angle(sm.rotation_values[k, j], out.rotation_values[k, j])
    assert change == pytest.approx(0.3, abs=1e-9)
    # the edit stays between the neighbouring knots
    T = sm.knot_times
    m = out.evaluate()
    outside = (walk.times < T[k - 1].min()) | (walk.times > T[k + 1].max())
    assert max(angle(m.rotations[outside], walk.rotations[outside]).max(), 0) < 1e-9


def test_a_true_pose_edit_ramps_over_the_pose_interval(cmu) -> None:
    """Section 5.1: turning the right arm 20 degrees in any true pose of the walk adds no short large acceleration.

    Judged by :func:`mocaplab.quality.angular_acceleration` of the edited joint
    between the neighbouring poses, against the input's there.  When a
    variable's knots could sit 42 ms apart (poses 2 and 3 of 16_15) the edit
    ramped back in 5 frames: 3.3 times the input's local acceleration.
    """
    walk = cmu("16_15")
    sm = extract(walk)
    j = walk.skeleton.index(walk.skeleton.roles["right_shoulder"])
    turn = quat.from_axis_angle([0, 0, 1], np.radians(20.0))
    ratios = []
    for k in range(1, sm.n_poses - 1):
        _, rot = sm.true_pose(k)
        target = np.array(rot)
        target[j] = quat.mul(rot[j], turn)
        out = edit_pose(sm, k, rotations=target, which="true").motion
        assert angle(out.rotations[int(round(sm.times[k] * walk.fps)), j], target[j]) < 1e-9  # the edit holds
        window = slice(int(round(sm.times[k - 1] * walk.fps)), int(round(sm.times[k + 1] * walk.fps)) + 1)
        before = quality.angular_acceleration(walk[window])[j]
        ratios.append(quality.angular_acceleration(out[window])[j] / before)
    assert max(ratios) < 1.5, np.round(ratios, 2)


def test_editing_the_non_staggered_pose_offsets_the_editing_knot(walk_sm) -> None:
    walk, sm = walk_sm
    k = 6
    j = walk.skeleton.index("LeftForeArm")
    assert sm.refinements[k, j + 1] != 0.0  # this knot has an editing knot
    new = quat.mul(sm.rotation_values[k, j], quat.from_axis_angle([1, 0, 0], 0.2))
    out = edit_pose(sm, k, rotations={"LeftForeArm": new})
    assert angle(out.non_staggered_pose(k)[1][j], new) < 1e-12
    before = sm.true_pose(k)[1][j]
    after = out.true_pose(k)[1][j]
    assert angle(before, after) == pytest.approx(0.2, abs=1e-6)
    others = np.delete(np.arange(walk.n_joints), j)
    assert angle(out.rotation_values[:, others], sm.rotation_values[:, others]).max() < 1e-12


def test_edit_offsets_blend_with_the_one_ramp(walk_sm) -> None:
    """Section 5.1's change of a knot fades to the neighbour's by displacement.blend_ramp (C2, no acceleration jump)."""
    from mocaplab.displacement import blend_ramp

    walk, _ = walk_sm
    # no refinements: the editing knots are the extreme knots, the ramp spans whole segments
    flat = extract(walk, max_poses=14, max_refinement=0.0, optimize=False)
    k, j = 6, walk.skeleton.index("LeftArm")
    turn = quat.from_axis_angle([0, 0, 1], 0.3)
    out = edit_pose(flat, k, rotations={"LeftArm": quat.mul(flat.rotation_values[k, j], turn)})
    t = walk.times[(walk.times > flat.times[k]) & (walk.times < flat.times[k + 1])]
    k0, k1, tn = flat.locate(t)
    s_old = flat.spline_values(k0, k1, tn)[1][:, j]
    d_old = quat.exp(flat.displacement_values(k0 + tn * (k1 - k0))[1][:, j])
    new = out.evaluate(t, noise=False).rotations[:, j]
    offset = quat.mul(quat.mul(quat.inv(s_old), new), quat.inv(d_old))  # new = s (+) offset (+) d
    x = tn[:, j + 1]
    assert np.allclose(quat.angle(offset), 0.3 * (1.0 - blend_ramp(x)), atol=1e-9)


def test_relative_exaggeration(walk_sm) -> None:
    walk, sm = walk_sm
    arms = ["LeftArm", "RightArm"]
    idx = [walk.skeleton.index(n) for n in arms]
    ref = 3
    toward = exaggerate(sm, -1.0, reference=ref, joints=arms)
    assert angle(toward.rotation_values[:, idx], sm.rotation_values[ref, idx][None]).max() < 1e-9
    # w_r = 1 doubles the angle from the average pose (geodesic extrapolation)
    _, mean = average_pose(sm)
    out = exaggerate(sm, 1.0, joints=arms)
    a0 = angle(mean[idx][None], sm.rotation_values[:, idx])
    a1 = angle(mean[idx][None], out.rotation_values[:, idx])
    assert np.allclose(a1, np.minimum(2 * a0, 2 * np.pi - 2 * a0), atol=1e-9)
    # the true-pose variant reaches its targets
    true_out = exaggerate(sm, 0.5, joints=arms, poses=[4], which="true", reference="previous")
    r_prev = sm.true_pose(3)[1]
    r_k = sm.true_pose(4)[1]
    expected = quat.mul(r_k, quat.exp(0.5 * quat.log(quat.mul(quat.inv(r_prev), r_k))))
    assert angle(true_out.true_pose(4)[1][idx], expected[idx]).max() < 1e-9
    with pytest.raises(ValueError, match="reference"):
        exaggerate(sm, 0.5, reference="median")  # type: ignore[arg-type]


def test_average_pose_ignores_quaternion_signs(walk_sm) -> None:
    _, sm = walk_sm
    flipped = np.array(sm.rotation_values)
    flipped[::2] *= -1
    import dataclasses

    other = dataclasses.replace(sm, rotation_values=flipped)
    assert angle(average_pose(sm)[1], average_pose(other)[1]).max() < 1e-9


def test_insert_and_delete_poses_keep_the_motion(walk_sm) -> None:
    walk, sm = walk_sm
    k = 4
    T = sm.knot_times
    t_new = float(0.5 * (T[k].max() + T[k + 1].min()))
    ins = insert_pose(sm, t_new)
    assert ins.n_poses == sm.n_poses + 1 and np.isclose(ins.times[k + 1], t_new)
    rot, pos = max_diff(ins.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    dele = delete_pose(sm, k)
    assert dele.n_poses == sm.n_poses - 1
    rot, pos = max_diff(dele.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    with pytest.raises(ValueError, match="interior"):
        delete_pose(sm, 0)
    with pytest.raises(ValueError, match="not on a pose"):
        insert_pose(sm, float(sm.times[3]))


def test_partial_pose_controls_a_subset(walk_sm) -> None:
    walk, sm = walk_sm
    k = 4
    T = sm.knot_times
    t_new = float(0.5 * (T[k].max() + T[k + 1].min()))
    part = insert_pose(sm, t_new, joints=["LeftArm", "LeftForeArm"])
    row = part.active[k + 1]
    assert row.sum() == 2 and row[part.variable_index("LeftArm")]
    rot, pos = max_diff(part.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    # timing and value edits work on it; uncontrolled variables are not refined there
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        moved = succession(part, 0.02, 1.0, joint="LeftArm")
    assert np.all(moved.refinements[k + 1][~row] == 0.0)
    assert moved.evaluate().n_frames == walk.n_frames


def test_constraint_layer_keeps_planted_feet(cmu) -> None:
    walk = cmu("16_15")
    sm = extract(walk, max_poses=14, optimize=False, constraints=True)
    roles = walk.skeleton.roles
    # the feet of the joint roles: each ankle (two-bone leg IK) and its toe (the foot turns about the ankle)
    assert sm.constraints is not None and sm.constraints.joints == roles.foot_joints()
    assert sm.constraints.kinds == ("foot", "toe", "foot", "toe")
    rot, pos = max_diff(sm.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    # lower the hips at a pose during a right-foot contact
    e = sm.constraints.joints.index(roles["right_ankle"])
    planted = sm.constraints.masks[:, e]
    k = int(np.argmax(planted[np.round(sm.times * walk.fps).astype(int)]))
    edited = edit_pose(sm, k, root_position=sm.root_values[k] + [0.0, -0.05, 0.0])
    for name in (roles["right_ankle"], roles["right_toe"]):
        j = walk.skeleton.index(name)
        free = edited.evaluate(constraints=False).global_positions()[:, j]
        held = edited.evaluate().global_positions()[:, j]
        orig = walk.global_positions()[:, j]
        assert np.linalg.norm(free - orig, axis=-1)[planted].max() > 0.02
        assert np.linalg.norm(held - orig, axis=-1)[planted].max() < 1e-4


def test_constraint_layer_holds_the_whole_foot(cmu) -> None:
    """Timing and leg edits turn the feet: the toes stay planted with the ankles, the stiller joint wins."""
    import dataclasses

    walk = cmu("16_15")
    sm = extract(walk, max_poses=14, optimize=False, constraints=True)
    layer = sm.constraints
    legs = [walk.skeleton.roles[f"{s}_{p}"] for s in ("left", "right") for p in ("hip", "knee", "ankle")]
    edited = exaggerate(sm, 0.5, joints=legs)
    out, free = edited.evaluate(), edited.evaluate(constraints=False)
    w, targets = layer.weights_and_targets(edited, out.times)
    idx = [walk.skeleton.index(n) for n in layer.joints]
    on = w == 1.0

    def error(m):
        return np.linalg.norm(m.global_positions()[:, idx] - targets, axis=-1)

    assert error(free)[on].max() > 0.1  # the edit moves every planted joint
    assert error(out)[on].max() < 0.003  # ankles and toes stay (within the ankle/toe compromise)
    # goals get the stiffness 1 / (speed + 0.05) of foot_goals: without it the ankles give way more
    assert np.allclose(layer.speeds, walk.joint_speeds()[:, idx])
    uniform = dataclasses.replace(edited, constraints=dataclasses.replace(layer, speeds=np.zeros_like(layer.speeds)))
    ankles = [layer.joints.index(walk.skeleton.roles[f"{s}_ankle"]) for s in ("left", "right")]
    held, even = error(out)[:, ankles], error(uniform.evaluate())[:, ankles]
    assert held[on[:, ankles]].mean() < 0.8 * even[on[:, ankles]].mean()
    with pytest.raises(ValueError, match="ankles, toes"):
        type(layer).from_contacts(walk, sm_contacts(walk), sm.times, joints=[walk.skeleton.roles["head"]])


def _knee_flexion(m, hinges, legs) -> np.ndarray:
    """Signed knee flexion (degrees) about the input's hinges, shape (F, 2): negative bends backwards."""
    g, p = m.global_rotations(), m.global_positions()
    out = []
    for (u, k, a), h in zip(legs, hinges, strict=True):
        thigh, shank = p[:, u] - p[:, k], p[:, a] - p[:, k]
        axis = quat.rotate(g[:, k], h)
        out.append(
            np.degrees(np.arctan2(np.einsum("ij,ij->i", np.cross(thigh, shank), axis), -np.sum(thigh * shank, -1)))
        )
    return np.stack(out, axis=1)


def _peak_acceleration(deg: np.ndarray, fps: float) -> float:
    return float(np.abs(np.diff(np.radians(deg), 2, axis=0)).max() * fps**2)


@pytest.fixture(scope="module")
def walk_layer(mocap_dir):
    from mocaplab import data
    from mocaplab.ik import hinge_axes, limb_joints

    walk = data.cmu("16_15")
    sm = extract(walk, constraints=True)
    legs = [limb_joints(walk.skeleton, walk.skeleton.roles[f"{s}_ankle"]) for s in ("left", "right")]
    return walk, sm, legs, hinge_axes(walk.global_rotations(), walk.global_positions(), legs)


def test_constraint_layer_keeps_the_input_knee_bend(walk_layer) -> None:
    """Exaggerated legs (w_r = 0.5) straighten the knees; the layer never bends one backwards, nor snaps it."""
    walk, sm, legs, hinges = walk_layer
    layer = sm.constraints
    assert layer.hinges is not None and np.allclose(layer.hinges[[0, 2]], hinges)  # measured on the input
    roles = walk.skeleton.roles
    edited = exaggerate(sm, 0.5, joints=[roles[f"{s}_{p}"] for s in ("left", "right") for p in ("hip", "knee", "ankle")])
    before = _knee_flexion(walk, hinges, legs)
    free = _knee_flexion(edited.evaluate(constraints=False), hinges, legs)
    held = _knee_flexion(edited.evaluate(), hinges, legs)
    assert before.min() > 10.0 and free.min() < 5.0  # the edit straightens the knees
    assert held.min() > 0.0
    assert _peak_acceleration(held, walk.fps) < 3.0 * _peak_acceleration(free, walk.fps)
    # the hinge of the input, not of the edited frames: a leg solved on hyperextended frames bends forward
    from mocaplab.goals import Goal, solve_goals

    ankle = roles["left_ankle"]
    j = walk.skeleton.index(ankle)
    bent_back = walk[100:140]
    rot = np.array(bent_back.rotations)
    knee = legs[0][1]
    rot[:, knee] = quat.mul(rot[:, knee], quat.from_axis_angle(hinges[0], np.radians(before[100:140, 0] + 5.0)))
    bent_back = bent_back.replace(rotations=rot)  # every frame 5 degrees backwards
    assert _knee_flexion(bent_back, hinges, legs)[:, 0].max() < 0
    target = bent_back.global_positions()[:, j] + [0.0, 0.05, 0.0]  # lift the ankle 5 cm: the knee must bend
    goal = [Goal(ankle, target, np.ones(40), kind="foot")]
    own = solve_goals(bent_back, goal, adjust_root=False)
    given = solve_goals(bent_back, goal, adjust_root=False, hinges={ankle: hinges[0]})
    assert _knee_flexion(own, hinges, legs)[:, 0].max() < 0  # estimated on these frames: further backwards
    assert _knee_flexion(given, hinges, legs)[:, 0].min() > 0
    with pytest.raises(ValueError, match="hinge"):
        solve_goals(bent_back, goal, hinges={ankle: np.zeros(2)})


def test_constraint_layer_does_not_fight_succession(walk_layer) -> None:
    """Whole-body succession delays the legs; holding the plants adds little knee acceleration (root lowered)."""
    import dataclasses

    walk, sm, legs, hinges = walk_layer
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)  # sparse poses: some knots pass halfway
        edited = succession(sm, 0.01, 1.0)
    free = _peak_acceleration(_knee_flexion(edited.evaluate(constraints=False), hinges, legs), walk.fps)
    held = _peak_acceleration(_knee_flexion(edited.evaluate(), hinges, legs), walk.fps)
    assert held < 2.0 * free
    # with the root held, the push-off legs snap straight and back
    stiff = dataclasses.replace(edited, constraints=dataclasses.replace(sm.constraints, adjust_root=False))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        snapped = _peak_acceleration(_knee_flexion(stiff.evaluate(), hinges, legs), walk.fps)
    assert snapped > 5.0 * free


def test_unreachable_targets_warn_with_their_frames(walk_layer) -> None:
    import dataclasses

    from mocaplab.staggered import UnreachableTargetWarning

    walk, sm, _, _ = walk_layer
    k = 8
    raised = edit_pose(sm, k, root_position=sm.root_values[k] + [0.0, 0.15, 0.0])
    stiff = dataclasses.replace(raised, constraints=dataclasses.replace(sm.constraints, adjust_root=False))
    with pytest.warns(UnreachableTargetWarning, match=r"out of reach on frames \d+-\d+") as caught:
        out = stiff.evaluate()
    frames = [int(x) for x in str(caught[0].message).split("frames ")[1].split(" ")[0].rstrip(",").split("-")]
    w, tg = sm.constraints.weights_and_targets(stiff, out.times)
    idx = [walk.skeleton.index(n) for n in sm.constraints.joints]
    miss = np.linalg.norm(out.global_positions()[:, idx] - tg, axis=-1)
    assert miss[frames[0] : frames[1] + 1].max() > 0.05  # the named frames are where the feet leave their plants
    # by default the root comes down instead: the plants hold, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnreachableTargetWarning)
        held = raised.evaluate()
    on = w == 1.0
    assert np.linalg.norm(held.global_positions()[:, idx] - tg, axis=-1)[on].max() < 0.003


@pytest.mark.filterwarnings("ignore::mocaplab.staggered.StaggeredTimingWarning")
def test_constraint_layer_follows_pose_edits_and_structure(walk_layer) -> None:
    walk, sm, _, _ = walk_layer
    roles = walk.skeleton.roles
    edited = exaggerate(sm, 0.5, joints=[roles[f"{s}_{p}"] for s in ("left", "right") for p in ("hip", "knee")])
    out = edited.evaluate()
    # inserting or deleting a pose leaves the layer where it was in time: the motion is unchanged
    T = edited.knot_times
    ins = insert_pose(edited, float(0.5 * (T[4].max() + T[5].min())))
    assert max_diff(ins.evaluate(), out)[0] < 1e-6
    assert np.allclose(ins.constraints.frame_times(ins), sm.constraints.frame_times(sm))
    # retiming a pose carries its contacts; a variable's timing carries them with its knots
    layer = sm.constraints
    moved = retime(sm, 6, float(sm.times[6] + 0.02))
    f = int(round(sm.times[6] * walk.fps))
    assert np.allclose(layer.frame_times(moved)[f], moved.times[6])
    import dataclasses

    own = dataclasses.replace(layer, timing=layer.joints)  # each foot joint's own refinements
    late = succession(sm, 0.01, 1.0)
    e = layer.joints.index(roles["left_ankle"])
    i = sm.variable_index(roles["left_ankle"])
    k = 5
    f = int(round((sm.times[k] + sm.refinements[k, i]) * walk.fps))  # the ankle's knot of pose k
    assert np.isclose(own.frame_times(late)[f, e], late.times[k] + late.refinements[k, i])
    assert np.isclose(layer.frame_times(late)[f, e], f / walk.fps)  # pose timing: succession leaves it


def test_runs_get_a_constraint_layer(cmu) -> None:
    run = cmu("09_06")
    sm = extract(run, constraints=True)
    assert sm.constraints.masks.any(axis=0).all()  # every foot joint has a stance
    assert max_diff(sm.evaluate(), run)[0] < 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        edited = succession(sm, 0.01, 1.0)
    w, tg = sm.constraints.weights_and_targets(edited, edited.evaluate().times)
    idx = [run.skeleton.index(n) for n in sm.constraints.joints]
    on = w == 1.0
    free = np.linalg.norm(edited.evaluate(constraints=False).global_positions()[:, idx] - tg, axis=-1)[on]
    held = np.linalg.norm(edited.evaluate().global_positions()[:, idx] - tg, axis=-1)[on]
    assert free.max() > 0.01 and held.max() < 0.005


def test_constraint_layer_validation(walk_layer) -> None:
    import dataclasses

    _, sm, _, _ = walk_layer
    layer = sm.constraints
    with pytest.raises(ValueError, match="timing"):
        dataclasses.replace(layer, timing=("LeftFoot",))
    with pytest.raises(ValueError, match="reach_tolerance"):
        dataclasses.replace(layer, reach_tolerance=0.0)
    with pytest.raises(ValueError, match="hinges"):
        dataclasses.replace(layer, hinges=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="masks"):
        dataclasses.replace(layer, masks=layer.masks[:-1])


def sm_contacts(walk):
    from mocaplab.contacts import stillness_contacts

    return stillness_contacts(walk)


def test_editor_drives_the_representation(cmu) -> None:
    walk = cmu("16_05")
    ed = StaggeredEditor(walk, max_poses=8, optimize=False)
    base = ed.evaluate()
    assert max_diff(base, walk)[0] < 1e-6
    ed.set_succession(s=0.02, l=2.0)
    assert not np.array_equal(ed.current.refinements, ed.base.refinements)
    ed.set_staggered(False)
    ns = ed.evaluate()
    ed.set_staggered(True)
    assert max_diff(ns, ed.evaluate())[0] > 1e-3
    ed.set_random(tau=0.02, seed=3)
    ed.set_exaggeration(0.3)
    ed.set_pose_count(5)
    assert ed.current.n_poses == 5 and len(ed.pose_table()) == 5
    ed.select(2)
    ns_pose, true_pose = ed.overlay()
    assert ns_pose.n_frames == true_pose.n_frames == 1
    c = ed.curves("LeftArm")
    assert c["values"].shape == (ed.evaluate().n_frames, 3) and c["knot_times"].size == 5
    # the editor agrees with the pure functions applied in its documented order
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        expected = randomize(succession(exaggerate(ed.base, 0.3), 0.02, 2.0), 0.02, seed=3)
    assert np.array_equal(expected.refinements, ed.current.refinements)
    assert max_diff(expected.evaluate(), ed.evaluate())[0] < 1e-12
    # undoing every edit gives back the clip
    ed.set_succession(s=0.0)
    ed.set_random(tau=0.0)
    ed.set_exaggeration(0.0)
    assert max_diff(ed.evaluate(), walk)[0] < 1e-6


# ------------------------------------------------------------ editor history
def _snapshot(ed: StaggeredEditor) -> tuple:
    m = ed.evaluate()
    return ed.params, np.array(ed.current.refinements), np.array(m.rotations), np.array(m.root_positions)


def _assert_snapshot(ed: StaggeredEditor, snap: tuple) -> None:
    params, refinements, rotations, root = snap
    assert ed.params == params
    m = ed.evaluate()
    assert np.array_equal(ed.current.refinements, refinements)
    assert np.array_equal(m.rotations, rotations) and np.array_equal(m.root_positions, root)


@pytest.fixture(scope="module")
def jump16_05(mocap_dir):
    from mocaplab import data

    return data.cmu("16_05")


def test_editor_undo_redo_reset_restore_current_exactly(jump16_05) -> None:
    ed = StaggeredEditor(jump16_05, max_poses=8, optimize=False)
    assert not ed.can_undo and not ed.can_redo
    with pytest.raises(IndexError, match="nothing to undo"):
        ed.undo()
    snaps = [_snapshot(ed)]
    edits = [
        lambda: ed.set_succession(s=0.02),
        lambda: ed.set_succession(l=2.0),
        lambda: ed.set_random(tau=0.03, seed=3),
        lambda: ed.set_random(by="limb"),
        lambda: ed.set_exaggeration(0.3, joints=["LeftArm", "RightArm"]),
        lambda: ed.set_pose_count(5),
        lambda: ed.set_staggered(False),
        lambda: ed.select(2),
        lambda: ed.set_succession(joint="LeftArm"),
    ]
    for edit_ in edits:
        edit_()
        ed.checkpoint()
        assert ed.params != snaps[-1][0], "every edit changes the record"
        snaps.append(_snapshot(ed))
    assert ed.params.exaggerate_joints == ("LeftArm", "RightArm") and ed.selected == 2 and ed.current.n_poses == 5
    for snap in reversed(snaps[:-1]):  # undo walks back through every state, exactly
        ed.undo()
        _assert_snapshot(ed, snap)
    assert not ed.can_undo and ed.can_redo
    for snap in snaps[1:]:
        ed.redo()
        _assert_snapshot(ed, snap)
    assert not ed.can_redo
    # reset is an edit: back to the start, and undoable
    ed.reset()
    _assert_snapshot(ed, snaps[0])
    assert ed.can_undo and max_diff(ed.evaluate(), jump16_05)[0] < 1e-6
    ed.undo()
    _assert_snapshot(ed, snaps[-1])
    # a new edit drops the redo states
    ed.undo()
    ed.set_succession(s=-0.01)
    assert not ed.can_redo and ed.s == -0.01


def test_editor_refits_only_when_the_pose_count_changes(jump16_05, monkeypatch) -> None:
    ed = StaggeredEditor(jump16_05, max_poses=8, optimize=False)
    calls: list = []
    extract_ = ed._extract
    monkeypatch.setattr(ed, "_extract", lambda *a, **k: calls.append(k["max_poses"]) or extract_(*a, **k))
    ed.set_succession(s=0.02)
    ed.set_random(tau=0.02)
    ed.undo()
    ed.reset()
    assert calls == []
    base8 = ed.base
    ed.set_pose_count(5)
    assert calls == [5]
    ed.undo()
    assert ed.base is base8 and ed.current.n_poses == 8
    ed.redo()
    assert calls == [5] and ed.current.n_poses == 5


def test_slider_changes_of_one_parameter_merge_until_checkpoint(jump16_05) -> None:
    ed = StaggeredEditor(jump16_05, max_poses=8, optimize=False)
    for s in (0.01, 0.02, 0.03):  # one slider drag
        ed.set_succession(s=s)
    ed.undo()
    assert ed.s == 0.0 and not ed.can_undo
    ed.set_succession(s=0.01)
    ed.checkpoint()
    ed.set_succession(s=0.02)
    ed.undo()
    assert ed.s == 0.01
    # another parameter starts a new step, without a checkpoint
    ed.set_succession(l=2.0)
    ed.set_random(tau=0.02)
    ed.undo()
    assert (ed.s, ed.l, ed.tau) == (0.01, 2.0, 0.0)
    # selections merge with each other, not with the edits
    ed.select(2)
    ed.select(3)
    ed.undo()
    assert ed.selected == 0 and ed.l == 2.0


def test_no_change_and_rejected_edits_push_nothing(jump16_05) -> None:
    ed = StaggeredEditor(jump16_05, max_poses=8, optimize=False)
    ed.set_succession(s=0.02)
    ed.checkpoint()
    before = _snapshot(ed)
    current = ed.current
    ed.set_succession(s=0.02)  # the value it already has
    ed.set_staggered(True)
    ed.select(0)
    for bad in (lambda: ed.set_succession(l=-1.0), lambda: ed.set_exaggeration(float("nan"))):
        bad()
        assert ed.message.startswith("edit rejected: Expected")
        assert ed.current is current
        _assert_snapshot(ed, before)
    with pytest.raises(ValueError, match="max_poses"):
        ed.set_pose_count(1)
    _assert_snapshot(ed, before)
    ed.undo()  # one step back is the start: nothing above was recorded
    assert not ed.can_undo and ed.s == 0.0 and ed.message == ""


def test_editor_parameters_are_read_only(jump16_05) -> None:
    import dataclasses

    ed = StaggeredEditor(jump16_05, max_poses=6, optimize=False)
    with pytest.raises(AttributeError):
        ed.s = 0.1  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        ed.params.s = 0.1  # type: ignore[misc]


def test_reset_at_the_start_and_selection_beyond_a_smaller_pose_count(jump16_05) -> None:
    ed = StaggeredEditor(jump16_05, max_poses=8, optimize=False)
    ed.reset()  # already there: nothing to undo afterwards
    assert not ed.can_undo
    ed.select(7)
    ed.set_pose_count(5)
    assert ed.selected == 4 and ed.overlay()[1].n_frames == 1  # the last pose stays selected
    ed.undo()
    assert ed.selected == 7 and ed.current.n_poses == 8


def test_editor_plants_the_feet_by_default(cmu) -> None:
    """The editor plays the constraint layer unless turned off (an undoable edit); the feet skate less with it."""
    from mocaplab import quality

    walk = cmu("16_15")
    ed = StaggeredEditor(walk, max_poses=10, optimize=False)
    assert ed.constraints and ed.current.constraints is not None
    ed.set_succession(s=0.02)
    ed.checkpoint()
    held = ed.evaluate()
    ed.set_constraints(False)
    ed.checkpoint()
    assert not ed.constraints and ed.current.constraints is not None  # still built: only not played
    free = ed.evaluate()
    assert max_diff(held, free)[0] > 1e-3
    skate_held = quality.compare(walk, held)["skate"].after
    skate_free = quality.compare(walk, free)["skate"].after
    assert skate_held < 0.6 * skate_free, (skate_held, skate_free)  # 1.57 against 3.13 mm/frame
    ed.undo()
    assert ed.constraints and max_diff(ed.evaluate(), held)[0] < 1e-12
    off = StaggeredEditor(walk, max_poses=10, optimize=False, constraints=False)
    off.set_succession(s=0.02)
    assert not off.constraints and max_diff(off.evaluate(), free)[0] < 1e-12
