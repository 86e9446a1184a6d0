"""Editing staggered poses (Coleman 2008, section 5): geometric and timing edits, constraints, editor."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mocaplab import quat
from mocaplab.staggered import (
    StaggeredEditor,
    StaggeredTimingWarning,
    extract,
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
    same = sm.succession(0.0, 2.0).randomize(0.0).exaggerate(0.0)
    rot, pos = max_diff(same.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    assert np.array_equal(same.refinements, sm.refinements)
    assert sm.succession(0.0) is sm


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
        out = sm.succession(s, l, joint="RightArm")
    d = succession_depths(sm.skeleton, "RightArm")
    dr = out.refinements - sm.refinements
    moved = np.isfinite(d)
    interior = slice(1, -1)
    assert np.allclose(dr[interior][:, moved], s * d[moved] ** l, atol=1e-12)
    assert np.all(dr[:, ~moved] == 0.0) and np.all(dr[[0, -1]] == 0.0)


def test_large_succession_warns_and_keeps_knots_ordered(walk_sm) -> None:
    _, sm = walk_sm
    with pytest.warns(StaggeredTimingWarning, match="closer to a neighbouring pose"):
        out = sm.succession(0.05, 2.0)
    T = out.times[:, None] + out.refinements
    assert np.all(np.diff(T, axis=0) > 0)
    assert out.evaluate().n_frames == sm.n_frames


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
        a = sm.randomize(0.03, joints=["LeftArm", "LeftForeArm"], seed=7)
        b = sm.randomize(0.03, joints=["LeftArm", "LeftForeArm"], seed=7)
        c = sm.randomize(0.03, joints=["LeftArm", "LeftForeArm"], seed=8)
    assert np.array_equal(a.refinements, b.refinements) and not np.array_equal(a.refinements, c.refinements)
    dr = a.refinements - sm.refinements
    cols = [sm.variable_index("LeftArm"), sm.variable_index("LeftForeArm")]
    assert np.abs(dr).max() <= 0.03 + 1e-12 and np.abs(dr[1:-1][:, cols]).max() > 0
    others = np.delete(dr, cols, axis=1)
    assert np.all(others == 0.0)


def test_retime_moves_the_pose_and_its_knots(walk_sm) -> None:
    walk, sm = walk_sm
    k = 5
    shift = 3 / walk.fps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        out = sm.retime(k, float(sm.times[k] + shift))
    assert out.times[k] == pytest.approx(sm.times[k] + shift)
    # the refined knot values are reached at the shifted knot times
    m = out.evaluate()
    j = sm.variable_index("RightLeg")
    f = int(round((sm.times[k] + sm.refinements[k, j] + shift) * walk.fps))
    assert angle(m.rotations[f, j - 1], sm.rotation_values[k, j - 1]) < 1e-9
    # far from the pose nothing changes
    far = (walk.times < sm.times[k - 1] - 0.3) | (walk.times > sm.times[k + 1] + 0.3)
    assert angle(m.rotations[far], walk.rotations[far]).max() < 1e-9
    with pytest.raises(ValueError, match="strictly between"):
        sm.retime(k, float(sm.times[k + 1] + 0.01))
    with pytest.raises(ValueError, match="first pose"):
        sm.retime(0, 0.1)


def test_editing_the_true_pose(walk_sm) -> None:
    walk, sm = walk_sm
    k = 6
    root, rot = sm.true_pose(k)
    target = np.array(rot)
    j = walk.skeleton.index("LeftArm")
    turn = quat.from_axis_angle([0, 0, 1], 0.3)
    target[j] = quat.mul(rot[j], turn)
    out = sm.edit_pose(k, rotations=target, root_position=root + [0.0, 0.04, 0.0], which="true")
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


def test_editing_the_non_staggered_pose_offsets_the_editing_knot(walk_sm) -> None:
    walk, sm = walk_sm
    k = 6
    j = walk.skeleton.index("LeftForeArm")
    assert sm.refinements[k, j + 1] != 0.0  # this knot has an editing knot
    new = quat.mul(sm.rotation_values[k, j], quat.from_axis_angle([1, 0, 0], 0.2))
    out = sm.edit_pose(k, rotations={"LeftForeArm": new})
    assert angle(out.non_staggered_pose(k)[1][j], new) < 1e-12
    before = sm.true_pose(k)[1][j]
    after = out.true_pose(k)[1][j]
    assert angle(before, after) == pytest.approx(0.2, abs=1e-6)
    others = np.delete(np.arange(walk.n_joints), j)
    assert angle(out.rotation_values[:, others], sm.rotation_values[:, others]).max() < 1e-12


def test_relative_exaggeration(walk_sm) -> None:
    walk, sm = walk_sm
    arms = ["LeftArm", "RightArm"]
    idx = [walk.skeleton.index(n) for n in arms]
    ref = 3
    toward = sm.exaggerate(-1.0, reference=ref, joints=arms)
    assert angle(toward.rotation_values[:, idx], sm.rotation_values[ref, idx][None]).max() < 1e-9
    # w_r = 1 doubles the angle from the average pose (geodesic extrapolation)
    _, mean = average_pose(sm)
    out = sm.exaggerate(1.0, joints=arms)
    a0 = angle(mean[idx][None], sm.rotation_values[:, idx])
    a1 = angle(mean[idx][None], out.rotation_values[:, idx])
    assert np.allclose(a1, np.minimum(2 * a0, 2 * np.pi - 2 * a0), atol=1e-9)
    # the true-pose variant reaches its targets
    true_out = sm.exaggerate(0.5, joints=arms, poses=[4], which="true", reference="previous")
    r_prev = sm.true_pose(3)[1]
    r_k = sm.true_pose(4)[1]
    expected = quat.mul(r_k, quat.exp(0.5 * quat.log(quat.mul(quat.inv(r_prev), r_k))))
    assert angle(true_out.true_pose(4)[1][idx], expected[idx]).max() < 1e-9
    with pytest.raises(ValueError, match="reference"):
        sm.exaggerate(0.5, reference="median")  # type: ignore[arg-type]


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
    ins = sm.insert_pose(t_new)
    assert ins.n_poses == sm.n_poses + 1 and np.isclose(ins.times[k + 1], t_new)
    rot, pos = max_diff(ins.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    dele = sm.delete_pose(k)
    assert dele.n_poses == sm.n_poses - 1
    rot, pos = max_diff(dele.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    with pytest.raises(ValueError, match="interior"):
        sm.delete_pose(0)
    with pytest.raises(ValueError, match="not on a pose"):
        sm.insert_pose(float(sm.times[3]))


def test_partial_pose_controls_a_subset(walk_sm) -> None:
    walk, sm = walk_sm
    k = 4
    T = sm.knot_times
    t_new = float(0.5 * (T[k].max() + T[k + 1].min()))
    part = sm.insert_pose(t_new, joints=["LeftArm", "LeftForeArm"])
    row = part.active[k + 1]
    assert row.sum() == 2 and row[part.variable_index("LeftArm")]
    rot, pos = max_diff(part.evaluate(), walk)
    assert rot < 1e-6 and pos < 1e-6
    # timing and value edits work on it; uncontrolled variables are not refined there
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", StaggeredTimingWarning)
        moved = part.succession(0.02, 1.0, joint="LeftArm")
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
    edited = sm.edit_pose(k, root_position=sm.root_values[k] + [0.0, -0.05, 0.0])
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
    edited = sm.exaggerate(0.5, joints=legs)
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
        expected = ed.base.exaggerate(0.3).succession(0.02, 2.0).randomize(0.02, seed=3)
    assert np.array_equal(expected.refinements, ed.current.refinements)
    assert max_diff(expected.evaluate(), ed.evaluate())[0] < 1e-12
    # undoing every edit gives back the clip
    ed.set_succession(s=0.0)
    ed.set_random(tau=0.0)
    ed.set_exaggeration(0.0)
    assert max_diff(ed.evaluate(), walk)[0] < 1e-6
