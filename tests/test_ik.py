"""Inverse kinematics: round trips through forward kinematics, clamping, swivel."""

from __future__ import annotations

import numpy as np
import pytest

from mocaplab import ik, quat
from mocaplab.kinematics import fk
from mocaplab.motion import Motion, Skeleton

LEG = ("LeftUpLeg", "LeftLeg", "LeftFoot")
ARM = ("RightArm", "RightForeArm", "RightHand")


def _chain_skeleton() -> Skeleton:
    """root -> hip -> knee -> ankle -> toe, plus a spine branch."""
    return Skeleton(
        ["root", "hip", "knee", "ankle", "toe", "spine"],
        [-1, 0, 1, 2, 3, 0],
        [[0, 0, 0], [0.1, -0.05, 0], [0.02, -0.42, 0.01], [-0.01, -0.4, 0.0], [0, -0.05, 0.12], [0, 0.2, 0]],
    )


def _random_quats(rng: np.random.Generator, shape: tuple[int, ...], scale: float = 1.0) -> np.ndarray:
    return quat.exp(rng.normal(scale=scale, size=shape + (3,)))


def _positions(rot, root, sk):
    return fk(rot, root, sk.offsets, sk.parents)[1]


def test_two_bone_round_trip_random_poses(rng):
    sk = _chain_skeleton()
    n = 400
    root = rng.normal(size=(n, 3))
    goal_pose = _random_quats(rng, (n, sk.n_joints))
    start_pose = _random_quats(rng, (n, sk.n_joints))
    start_pose[:, 0] = goal_pose[:, 0]  # same hip position, so the target is reachable
    target = _positions(goal_pose, root, sk)[:, 3]
    new = ik.two_bone_ik(start_pose, root, sk, "ankle", target)
    reached = _positions(new, root, sk)[:, 3]
    assert np.abs(reached - target).max() < 1e-4  # 0.1 mm
    # only the hip and knee rotations changed
    changed = np.any(np.abs(new - start_pose) > 1e-12, axis=(0, 2))
    assert changed.tolist() == [False, True, True, False, False, False]


def test_two_bone_round_trip_on_cmu_poses(cmu, rng):
    walk = cmu("16_15")[::4]
    sk = walk.skeleton
    goal = walk.global_positions()
    rot = np.array(walk.rotations)
    for names in (LEG, ARM):
        for name in names[:2]:
            j = sk.index(name)
            rot[:, j] = quat.mul(_random_quats(rng, (walk.n_frames,), 0.3), rot[:, j])
    before = rot.copy()
    for names in (LEG, ARM):
        end = sk.index(names[2])
        new = ik.two_bone_ik(rot, walk.root_positions, sk, end, goal[:, end])
        reached = _positions(new, walk.root_positions, sk)[:, end]
        assert np.abs(reached - goal[:, end]).max() < 1e-4
    np.testing.assert_array_equal(rot, before)  # input not mutated


def test_end_rotation_sets_the_global_orientation(cmu, rng):
    walk = cmu("16_15")[:60]
    sk = walk.skeleton
    foot = sk.index("LeftFoot")
    keep = walk.global_rotations()[:, foot]
    target = walk.global_positions()[:, foot] + [0.05, 0.08, -0.03]
    new = ik.two_bone_ik(walk.rotations, walk.root_positions, sk, foot, target, end_rotation=keep)
    grot, gpos = fk(new, walk.root_positions, sk.offsets, sk.parents)
    assert np.abs(gpos[:, foot] - target).max() < 1e-9
    assert np.degrees(quat.angle(quat.mul(quat.inv(keep), grot[:, foot]))).max() < 1e-6


