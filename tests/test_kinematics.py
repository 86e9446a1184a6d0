"""Forward kinematics on hand-made chains; Euler angles against scipy."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocaplab import kinematics, quat
from mocaplab.io import euler
from mocaplab.motion import Skeleton

SIX_ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
SHORT_ORDERS = ["X", "Y", "Z"] + ["".join(p) for p in itertools.permutations("XYZ", 2)]


# ------------------------------------------------------------------- Euler


@pytest.mark.parametrize("order", SIX_ORDERS + SHORT_ORDERS)
def test_euler_to_quat_matches_scipy(order, rng):
    angles = rng.uniform(-400.0, 400.0, size=(64, 5, len(order)))
    got = euler.to_quat(order, angles, degrees=True)
    expected = Rotation.from_euler(order, angles.reshape(-1, len(order)), degrees=True).as_quat()
    assert got.shape == (64, 5, 4)
    assert np.allclose(got.reshape(-1, 4), expected, atol=1e-14)


@pytest.mark.parametrize("order", SIX_ORDERS)
def test_euler_radians_and_single_triple(order, rng):
    a = rng.uniform(-np.pi, np.pi, size=3)
    expected = Rotation.from_euler(order, a).as_quat()
    assert np.allclose(euler.to_quat(order, a, degrees=False), expected, atol=1e-14)
    assert np.allclose(euler.to_quat(order.lower(), np.degrees(a)), expected, atol=1e-14)


@pytest.mark.parametrize("order", SIX_ORDERS)
def test_euler_from_quat_matches_scipy_and_round_trips(order, rng):
    q = Rotation.random(200, random_state=rng).as_quat()
    angles = euler.from_quat(order, q)
    assert np.allclose(angles, Rotation.from_quat(q).as_euler(order, degrees=True), atol=1e-10)
    back = euler.to_quat(order, angles)
    d = np.minimum(np.abs(back - q).max(-1), np.abs(back + q).max(-1))
    assert d.max() < 1e-12


def test_euler_order_is_intrinsic_in_written_order():
    # "ZYX" (a, b, c) is Rz(a) @ Ry(b) @ Rx(c): x is rotated about X first
    q = euler.to_quat("ZYX", [90.0, 0.0, 90.0])
    # Rx(90) takes y to z; Rz(90) leaves z
    assert np.allclose(quat.rotate(q, [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0], atol=1e-12)
    assert np.allclose(quat.rotate(q, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-12)


def test_euler_gimbal_lock_is_still_exact():
    q = euler.to_quat("ZYX", [30.0, 90.0, 10.0])
    back = euler.to_quat("ZYX", euler.from_quat("ZYX", q))
    assert np.allclose(quat.rotate(back, [1.0, 2.0, 3.0]), quat.rotate(q, [1.0, 2.0, 3.0]), atol=1e-9)


@pytest.mark.parametrize("order", ["", "XX", "XYX", "XYZW", "ABC", "xyzx"])
def test_euler_bad_orders(order):
    with pytest.raises(ValueError, match="Euler order"):
        euler.to_quat(order, np.zeros(max(len(order), 1)))


def test_euler_wrong_angle_count():
    with pytest.raises(ValueError, match=r"last axis 3 for order 'ZYX', got shape \(5, 2\)"):
        euler.to_quat("ZYX", np.zeros((5, 2)))
    with pytest.raises(ValueError, match="three-axis order"):
        euler.from_quat("ZY", np.array([0, 0, 0, 1.0]))


def test_euler_column_view_of_a_table(rng):
    # a non-contiguous column slice (as when reading a BVH channel table)
    table = rng.uniform(-180, 180, size=(300, 20))
    view = table[:, 2:17].reshape(300, 5, 3)
    expected = Rotation.from_euler("YXZ", view.reshape(-1, 3), degrees=True).as_quat().reshape(300, 5, 4)
    assert np.allclose(euler.to_quat("YXZ", view), expected, atol=1e-14)


# ---------------------------------------------------------------------- FK


def chain():
    """root -> a (0, 1, 0) -> b (0, 0, 2)."""
    offsets = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
    parents = np.array([-1, 0, 1])
    return offsets, parents


def test_fk_rest_pose_sums_offsets():
    offsets, parents = chain()
    rot = quat.identity((1, 3))
    grot, gpos = kinematics.fk(rot, np.array([[5.0, 0.0, 0.0]]), offsets, parents)
    assert np.allclose(gpos[0], [[5, 0, 0], [5, 1, 0], [5, 1, 2]])
    assert np.allclose(grot, quat.identity((1, 3)))


def test_fk_hand_computed_chain():
    offsets, parents = chain()
    rz90 = quat.from_axis_angle([0, 0, 1], np.pi / 2)
    rx90 = quat.from_axis_angle([1, 0, 0], np.pi / 2)
    rot = np.stack([rz90, rx90, quat.identity()])[None]  # one frame
    grot, gpos = kinematics.fk(rot, np.array([[1.0, 2.0, 3.0]]), offsets, parents)
    # a = root + Rz90 (0,1,0) = root + (-1,0,0)
    assert np.allclose(gpos[0, 1], [0.0, 2.0, 3.0])
    # b = a + Rz90 Rx90 (0,0,2): Rx90 (0,0,2) = (0,-2,0); Rz90 (0,-2,0) = (2,0,0)
    assert np.allclose(gpos[0, 2], [2.0, 2.0, 3.0])
    assert np.allclose(grot[0, 2], quat.mul(rz90, rx90))


def test_fk_translations_replace_offsets():
    offsets, parents = chain()
    rot = quat.identity((2, 3))
    tr = np.broadcast_to(offsets, (2, 3, 3)).copy()
    tr[1, 2] = [0.0, 0.0, 5.0]
    _, gpos = kinematics.fk(rot, np.zeros((2, 3)), offsets, parents, translations=tr)
    assert np.allclose(gpos[0, 2], [0, 1, 2]) and np.allclose(gpos[1, 2], [0, 1, 5])


def test_fk_branching_tree_matches_per_joint_loop(rng):
    parents = np.array([-1, 0, 1, 2, 0, 4, 0, 6, 7, 7, 9])
    offsets = rng.normal(size=(11, 3))
    rot = Rotation.random(40 * 11, random_state=rng).as_quat().reshape(40, 11, 4)
    root = rng.normal(size=(40, 3))
    grot, gpos = kinematics.fk(rot, root, offsets, parents)
    G = np.empty_like(rot)
    P = np.empty((40, 11, 3))
    G[:, 0], P[:, 0] = rot[:, 0], root
    for j in range(1, 11):
        G[:, j] = quat.mul(G[:, parents[j]], rot[:, j])
        P[:, j] = P[:, parents[j]] + quat.rotate(G[:, parents[j]], offsets[j])
    assert np.allclose(grot, G, atol=1e-14) and np.allclose(gpos, P, atol=1e-13)


def test_fk_does_not_mutate_inputs(rng):
    offsets, parents = chain()
    rot = Rotation.random(6, random_state=rng).as_quat().reshape(2, 3, 4)
    root = rng.normal(size=(2, 3))
    copies = [a.copy() for a in (rot, root, offsets, parents)]
    kinematics.fk(rot, root, offsets, parents)
    assert all(np.array_equal(a, b) for a, b in zip((rot, root, offsets, parents), copies, strict=True))


def test_fk_shape_errors():
    offsets, parents = chain()
    with pytest.raises(ValueError, match=r"`rotations` of shape \(\.\.\., J, 4\), got \(2, 3\)"):
        kinematics.fk(np.zeros((2, 3)), np.zeros((2, 3)), offsets, parents)
    with pytest.raises(ValueError, match=r"`root_positions` of shape \(3,\), got \(1, 3\)"):
        kinematics.fk(quat.identity((3,)), np.zeros((1, 3)), offsets, parents)
    with pytest.raises(ValueError, match=r"`root_positions` of shape \(1, 3\), got \(2, 3\)"):
        kinematics.fk(quat.identity((1, 3)), np.zeros((2, 3)), offsets, parents)


def test_fk_broadcasts_over_leading_axes():
    # one pose, a clip and a batch of clips give the same joints: the frame axis is not special
    rng = np.random.default_rng(3)
    offsets, parents = chain()
    rot = quat.normalize(rng.normal(size=(2, 5, 3, 4)))
    root = rng.normal(size=(2, 5, 3))
    trans = rng.normal(size=(2, 5, 3, 3))
    for t in (None, trans):
        grot, gpos = kinematics.fk(rot, root, offsets, parents, translations=t)
        assert grot.shape == (2, 5, 3, 4) and gpos.shape == (2, 5, 3, 3)
        for b in range(2):
            clip = kinematics.fk(rot[b], root[b], offsets, parents, translations=None if t is None else t[b])
            assert np.array_equal(clip[1], gpos[b]) and np.array_equal(clip[0], grot[b])
            pose = kinematics.fk(rot[b, 4], root[b, 4], offsets, parents, translations=None if t is None else t[b, 4])
            assert pose[1].shape == (3, 3) and np.array_equal(pose[1], gpos[b, 4])
    with pytest.raises(ValueError, match=r"`translations` of shape \(2, 5, 3, 3\)"):
        kinematics.fk(rot, root, offsets, parents, translations=trans[:, :4])


def test_joint_depths_one_home():
    _, parents = chain()
    sk = Skeleton([f"j{i}" for i in range(4)], [-1, 0, 1, 0], np.zeros((4, 3)))
    assert kinematics.joint_depths(np.array([-1, 0, 1, 0])).tolist() == [0, 1, 2, 1] == sk.depth().tolist()
    assert kinematics.joint_depths(parents).tolist() == list(range(len(parents)))


def test_velocities_of_linear_motion():
    t = np.arange(10) / 30.0
    pos = np.stack([2.0 * t, np.zeros_like(t), -t], axis=-1)[:, None, :]
    vel = kinematics.velocities(pos, 30.0)
    assert np.allclose(vel[:, 0], [2.0, 0.0, -1.0])
    assert np.array_equal(kinematics.velocities(pos[:1], 30.0), np.zeros((1, 1, 3)))


@pytest.mark.parametrize("order", ["ZXY", "YX", "Z"])
def test_euler_channels_component_major_matches_to_quat(order, rng):
    table = rng.uniform(-360, 360, size=(3 * 7 + 2, 50))  # (channels, frames), as a file reader holds it
    channels = [table[k : k + 3 * 7 : 3] for k in range(len(order))]  # (7, 50) views
    out = np.empty((4, 7, 50))
    euler.to_quat_channels(order, channels, out)
    angles = np.stack(channels, axis=-1)  # (7, 50, k)
    assert np.allclose(out.transpose(1, 2, 0), euler.to_quat(order, angles), atol=1e-15)


def test_angular_velocities_of_a_steady_turn_about_any_axis(rng):
    """A turn at a constant rate about a fixed tilted axis: that rate on every frame, the ends included."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    start = quat.normalize(rng.normal(size=4))
    fps, rate = 30.0, 2.5  # rad/s
    q = quat.mul(quat.from_axis_angle(np.tile(axis, (10, 1)), rate * np.arange(10) / fps), start)
    w = kinematics.angular_velocities(q, fps)
    np.testing.assert_allclose(w, np.tile(rate * axis, (10, 1)), atol=1e-9)
    # world axes: a turn of each frame seen from the joint's own frame would differ
    assert not np.allclose(quat.rotate(quat.inv(q[3]), w[3]), w[3])
    # batched over joints, and a sign flip of a quaternion changes nothing
    both = np.stack([q, -q], axis=1)
    np.testing.assert_allclose(kinematics.angular_velocities(both, fps)[:, 1], w, atol=1e-9)
    assert kinematics.angular_velocities(q[:1], fps).shape == (1, 3) and not kinematics.angular_velocities(q[:1], fps).any()
