"""The data model: validation, read-only arrays, slicing, resampling, mirroring."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mocaplab import quat
from mocaplab.motion import Motion, Skeleton, concatenate
from mocaplab.roles import mirror_name


def skeleton() -> Skeleton:
    """Hips with a left and a right leg of two joints each, end sites at the feet."""
    return Skeleton(
        names=["Hips", "LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg"],
        parents=[-1, 0, 1, 0, 3],
        offsets=[[0, 0, 0], [0.1, 0, 0], [0, -0.4, 0], [-0.1, 0, 0], [0, -0.4, 0]],
        end_site_parents=[2, 4],
        end_site_offsets=[[0.02, -0.4, 0.1], [-0.02, -0.4, 0.1]],
    )


def random_motion(rng: np.random.Generator, frames: int = 12, fps: float = 30.0) -> Motion:
    sk = skeleton()
    rot = Rotation.random(frames * sk.n_joints, random_state=rng).as_quat().reshape(frames, sk.n_joints, 4)
    root = np.cumsum(rng.normal(scale=0.01, size=(frames, 3)), axis=0) + [0, 0.9, 0]
    return Motion(sk, rot, root, fps, name="test")


# -------------------------------------------------------------- validation


def test_skeleton_validation_messages():
    with pytest.raises(ValueError, match="Expected at least one joint in `names`, got none"):
        Skeleton([], [], np.zeros((0, 3)))
    with pytest.raises(ValueError, match=re.escape("Expected unique joint names, got duplicates ['a']")):
        Skeleton(["a", "a"], [-1, 0], np.zeros((2, 3)))
    with pytest.raises(ValueError, match=re.escape("Expected parents[0] == -1 (the root), got 0")):
        Skeleton(["a", "b"], [0, 0], np.zeros((2, 3)))
    with pytest.raises(ValueError, match=re.escape("Expected 0 <= parents[j] < j, violated at joints [1]")):
        Skeleton(["a", "b", "c"], [-1, 2, 0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match=re.escape("Expected finite `offsets` of shape (2, 3), got shape (2, 2)")):
        Skeleton(["a", "b"], [-1, 0], np.zeros((2, 2)))
    with pytest.raises(ValueError, match="Invalid channels"):
        Skeleton(["a"], [-1], np.zeros((1, 3)), channels=[("Wrotation",)])


def test_motion_validation_messages():
    sk = skeleton()
    ok = quat.identity((3, 5))
    with pytest.raises(TypeError, match="Expected `skeleton` to be a Skeleton, got str"):
        Motion("hips", ok, np.zeros((3, 3)), 30.0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=re.escape("Expected `rotations` of shape (F, 5, 4) with F >= 1, got (3, 4, 4)")):
        Motion(sk, quat.identity((3, 4)), np.zeros((3, 3)), 30.0)
    with pytest.raises(ValueError, match=re.escape("Expected `rotations` of shape (F, 5, 4) with F >= 1, got (0, 5, 4)")):
        Motion(sk, np.zeros((0, 5, 4)), np.zeros((0, 3)), 30.0)
    with pytest.raises(ValueError, match=re.escape("Expected `root_positions` of shape (3, 3), got (2, 3)")):
        Motion(sk, ok, np.zeros((2, 3)), 30.0)
    bad = ok.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="Expected finite `rotations` and `root_positions`, got NaN or inf"):
        Motion(sk, bad, np.zeros((3, 3)), 30.0)
    root = np.zeros((3, 3))
    root[2, 1] = np.inf
    with pytest.raises(ValueError, match="Expected finite `rotations` and `root_positions`, got NaN or inf"):
        Motion(sk, ok, root, 30.0)
    bad = ok.copy()
    bad[2, 3] = [0, 0, 0, 2.0]
    with pytest.raises(ValueError, match="Expected unit quaternions in `rotations`, got norm 2 at frame 2, joint 'RightUpLeg'"):
        Motion(sk, bad, np.zeros((3, 3)), 30.0)
    with pytest.raises(ValueError, match=re.escape("Expected `fps` from 0.1 to 10000 frames per second, got 0")):
        Motion(sk, ok, np.zeros((3, 3)), 0)
    for fps in (float("nan"), 1e-300, 1e5, 1e300, float("inf")):
        with pytest.raises(ValueError, match=re.escape(f"Expected `fps` from 0.1 to 10000 frames per second, got {fps!r}")):
            Motion(sk, ok, np.zeros((3, 3)), fps)
    with pytest.raises(ValueError, match="number of frames per second"):
        Motion(sk, ok, np.zeros((3, 3)), "fast")
    with pytest.raises(ValueError, match=re.escape("Expected finite `translations` of shape (3, 5, 3), got (3, 5)")):
        Motion(sk, ok, np.zeros((3, 3)), 30.0, translations=np.zeros((3, 5)))


def test_nearly_unit_quaternions_are_normalised():
    sk = skeleton()
    rot = quat.identity((2, 5)) * (1 + 5e-4)
    m = Motion(sk, rot, np.zeros((2, 3)), 30.0)
    assert np.allclose(np.linalg.norm(m.rotations, axis=-1), 1.0, atol=1e-15)


# ------------------------------------------------------------ immutability


def test_arrays_are_read_only_copies(rng):
    sk = skeleton()
    rot = quat.identity((4, 5))
    root = np.zeros((4, 3))
    m = Motion(sk, rot, root, 30.0)
    rot[0, 0] = [1.0, 0, 0, 0]
    root[0] = 5.0
    assert np.array_equal(m.rotations[0, 0], [0, 0, 0, 1.0]) and np.array_equal(m.root_positions[0], [0, 0, 0])
    for arr in (m.rotations, m.root_positions, m.global_positions(), m.global_rotations(), sk.offsets, sk.parents):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[...] = 0
    with pytest.raises(AttributeError):
        m.fps = 60.0  # type: ignore[misc]


def test_replace_validates_and_shares_unchanged_arrays(rng):
    m = random_motion(rng)
    m2 = m.replace(fps=60.0)
    assert m2.fps == 60.0 and m.fps == 30.0
    assert np.shares_memory(m2.rotations, m.rotations)  # read-only, so sharing is safe
    with pytest.raises(ValueError, match="Expected `fps` from 0.1 to 10000"):
        m.replace(fps=-1.0)
    with pytest.raises(ValueError, match="Expected `fps` from 0.1 to 10000"):
        m.resample(1e300)  # refused before any array is sized by it


def test_editing_recipe_from_the_docs(rng):
    m = random_motion(rng)
    rot = np.array(m.rotations)
    rot[:, 1] = quat.identity()
    edited = m.replace(rotations=rot)
    rot[:, 2] = quat.identity()  # later changes to the copy do not leak in
    assert np.allclose(edited.rotations[:, 1], quat.identity((12,)))
    assert not np.allclose(edited.rotations[:, 2], quat.identity((12,)))
    assert not np.allclose(m.rotations[:, 1], quat.identity((12,)))


# -------------------------------------------------------------- operations


def test_sizes_and_times(rng):
    m = random_motion(rng, frames=31, fps=30.0)
    assert (m.n_frames, m.n_joints, len(m)) == (31, 5, 31)
    assert m.dt == pytest.approx(1 / 30) and m.duration == pytest.approx(1.0)
    assert np.allclose(m.times, np.arange(31) / 30)
    assert "31 frames, 5 joints, 30 fps" in repr(m)


def test_slicing(rng):
    m = random_motion(rng, frames=20)
    s = m[5:15]
    assert s.n_frames == 10 and s.fps == m.fps
    assert np.array_equal(s.rotations, m.rotations[5:15])
    assert np.allclose(s.global_positions(), m.global_positions()[5:15])
    e = m[::2]
    assert e.n_frames == 10 and e.fps == m.fps / 2
    assert np.array_equal(e.root_positions, m.root_positions[::2])
    assert m[-3:].n_frames == 3
    with pytest.raises(ValueError, match="selects no frames"):
        m[30:40]
    with pytest.raises(ValueError, match="positive slice step"):
        m[::-1]
    with pytest.raises(TypeError, match="Expected a slice of frames, got int"):
        m[3]  # type: ignore[index]


def test_concatenate(rng):
    a, b = random_motion(rng, frames=7), random_motion(rng, frames=5)
    c = concatenate([a, b])
    assert c.n_frames == 12
    assert np.array_equal(c.rotations[:7], a.rotations) and np.array_equal(c.rotations[7:], b.rotations)
    assert np.array_equal(c.root_positions[7:], b.root_positions)
    with pytest.raises(ValueError, match="at least one motion"):
        concatenate([])
    with pytest.raises(ValueError, match="Motion 1 runs at 60.0 fps, motion 0 at 30.0 fps"):
        concatenate([a, b.replace(fps=60.0)])
    other = a.replace(skeleton=a.skeleton.scaled(2.0))
    with pytest.raises(ValueError, match="Motion 1 has a different skeleton from motion 0"):
        concatenate([a, other])


def test_resample_is_exact_at_original_frames(rng):
    m = random_motion(rng, frames=13, fps=30.0)
    up = m.resample(60.0)
    assert up.fps == 60.0 and up.n_frames == 25
    d = np.abs(np.sum(up.rotations[::2] * m.rotations, axis=-1))
    assert np.allclose(d, 1.0, atol=1e-12)
    assert np.allclose(up.root_positions[::2], m.root_positions, atol=1e-14)
    assert np.allclose(up.global_positions()[::2], m.global_positions(), atol=1e-12)


def test_resample_interpolates_by_slerp():
    sk = Skeleton(["a"], [-1], np.zeros((1, 3)))
    rot = np.stack([quat.identity((1,)), quat.from_axis_angle([[0, 1, 0]], [1.0])])
    m = Motion(sk, rot, np.array([[0, 0, 0], [2.0, 0, 0]]), 10.0)
    up = m.resample(40.0)
    assert up.n_frames == 5
    assert np.allclose(quat.angle(up.rotations[:, 0]), [0, 0.25, 0.5, 0.75, 1.0], atol=1e-12)
    assert np.allclose(up.root_positions[:, 0], [0, 0.5, 1.0, 1.5, 2.0])
    down = m.resample(10.0)
    assert down.n_frames == 2 and np.allclose(down.rotations, m.rotations)


def test_mirror_name():
    assert mirror_name("LeftArm") == "RightArm"
    assert mirror_name("RightUpLeg") == "LeftUpLeg"
    assert mirror_name("lThigh") == "rThigh"
    assert mirror_name("LHipJoint") == "RHipJoint"
    assert mirror_name("Spine") == "Spine"


def test_mirror_twice_is_identity(rng):
    m = random_motion(rng)
    mm = m.mirror().mirror()
    assert np.allclose(mm.global_positions(), m.global_positions(), atol=1e-12)
    assert np.allclose(mm.skeleton.offsets, m.skeleton.offsets)


def test_mirror_swaps_sides_and_reflects_x(rng):
    m = random_motion(rng)
    mi = m.mirror()
    swap = m.skeleton.mirror_map()
    assert swap.tolist() == [0, 3, 4, 1, 2]
    p, q = m.global_positions(), mi.global_positions()
    flip = np.array([-1.0, 1.0, 1.0])
    assert np.allclose(q, p[:, swap] * flip, atol=1e-12)
    e, f = m.end_site_positions(), mi.end_site_positions()
    # end site 0 hangs from LeftLeg in both; in the mirror it shows the right foot
    assert np.allclose(f[:, 0], e[:, 1] * flip, atol=1e-12)


def test_transformed_and_with_root(rng):
    m = random_motion(rng)
    t = m.transformed(yaw=np.pi / 2, translation=(1.0, 0.0, 0.0))
    p, q = m.global_positions(), t.global_positions()
    # yaw +90 deg about Y maps (x, z) to (z, -x)
    assert np.allclose(q[..., 0], p[..., 2] + 1.0, atol=1e-12)
    assert np.allclose(q[..., 2], -p[..., 0], atol=1e-12)
    assert np.allclose(q[..., 1], p[..., 1])
    r = m.with_root(root_positions=np.zeros((12, 3)))
    assert np.allclose(r.global_positions() - r.root_positions[:, None], p - m.root_positions[:, None])


def test_operations_never_mutate_their_input(rng):
    m = random_motion(rng)
    before = [np.array(a) for a in (m.rotations, m.root_positions, m.skeleton.offsets)]
    m[2:5], m.resample(45.0), m.mirror(), m.transformed(yaw=1.0), concatenate([m, m]), m.sample([0.1, 0.2])
    m.with_root(root_rotations=quat.identity((12,)))
    after = (m.rotations, m.root_positions, m.skeleton.offsets)
    assert all(np.array_equal(a, b) for a, b in zip(before, after, strict=True))


def test_skeleton_helpers():
    sk = skeleton()
    assert sk.index("RightLeg") == 4
    with pytest.raises(KeyError, match="No joint named 'Tail'"):
        sk.index("Tail")
    assert sk.children(0) == [1, 3]
    assert sk.depth().tolist() == [0, 1, 2, 1, 2]
    assert sk.chain("Hips", "RightLeg") == [0, 3, 4]
    with pytest.raises(ValueError, match="does not descend"):
        sk.chain("LeftUpLeg", "RightLeg")
    assert np.allclose(sk.scaled(2.0).end_site_offsets, 2 * sk.end_site_offsets)


def test_chain_accepts_numpy_indices_and_rejects_bad_ones():
    sk = skeleton()
    assert sk.chain(np.int64(0), np.int64(4)) == [0, 3, 4]
    assert sk.chain(0, "RightLeg") == [0, 3, 4]
    for bad in (-1, 5):
        with pytest.raises(ValueError, match=r"Expected `start` to be a joint name or an index in \[0, 5\)"):
            sk.chain(bad, 4)
    with pytest.raises(ValueError, match="Expected `end`"):
        sk.chain(0, 9)


def test_mirror_map_pairs_acclaim_names():
    # CMU ASF/AMC names: lowercase l/r prefix on a lowercase word
    names = ["root", "lfemur", "ltibia", "rfemur", "rtibia", "lowerback", "rhand"]
    sk = Skeleton(names, [-1, 0, 1, 0, 3, 0, 5], np.zeros((7, 3)))
    assert sk.mirror_map().tolist() == [0, 3, 4, 1, 2, 5, 6]


def test_end_site_positions_rest_pose():
    sk = skeleton()
    m = Motion(sk, quat.identity((1, 5)), np.array([[0, 1.0, 0]]), 30.0)
    assert np.allclose(m.end_site_positions()[0], [[0.12, 0.2, 0.1], [-0.12, 0.2, 0.1]])


def test_sample_and_with_root_check_their_arguments(cmu):
    walk = cmu("16_15")[:20]
    with pytest.raises(ValueError, match="fps"):
        walk.sample([0.0, 0.01], fps=0)
    with pytest.raises(ValueError, match=r"root_rotations.*\(20, 4\)"):
        walk.with_root(root_rotations=np.zeros((19, 4)))


def test_concatenate_accepts_frame_rates_equal_to_file_precision(cmu):
    walk = cmu("16_15")[:10]
    from_file = walk.replace(fps=1.0 / 0.0083333)  # a BVH "Frame Time: .0083333"
    assert concatenate([walk, from_file]).n_frames == 20
    with pytest.raises(ValueError, match="fps"):
        concatenate([walk, walk.replace(fps=60.0)])


def test_public_arrays_cannot_be_made_writeable_again(rng):
    from mocaplab.contacts import Contacts
    from mocaplab.goals import Goal

    m0 = random_motion(rng)
    m = m0.replace(translations=np.broadcast_to(m0.skeleton.offsets, (m0.n_frames, m0.n_joints, 3)))
    sk = m.skeleton
    arrays = {
        "rotations": m.rotations,
        "root_positions": m.root_positions,
        "translations": m.translations,
        "offsets": sk.offsets,
        "parents": sk.parents,
        "end_site_parents": sk.end_site_parents,
        "end_site_offsets": sk.end_site_offsets,
        "global_positions": m.global_positions(),
        "global_rotations": m.global_rotations(),
        "contacts.mask": Contacts(("a",), np.zeros((4, 1), dtype=bool), 30.0).mask,
    }
    g = Goal(sk.names[2], np.zeros((m.n_frames, 3)), np.ones(m.n_frames))
    arrays.update({"goal.targets": g.targets, "goal.weights": g.weights, "goal.stiffness": g.stiffness})
    for name, a in arrays.items():
        assert not a.flags.writeable, name
        with pytest.raises(ValueError):
            a.flags.writeable = True
        with pytest.raises(ValueError):
            a[...] = 0