@pytest.mark.parametrize("extra", [0.0, 1e-12, 1e-6, 0.5, 3.0])
def test_unreachable_targets_clamp_straight_without_nan(extra):
    sk = _chain_skeleton()
    rng = np.random.default_rng(3)
    n = 50
    root = np.zeros((n, 3))
    rot = _random_quats(rng, (n, sk.n_joints), 0.4)
    pos = _positions(rot, root, sk)
    full = np.linalg.norm(sk.offsets[2]) + np.linalg.norm(sk.offsets[3])
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    target = pos[:, 1] + direction * (full + extra)
    new = ik.two_bone_ik(rot, root, sk, "ankle", target)
    assert np.all(np.isfinite(new))
    p = _positions(new, root, sk)
    hip, knee, ankle = p[:, 1], p[:, 2], p[:, 3]
    # straight: hip-ankle distance equals the sum of the bones
    np.testing.assert_allclose(np.linalg.norm(ankle - hip, axis=1), full, atol=1e-6)
    # and pointing at the target
    got = (ankle - hip) / np.linalg.norm(ankle - hip, axis=1, keepdims=True)
    np.testing.assert_allclose(got, direction, atol=1e-6)
    assert np.all(np.linalg.norm(knee - hip, axis=1) > 0)


def test_target_at_the_upper_joint_does_not_nan():
    sk = _chain_skeleton()
    rot = _random_quats(np.random.default_rng(0), (4, sk.n_joints), 0.5)
    root = np.zeros((4, 3))
    hip = _positions(rot, root, sk)[:, 1]
    new = ik.two_bone_ik(rot, root, sk, "ankle", hip)
    assert np.all(np.isfinite(new))


def test_default_swivel_keeps_the_bending_plane(rng):
    sk = _chain_skeleton()
    n = 200
    root = np.zeros((n, 3))
    rot = _random_quats(rng, (n, sk.n_joints), 0.6)
    p0 = _positions(rot, root, sk)
    target = p0[:, 3] + rng.normal(scale=0.1, size=(n, 3))
    new = ik.two_bone_ik(rot, root, sk, "ankle", target, keep_bend=False)  # independent random poses: no clip-wide hinge
    p1 = _positions(new, root, sk)
    old_n = np.cross(p0[:, 2] - p0[:, 1], p0[:, 3] - p0[:, 1])
    new_n = np.cross(p1[:, 2] - p1[:, 1], p1[:, 3] - p1[:, 1])
    axis = p1[:, 3] - p1[:, 1]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    want = old_n - np.sum(old_n * axis, axis=1, keepdims=True) * axis
    cos = np.sum(want * new_n, axis=1) / np.linalg.norm(want, axis=1) / np.linalg.norm(new_n, axis=1)
    full = np.linalg.norm(sk.offsets[2]) + np.linalg.norm(sk.offsets[3])
    reachable = np.linalg.norm(target - p0[:, 1], axis=1) < 0.95 * full
    bent = np.linalg.norm(old_n, axis=1) > 0.05 * full**2  # away from straight limbs
    ok = reachable & bent
    assert ok.sum() > 50
    assert np.all(cos[ok] > 1 - 1e-9)


def test_pole_puts_the_knee_in_the_pole_half_plane():
    sk = _chain_skeleton()
    rot = quat.identity((3, sk.n_joints))
    rot[:, 2] = quat.from_axis_angle([1.0, 0, 0], 0.8)  # bent knee
    root = np.zeros((3, 3))
    p0 = _positions(rot, root, sk)
    target = p0[:, 3] + [0.0, 0.05, 0.0]
    poles = np.array([[1.0, -0.4, 0.0], [-1.0, -0.4, 0.0], [0.0, -0.4, 1.0]])
    new = ik.two_bone_ik(rot, root, sk, "ankle", target, pole=poles)
    p1 = _positions(new, root, sk)
    axis = (p1[:, 3] - p1[:, 1]) / np.linalg.norm(p1[:, 3] - p1[:, 1], axis=1, keepdims=True)

    def perp(v):
        return v - np.sum(v * axis, axis=1, keepdims=True) * axis

    knee, pole = perp(p1[:, 2] - p1[:, 1]), perp(poles - p1[:, 1])
    cos = np.sum(knee * pole, axis=1) / np.linalg.norm(knee, axis=1) / np.linalg.norm(pole, axis=1)
    np.testing.assert_allclose(cos, 1.0, atol=1e-9)
    np.testing.assert_allclose(p1[:, 3], target, atol=1e-9)


def test_straight_limb_bends_about_the_given_axis():
    sk = Skeleton(["hip", "knee", "ankle"], [-1, 0, 1], [[0, 0, 0], [0, -0.5, 0], [0, -0.5, 0]])
    rot = quat.identity((1, 3))
    new = ik.two_bone_ik(rot, np.zeros((1, 3)), sk, "ankle", [0.0, -0.8, 0.0], bend_axis=[1.0, 0.0, 0.0])
    p = _positions(new, np.zeros((1, 3)), sk)[0]
    np.testing.assert_allclose(p[2], [0, -0.8, 0], atol=1e-12)
    assert abs(p[1, 0]) < 1e-12  # the knee moved in the y-z plane only
    assert abs(p[1, 2]) > 0.1


def test_two_bone_deltas_broadcast_and_identity():
    a, b, c = np.array([0, 1.0, 0]), np.array([0.05, 0.55, 0.1]), np.array([0, 0.1, 0])
    qu, qm = ik.two_bone_deltas(a, b, c, c)  # target where the end already is
    np.testing.assert_allclose(quat.angle(qu), 0.0, atol=1e-7)
    np.testing.assert_allclose(quat.angle(qm), 0.0, atol=1e-7)
    qu, qm = ik.two_bone_deltas(a, b, c, np.tile(c, (5, 1)) + 0.01)
    assert qu.shape == (5, 4) and qm.shape == (5, 4)


def test_limb_joints_on_cmu(cmu):
    sk = cmu("16_15").skeleton
    assert [sk.names[j] for j in ik.limb_joints(sk, "LeftFoot")] == list(LEG)
    assert [sk.names[j] for j in ik.limb_joints(sk, "RightHand")] == list(ARM)
    with pytest.raises(ValueError, match="parent and a grandparent"):
        ik.limb_joints(sk, "LHipJoint")


def test_dls_reaches_targets_with_spine_and_arm(cmu, rng):
    walk = cmu("16_15")[::10]
    sk = walk.skeleton
    chain = ["LowerBack", "Spine", "Spine1", "RightShoulder", "RightArm", "RightForeArm"]
    # targets from FK of a perturbed pose of the same chain: reachable by construction
    goal = np.array(walk.rotations)
    for name in chain:
        j = sk.index(name)
        goal[:, j] = quat.mul(_random_quats(rng, (walk.n_frames,), 0.15), goal[:, j])
    hand = sk.index("RightHand")
    target = _positions(goal, walk.root_positions, sk)[:, hand]
    new = ik.dls_ik(walk.rotations, walk.root_positions, sk, chain, "RightHand", target, iterations=50)
    reached = _positions(new, walk.root_positions, sk)[:, hand]
    assert np.linalg.norm(reached - target, axis=1).max() < 1e-4
    others = [j for j in range(sk.n_joints) if sk.names[j] not in chain]
    np.testing.assert_array_equal(new[:, others], walk.rotations[:, others])


def test_dls_two_effectors_and_frozen_joint(cmu, rng):
    walk = cmu("16_15")[20:40]
    sk = walk.skeleton
    chain = ["Spine1", "LeftArm", "LeftForeArm", "RightArm", "RightForeArm"]
    goal = np.array(walk.rotations)
    for name in chain[1:]:
        goal[:, sk.index(name)] = quat.mul(_random_quats(rng, (walk.n_frames,), 0.2), goal[:, sk.index(name)])
    effectors = ["LeftHand", "RightHand"]
    targets = _positions(goal, walk.root_positions, sk)[:, [sk.index(e) for e in effectors]]
    weights = [0.0, 1.0, 1.0, 1.0, 1.0]
    new = ik.dls_ik(walk.rotations, walk.root_positions, sk, chain, effectors, targets, joint_weights=weights)
    reached = _positions(new, walk.root_positions, sk)[:, [sk.index(e) for e in effectors]]
    assert np.linalg.norm(reached - targets, axis=-1).max() < 1e-4
    np.testing.assert_array_equal(new[:, sk.index("Spine1")], walk.rotations[:, sk.index("Spine1")])


def test_dls_unreachable_target_stays_finite(cmu):
    walk = cmu("16_15")[:5]
    sk = walk.skeleton
    new = ik.dls_ik(walk.rotations, walk.root_positions, sk, ["RightArm", "RightForeArm"], "RightHand", [5.0, 5.0, 5.0])
    assert np.all(np.isfinite(new))
    hand = _positions(new, walk.root_positions, sk)[:, sk.index("RightHand")]
    before = walk.global_positions()[:, sk.index("RightHand")]
    assert np.all(np.linalg.norm(hand - [5, 5, 5], axis=1) < np.linalg.norm(before - [5, 5, 5], axis=1))


def test_reach_motion_level(cmu):
    walk = cmu("16_15")[:30]
    sk = walk.skeleton
    foot = sk.index("RightFoot")
    target = walk.global_positions()[:, foot] + [0.0, 0.1, 0.0]
    lifted = ik.reach(walk, "RightFoot", target)
    assert isinstance(lifted, Motion)
    assert np.abs(lifted.global_positions()[:, foot] - target).max() < 1e-9
    angle = quat.angle(quat.mul(quat.inv(walk.global_rotations()[:, foot]), lifted.global_rotations()[:, foot]))
    assert angle.max() < 1e-8  # the foot kept its orientation
    hand = sk.index("LeftHand")
    t2 = walk.global_positions()[:, hand] + [0.0, 0.1, 0.0]
    moved = ik.reach(walk, "LeftHand", t2, chain=["Spine1", "LeftArm", "LeftForeArm"], iterations=40)
    assert np.abs(moved.global_positions()[:, hand] - t2).max() < 1e-4


def test_bad_inputs_raise_clear_errors(cmu):
    walk = cmu("16_15")[:5]
    sk = walk.skeleton
    with pytest.raises(ValueError, match=r"`target` of shape \(3,\) or \(5, 3\)"):
        ik.two_bone_ik(walk.rotations, walk.root_positions, sk, "LeftFoot", np.zeros((4, 3)))
    with pytest.raises(ValueError, match="`rotations` of shape"):
        ik.two_bone_ik(walk.rotations[:, :3], walk.root_positions, sk, "LeftFoot", np.zeros(3))
    with pytest.raises(KeyError, match="No joint named"):
        ik.two_bone_ik(walk.rotations, walk.root_positions, sk, "Tail", np.zeros(3))
    with pytest.raises(ValueError, match="do not descend"):
        ik.dls_ik(walk.rotations, walk.root_positions, sk, ["LeftArm"], "RightHand", np.zeros(3))
    with pytest.raises(ValueError, match="`targets` of shape"):
        ik.dls_ik(walk.rotations, walk.root_positions, sk, ["RightArm"], "RightHand", np.zeros((2, 2, 3)))
    with pytest.raises(TypeError, match="apply only with `chain`"):
        ik.reach(walk, "RightHand", np.zeros(3), damping=0.1)


def _knee_clip(angles_deg):
    """The chain skeleton with its knee bent by the given angles about +X (negative: hyperextended)."""
    sk = _chain_skeleton()
    n = len(angles_deg)
    rot = quat.identity((n, sk.n_joints))
    rot[:, 2] = quat.from_axis_angle(np.array([1.0, 0, 0]), np.radians(angles_deg))
    return sk, rot, np.zeros((n, 3))


def _signed_knee(rot, root, sk):
    p = _positions(rot, root, sk)
    u, v = p[:, 1] - p[:, 2], p[:, 3] - p[:, 2]
    cross = np.cross(u, v)
    # the clip's bend is about +X in the knee frame: its sign tells the side
    return np.degrees(np.pi - np.arctan2(np.linalg.norm(cross, axis=1), np.sum(u * v, axis=1))) * np.sign(cross[:, 0])


def test_a_limb_never_flips_its_bending_direction():
    # a walk-like knee: bent 30-40 degrees, but hyperextended by about 0.1 degree on one frame
    sk, rot, root = _knee_clip([30.0, 40.0, -4.5, 35.0])  # the rest pose is bent 4.4 degrees
    side = np.sign(_signed_knee(rot, root, sk)[0])
    before = side * _signed_knee(rot, root, sk)
    assert before[2] < 0 < before[0]
    p0 = _positions(rot, root, sk)
    target = p0[:, 3] + [0.0, 0.04, 0.0]  # raise the ankle: the knee must bend more
    kept = side * _signed_knee(ik.two_bone_ik(rot, root, sk, "ankle", target), root, sk)
    assert np.all(kept > 5.0), kept  # every frame bends forwards, the hyperextended one too
    flipped = side * _signed_knee(ik.two_bone_ik(rot, root, sk, "ankle", target, keep_bend=False), root, sk)
    assert flipped[2] < -5.0  # the old behaviour: bending further backwards
    # the hinge estimate is close to the knee rotation axis
    grot, gpos = fk(rot, root, sk.offsets, sk.parents)
    assert abs(ik.hinge_axes(grot, gpos, [(1, 2, 3)])[0, 0]) > 0.98  # about +X (the bones are not coplanar)


def test_unreachable_targets_are_reported():
    sk, rot, root = _knee_clip([30.0, 30.0])
    p0 = _positions(rot, root, sk)
    full = np.linalg.norm(sk.offsets[2]) + np.linalg.norm(sk.offsets[3])
    hip = p0[:, 1]
    target = np.stack([hip[0] + [0, -0.5 * full, 0], hip[1] + [0, -(full + 0.07), 0]])
    new, residual = ik.two_bone_ik(rot, root, sk, "ankle", target, return_residual=True)
    assert residual[0] == 0.0 and residual[1] == pytest.approx(0.07, abs=1e-12)
    reached = _positions(new, root, sk)[:, 3]
    assert np.linalg.norm(reached[0] - target[0]) < 1e-9
    assert np.linalg.norm(reached[1] - target[1]) == pytest.approx(0.07, abs=1e-9)


def test_limb_joints_follow_the_roles_past_helper_joints():
    # hip -> knee -> twist (zero length) -> ankle: the limb skips the twist bone
    sk = Skeleton(
        ["Hips", "UpperLeg_L", "LowerLeg_L", "LowerLegTwist_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Spine", "Head"],
        [-1, 0, 1, 2, 3, 0, 5, 6, 0, 8],
        [[0, 1, 0], [0.1, 0, 0], [0, -0.45, 0], [0, 0, 0], [0, -0.45, 0], [-0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0],
         [0, 0.5, 0], [0, 0.2, 0]],
    )
    assert ik.limb_joints(sk, "Foot_L") == (1, 2, 4)
    assert ik.limb_joints(sk, "Foot_R") == (5, 6, 7)
    rot = quat.identity((2, sk.n_joints))
    rot[:, 2] = quat.from_axis_angle(np.array([1.0, 0, 0]), 0.5)
    root = np.array([[0, 1.0, 0]] * 2)
    target = _positions(rot, root, sk)[:, 4] + [0, 0.05, 0.02]
    new = ik.two_bone_ik(rot, root, sk, "Foot_L", target)
    assert np.abs(_positions(new, root, sk)[:, 4] - target).max() < 1e-9
    assert np.allclose(new[:, 3], rot[:, 3])  # the twist joint is carried rigidly


def test_end_rotation_is_kept_below_a_twist_joint(rng):
    # hip -> knee -> twist (animated, zero length) -> ankle: the ankle's wanted global
    # orientation is rebuilt in its real parent's frame, the twist joint's
    sk = Skeleton(
        ["Hips", "UpperLeg_L", "LowerLeg_L", "LowerLegTwist_L", "Foot_L", "UpperLeg_R", "LowerLeg_R", "Foot_R"],
        [-1, 0, 1, 2, 3, 0, 5, 6],
        [[0, 1, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.2, 0], [0, -0.25, 0], [-0.1, 0, 0], [0, -0.45, 0], [0, -0.45, 0]],
    )
    rot = _random_quats(rng, (6, sk.n_joints), 0.3)
    root = np.tile([0.0, 1.0, 0.0], (6, 1))
    grot = fk(rot, root, sk.offsets, sk.parents)[0]
    target = _positions(rot, root, sk)[:, 4] + [0.05, 0.08, -0.03]
    new = ik.two_bone_ik(rot, root, sk, "Foot_L", target, end_rotation=grot[:, 4])
    new_grot, new_pos = fk(new, root, sk.offsets, sk.parents)
    assert np.abs(new_pos[:, 4] - target).max() < 1e-9
    assert quat.angle(quat.mul(quat.inv(grot[:, 4]), new_grot[:, 4])).max() < 1e-9
    np.testing.assert_array_equal(new[:, 3], rot[:, 3])


def test_two_bone_ik_warns_once_for_targets_beyond_reach():
    sk = _chain_skeleton()
    rot = quat.identity((5, sk.n_joints))
    root = np.zeros((5, 3))
    ankle = _positions(rot, root, sk)[:, 3]
    target = np.array(ankle)
    target[2:4] = ankle[2:4] + [0.0, -0.3, 0.0]  # frames 2-3: 0.3 m below a straight leg
    expected = r"'ankle' out of reach on frames 2-3 \(2 frames\): missed by up to (299|300) mm"
    with pytest.warns(ik.UnreachableTargetWarning, match=expected) as rec:
        ik.two_bone_ik(rot, root, sk, "ankle", target, bend_axis=[1, 0, 0])
    assert len(rec) == 1 and rec[0].filename == __file__
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ik.two_bone_ik(rot, root, sk, "ankle", ankle + [0.0, 0.05, 0.0], bend_axis=[1, 0, 0])
        ik.two_bone_ik(rot, root, sk, "ankle", target, bend_axis=[1, 0, 0], warn_unreachable=False)


def test_a_sideways_bend_crossing_the_hinge_plane_swivels_without_a_flip():
    # a nearly straight standing leg (optitrack capture) bends 6 degrees about an axis that turns across
    # the plane perpendicular to the knee's hinge; held on its own ankle position, the knee used to jump
    # to the other side of the leg in one frame (48 mm); it must swivel over the frames and still reach
    n = 200
    l1, l2 = 0.45, 0.43
    hinge = np.array([1.0, 0.0, 0.0])
    phi = np.linspace(np.radians(60.0), np.radians(120.0), n)  # bend axis angle from the hinge
    axis = np.stack([np.cos(phi), np.zeros(n), np.sin(phi)], axis=-1)
    upper = np.zeros((n, 3))
    middle = np.tile([0.0, -l1, 0.0], (n, 1))
    lower = quat.rotate(quat.exp(axis * np.radians(6.0)), np.tile([0.0, -l2, 0.0], (n, 1)))
    end = middle + lower
    q_up, q_mid = ik.two_bone_deltas(upper, middle, end, end, hinge=np.tile(hinge, (n, 1)))
    knee = quat.rotate(q_up, middle - upper) + upper
    ankle = upper + quat.rotate(q_up, (middle - upper) + quat.rotate(q_mid, lower))
    np.testing.assert_allclose(ankle, end, atol=1e-9)  # reached on every frame
    steps = np.linalg.norm(np.diff(knee, axis=0), axis=-1)
    assert steps.max() < 2e-3, f"knee moved {steps.max() * 1000:.1f} mm in one frame at {steps.argmax()}"
    # on the hinge's side at both ends: the knee bends forward (its hinge turns the shin backward)
    bend = np.cross(upper - knee, ankle - knee)
    assert np.dot(bend[0], hinge) > 0 and np.dot(bend[-1], hinge) > 0
